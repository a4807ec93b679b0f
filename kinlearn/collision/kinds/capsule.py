"""The capsule kind: the points within ``radius`` of a segment, one row ``[cx, cy, cz, radius,
half_length, R (9, row-major)]``, the segment from −half_length to +half_length along its local z."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import torch

from ...body.jit import jit
from .primitive import (
    CENTRE,
    IDENTITY,
    NET_AABB,
    NET_CYLINDER,
    NET_EXTENT,
    TINY,
    Primitive,
    beyond,
    extent_row,
    extent_tensor,
    positive,
    rotation,
    safe_sqrt,
    vec,
)

__all__ = ["AXIS", "BOUND", "HALF_LENGTH", "RADIUS", "ROTATION", "Capsule"]

#: The row's columns after its centre: radius, half length of its segment, rotation (row-major; its
#: last column is the segment's direction).
RADIUS, HALF_LENGTH, ROTATION = 3, 4, slice(5, 14)
#: The columns of the segment's direction (column 2 of R) in the row.
AXIS = [ROTATION.start + 2, ROTATION.start + 5, ROTATION.start + 8]
#: The packed row's last column: the radius of its bounding ball, radius + half length.
BOUND = 14
_RA, _HL, _A = RADIUS, HALF_LENGTH, ROTATION.start + 2


@dataclass(frozen=True)
class Capsule(Primitive):
    """A capsule: ``centre`` (3,), ``radius``, the ``half_length`` of its segment along its local z axis,
    and ``rotation`` (as for :class:`~kinlearn.collision.kinds.box.Box`; default: the segment along the
    base frame's z). The obstacle network reads it as the cylinder that holds it (radius, half length
    plus radius)."""

    kind: ClassVar[str] = "capsule"
    table: ClassVar[str] = "capsules"
    width: ClassVar[int] = 14
    layout: ClassVar[str] = "[cx, cy, cz, radius, half_length, R00, …, R22]"
    sizes: ClassVar[slice] = slice(RADIUS, HALF_LENGTH + 1)
    size_name: ClassVar[str] = "radius and half length"
    rotation_columns: ClassVar[slice] = ROTATION
    pad: ClassVar[tuple[float, ...]] = (0.0, 0.0, 0.0, 1.0, 1.0, *IDENTITY)
    packed_width: ClassVar[int] = BOUND + 1
    network_flags: ClassVar[tuple[float, float]] = (0.0, 1.0)

    centre: tuple[float, float, float]
    radius: float
    half_length: float
    rotation: tuple[float, ...] = IDENTITY

    def __post_init__(self):
        object.__setattr__(self, "centre", vec(self.centre, 3, "a capsule's centre"))
        object.__setattr__(self, "radius", positive(self.radius, "a capsule's radius"))
        object.__setattr__(self, "half_length", positive(self.half_length, "a capsule's half length"))
        object.__setattr__(self, "rotation", rotation(self.rotation, "a capsule"))

    def row(self) -> tuple[float, ...]:
        return (*self.centre, self.radius, self.half_length, *self.rotation)

    @classmethod
    def from_row(cls, row) -> Capsule:
        return cls(tuple(row[CENTRE]), row[RADIUS], row[HALF_LENGTH], tuple(row[ROTATION]))

    @staticmethod
    def point_distance(p: torch.Tensor, rows: torch.Tensor) -> torch.Tensor:
        dx, dy, dz = p[..., 0] - rows[..., 0], p[..., 1] - rows[..., 1], p[..., 2] - rows[..., 2]
        ax, ay, az = rows[..., AXIS[0]], rows[..., AXIS[1]], rows[..., AXIS[2]]
        h = rows[..., HALF_LENGTH]
        s = torch.minimum(torch.maximum(dx * ax + dy * ay + dz * az, -h), h)
        ex, ey, ez = dx - s * ax, dy - s * ay, dz - s * az
        return safe_sqrt(ex * ex + ey * ey + ez * ez) - rows[..., RADIUS]

    @staticmethod
    def aabb_half_extents(rows: torch.Tensor) -> torch.Tensor:
        a = rows[..., AXIS]
        return rows[..., RADIUS : RADIUS + 1] + rows[..., HALF_LENGTH : HALF_LENGTH + 1] * a.abs()

    @staticmethod
    def shape_tensor(rows: torch.Tensor) -> torch.Tensor:
        r = rows[..., RADIUS]
        return extent_tensor((r, r, rows[..., HALF_LENGTH] + r), rows[..., ROTATION])

    @classmethod
    def coal_shape(cls, row: np.ndarray):
        import coal

        R = np.asarray(row[ROTATION], dtype=np.float64).reshape(3, 3)
        shape = coal.Capsule(float(row[RADIUS]), 2.0 * float(row[HALF_LENGTH]))
        return shape, R, np.asarray(row[CENTRE], dtype=np.float64)


# --------------------------------------------------------------------------------------------------
# The compiled twin: packed rows are the row, then BOUND
# --------------------------------------------------------------------------------------------------


@jit
def distance(x, y, z, t, i):
    """Signed distance from the point to capsule ``i`` of table ``t``: to the nearest point of its
    segment, less its radius."""
    dx, dy, dz = x - t[i, 0], y - t[i, 1], z - t[i, 2]
    ax, ay, az = t[i, _A], t[i, _A + 3], t[i, _A + 6]
    h = t[i, _HL]
    s = min(max(dx * ax + dy * ay + dz * az, -h), h)
    ex, ey, ez = dx - s * ax, dy - s * ay, dz - s * az
    return math.sqrt(max(ex * ex + ey * ey + ez * ez, TINY)) - t[i, _RA]


@jit(inline="always")
def nearest(x, y, z, t, d):
    """min(``d``, the point's signed distance to every capsule of ``t``), culled by bounding balls."""
    for i in range(t.shape[0]):
        if not beyond(x, y, z, t, i, t[i, BOUND], d):
            d = min(d, distance(x, y, z, t, i))
    return d


@jit(inline="always")
def nearest_many(X, Y, Z, M, t, out):
    """``out[m] = min(out[m], distance of point m)`` for the first ``M`` points, capsule by capsule."""
    for i in range(t.shape[0]):
        for m in range(M):
            out[m] = min(out[m], distance(X[m], Y[m], Z[m], t, i))


@jit(inline="always")
def radius(t, i):
    """The radius of the ball about row ``i``'s centre that holds it."""
    return t[i, BOUND]


@jit(inline="always")
def pack(rows, out):
    """Packed rows ``out (n, 15)`` of rows ``(n, 14)``: each followed by radius + half length."""
    for i in range(rows.shape[0]):
        for j in range(BOUND):
            out[i, j] = rows[i, j]
        out[i, BOUND] = rows[i, _RA] + rows[i, _HL]


@jit(inline="always")
def network_count(t):
    """How many rows of the obstacle network's input the packed table ``t`` gives: one per row."""
    return t.shape[0]


@jit(inline="always")
def network_row(t, i, out, r):
    """Row ``r`` of the obstacle network's input for capsule ``i``: its centre and bounding half extents
    r + h |a| per axis (a its axis), and the extent tensor and flag of the cylinder that holds it (radius
    r, half length h + r), as :meth:`Capsule.aabb_half_extents` and :meth:`Capsule.shape_tensor`."""
    for a in range(3):
        out[r, a] = t[i, a]
        out[r, NET_AABB + a] = t[i, _RA] + t[i, _HL] * abs(t[i, _A + 3 * a])
    extent_row(out, r, NET_EXTENT, t[i, _RA], t[i, _RA], t[i, _HL] + t[i, _RA], t[i], _A - 2)
    out[r, NET_CYLINDER] = 1.0
