"""Obstacle primitives as types: one class per kind (:mod:`kinlearn.collision.kinds`, one module each:
its dataclass, row layout, torch signed distance and compiled twin), gathered here with what is drawn
or converted of them.

Each kind is a frozen dataclass (what a user writes: :class:`Sphere`, :class:`Box`, :class:`Cylinder`,
:class:`Plane`) and a row layout (how a :class:`~kinlearn.collision.Scene` stores a batch of them, one
float row per primitive). :data:`KINDS` is the dispatch table: kind name → class, and every class
carries its torch signed distance from points (:meth:`Primitive.point_distance`), batched and
differentiable. A sphere's signed distance to a primitive is the point distance of its centre minus
its radius, exact for these convex shapes both apart and overlapping (then minus the penetration
depth). A new kind is one module in :mod:`kinlearn.collision.kinds` and its row in its table.

Row layouts (metres; ``R`` a rotation matrix, row-major, whose columns are the primitive's local axes
in the base frame):

=============  =====  ===================================================================================
kind           width  row
=============  =====  ===================================================================================
``sphere``     4      ``[x, y, z, radius]``
``box``        15     ``[cx, cy, cz, hx, hy, hz, R00, R01, …, R22]``: centre, half extents, orientation
``cylinder``   14     ``[cx, cy, cz, radius, half_length, R00, …, R22]``: axis along the local z
``plane``      4      ``[nx, ny, nz, offset]``: a unit normal, solid where n · p ≤ offset
=============  =====  ===================================================================================

A box's first six numbers are those of the axis-aligned layout ``[centre, half extents]`` that scenes
used before, so an axis-aligned box reads the same either way.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch

from ..errors import ObstacleError
from .kinds import KINDS, SCENE_KINDS, Box, Cylinder, Plane, Primitive, Sphere
from .kinds.primitive import IDENTITY, ROTATION_TOLERANCE, check_rotations, safe_sqrt

__all__ = [
    "IDENTITY",
    "KINDS",
    "ROTATION_TOLERANCE",
    "SCENE_KINDS",
    "Box",
    "Cylinder",
    "Plane",
    "Primitive",
    "Sphere",
    "aabb_half_extents",
    "check_rotations",
    "quaternion_from_rotation",
    "rotation_from_quaternion",
    "safe_sqrt",
    "shape_tensor",
]


def aabb_half_extents(kind: type[Primitive], rows: torch.Tensor) -> torch.Tensor:
    """``(..., 3)``: half extents of each primitive's axis-aligned bounding box (for a sphere its
    radius three times; for an axis-aligned box its own half extents, exactly)."""
    if kind not in SCENE_KINDS:
        raise ObstacleError(f"no bounding box for primitives of kind {kind.kind!r}")
    return kind.aabb_half_extents(rows)


def shape_tensor(kind: type[Primitive], rows: torch.Tensor) -> torch.Tensor:
    """``(..., 6)``: each primitive's extent tensor ``L = R diag(e) Rᵀ`` as ``[Lxx, Lyy, Lzz, Lxy, Lxz,
    Lyz]`` (m), ``e`` its half extents in its own frame (a sphere's radius three times, a box's half
    extents, a cylinder's ``(r, r, h)``). One tensor per shape however its frame is written (flipping an
    axis, or turning a cylinder about its own, leaves it unchanged), where a bounding box forgets which
    way a rotated box lies. Summed term by term in a fixed order (as the compiled rows are)."""
    if kind not in SCENE_KINDS:
        raise ObstacleError(f"no shape tensor for primitives of kind {kind.kind!r}")
    return kind.shape_tensor(rows)


def rotation_from_quaternion(q: Sequence[float]) -> np.ndarray:
    """``(3, 3)`` rotation of a quaternion ``[x, y, z, w]`` (normalised first; ROS's order)."""
    x, y, z, w = np.asarray(q, dtype=np.float64) / np.linalg.norm(np.asarray(q, dtype=np.float64))
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def quaternion_from_rotation(R) -> np.ndarray:
    """``[x, y, z, w]`` (w ≥ 0) of a rotation matrix ``(3, 3)``."""
    R = np.asarray(R, dtype=np.float64).reshape(3, 3)
    t = np.trace(R)
    if t > 0:
        s = 2.0 * np.sqrt(1.0 + t)
        q = [(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, s / 4]
    else:
        i = int(np.argmax(np.diag(R)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + R[i, i] - R[j, j] - R[k, k])
        q = [0.0, 0.0, 0.0, (R[k, j] - R[j, k]) / s]
        q[i] = s / 4
        q[j] = (R[j, i] + R[i, j]) / s
        q[k] = (R[k, i] + R[i, k]) / s
    q = np.asarray(q)
    return -q if q[3] < 0 else q


def box_faces(row: Sequence[float]) -> list[np.ndarray]:
    """The six faces ``(4, 3)`` of a box row (15 numbers, or 6 for an axis-aligned box), for drawing."""
    row = np.asarray(row, dtype=np.float64)
    R = row[6:15].reshape(3, 3) if row.shape[0] == 15 else np.eye(3)
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)
    corners = row[:3] + (signs * row[3:6]) @ R.T
    quads = ((0, 1, 3, 2), (4, 5, 7, 6), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5))
    return [corners[list(f)] for f in quads]


def cylinder_faces(row: Sequence[float], segments: int = 16) -> list[np.ndarray]:
    """A cylinder row (14 numbers) as ``segments`` side quads and its two caps, for drawing."""
    row = np.asarray(row, dtype=np.float64)
    R, r, h = row[5:14].reshape(3, 3), row[3], row[4]
    a = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    ring = np.stack([r * np.cos(a), r * np.sin(a), np.zeros_like(a)], axis=1)
    up = np.array([0.0, 0.0, h])
    lo = row[:3] + (ring - up) @ R.T
    hi = row[:3] + (ring + up) @ R.T
    sides = [
        np.stack([lo[i], lo[(i + 1) % segments], hi[(i + 1) % segments], hi[i]]) for i in range(segments)
    ]
    return [*sides, lo, hi]
