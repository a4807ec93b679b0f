"""The box kind: a box in any orientation, one row ``[cx, cy, cz, hx, hy, hz, R (9, row-major)]``."""

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

__all__ = ["BOUND", "HALF", "ROTATION", "Box"]

#: The row's columns after its centre: half extents along its local axes, its rotation (row-major;
#: its columns are the local axes in the base frame).
HALF, ROTATION = slice(3, 6), slice(6, 15)
#: The packed row's last column: the radius of its bounding ball, ‖half extents‖.
BOUND = 15
_H, _R = HALF.start, ROTATION.start


@dataclass(frozen=True)
class Box(Primitive):
    """A box in any orientation: ``centre`` (3,), ``half_extents`` (3,) along its local axes, and
    ``rotation`` (3 × 3 or 9 numbers row-major; its columns are the local axes; default: axis-aligned)."""

    kind: ClassVar[str] = "box"
    table: ClassVar[str] = "boxes"
    width: ClassVar[int] = 15
    layout: ClassVar[str] = "[cx, cy, cz, hx, hy, hz, R00, R01, R02, R10, R11, R12, R20, R21, R22]"
    sizes: ClassVar[slice] = HALF
    size_name: ClassVar[str] = "half extent"
    rotation_columns: ClassVar[slice] = ROTATION
    pad: ClassVar[tuple[float, ...]] = (0.0, 0.0, 0.0, 1.0, 1.0, 1.0, *IDENTITY)
    packed_width: ClassVar[int] = BOUND + 1

    centre: tuple[float, float, float]
    half_extents: tuple[float, float, float]
    rotation: tuple[float, ...] = IDENTITY

    def __post_init__(self):
        object.__setattr__(self, "centre", vec(self.centre, 3, "a box's centre"))
        h = vec(self.half_extents, 3, "a box's half extents")
        for v in h:
            positive(v, "a box's half extent")
        object.__setattr__(self, "half_extents", h)
        object.__setattr__(self, "rotation", rotation(self.rotation, "a box"))

    def row(self) -> tuple[float, ...]:
        return (*self.centre, *self.half_extents, *self.rotation)

    @classmethod
    def from_row(cls, row) -> Box:
        return cls(tuple(row[CENTRE]), tuple(row[HALF]), tuple(row[ROTATION]))

    @staticmethod
    def point_distance(p: torch.Tensor, rows: torch.Tensor) -> torch.Tensor:
        x, y, z = local(p, rows, ROTATION)
        qx, qy, qz = x.abs() - rows[..., _H], y.abs() - rows[..., _H + 1], z.abs() - rows[..., _H + 2]
        ox, oy, oz = qx.clamp_min(0.0), qy.clamp_min(0.0), qz.clamp_min(0.0)
        inside = torch.maximum(torch.maximum(qx, qy), qz).clamp_max(0.0)
        return safe_sqrt(ox * ox + oy * oy + oz * oz) + inside

    @staticmethod
    def aabb_half_extents(rows: torch.Tensor) -> torch.Tensor:
        R = rows[..., ROTATION].unflatten(-1, (3, 3)).abs()
        return (R * rows[..., HALF].unsqueeze(-2)).sum(-1)

    @staticmethod
    def shape_tensor(rows: torch.Tensor) -> torch.Tensor:
        e = rows[..., HALF]
        return extent_tensor((e[..., 0], e[..., 1], e[..., 2]), rows[..., ROTATION])

    @classmethod
    def coal_shape(cls, row: np.ndarray):
        import coal

        h = np.asarray(row[HALF], dtype=np.float64)
        R = np.asarray(row[ROTATION], dtype=np.float64).reshape(3, 3)
        return coal.Box(*(2.0 * h)), R, np.asarray(row[CENTRE], dtype=np.float64)


# --------------------------------------------------------------------------------------------------
# The compiled twin: packed rows are the row, then BOUND
# --------------------------------------------------------------------------------------------------


@jit
def distance(x, y, z, t, i):
    """Signed distance from the point to box ``i`` of table ``t``: with q = |Rᵀ(p − c)| − h per axis,
    ‖max(q, 0)‖ + min(max_i q_i, 0)."""
    dx, dy, dz = x - t[i, 0], y - t[i, 1], z - t[i, 2]
    qx = abs(dx * t[i, _R] + dy * t[i, _R + 3] + dz * t[i, _R + 6]) - t[i, _H]
    qy = abs(dx * t[i, _R + 1] + dy * t[i, _R + 4] + dz * t[i, _R + 7]) - t[i, _H + 1]
    qz = abs(dx * t[i, _R + 2] + dy * t[i, _R + 5] + dz * t[i, _R + 8]) - t[i, _H + 2]
    ox, oy, oz = max(qx, 0.0), max(qy, 0.0), max(qz, 0.0)
    return math.sqrt(max(ox * ox + oy * oy + oz * oz, TINY)) + min(max(max(qx, qy), qz), 0.0)


@jit(inline="always")
def nearest(x, y, z, t, d):
    """min(``d``, the point's signed distance to every box of ``t``): a box whose bounding ball is
    already farther than ``d`` is not evaluated (the minimum is the same, to the bit)."""
    for i in range(t.shape[0]):
        if not beyond(x, y, z, t, i, t[i, BOUND], d):
            d = min(d, distance(x, y, z, t, i))
    return d


@jit(inline="always")
def nearest_many(X, Y, Z, M, t, out):
    """``out[m] = min(out[m], distance of point m)`` for the first ``M`` points, box by box."""
    for i in range(t.shape[0]):
        for m in range(M):
            out[m] = min(out[m], distance(X[m], Y[m], Z[m], t, i))


@jit(inline="always")
def radius(t, i):
    """The radius of the ball about row ``i``'s centre that holds it."""
    return t[i, BOUND]


@jit(inline="always")
def pack(rows, out):
    """Packed rows ``out (n, 16)`` of rows ``(n, 15)``: each followed by ‖half extents‖."""
    for i in range(rows.shape[0]):
        for j in range(BOUND):
            out[i, j] = rows[i, j]
        out[i, BOUND] = math.sqrt(
            rows[i, _H] * rows[i, _H] + rows[i, _H + 1] * rows[i, _H + 1] + rows[i, _H + 2] * rows[i, _H + 2]
        )


@jit(inline="always")
def network_count(t):
    """How many rows of the obstacle network's input the packed table ``t`` gives: one per row."""
    return t.shape[0]


@jit(inline="always")
def network_row(t, i, out, r):
    """Row ``r`` of the obstacle network's input for box ``i``: centre, bounding half extents
    Σ_b |R_ab| h_b (summed in the order b = 0, 1, 2, as torch sums three terms) and extent tensor."""
    for a in range(3):
        out[r, a] = t[i, a]
        out[r, NET_AABB + a] = (
            abs(t[i, _R + 3 * a]) * t[i, _H]
            + abs(t[i, _R + 1 + 3 * a]) * t[i, _H + 1]
            + abs(t[i, _R + 2 + 3 * a]) * t[i, _H + 2]
        )
    extent_row(out, r, NET_EXTENT, t[i, _H], t[i, _H + 1], t[i, _H + 2], t[i], _R)
