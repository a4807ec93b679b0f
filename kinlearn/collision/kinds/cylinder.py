"""The cylinder kind: a solid cylinder, one row ``[cx, cy, cz, radius, half_length, R (9, row-major)]``,
its axis along its local z."""

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
    local,
    positive,
    rotation,
    safe_sqrt,
    vec,
)

__all__ = ["AXIS", "BOUND", "HALF_LENGTH", "RADIUS", "ROTATION", "Cylinder"]

#: The row's columns after its centre: radius, half length, rotation (row-major; its columns are the
#: local axes in the base frame, the last one the cylinder's axis).
RADIUS, HALF_LENGTH, ROTATION = 3, 4, slice(5, 14)
#: The columns of the axis (column 2 of R) in the row.
AXIS = [ROTATION.start + 2, ROTATION.start + 5, ROTATION.start + 8]
#: The packed row's last column: the radius of its bounding ball, hypot(radius, half length).
BOUND = 14
_RA, _HL, _R = RADIUS, HALF_LENGTH, ROTATION.start


@dataclass(frozen=True)
class Cylinder(Primitive):
    """A solid cylinder: ``centre`` (3,), ``radius``, ``half_length`` along its local z axis, and
    ``rotation`` (as for :class:`~kinlearn.collision.kinds.box.Box`; default: the axis along the base
    frame's z)."""

    kind: ClassVar[str] = "cylinder"
    table: ClassVar[str] = "cylinders"
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
        object.__setattr__(self, "centre", vec(self.centre, 3, "a cylinder's centre"))
        object.__setattr__(self, "radius", positive(self.radius, "a cylinder's radius"))
        object.__setattr__(self, "half_length", positive(self.half_length, "a cylinder's half length"))
        object.__setattr__(self, "rotation", rotation(self.rotation, "a cylinder"))

    @property
    def axis(self) -> tuple[float, float, float]:
        """The cylinder's axis (its local z) in the base frame."""
        R = self.rotation
        return (R[2], R[5], R[8])

    def row(self) -> tuple[float, ...]:
        return (*self.centre, self.radius, self.half_length, *self.rotation)

    @classmethod
    def from_row(cls, row) -> Cylinder:
        return cls(tuple(row[CENTRE]), row[RADIUS], row[HALF_LENGTH], tuple(row[ROTATION]))

    @staticmethod
    def point_distance(p: torch.Tensor, rows: torch.Tensor) -> torch.Tensor:
        x, y, z = local(p, rows, ROTATION)
        radial = safe_sqrt(x * x + y * y) - rows[..., RADIUS]
        axial = z.abs() - rows[..., HALF_LENGTH]
        o_r, o_a = radial.clamp_min(0.0), axial.clamp_min(0.0)
        return safe_sqrt(o_r * o_r + o_a * o_a) + torch.maximum(radial, axial).clamp_max(0.0)

    @staticmethod
    def aabb_half_extents(rows: torch.Tensor) -> torch.Tensor:
        a = rows[..., AXIS]
        r, h = rows[..., RADIUS : RADIUS + 1], rows[..., HALF_LENGTH : HALF_LENGTH + 1]
        return r * safe_sqrt(1.0 - a * a) + h * a.abs()

    @staticmethod
    def shape_tensor(rows: torch.Tensor) -> torch.Tensor:
        r, h = rows[..., RADIUS], rows[..., HALF_LENGTH]
        return extent_tensor((r, r, h), rows[..., ROTATION])

    @classmethod
    def coal_shape(cls, row: np.ndarray):
        import coal

        R = np.asarray(row[ROTATION], dtype=np.float64).reshape(3, 3)
        shape = coal.Cylinder(float(row[RADIUS]), 2.0 * float(row[HALF_LENGTH]))
        return shape, R, np.asarray(row[CENTRE], dtype=np.float64)


# --------------------------------------------------------------------------------------------------
# The compiled twin: packed rows are the row, then BOUND
# --------------------------------------------------------------------------------------------------


@jit
def distance(x, y, z, t, i):
    """Signed distance from the point to cylinder ``i`` of table ``t``: with a = ρ − radius and
    b = |z| − half length in its frame, √(max(a, 0)² + max(b, 0)²) + min(max(a, b), 0)."""
    dx, dy, dz = x - t[i, 0], y - t[i, 1], z - t[i, 2]
    lx = dx * t[i, _R] + dy * t[i, _R + 3] + dz * t[i, _R + 6]
    ly = dx * t[i, _R + 1] + dy * t[i, _R + 4] + dz * t[i, _R + 7]
    lz = dx * t[i, _R + 2] + dy * t[i, _R + 5] + dz * t[i, _R + 8]
    radial = math.sqrt(max(lx * lx + ly * ly, TINY)) - t[i, _RA]
    axial = abs(lz) - t[i, _HL]
    o_r, o_a = max(radial, 0.0), max(axial, 0.0)
    return math.sqrt(max(o_r * o_r + o_a * o_a, TINY)) + min(max(radial, axial), 0.0)


@jit(inline="always")
def nearest(x, y, z, t, d):
    """min(``d``, the point's signed distance to every cylinder of ``t``), culled by bounding balls."""
    for i in range(t.shape[0]):
        if not beyond(x, y, z, t, i, t[i, BOUND], d):
            d = min(d, distance(x, y, z, t, i))
    return d


@jit(inline="always")
def nearest_many(X, Y, Z, M, t, out):
    """``out[m] = min(out[m], distance of point m)`` for the first ``M`` points, cylinder by cylinder."""
    for i in range(t.shape[0]):
        for m in range(M):
            out[m] = min(out[m], distance(X[m], Y[m], Z[m], t, i))


@jit(inline="always")
def radius(t, i):
    """The radius of the ball about row ``i``'s centre that holds it."""
    return t[i, BOUND]


@jit(inline="always")
def pack(rows, out):
    """Packed rows ``out (n, 15)`` of rows ``(n, 14)``: each followed by hypot(radius, half length)."""
    for i in range(rows.shape[0]):
        for j in range(BOUND):
            out[i, j] = rows[i, j]
        out[i, BOUND] = math.hypot(rows[i, _RA], rows[i, _HL])


@jit(inline="always")
def network_count(t):
    """How many rows of the obstacle network's input the packed table ``t`` gives: one per row."""
    return t.shape[0]


@jit(inline="always")
def network_row(t, i, out, r):
    """Row ``r`` of the obstacle network's input for cylinder ``i``: centre, bounding half extents
    r √(1 − a²) + h |a| per axis (a its axis), extent tensor of (r, r, h) and the is-cylinder flag."""
    for a in range(3):
        out[r, a] = t[i, a]
        ax = t[i, _R + 2 + 3 * a]  # the axis: column 2 of R
        out[r, NET_AABB + a] = t[i, _RA] * math.sqrt(max(1.0 - ax * ax, TINY)) + t[i, _HL] * abs(ax)
    extent_row(out, r, NET_EXTENT, t[i, _RA], t[i, _RA], t[i, _HL], t[i], _R)
    out[r, NET_CYLINDER] = 1.0
