"""The engine's truth about a body, for tests and benches only: the oracle perception is judged against.

Read from pybullet's own records (collision shape, dynamics, visual colour), never from what the camera or the
hand sensed. Nothing the runner calls imports this module (tests/test_perception.py checks the run path's sources).
"""

from __future__ import annotations

import math

import numpy as np
import pybullet as p


def truth(client: int, body: int) -> dict:
    """{rgb, extent_cm (sorted descending), fill, mass_g} of a single-primitive body, from the engine."""
    shapes = p.getCollisionShapeData(body, -1, physicsClientId=client)
    if len(shapes) != 1:
        raise ValueError(f"body {body} has {len(shapes)} collision shapes; the oracle reads single primitives")
    kind, dims = shapes[0][2], shapes[0][3]
    if kind == p.GEOM_BOX:
        size, fill = np.asarray(dims, dtype=float), 1.0
    elif kind == p.GEOM_CYLINDER:
        size, fill = np.array([2 * dims[1], 2 * dims[1], dims[0]]), math.pi / 4
    elif kind == p.GEOM_SPHERE:
        size, fill = np.full(3, 2.0 * dims[0]), math.pi / 6
    else:
        raise ValueError(f"body {body}: the oracle reads boxes, cylinders and spheres, not shape type {kind}")
    rgba = p.getVisualShapeData(body, physicsClientId=client)[0][7]
    return {"rgb": np.asarray(rgba[:3], dtype=float), "extent_cm": np.sort(size * 100.0)[::-1].copy(),
            "fill": float(fill), "mass_g": float(p.getDynamicsInfo(body, -1, physicsClientId=client)[0] * 1000.0)}


def aabb_top(client: int, body: int) -> np.ndarray:
    """(3,) the middle of the body's bounding box at the height of its top: where the hand should go."""
    lo, hi = (np.asarray(v) for v in p.getAABB(body, -1, physicsClientId=client))
    return np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, hi[2]])
