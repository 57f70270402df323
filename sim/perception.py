"""What the robot senses about an object on the stand, from two camera images: the measurement dict the agent's
encoder consumes.

    {"rgb": (3,) in 0..1, "extent_cm": (3,) sorted descending, "fill": float, "mass_g": float}

Nothing here reads the engine's answers about the object (no AABB, collision shape or base pose): only rendered
images (colour, depth buffer, segmentation mask) and what the robot knows of its own workspace, where its stand is
and how high its top is (`Workspace`). The segmentation mask stands in for figure-ground segmentation.

Two views (`CameraConfig`), each one TinyRenderer image (~15 ms each; the world hides the robot from them,
`World.robot_unseen`, whose meshes would triple that, and the table and the floor, whose area doubled it):
1. a side view from the robot's right (-y), 10 degrees above the horizontal, aimed at the stand (rolled 15 degrees
   about its axis, so upright edges cross the pixel grid): a fixed glance that finds the object (where it is, how
   wide, how tall) and gives its side profile;
2. a top view straight down, from 30 cm above the object's top, centred and zoomed on what the glance found (so a
   1.5 cm cube is ~100 pixels across and a 9 cm box ~200), as an eye that turns and zooms onto the object.
The iCub's head sits behind the stand and cannot look from these two places; they stand for a head that moves
around the stand (or a stand that turns), which is what a real robot would do to measure an object.

Each pixel under the mask is back-projected to a world point: camera intrinsics from the projection matrix
(P[0,0], P[1,1]), depth linearised from the nonlinear depth buffer, z = far near / (far - (far - near) d).
- extent_cm: height = the top view's highest point above the stand top (depth along a vertical optical axis is
  height itself); the two horizontal sides = the minimum-area rectangle (rotating calipers over the convex hull)
  of the top view's outline, each boundary pixel taken as its square (its four corners back-projected at its
  depth), which makes the outline unbiased to +-half a pixel. So a box turned about z, or lying on its side, is
  measured along its own sides. Sorted descending.
- fill (volume / bounding-box volume): the top silhouette's area over its rectangle's area (a disc: pi/4), times
  the side profile's mean of (width(z) / widest)^2 over the height (a cylinder or box: 1, a sphere: 2/3), where
  widest is the top view's outline as the side camera sees it (between its two grazing rays), capped at 1. This
  is exact when every horizontal cross-section is the footprint scaled (prisms standing on a face, spheres): cube
  and box 1, upright cylinder pi/4, sphere pi/6. A cylinder lying on its side breaks that assumption (it would
  read about 1); no object of the experiment lies on its side (objects stand as their dims describe them).
- rgb: the mean colour of the top view's pixels under the mask, rendered with flat light (ambient only), so a
  pixel carries its surface's colour, not the light's.
- mass_g: the weight felt when lifting (sim/episode.py, sim/world.py `weigh`), not from here.
The agent never sees the file's labels: nothing here reads an ObjectSpec.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pybullet as p

MEASUREMENT_KEYS = ("rgb", "extent_cm", "fill", "mass_g")


@dataclass(frozen=True)
class CameraConfig:
    """The two views. Image sizes barely change the cost (a render is ~20 ms whatever its size: the scene's meshes)
    but set the precision: at 256 px the side view sees 0.7 mm per pixel, the zoomed top view 0.1-0.6 mm."""
    width: int = 256                  # both views are square, this many pixels a side
    near: float = 0.05                # near/far of the depth buffer: 30x apart keeps it fine (~1e-7 m in float32)
    far: float = 1.5
    side_distance: float = 0.45       # m from the stand's axis
    side_azimuth_deg: float = -90.0   # from -y, the robot's right: nothing of the robot or the jar in between
    side_elevation_deg: float = 10.0  # low, so the profile sees the lower half of a sphere; above 0 so the stand
                                      # top never hides the object's foot
    side_roll_deg: float = 15.0       # the camera rolled about its axis: an upright edge then crosses the pixel
                                      # columns, so the rows' half-pixel errors average out along it instead of
                                      # all being the same (a 2 cm cube's fill was off by 0.07 without)
    side_field_cm: float = 20.0       # wide enough for a 12.7 cm footprint diagonal and a 12 cm tall object
    side_aim_cm: float = 6.0          # aimed this far above the stand top
    top_distance: float = 0.30        # m above the object's top
    top_field: float = 1.5            # the top view's field = this x the glance's largest width + top_pad_cm
    top_pad_cm: float = 1.0           # (the glance sees a sphere's front, so its centre can be off by 0.2 widths)
    min_pixels: int = 30              # fewer object pixels than this in a view: not seen


@dataclass(frozen=True)
class Workspace:
    """What the robot knows of its own workspace (not of the object): where the stand is and its top's height."""
    stand_xy: tuple
    stand_top_z: float


@dataclass
class View:
    """One rendered image with what is needed to back-project it."""
    rgb: np.ndarray        # (H, W, 3) uint8
    depth: np.ndarray      # (H, W) metres along the optical axis
    seg: np.ndarray        # (H, W) body id per pixel, -1 none
    cam_to_world: np.ndarray  # (4, 4)
    fx: float              # P[0,0], P[1,1]: x_ndc = fx x_cam / z, in the projection matrix's terms
    fy: float

    def back_project(self, rows, cols, du=0.0, dv=0.0) -> np.ndarray:
        """(N, 3) world points at pixel (row, col) offset by (dv, du) pixels from its centre, at its depth."""
        h, w = self.depth.shape
        z = self.depth[rows, cols]
        x_ndc = (2.0 * (cols + 0.5 + du) / w) - 1.0
        y_ndc = 1.0 - (2.0 * (rows + 0.5 + dv) / h)
        cam = np.stack([x_ndc * z / self.fx, y_ndc * z / self.fy, -z, np.ones_like(z)], axis=-1)
        return (cam @ self.cam_to_world.T)[:, :3]

    def pixel_size(self, z) -> float:
        """Side of one pixel, in metres, on a plane facing the camera at depth z."""
        return 2.0 * z / (self.fx * self.depth.shape[1])


@dataclass
class Percept:
    """What the robot saw: the measurement (mass not yet felt) and where the object's top is, for the hand."""
    measurement: dict
    top_centre: np.ndarray  # (3,) world: the middle of the object's footprint at the height of its top
    height_m: float


def render(client: int, eye, target, width: int, height: int, fov_deg: float, near: float = 0.02,
           far: float = 3.0, flat: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """One TinyRenderer image: (rgb (H, W, 3) uint8, segmentation (H, W) int: body id of each pixel, -1 none).

    flat=True: ambient light only, so a pixel's colour is its surface's colour."""
    v = take_view(client, eye, target, [0, 0, 1], fov_deg, width, height, near, far, flat)
    return v.rgb, v.seg


def take_view(client: int, eye, target, up, fov_deg: float, width: int, height: int, near: float, far: float,
              flat: bool = True) -> View:
    """Render one image with its depth (linearised) and segmentation, and the matrices to back-project it."""
    view = p.computeViewMatrix(list(map(float, eye)), list(map(float, target)), list(map(float, up)),
                               physicsClientId=client)
    proj = p.computeProjectionMatrixFOV(fov_deg, width / height, near, far, physicsClientId=client)
    light = dict(lightAmbientCoeff=1.0, lightDiffuseCoeff=0.0, lightSpecularCoeff=0.0) if flat else \
        dict(lightAmbientCoeff=0.6, lightDiffuseCoeff=0.5, lightSpecularCoeff=0.05, lightDirection=[0.6, -0.8, 2.0])
    _, _, rgba, depth, seg = p.getCameraImage(width, height, view, proj, renderer=p.ER_TINY_RENDERER, shadow=0,
                                              physicsClientId=client, **light)
    rgba = np.asarray(rgba, dtype=np.uint8).reshape(height, width, 4)
    seg = np.asarray(seg, dtype=np.int64).reshape(height, width)
    body = np.where(seg >= 0, seg & ((1 << 24) - 1), -1)  # pybullet packs (link + 1) << 24 | body
    d = np.asarray(depth, dtype=np.float64).reshape(height, width)
    z = far * near / (far - (far - near) * d)             # the depth buffer is nonlinear in distance
    V = np.asarray(view, dtype=np.float64).reshape(4, 4).T  # pybullet's matrices are column-major
    P = np.asarray(proj, dtype=np.float64).reshape(4, 4).T
    return View(rgba[:, :, :3].copy(), z, body, np.linalg.inv(V), float(P[0, 0]), float(P[1, 1]))


# -- geometry ---------------------------------------------------------------------------------------------------------

def convex_hull(xy: np.ndarray) -> np.ndarray:
    """(K, 2) vertices of the convex hull of (N, 2) points, counter-clockwise (Andrew's monotone chain)."""
    pts = np.unique(np.round(np.asarray(xy, dtype=np.float64), 12), axis=0)  # sorted by x, then y
    if len(pts) <= 2:
        return pts

    def half(seq):
        out = []
        for q in seq:
            while len(out) >= 2 and ((out[-1][0] - out[-2][0]) * (q[1] - out[-2][1])
                                     - (out[-1][1] - out[-2][1]) * (q[0] - out[-2][0])) <= 0:
                out.pop()
            out.append(q)
        return out

    lst = pts.tolist()
    lower, upper = half(lst), half(lst[::-1])
    return np.asarray(lower[:-1] + upper[:-1])


def min_area_rect(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """The smallest-area rectangle around (N, 2) points: (centre (2,), sides (2,) longest first, angle of the
    longest side in radians). Rotating calipers: the best rectangle has a side along a hull edge."""
    hull = convex_hull(xy)
    if len(hull) < 3:
        raise ValueError("min_area_rect needs points spanning an area")
    edges = np.roll(hull, -1, axis=0) - hull
    angles = np.unique(np.mod(np.arctan2(edges[:, 1], edges[:, 0]), np.pi / 2))
    c, s = np.cos(angles), np.sin(angles)
    u = hull[None, :, 0] * c[:, None] + hull[None, :, 1] * s[:, None]     # along the edge
    v = -hull[None, :, 0] * s[:, None] + hull[None, :, 1] * c[:, None]    # across it
    du, dv = u.max(1) - u.min(1), v.max(1) - v.min(1)
    k = int(np.argmin(du * dv))
    cu, cv = (u[k].max() + u[k].min()) / 2, (v[k].max() + v[k].min()) / 2
    centre = np.array([cu * c[k] - cv * s[k], cu * s[k] + cv * c[k]])
    if du[k] >= dv[k]:
        return centre, np.array([du[k], dv[k]]), float(angles[k])
    return centre, np.array([dv[k], du[k]]), float(angles[k] + np.pi / 2)


def _mask(view: View, body: int, what: str, min_pixels: int) -> np.ndarray:
    mask = view.seg == body
    if mask.sum() < min_pixels:
        raise RuntimeError(f"body {body} is not in the {what} view")
    if mask[0].any() or mask[-1].any() or mask[:, 0].any() or mask[:, -1].any():
        raise RuntimeError(f"body {body} does not fit in the {what} view (it touches the image border)")
    return mask


# -- the two views ---------------------------------------------------------------------------------------------------

def side_view(client: int, body: int, ws: Workspace, cam: CameraConfig) -> dict:
    """The glance from the side: where the object is, how wide and tall, and its width at each height."""
    az, el = math.radians(cam.side_azimuth_deg), math.radians(cam.side_elevation_deg)
    aim = np.array([ws.stand_xy[0], ws.stand_xy[1], ws.stand_top_z + cam.side_aim_cm / 100.0])
    toward = np.array([math.cos(az) * math.cos(el), math.sin(az) * math.cos(el), math.sin(el)])
    fwd = -np.array([math.cos(az), math.sin(az), 0.0])         # horizontal, away from the camera
    right = np.array([fwd[1], -fwd[0], 0.0])                   # horizontal, to the camera's right
    roll = math.radians(cam.side_roll_deg)
    up = math.cos(roll) * np.array([0.0, 0.0, 1.0]) + math.sin(roll) * right
    for widen in (1.0, 2.0, 4.0):   # a tall box seen edge-on from the side looks narrow: zoom out   # an object too big for the usual field (taller than ~14 cm): look again, wider
        fov = math.degrees(2 * math.atan(widen * cam.side_field_cm / 200.0 / cam.side_distance))
        view = take_view(client, aim + cam.side_distance * toward, aim, up, fov, cam.width, cam.width,
                         cam.near, cam.far)
        try:
            mask = _mask(view, body, "side", cam.min_pixels)
            break
        except RuntimeError as e:
            if widen > 1.0 or "not in the" in str(e):
                raise
    rows, cols = np.nonzero(mask)
    pts = view.back_project(rows, cols)
    a, f = pts @ right, pts @ fwd
    centre = (a.min() + a.max()) / 2 * right + (f.min() + f.max()) / 2 * fwd
    # the outline's left and right ends of each image row, each pixel as its square (half a pixel beyond its
    # centre), at their depth: (height, lateral position) pairs tracing the object's two sides
    r_idx = np.nonzero(mask.any(axis=1))[0]
    first = np.argmax(mask[r_idx], axis=1)
    last = mask.shape[1] - 1 - np.argmax(mask[r_idx, ::-1], axis=1)
    lpts, rpts = view.back_project(r_idx, first, du=-0.5), view.back_project(r_idx, last, du=+0.5)
    return {"centre_xy": centre[:2], "width": float(max(a.max() - a.min(), f.max() - f.min())),
            "top_z": float(pts[:, 2].max()), "left": (lpts[:, 2], lpts @ right), "right": (rpts[:, 2], rpts @ right),
            "lateral": right[:2], "fwd": fwd[:2], "view": view}


def top_view(client: int, body: int, centre_xy, top_z: float, width: float, cam: CameraConfig,
             widen: float = 1.0) -> View:
    half = (cam.top_field * width + cam.top_pad_cm / 100.0) / 2 * widen
    eye = [centre_xy[0], centre_xy[1], top_z + cam.top_distance]
    fov = math.degrees(2 * math.atan(half / cam.top_distance))
    return take_view(client, eye, [centre_xy[0], centre_xy[1], top_z - 0.05], [1, 0, 0], fov, cam.width,
                     cam.width, cam.near, cam.far)


def profile_factor(left, right, bottom: float, top: float, bins: int, widest: float) -> float:
    """Mean over the height of (width(z) / widest)^2 from the side view: 1 for a prism, 2/3 for a sphere.

    left, right: (heights, lateral positions) of the two sides' outline points. Each side is binned by height
    (bins about one image row tall; its outermost point in each bin), an empty bin takes its nearest neighbour's,
    and the width is right - left. `widest` comes from the top view's outline, measured to a fraction of a pixel,
    not from the noisiest of these bins."""
    centres = np.arange(bins) + 0.5

    def side(z, a, sign):
        k = np.clip(((z - bottom) / (top - bottom) * bins).astype(np.int64), 0, bins - 1)
        out = np.full(bins, -np.inf)
        np.maximum.at(out, k, sign * a)
        ok = np.isfinite(out)
        return sign * np.interp(centres, centres[ok], out[ok])

    w = side(*right, 1.0) - side(*left, -1.0)
    return float(np.mean((w / widest) ** 2))


def support(xy: np.ndarray, n: np.ndarray, px: float) -> float:
    """How far an outline (the centres of its boundary pixels, xy) reaches along the unit vector n, to a fraction
    of a pixel: along a straight edge at angle t to the pixel grid, the centres of the pixels on the boundary
    (8-neighbourhood) lie between 0 and |cos t| + |sin t| pixels inside it, evenly, so the edge is their mean
    distance plus half that (+-half a pixel along the grid, exact in the mean)."""
    t = (abs(n[0]) + abs(n[1])) * px   # the digital edge's thickness along n
    d = xy @ n
    return float(d[d >= d.max() - t].mean()) + t / 2


def width_seen_from(xy: np.ndarray, px: float, eye_xy, fwd, right) -> float:
    """The footprint outline's width across a side camera's view as that camera sees it: the lateral positions
    where the two rays from its eye that graze the outline touch it. In perspective a box turned a little shows
    the corner that faces the camera, not the one behind, so its orthographic width would be too wide. Each
    grazing point is placed to a fraction of a pixel by `support` across its ray."""
    d = xy - np.asarray(eye_xy)[None, :]
    ang = np.arctan2(d @ right, d @ fwd)
    lateral = []
    for k, sign in ((int(np.argmax(ang)), 1.0), (int(np.argmin(ang)), -1.0)):
        th = ang[k]
        n = sign * (-math.sin(th) * np.asarray(fwd) + math.cos(th) * np.asarray(right))  # across the ray, outward
        q = xy[k] + (support(xy, n, px) - xy[k] @ n) * n
        lateral.append(float(q @ right))
    return lateral[0] - lateral[1]


def outline(view: View, mask: np.ndarray) -> tuple[np.ndarray, float]:
    """The centres of the mask's boundary pixels (8-neighbourhood) back-projected, xy (N, 2), and the pixel size
    at their depth."""
    inner = np.zeros_like(mask)
    inner[1:-1, 1:-1] = np.logical_and.reduce([mask[1 + dr:mask.shape[0] - 1 + dr, 1 + dc:mask.shape[1] - 1 + dc]
                                               for dr in (-1, 0, 1) for dc in (-1, 0, 1)])
    br, bc = np.nonzero(mask & ~inner)
    return view.back_project(br, bc)[:, :2], view.pixel_size(float(np.median(view.depth[br, bc])))


def outline_rect(xy: np.ndarray, px: float) -> tuple[np.ndarray, np.ndarray]:
    """The footprint's rectangle from its outline: (centre xy (2,), sides (2,) longest first). The smallest
    rectangle around the pixel centres gives the orientation, `support` places each side."""
    _, _, angle = min_area_rect(xy)
    u = np.array([math.cos(angle), math.sin(angle)])
    v = np.array([-u[1], u[0]])
    eu, e_u, ev, e_v = (support(xy, n, px) for n in (u, -u, v, -v))
    return (eu - e_u) / 2 * u + (ev - e_v) / 2 * v, np.sort([eu + e_u, ev + e_v])[::-1]


def look(client: int, body: int, ws: Workspace, camera: CameraConfig = CameraConfig()) -> Percept:
    """Look at the object standing on the stand: colour, extents, fill, and where its top is."""
    side = side_view(client, body, ws, camera)
    for widen in (1.0, 2.0, 4.0):   # a tall box seen edge-on from the side looks narrow: zoom out
        top = top_view(client, body, side["centre_xy"], side["top_z"], side["width"], camera, widen)
        try:
            mask = _mask(top, body, "top", camera.min_pixels)
            break
        except RuntimeError:
            if widen == 4.0:
                raise
    rows, cols = np.nonzero(mask)
    eye_z = top.cam_to_world[2, 3]
    top_z = float(eye_z - top.depth[rows, cols].min())  # the optical axis is vertical: depth is height
    height = top_z - ws.stand_top_z
    xy, px = outline(top, mask)
    centre, sides = outline_rect(xy, px)
    # the silhouette's area on the plane of its outline (a sphere's is its widest circle, not its top)
    top_fill = len(rows) * px * px / (sides[0] * sides[1])
    widest = width_seen_from(xy, px, side["view"].cam_to_world[:2, 3], side["fwd"], side["lateral"])
    bins = int(np.clip(round(height / side["view"].pixel_size(camera.side_distance)), 8, 256))
    prof = profile_factor(side["left"], side["right"], ws.stand_top_z, top_z, bins, widest)
    rgb = top.rgb[mask].astype(np.float64).mean(axis=0) / 255.0
    extent = np.sort(np.array([sides[0], sides[1], height]) * 100.0)[::-1].copy()
    m = {"rgb": rgb, "extent_cm": extent, "fill": float(min(top_fill * prof, 1.0)), "mass_g": 0.0}
    return Percept(m, np.array([centre[0], centre[1], top_z]), float(height))


def measure(client: int, body: int, mass_g: float, ws: Workspace, camera: CameraConfig = CameraConfig()) -> dict:
    """The measurement dict for a body standing at rest on the stand, given the mass felt when it was lifted."""
    return {**look(client, body, ws, camera).measurement, "mass_g": float(mass_g)}


def rests_on_bottom(client: int, body: int, hidden: tuple, jar_xy, bottom_z: float, direction_xy,
                    tolerance_m: float = 0.006, fov_deg: float = 50.0, size: int = 128) -> bool:
    """What the robot sees in the jar once everything is still: does the object lie on the bottom (it sank) or
    float? One side view through the glass, level with the jar's lower part, from 35 cm away along `direction_xy`
    (from the jar; across the line from the robot to the jar, so neither the robot's body nor the ball at the far
    wall stands in front of the object); the glass and the water are see-through to the eye (their visuals,
    `hidden` body ids, are made invisible for the render and restored). The object sank when its lowest visible
    point is within `tolerance_m` (two pixels) of the jar's inner bottom: a floater rides at least its draft above
    it. An object the view does not show at all did not sink: the view holds the whole inner bottom of any jar the
    objects file admits (at most 29 cm wide: its nearest edge 20.5 cm from the eye, where the view reaches 9.5 cm
    below its centre, 6 cm above the bottom; tests/test_world.py), so what lies on the bottom is in it, and a
    floater in deep water (the file admits up to 44 cm of it) rides above it."""
    saved = []
    for b in hidden:
        rgba = p.getVisualShapeData(b, physicsClientId=client)[0][7]
        saved.append((b, rgba))
        p.changeVisualShape(b, -1, rgbaColor=[*rgba[:3], 0.0], physicsClientId=client)
    try:
        centre = np.array([jar_xy[0], jar_xy[1], bottom_z + 0.06])
        d = np.asarray(direction_xy, dtype=float)
        eye = centre + np.append(d / np.linalg.norm(d) * 0.35, 0.0)
        view = take_view(client, eye, centre, [0, 0, 1], fov_deg, size, size, 0.02, 2.0)
    finally:
        for b, rgba in saved:
            p.changeVisualShape(b, -1, rgbaColor=list(rgba), physicsClientId=client)
    rows, cols = np.nonzero(view.seg == body)
    if len(rows) == 0:
        return False    # nothing of it near the bottom: it floats above the view
    lowest = view.back_project(rows, cols, dv=0.5)[:, 2].min()   # each pixel's lower edge
    return bool(lowest - bottom_z < tolerance_m)


def perceive_tube(client: int, contents: int, tube_xy, bottom_z: float, rim_z: float,
                  camera: CameraConfig = CameraConfig(), fov_deg: float = 25.0) -> dict:
    """A tube of the Aesop battery (sim/tubes.py) seen from straight above its mouth: what fills it.

    contents: the body of its water (the visual) or its bed, segmented as an object is. The robot knows where the
    tube stands, its floor and its rim (its workspace), not what is in it. Returns {"width_cm": the contents' outline
    across (the tube's inner width), "level_cm": the surface's height above the floor (the median of its pixels'
    back-projected heights: a floating reward's pixels are not the contents'), "substrate_rgb": their mean colour in
    flat light}. 25 degrees from 30 cm above the rim holds a 13 cm wide tube."""
    x, y = float(tube_xy[0]), float(tube_xy[1])
    v = take_view(client, [x, y, rim_z + 0.30], [x, y, bottom_z], [1, 0, 0], fov_deg, camera.width, camera.width,
                  camera.near, camera.far)
    mask = _mask(v, contents, "tube", 20)
    xy, px = outline(v, mask)
    _, sides = outline_rect(xy, px)
    rows, cols = np.nonzero(mask)
    z = v.back_project(rows, cols)[:, 2]
    return {"width_cm": float(np.mean(sides)) * 100.0, "level_cm": float(np.median(z) - bottom_z) * 100.0,
            "substrate_rgb": [float(c) for c in v.rgb[mask].mean(axis=0) / 255.0]}
