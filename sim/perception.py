"""What the robot senses about an object: the measurement dict the agent's encoder consumes.

    {"rgb": (3,) in 0..1, "extent_cm": (3,) sorted descending, "fill": float, "mass_g": float}

- rgb: the mean pixel colour of the object's segmentation mask in a small camera image, rendered with flat
  lighting (ambient only) so that a surface's pixels carry its own colour, not the light's.
- extent_cm: the sides of the object's axis-aligned bounding box as it stands at rest (it stands unrotated on the
  stand, so the box is tight), sorted descending: what the eye measures whatever the pose.
- fill: volume / bounding-box volume of its collision geometry (1 box, pi/4 cylinder, pi/6 sphere): the shape cue.
- mass_g: the weight felt when lifting (sim/episode.py), not from here.
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
    """The robot's eye on the stand: a small image is enough for a mean colour and cheap to render."""
    width: int = 96
    height: int = 96
    fov_deg: float = 40.0           # a 26 cm wide view at 35 cm: the largest object fills a third of it
    eye_offset: tuple = (-0.20, 0.0, 0.30)   # m from the object's centre: from the robot's side, from above
    near: float = 0.02
    far: float = 2.0


def render(client: int, eye, target, width: int, height: int, fov_deg: float, near: float = 0.02,
           far: float = 3.0, flat: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """One TinyRenderer image: (rgb (H, W, 3) uint8, segmentation (H, W) int: body id of each pixel, -1 none).

    flat=True: ambient light only, so a pixel's colour is its surface's colour."""
    view = p.computeViewMatrix(list(eye), list(target), [0, 0, 1], physicsClientId=client)
    proj = p.computeProjectionMatrixFOV(fov_deg, width / height, near, far, physicsClientId=client)
    light = dict(lightAmbientCoeff=1.0, lightDiffuseCoeff=0.0, lightSpecularCoeff=0.0) if flat else \
        dict(lightAmbientCoeff=0.6, lightDiffuseCoeff=0.5, lightSpecularCoeff=0.05, lightDirection=[0.6, -0.8, 2.0])
    _, _, rgba, _, seg = p.getCameraImage(width, height, view, proj, renderer=p.ER_TINY_RENDERER, shadow=0,
                                          physicsClientId=client, **light)
    rgba = np.asarray(rgba, dtype=np.uint8).reshape(height, width, 4)
    seg = np.asarray(seg, dtype=np.int64).reshape(height, width)
    body = np.where(seg >= 0, seg & ((1 << 24) - 1), -1)  # pybullet packs (link + 1) << 24 | body
    return rgba[:, :, :3].copy(), body


def mean_colour(client: int, body: int, camera: CameraConfig = CameraConfig()) -> np.ndarray:
    """(3,) mean colour in 0..1 of the pixels showing `body`, seen from camera.eye_offset."""
    centre = np.asarray(p.getBasePositionAndOrientation(body, physicsClientId=client)[0])
    rgb, seg = render(client, centre + np.asarray(camera.eye_offset), centre, camera.width, camera.height,
                      camera.fov_deg, camera.near, camera.far, flat=True)
    mask = seg == body
    if not mask.any():
        raise RuntimeError(f"body {body} is not in view of the perception camera")
    return rgb[mask].astype(np.float64).mean(axis=0) / 255.0


def extent_cm(client: int, body: int) -> np.ndarray:
    """(3,) sides of the body's bounding box in cm, sorted descending (tight for an unrotated body)."""
    lo, hi = p.getAABB(body, -1, physicsClientId=client)
    return np.sort((np.asarray(hi) - np.asarray(lo)) * 100.0)[::-1].copy()


def fill(client: int, body: int) -> float:
    """Volume / bounding-box volume of the body's (single, primitive) collision shape."""
    shapes = p.getCollisionShapeData(body, -1, physicsClientId=client)
    if len(shapes) != 1:
        raise ValueError(f"body {body} has {len(shapes)} collision shapes; fill needs exactly one primitive")
    kind = shapes[0][2]
    ratio = {p.GEOM_BOX: 1.0, p.GEOM_CYLINDER: math.pi / 4.0, p.GEOM_SPHERE: math.pi / 6.0}.get(kind)
    if ratio is None:
        raise ValueError(f"body {body}: fill is defined for box, cylinder and sphere shapes, not type {kind}")
    return ratio


def measure(client: int, body: int, mass_g: float, camera: CameraConfig = CameraConfig()) -> dict:
    """The measurement dict for a body standing at rest, given the mass felt when it was lifted."""
    return {"rgb": mean_colour(client, body, camera), "extent_cm": extent_cm(client, body),
            "fill": float(fill(client, body)), "mass_g": float(mass_g)}
