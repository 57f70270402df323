"""Water in a cylindrical jar: Archimedes by simulation, not by formula.

Every body in the water carries a fixed cloud of sample points filling its geometry (a regular grid, each point the
same share of the exact volume). Each physics step the points' heights follow from the body's pose (one numpy pass
per body), and a point counts as wet by the fraction of its grid cell's height that lies below the surface, inside the
jar. So
    V_sub = sum of wet fractions x point volume,      centre of buoyancy = their weighted mean,
and the body gets the force rho g V_sub upwards at the centre of buoyancy, plus drag and angular damping so that it
settles. Smoothing each point over its cell (instead of counting it as wet or dry) makes V_sub continuous in the
pose: exact for a box resting on any face and for an upright cylinder, and free of the one-layer jumps that keep a
floater bobbing forever.

A sphere wholly inside the jar (the ball, a dropped ball) needs no points: its wet part is a cap whose volume,
centroid and waterplane are closed forms of its depth, exact in any pose. The ball floats cut by the surface all
the time, so its points cost more than any object's; in closed form a drop's water step fell from ~97 to ~68 us
(four drops of the default set, same machine, 2026-12-02). Cut by the wall or the floor it falls back to its points.

The water level follows from volume conservation: L = L_water + sum_b V_sub_b(L) / A, with L_water the level of the
water alone and A the jar's cross-section. V_sub depends on L, so this is solved each step (Newton on a monotone
function, piecewise linear in the points, from the previous level; two or three iterations) over the points near
the surface only: a point more than a cell below it is wet at any level close to the last one, one above it dry.

Cost: measured against evaluating every point every step (the previous version, same machine, 2026-12-01), 120 ->
46 us per step for the ball alone (its points; now a cap) and 350 -> 125 us with a floating cylinder beside it;
`python benches/episode_speed.py` prints the cost per step of a drop episode beside pybullet's own step. With
spheres alone in the water (the ball, before and after a drop) the level is solved in Python floats, the same
operations as numpy's in the same order: the ball's water step went from ~34 to ~16 us (2026-12-02, the outcomes
of the default set's 13 simulations and a generated set's 9 the same bit for bit). A body whose bounding sphere
reaches the wall but whose posed points cannot (a bound from its pose) skips the wall's mask, and a floating sphere
skips the bounds of the wholly-wet test it cannot pass: the ball's step ~25 -> ~18 us (2026-12-07, every outcome
and pose of the default set and two generated sets the same bit for bit).

The robot's links neither float nor displace water: only registered bodies do (the dropped object and the ball).
Units: metres, kilograms, seconds (pybullet's).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np
import pybullet as p

from sim.objects import FILL, JarSpec, ObjectsConfig, ObjectSpec

CM, G = 0.01, 0.001  # the objects file's cm and g in pybullet's metres and kilograms
# a margin far above the rounding of a few float operations on lengths under a metre (~1e-16 m) and far below any
# length of the model: a bound that holds by this much holds for the computed floats too, so a test it passes
# leaves a result as it was, bit for bit
_SURE_M = 1e-9


@dataclass
class WaterConfig:
    density: float = 1000.0      # kg/m^3, fresh water
    gravity: float = 9.81        # m/s^2, must match the world's gravity
    # sample points per body (a grid over its bounding box, ~16 cells a side): the smoothed V_sub of a body in any
    # pose is within 0.5 % of its volume of exact (measured against 10^6 random points), and a step stays well under
    # a millisecond. The displacement at rest does not even depend on it: a floater at rest carries its weight, so
    # its V_sub is m / rho whatever the sampling, and a sunk object is wet all through.
    points_per_body: int = 4096
    # linear drag: a body carrying its own mass of water relaxes its velocity in this time (see `Water.step`).
    # 0.15 s damps a floater's bob in a few cycles yet lets a sinker fall at ~0.3 m/s (real water lets it fall
    # faster; the end state, which is all that is measured, is the same).
    drag_time_s: float = 0.15
    # quadratic (form) drag, relative rate Cq |v| / l with l the body's size: tames the entry splash.
    quadratic_drag: float = 0.5
    # angular damping time, same scaling: stops a floater rocking within a second.
    angular_drag_time_s: float = 0.1
    # a floater bobs at sqrt(rho g a_wp / m) (14 g float: 7 Hz) and real water damps that by radiating waves;
    # we damp it at this fraction of critical, so it is still within ~0.3 s, and the level with it.
    heave_damping_ratio: float = 0.7
    level_tolerance_m: float = 1e-10   # 0.1 nm: far below any reading, cheap to reach with Newton
    level_max_iterations: int = 30
    # a body is taken as dry / wholly wet without looking at its points when its bounding sphere is this far above /
    # below the last level: 1 cm, more than the level can move in one step (~4 mm for the widest object at 2 m/s)
    shortcut_margin_m: float = 0.01
    # the Newton iterations look only at the points of a cut body within this of the last level (plus half a cell):
    # 2 mm is ~100x the level's move per step once an object is in (~1 mm in a step only for the widest object
    # entering at 2 m/s); a level found beyond it is solved again over every point.
    level_band_m: float = 0.002


def sample_points(shape: str, size_xyz: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points filling a body (frame at its centre, z up), equal weights summing to its exact volume.

    Returns (points (N, 3), weights (N,), spacing (3,)): the grid's cell sides, from which each step takes the
    height of a cell as posed (the thickness a point stands for when the surface cuts it). Deterministic: a
    regular grid of cell centres, kept if inside the shape.
    """
    size = np.asarray(size_xyz, dtype=float)
    if shape not in FILL:
        raise ValueError(f"unknown shape {shape!r} (known: {', '.join(FILL)})")
    if size.shape != (3,) or not np.all(size > 0):
        raise ValueError(f"size_xyz must be 3 positive numbers, not {size_xyz}")
    spacing = (np.prod(size) / n) ** (1.0 / 3.0)  # cells over the bounding box; ~n*FILL of them are inside
    k = np.maximum(2, np.round(size / spacing)).astype(int)
    axes = [((np.arange(k[i]) + 0.5) / k[i] - 0.5) * size[i] for i in range(3)]
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    half = size / 2.0
    if shape == "cylinder":
        pts = pts[(pts[:, 0] / half[0]) ** 2 + (pts[:, 1] / half[1]) ** 2 <= 1.0]
    elif shape == "sphere":
        pts = pts[np.sum((pts / half) ** 2, axis=1) <= 1.0]
    volume = float(np.prod(size)) * FILL[shape]
    weights = np.full(len(pts), volume / len(pts))
    return pts, weights, size / k


def _cap(h, r):
    """A sphere's cap of depth h (0 <= h <= 2r): its volume (m^3) and the area of its flat face (m^2, dV/dh)."""
    return np.pi * h * h * (3.0 * r - h) / 3.0, np.pi * h * (2.0 * r - h)


def _clip(x: float, lo: float, hi: float) -> float:
    """np.clip of one float, the same bits (a -0.0 above lo = 0.0 is kept, as numpy keeps it)."""
    x = x if x >= lo else lo
    return x if x <= hi else hi


def quat_to_matrix(q) -> np.ndarray:
    """pybullet quaternion (x, y, z, w) -> 3x3 rotation matrix."""
    x, y, z, w = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


@dataclass
class _Body:
    points_t: np.ndarray    # (3, N) body frame, a row per axis (contiguous: one pass per axis)
    weights: np.ndarray     # (N,) m^3 each
    spacing: np.ndarray     # (3,) m, the sample grid's cell sides in the body frame
    volume: float           # m^3
    bound: float            # m, radius of a sphere about the centre holding every point's cell
    reach: float            # m, the farthest point from the centre
    half: np.ndarray        # (3,) m, the farthest point from the centre along each body axis
    size: float             # m, characteristic length for drag
    mass: float             # kg
    inertia: np.ndarray     # (3,) principal moments in the body frame, kg m^2
    v_sub: float = 0.0      # m^3, at the last step
    waterplane: float = 0.0  # m^2, the body's cross-section at the surface, at the last step
    cob: np.ndarray | None = None
    R: np.ndarray | None = None  # (3, 3) its orientation at the last step, when in water
    radius: float = 0.0     # m, a sphere's (its wet part is a cap, in closed form), else 0
    # lower bounds, in any pose, of how far a point reaches above the centre and of a cell's posed height (a unit
    # vector's components sum to at least 1): they tell that a body is not wholly wet without posing its bounds
    low_reach: float = 0.0
    low_layer: float = 0.0
    corners: np.ndarray | None = None   # (3, 8) the corners of the box of `half` extents, body frame


class Water:
    """The water of one jar; call `step()` before every `p.stepSimulation()`."""

    def __init__(self, client: int, center_xy, bottom_z: float, inner_radius: float, water_volume: float,
                 timestep: float, config: WaterConfig | None = None):
        if inner_radius <= 0 or water_volume < 0:
            raise ValueError(f"jar radius must be > 0 and water volume >= 0, not {inner_radius}, {water_volume}")
        self.client = client
        self.timestep = float(timestep)
        self.config = config or WaterConfig()
        self.center_xy = np.asarray(center_xy, dtype=float)
        self._column = (float(self.center_xy[0]), float(self.center_xy[1]), float(inner_radius))  # Python floats
        self.bottom_z = float(bottom_z)
        self.radius = float(inner_radius)
        self.area = math.pi * inner_radius ** 2
        self.water_volume = float(water_volume)
        self.bodies: dict[int, _Body] = {}
        self.level = self.bottom_z + self.water_volume / self.area  # world z of the surface

    @property
    def depth(self) -> float:
        """Height of the surface above the jar's inner bottom, m."""
        return self.level - self.bottom_z

    def add_body(self, body_id: int, shape: str, size_xyz, cloud=None):
        """Register a body (its frame at its centre, z along its axis); mass and inertia are read from pybullet.
        cloud: (points, weights, spacing) of a body that is not a solid primitive (a hollow cup: its walls only)."""
        pts, w, spacing = cloud if cloud is not None else sample_points(shape, size_xyz, self.config.points_per_body)
        info = p.getDynamicsInfo(body_id, -1, physicsClientId=self.client)
        reach = float(np.linalg.norm(pts, axis=1).max())
        bound = reach + float(np.linalg.norm(spacing)) / 2  # the points and their cells
        size = np.asarray(size_xyz, dtype=float)
        round_ = shape == "sphere" and np.ptp(size) <= 1e-12 * size[0]
        half = np.abs(pts).max(axis=0)
        self.bodies[body_id] = _Body(np.ascontiguousarray(pts.T), w, spacing, float(w.sum()), bound, reach,
                                     half, float(w.sum()) ** (1.0 / 3.0),
                                     info[0], np.asarray(info[2]), radius=float(size[0]) / 2 if round_ else 0.0,
                                     low_reach=min(float(half.min()), reach), low_layer=float(np.min(spacing)),
                                     corners=(np.array(list(itertools.product((-1.0, 1.0), repeat=3))) * half).T)

    def remove_body(self, body_id: int):
        self.bodies.pop(body_id, None)

    def submerged_volume(self, body_id: int) -> float:
        """V_sub of a body at the last step, m^3."""
        return self.bodies[body_id].v_sub

    def reset_level(self):
        """Level of the water alone (bodies are re-evaluated at the next step)."""
        self.level = self.bottom_z + self.water_volume / self.area
        for b in self.bodies.values():
            b.v_sub, b.cob = 0.0, None

    def column(self, pos) -> tuple[float, float, float]:
        """The cylinder of water a body at `pos` is in: (axis x, axis y, inner radius). One jar here; tubes joined by
        a hidden channel (sim/tubes.py) answer with the tube the body is in, sharing one level and one area."""
        return self._column

    def update_level(self) -> list:
        """Solve the level for the bodies' current poses; returns [(id, body, position)] of the bodies in water.

        A body whose bounding sphere is clear of the water (above the surface, outside the wall) is dry, and one
        whose points are all inside the wall and whose cells are all under water is wet all through (its centre of
        buoyancy is its centre, the points being centred): only bodies that the surface or the wall cuts are
        evaluated point by point, so an object on the stand, in the hand or sunk costs nothing. Of those, only the
        points within `level_band_m` of the last level (plus half a cell) enter the Newton iterations: the others
        are wet, or dry, at any level in the band; a level found outside the band is solved again over every point.
        """
        c, cl = self.config, self.client
        wet_volume, cut, caps, out = 0.0, [], [], []
        for bid, b in self.bodies.items():
            pos, orn = p.getBasePositionAndOrientation(bid, physicsClientId=cl)
            cx, cy, radius = self.column(pos)
            off_axis = math.hypot(pos[0] - cx, pos[1] - cy)
            if (off_axis - b.bound >= radius or pos[2] - b.bound >= self.level + c.shortcut_margin_m
                    or pos[2] + b.bound <= self.bottom_z):
                b.v_sub, b.waterplane, b.cob, b.R = 0.0, 0.0, None, None
                continue
            xyz, pos = pos, np.asarray(pos)
            out.append((bid, b, pos))
            b.R = R = quat_to_matrix(orn)
            if (b.radius and off_axis + b.radius < radius and xyz[2] - b.radius > self.bottom_z
                    and xyz[2] + b.low_reach + 0.5 * b.low_layer > self.level - c.shortcut_margin_m + _SURE_M):
                caps.append((b, xyz))   # a whole sphere in the jar, surely not wholly wet: its wet part is a cap
                continue
            up = np.abs(R[2])
            layer = float(up @ b.spacing)                  # the height of a grid cell as posed
            reach_z = min(float(up @ b.half), b.reach)     # no point lies farther above or below the centre
            walled = off_axis + b.reach >= radius          # a point may be outside the wall
            floored = pos[2] - reach_z <= self.bottom_z    # or below the bottom
            if not (walled or floored) and pos[2] + reach_z + 0.5 * layer < self.level - c.shortcut_margin_m:
                b.v_sub, b.waterplane, b.cob = b.volume, 0.0, pos
                wet_volume += b.volume
                continue
            if b.radius and off_axis + b.radius < radius and pos[2] - b.radius > self.bottom_z:
                caps.append((b, xyz))   # a whole sphere in the jar: its wet part is a cap
                continue
            z = R[2] @ b.points_t + pos[2]
            w = b.weights
            if walled and off_axis + self._across(R, b) + _SURE_M < radius:
                walled = False   # the bounding sphere reaches the wall, but no point does: each is inside (True)
            if walled:
                x, y = R[0] @ b.points_t + (pos[0] - cx), R[1] @ b.points_t + (pos[1] - cy)
                w = w * ((x * x + y * y < radius ** 2) & (z > self.bottom_z))
            elif floored:   # the same product: a mask that is True for every point is left out of it
                w = w * (z > self.bottom_z)
            cut.append((b, pos, z, w, layer))
        base = self.bottom_z + (self.water_volume + wet_volume) / self.area
        if not cut and not caps:
            self.level = base
            return out
        bottoms = [pos[2] - b.radius for b, pos in caps]
        radii = [b.radius for b, _ in caps]
        for band in (c.level_band_m, math.inf):
            lo, hi = self.level - band, self.level + band
            parts = []
            for b, pos, z, w, layer in cut:
                wet = z < lo - 0.5 * layer                               # wet at every level from lo up
                near = np.flatnonzero((z < hi + 0.5 * layer) ^ wet)     # the rest below hi + half a cell
                parts.append((w[near], z[near], layer, float(w @ wet), wet, near))   # (those above stay dry)
            L = self._solve(base, parts, bottoms, radii)
            if lo <= L <= hi or not cut:
                break
        self.level = L
        for (b, pos), bottom in zip(caps, bottoms):
            r = b.radius
            h = _clip(L - bottom, 0.0, 2.0 * r)
            b.v_sub, b.waterplane = _cap(h, r)
            # the cap's centroid lies 3 (2r - h)^2 / (4 (3r - h)) below the centre (r for h -> 0, 0 for h = 2r)
            # (pos - [0, 0, that] as numpy subtracts, in Python floats: x - 0.0 is x, -0.0 too)
            b.cob = np.array((pos[0] - 0.0, pos[1] - 0.0, pos[2] - 3.0 * (2.0 * r - h) ** 2 / (4.0 * (3.0 * r - h)))) \
                if h > 0 else None
        for (b, pos, _, w, _), (w_near, z_near, layer, _, wet, near) in zip(cut, parts):
            u = 0.5 + (L - z_near) / layer
            share = w * wet                       # each point's wet volume
            share[near] = w_near * np.minimum(np.maximum(u, 0.0), 1.0)   # np.clip's arithmetic (see _solve_points)
            b.v_sub = float(share.sum())
            b.waterplane = float(w_near @ ((u > 0) & (u < 1))) / layer  # dV_sub/dL: the area the surface cuts
            b.cob = b.R @ (b.points_t @ share) / b.v_sub + pos if b.v_sub > 0 else None
        return out

    @staticmethod
    def _across(R: np.ndarray, b: _Body) -> float:
        """How far any point of `b` posed by R lies from its centre across the vertical, at most: every point lies in
        the box of its `half` extents, whose farthest point across the vertical is a corner (the distance is convex),
        and never farther than the farthest point."""
        h = R[:2] @ b.corners
        return min(float(np.sqrt(h[0] * h[0] + h[1] * h[1]).max()), b.reach)

    def _solve(self, base: float, parts: list, bottoms: list, radii: list) -> float:
        """Newton on L = base + V_sub(L) / A (monotone), from the last level. parts: per cut body (weights and
        heights of the points near the surface, the cell height, the volume wet below them, ...); bottoms, radii:
        the spheres taken in closed form (their lowest point and radius)."""
        if not parts and 0 < len(radii) < 8:
            return self._solve_caps(base, bottoms, radii)
        return self._solve_points(base, parts, bottoms, radii)

    def _solve_points(self, base: float, parts: list, bottoms: list, radii: list) -> float:
        """The points' part in numpy; the spheres' caps (fewer than 8) in Python floats as in `_solve_caps` (the
        same bits as numpy's), and the points' clip as maximum then minimum, which is np.clip's arithmetic (u is
        never -0.0: it is 0.5 plus a number) without its Python wrapper."""
        c = self.config
        if len(radii) >= 8:
            return self._solve_points_numpy(base, parts, np.array(bottoms), np.array(radii))
        w, z, layer, fixed = self._stacked(base, parts)
        w_per_layer = w / layer
        maximum, minimum, area, L = np.maximum, np.minimum, self.area, self.level
        for _ in range(c.level_max_iterations):
            u = 0.5 + (L - z) / layer
            cap = face = 0.0   # numpy's sum of no caps; of one, that cap; of a few, left to right
            for k, (bottom, r) in enumerate(zip(bottoms, radii)):
                v, a = _cap(_clip(L - bottom, 0.0, 2.0 * r), r)
                cap, face = (v, a) if k == 0 else (cap + v, face + a)
            f = L - fixed - (float(w @ minimum(maximum(u, 0.0), 1.0)) + cap) / area
            slope = 1.0 - (float(w_per_layer @ ((u > 0) & (u < 1))) + face) / area
            step = f / slope
            L -= step
            if abs(step) < c.level_tolerance_m:
                break
        return L

    def _stacked(self, base: float, parts: list):
        """The bodies' sample points as one set (weights, heights, layer thickness) and the level the water would
        have with only what is fixed (the base and each body's volume wholly under)."""
        if not parts:
            w = z = layer = np.zeros(0)
        elif len(parts) == 1:
            w, z, layer = parts[0][:3]
        else:
            w, z = np.concatenate([x[0] for x in parts]), np.concatenate([x[1] for x in parts])
            layer = np.concatenate([np.full(len(x[1]), x[2]) for x in parts])
        return w, z, layer, base + sum(x[3] for x in parts) / self.area

    def _solve_points_numpy(self, base: float, parts: list, bottoms: np.ndarray, radii: np.ndarray) -> float:
        c = self.config
        w, z, layer, fixed = self._stacked(base, parts)
        w_per_layer = w / layer
        L = self.level
        for _ in range(c.level_max_iterations):
            u = 0.5 + (L - z) / layer
            cap, face = _cap(np.clip(L - bottoms, 0.0, 2.0 * radii), radii)
            f = L - fixed - (w @ np.clip(u, 0.0, 1.0) + cap.sum()) / self.area
            slope = 1.0 - (w_per_layer @ ((u > 0) & (u < 1)) + face.sum()) / self.area
            step = f / slope
            L -= step
            if abs(step) < c.level_tolerance_m:
                break
        return L

    def _solve_caps(self, base: float, bottoms: list, radii: list) -> float:
        """`_solve` with 1-7 spheres alone (the ball, mostly), in Python floats: the same operations in the same
        order as numpy's (np.clip keeps a -0.0, a short sum runs left to right), so the same level bit for bit, in
        less time (numpy's calls cost more than its arithmetic here)."""
        c, area = self.config, self.area
        fixed = base + 0 / area
        L = self.level
        for _ in range(c.level_max_iterations):
            cap = face = None
            for bottom, r in zip(bottoms, radii):
                v, a = _cap(_clip(L - bottom, 0.0, 2.0 * r), r)
                cap, face = (v, a) if cap is None else (cap + v, face + a)
            f = L - fixed - (0.0 + cap) / area
            slope = 1.0 - (0.0 + face) / area
            step = f / slope
            L -= step
            if abs(step) < c.level_tolerance_m:
                break
        return L

    def step(self):
        """Update the level and push every wet body: buoyancy at its centre of buoyancy, drag, angular damping.

        Drag is a relaxation of the body's velocity at the rate k = (rho V_sub / m) (1 / drag_time + Cq |v| / l),
        applied as the exact exponential decay over one timestep, so it never reverses a velocity however light
        the body (an explicit drag force on a 14 g float pushed under would blow up). Same for the spin.
        """
        c, dt, cl = self.config, self.timestep, self.client
        for bid, b, pos in self.update_level():
            if b.v_sub <= 0.0:
                continue
            m_water = c.density * b.v_sub
            p.applyExternalForce(bid, -1, [0.0, 0.0, m_water * c.gravity], b.cob.tolist(), p.WORLD_FRAME,
                                 physicsClientId=cl)
            (vx, vy, vz), w = p.getBaseVelocity(bid, physicsClientId=cl)
            ratio = m_water / b.mass
            k = ratio * (1.0 / c.drag_time_s + c.quadratic_drag * math.sqrt(vx * vx + vy * vy + vz * vz) / b.size)
            decay = b.mass * (1.0 - math.exp(-k * dt)) / dt
            # heave: a body cut by the surface bobs at sqrt(rho g a_wp / m); damp that at the chosen ratio
            k_heave = 2.0 * c.heave_damping_ratio * math.sqrt(c.density * c.gravity * b.waterplane / b.mass)
            heave = b.mass * (1.0 - math.exp(-k_heave * dt)) / dt
            p.applyExternalForce(bid, -1, [-decay * vx, -decay * vy, -(decay + heave) * vz], pos.tolist(),
                                 p.WORLD_FRAME, physicsClientId=cl)
            k_ang = ratio / c.angular_drag_time_s
            torque = b.R @ (b.inertia * (b.R.T @ w)) * (-(1.0 - math.exp(-k_ang * dt)) / dt)  # -I_world w (...)
            p.applyExternalTorque(bid, -1, torque.tolist(), p.WORLD_FRAME, physicsClientId=cl)


@dataclass
class TankConfig:
    """The jar, its water and the green ball, and how the physics is stepped and judged settled."""
    timestep_s: float = 1.0 / 240.0        # pybullet's default; stable for 14 g bodies in contact at this size
    solver_iterations: int = 50            # pybullet's default; enough for a few stacked light bodies
    gravity: float = 9.81
    wall_thickness_cm: float = 0.5         # glass jar walls
    bottom_thickness_cm: float = 1.0
    # the round wall as a ring of flat staves: 32 keep the polygon's area within 0.3 % of the circle's
    staves: int = 32
    jar_rgba: tuple = (0.75, 0.85, 0.95, 0.3)
    water_rgba: tuple = (0.2, 0.45, 0.9, 0.35)
    # a ping-pong ball (40 mm, 2.7 g): floats high (0.7 cm draft) and every object the file admits fits beside
    # it (sim/objects.py checks against the same diameter)
    ball_diameter_cm: float = ObjectsConfig.ball_diameter_cm
    ball_mass_g: float = 2.7
    ball_rgb: tuple = (0.1, 0.75, 0.15)
    object_friction: float = 0.6           # wood/plastic on glass
    wall_friction: float = 0.2             # wet glass: low, so nothing hangs on the wall instead of floating
    # settled: every body in the water moves slower than these, and the level changes by less than
    # settle_level_cm, over settle_windows windows in a row of settle_window_steps each (see run_until_settled).
    # 1 mm/s: a floater bobbing that fast moves the level by < 0.02 cm^3.
    settle_speed_m_s: float = 0.001
    settle_spin_rad_s: float = 0.02
    settle_level_cm: float = 0.001       # the level reading's resolution (sim/world.py), 0.1 cm^3 in a 12 cm jar
    settle_window_steps: int = 24        # 0.1 s: a bobbing float (period 0.14 s for 14 g) cannot look still
    settle_windows: int = 2
    # everything of the default set is still within ~1 s of its release; only a jammed object would need more
    settle_timeout_s: float = 10.0
    water: WaterConfig = field(default_factory=WaterConfig)


def _draft_sphere_m(radius: float, volume: float) -> float:
    """Depth of a sphere's cap holding `volume` (bisection: the cap volume grows with depth)."""
    lo, hi = 0.0, 2.0 * radius
    for _ in range(60):
        h = 0.5 * (lo + hi)
        lo, hi = (h, hi) if math.pi * h * h * (3 * radius - h) / 3.0 < volume else (lo, h)
    return 0.5 * (lo + hi)


def round_visual(client: int, shape: str, radius: float, length: float, rgb, segments: int = 64) -> int:
    """A finely tessellated visual mesh for a cylinder (axis z) or a sphere, as the camera should see it.

    pybullet's own GEOM_SPHERE visual is a coarse polygon (a 5 cm sphere looks 4.75 cm across its flats) and its
    GEOM_CYLINDER visual is ~1 mm larger than the collision cylinder, so the camera measured the renderer's
    meshes, not the objects. With 64 segments the outline is within 0.12 % of the circle."""
    n, verts, normals, idx = segments, [], [], []
    if shape == "sphere":
        rings = n // 2
        for i in range(rings + 1):
            th = math.pi * i / rings
            for j in range(n):
                ph = 2 * math.pi * j / n
                u = [math.sin(th) * math.cos(ph), math.sin(th) * math.sin(ph), math.cos(th)]
                normals.append(u)
                verts.append([radius * c for c in u])
        for i in range(rings):
            for j in range(n):
                a, b = i * n + j, i * n + (j + 1) % n
                idx += [a, a + n, b, b, a + n, b + n]
    else:
        h = length / 2
        for j in range(n):  # the wall: two rings with radial normals
            ph = 2 * math.pi * j / n
            c, s = math.cos(ph), math.sin(ph)
            verts += [[radius * c, radius * s, -h], [radius * c, radius * s, h]]
            normals += [[c, s, 0.0], [c, s, 0.0]]
        for j in range(n):
            a, b = 2 * j, 2 * ((j + 1) % n)
            idx += [a, b, a + 1, b, b + 1, a + 1]
        for z, sign in ((-h, -1.0), (h, 1.0)):  # the caps: a fan around their centre
            centre = len(verts)
            verts.append([0.0, 0.0, z])
            normals.append([0.0, 0.0, sign])
            for j in range(n):
                ph = 2 * math.pi * j / n
                verts.append([radius * math.cos(ph), radius * math.sin(ph), z])
                normals.append([0.0, 0.0, sign])
            for j in range(n):
                a, b = centre + 1 + j, centre + 1 + (j + 1) % n
                idx += [centre, a, b] if sign > 0 else [centre, b, a]
    return p.createVisualShape(p.GEOM_MESH, vertices=verts, indices=idx, normals=normals, rgbaColor=[*rgb, 1],
                               physicsClientId=client)


def make_body(client: int, shape: str, size_xyz_m, mass_kg: float, rgb, pos, friction: float) -> int:
    """A uniform-density primitive with its exact inertia (z along a cylinder's axis)."""
    sx, sy, sz = (float(v) for v in size_xyz_m)
    if shape == "cylinder":
        col = p.createCollisionShape(p.GEOM_CYLINDER, radius=sx / 2, height=sz, physicsClientId=client)
        vis = round_visual(client, "cylinder", sx / 2, sz, rgb)
        r2 = (sx / 2) ** 2
        inertia = [mass_kg * (3 * r2 + sz * sz) / 12] * 2 + [mass_kg * r2 / 2]
    elif shape == "sphere":
        col = p.createCollisionShape(p.GEOM_SPHERE, radius=sx / 2, physicsClientId=client)
        vis = round_visual(client, "sphere", sx / 2, sx, rgb)
        inertia = [0.4 * mass_kg * (sx / 2) ** 2] * 3
    else:  # cube, box
        half = [sx / 2, sy / 2, sz / 2]
        col = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=client)
        vis = p.createVisualShape(p.GEOM_BOX, halfExtents=half, rgbaColor=[*rgb, 1], physicsClientId=client)
        inertia = [mass_kg * (sy * sy + sz * sz) / 12, mass_kg * (sx * sx + sz * sz) / 12,
                   mass_kg * (sx * sx + sy * sy) / 12]
    body = p.createMultiBody(mass_kg, col, vis, list(pos), physicsClientId=client)
    p.changeDynamics(body, -1, localInertiaDiagonal=inertia, lateralFriction=friction, rollingFriction=1e-4,
                     spinningFriction=1e-4, restitution=0.0, linearDamping=0.0, angularDamping=0.0,
                     physicsClientId=client)
    return body


def tube_mesh(r_in: float, r_out: float, z_bottom: float, z_top: float, n: int) -> tuple[list, list]:
    """Triangles of an open glass: inner and outer wall, rim, and a floor at z_bottom (outer wall down to 0)."""
    verts = []
    for i in range(n):
        a = 2 * math.pi * i / n
        for r, z0 in ((r_in, z_bottom), (r_out, 0.0)):
            verts += [[r * math.cos(a), r * math.sin(a), z0], [r * math.cos(a), r * math.sin(a), z_top]]
    verts += [[0.0, 0.0, z_bottom], [0.0, 0.0, 0.0]]  # floor centres, inside and underneath
    centre_in, centre_out = 4 * n, 4 * n + 1

    def v(i, wall, top):  # wall 0: inner, 1: outer
        return (i % n) * 4 + wall * 2 + top

    tris = []
    for i in range(n):
        for wall in (0, 1):
            a, b, c, d = v(i, wall, 0), v(i + 1, wall, 0), v(i + 1, wall, 1), v(i, wall, 1)
            tris += [a, b, c, a, c, d] if wall else [a, c, b, a, d, c]  # faces point out of the glass
        a, b, c, d = v(i, 0, 1), v(i + 1, 0, 1), v(i + 1, 1, 1), v(i, 1, 1)
        tris += [a, b, c, a, c, d]                                       # rim
        tris += [centre_in, v(i, 0, 0), v(i + 1, 0, 0)]                  # floor, seen from inside
        tris += [centre_out, v(i + 1, 1, 0), v(i, 1, 0)]                 # underside
    return verts, tris


class Tank:
    """A glass jar of water with the green ball floating in it; steps the physics with the water's forces.

    `jar.water_depth_cm` is the level at the start *with the ball floating*: that is what the robot sees, and what
    `sim.objects.archimedes_cm3` starts from. So the water alone is A * depth - (the ball's displaced volume).
    """

    def __init__(self, client: int, jar: JarSpec, center_xy, floor_z: float, config: TankConfig | None = None):
        self.client, self.jar = client, jar
        self.config = c = config or TankConfig()
        if c.ball_diameter_cm > jar.inner_diameter_cm - 2 * ObjectsConfig.fit_clearance_cm:
            raise ValueError(f"jar inner_diameter_cm {jar.inner_diameter_cm} is too narrow for the "
                             f"{c.ball_diameter_cm} cm ball")
        draft_cm = self.ball_draft_cm(c)
        if jar.water_depth_cm <= draft_cm:   # the objects file asks for more (ObjectsConfig.min_water_depth_cm)
            raise ValueError(f"jar water_depth_cm {jar.water_depth_cm} is too shallow for the ball to float (its "
                             f"draft is {draft_cm:.2f} cm)")
        p.setGravity(0, 0, -c.gravity, physicsClientId=client)  # the water's forces assume these two
        p.setPhysicsEngineParameter(fixedTimeStep=c.timestep_s, numSolverIterations=c.solver_iterations,
                                    physicsClientId=client)
        self.center = np.array([center_xy[0], center_xy[1], floor_z], dtype=float)
        R, t, H = jar.inner_diameter_cm / 2 * CM, c.wall_thickness_cm * CM, jar.height_cm * CM
        self.bottom_z = floor_z + c.bottom_thickness_cm * CM  # the inner bottom, where the water starts
        self.rim_z = self.bottom_z + H
        self.jar_body = self._make_jar(R, t, H)
        self.ball_volume = c.ball_mass_g * G / c.water.density
        water_volume = math.pi * R * R * jar.water_depth_cm * CM - self.ball_volume
        self.water = Water(client, center_xy, self.bottom_z, R, water_volume, c.timestep_s, c.water)
        d = c.ball_diameter_cm * CM
        self.ball = make_body(client, "sphere", [d] * 3, c.ball_mass_g * G, c.ball_rgb, self.ball_rest_pos(),
                              c.object_friction)
        self.water.add_body(self.ball, "sphere", [d] * 3)
        self.water_visual = self._make_water_visual(R)

    @staticmethod
    def ball_draft_cm(config: TankConfig) -> float:
        """How deep the green ball floats in still water, cm."""
        r = config.ball_diameter_cm * CM / 2
        return _draft_sphere_m(r, config.ball_mass_g * G / config.water.density) / CM

    def _make_jar(self, R: float, t: float, H: float) -> int:
        """One static body: a round bottom plate and a ring of thin staves; it looks like a glass tube.

        pybullet keeps at most 16 parts per compound shape (and crashes on long visual arrays), so the staves
        ride on fixed links, 16 per link, and the look is one mesh.
        """
        c, n, bt = self.config, self.config.staves, self.config.bottom_thickness_cm * CM
        width = 2 * (R + t) * math.tan(math.pi / n) * 1.02  # outer edges overlap a little: no gaps
        cl = self.client
        walls = []
        for first in range(0, n, 16):
            idx = range(first, min(n, first + 16))
            walls.append(p.createCollisionShapeArray(
                [p.GEOM_BOX] * len(idx), halfExtents=[[t / 2, width / 2, H / 2]] * len(idx),
                collisionFramePositions=[[(R + t / 2) * math.cos(2 * math.pi * i / n),
                                          (R + t / 2) * math.sin(2 * math.pi * i / n), bt + H / 2] for i in idx],
                collisionFrameOrientations=[p.getQuaternionFromEuler([0, 0, 2 * math.pi * i / n]) for i in idx],
                physicsClientId=cl))
        bottom = p.createCollisionShape(p.GEOM_CYLINDER, radius=R + t, height=bt,
                                        collisionFramePosition=[0, 0, bt / 2], physicsClientId=cl)
        verts, tris = tube_mesh(R, R + t, bt, bt + H, n)
        vis = p.createVisualShape(p.GEOM_MESH, vertices=verts, indices=tris, rgbaColor=list(c.jar_rgba),
                                  physicsClientId=cl)
        k = len(walls)
        body = p.createMultiBody(0, bottom, vis, self.center.tolist(), linkMasses=[0] * k,
                                 linkCollisionShapeIndices=walls, linkVisualShapeIndices=[-1] * k,
                                 linkPositions=[[0, 0, 0]] * k, linkOrientations=[[0, 0, 0, 1]] * k,
                                 linkInertialFramePositions=[[0, 0, 0]] * k,
                                 linkInertialFrameOrientations=[[0, 0, 0, 1]] * k, linkParentIndices=[0] * k,
                                 linkJointTypes=[p.JOINT_FIXED] * k, linkJointAxis=[[0, 0, 1]] * k,
                                 physicsClientId=cl)
        for link in range(-1, k):
            p.changeDynamics(body, link, lateralFriction=c.wall_friction, restitution=0.0, physicsClientId=cl)
        for link in range(k):  # pybullet draws a link without a visual shape as its collision shape: hide it
            p.changeVisualShape(body, link, rgbaColor=[1, 1, 1, 0], physicsClientId=cl)
        return body

    def _make_water_visual(self, R: float) -> int:
        """Visual only, as tall as the jar; its top is moved to the level (the rest hides under the floor)."""
        vis = p.createVisualShape(p.GEOM_CYLINDER, radius=R * 0.995, length=self.jar.height_cm * CM,
                                  rgbaColor=list(self.config.water_rgba), physicsClientId=self.client)
        body = p.createMultiBody(0, -1, vis, [0, 0, -10], physicsClientId=self.client)
        self.sync_visuals(body)
        return body

    def sync_visuals(self, body: int | None = None):
        """Move the water's visual so its top is at the current level."""
        z = self.water.level - self.jar.height_cm * CM / 2
        p.resetBasePositionAndOrientation(self.water_visual if body is None else body,
                                          [self.center[0], self.center[1], z], [0, 0, 0, 1],
                                          physicsClientId=self.client)

    def ball_rest_pos(self) -> list:
        """The ball floating at rest on the jar's axis at the start level."""
        r = self.config.ball_diameter_cm * CM / 2
        draft = _draft_sphere_m(r, self.ball_volume)
        return [self.center[0], self.center[1], self.bottom_z + self.jar.water_depth_cm * CM + r - draft]

    @property
    def level_cm(self) -> float:
        """The current water depth above the inner bottom, cm (exact: the robot's reading is in the world)."""
        return self.water.depth / CM

    def reset(self):
        """Water back to its start level, the ball back at rest on the axis."""
        p.resetBasePositionAndOrientation(self.ball, self.ball_rest_pos(), [0, 0, 0, 1], physicsClientId=self.client)
        p.resetBaseVelocity(self.ball, [0, 0, 0], [0, 0, 0], physicsClientId=self.client)
        self.water.reset_level()
        self.water.update_level()
        self.sync_visuals()

    def add_object(self, spec: ObjectSpec, pos, orn=(0, 0, 0, 1)) -> int:
        """An object of the file as a pybullet body, registered with the water."""
        size = spec.size_xyz_cm * CM
        body = make_body(self.client, spec.shape, size, spec.mass_g * G, spec.rgb, pos, self.config.object_friction)
        p.resetBasePositionAndOrientation(body, list(pos), list(orn), physicsClientId=self.client)
        self.water.add_body(body, spec.shape, size)
        return body

    def step(self):
        """One physics step: the water's forces, then pybullet."""
        self.water.step()
        p.stepSimulation(physicsClientId=self.client)

    def poses(self) -> dict:
        """Pose of every body in the water: {id: (position (3,), quaternion xyzw (4,))}."""
        return {bid: tuple(np.asarray(x) for x in p.getBasePositionAndOrientation(bid, physicsClientId=self.client))
                for bid in self.water.bodies}

    def moved_less_than(self, before: dict, seconds: float) -> bool:
        """Every body in the water moved and turned slower than the settle thresholds since `before` (poses).

        Judged on poses over a window, not on pybullet's reported velocities: a box resting on the bottom shows
        ~1 mm/s of contact jitter in its velocity while its pose drifts by microns.
        """
        c = self.config
        now = self.poses()
        for bid, (pos, orn) in before.items():
            if bid not in now:
                continue
            dq = p.getDifferenceQuaternion(orn.tolist(), now[bid][1].tolist(), physicsClientId=self.client)
            angle = 2.0 * math.atan2(np.linalg.norm(dq[:3]), abs(dq[3]))
            moved = np.linalg.norm(now[bid][0] - pos)
            if moved > c.settle_speed_m_s * seconds or angle > c.settle_spin_rad_s * seconds:
                return False
        return True

    def run_until_settled(self, on_step=None) -> tuple[bool, int]:
        """Step until settled or until the timeout; returns (settled, steps taken).

        Settled: over each of `settle_windows` windows in a row of `settle_window_steps`, every body in the water
        moved slower than the settle thresholds and the level changed by less than `settle_level_cm`.
        `on_step(i)` is called after every step (for recording frames).
        """
        c = self.config
        max_steps = int(round(c.settle_timeout_s / c.timestep_s))
        seconds = c.settle_window_steps * c.timestep_s
        quiet, poses, level = 0, self.poses(), self.level_cm
        for i in range(max_steps):
            self.step()
            if on_step is not None:
                on_step(i)
            if (i + 1) % c.settle_window_steps == 0:
                still = self.moved_less_than(poses, seconds) and abs(self.level_cm - level) < c.settle_level_cm
                quiet = quiet + 1 if still else 0
                if quiet >= c.settle_windows:
                    return True, i + 1
                poses, level = self.poses(), self.level_cm
        return False, max_steps
