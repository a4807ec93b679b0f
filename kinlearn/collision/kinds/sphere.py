"""The sphere kind: a ball, one row ``[x, y, z, radius]``."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import torch

from ...body.jit import jit
from .primitive import CENTRE, NET_AABB, NET_EXTENT, NET_SPHERE, TINY, Primitive, positive, safe_sqrt, vec

__all__ = ["RADIUS", "Sphere"]

#: The row's columns: centre (:data:`~kinlearn.collision.kinds.primitive.CENTRE`), then the radius.
RADIUS = 3
_R = RADIUS


@dataclass(frozen=True)
class Sphere(Primitive):
    """A ball: ``centre`` (3,) and ``radius``."""

    kind: ClassVar[str] = "sphere"
    table: ClassVar[str] = "spheres"
    width: ClassVar[int] = 4
    layout: ClassVar[str] = "[x, y, z, radius]"
    sizes: ClassVar[slice] = slice(RADIUS, RADIUS + 1)
    size_name: ClassVar[str] = "radius"
    pad: ClassVar[tuple[float, ...]] = (0.0, 0.0, 0.0, 1.0)
    #: Packed as it is: its radius is its bounding radius.
    packed_width: ClassVar[int] = 4
    network_flags: ClassVar[tuple[float, float]] = (1.0, 0.0)

    centre: tuple[float, float, float]
    radius: float

    def __post_init__(self):
        object.__setattr__(self, "centre", vec(self.centre, 3, "a sphere's centre"))
        object.__setattr__(self, "radius", positive(self.radius, "a sphere's radius"))

    def row(self) -> tuple[float, ...]:
        return (*self.centre, self.radius)

    @classmethod
    def from_row(cls, row) -> Sphere:
        return cls(tuple(row[CENTRE]), row[RADIUS])

    @staticmethod
    def point_distance(p: torch.Tensor, rows: torch.Tensor) -> torch.Tensor:
        dx, dy, dz = p[..., 0] - rows[..., 0], p[..., 1] - rows[..., 1], p[..., 2] - rows[..., 2]
        return safe_sqrt(dx * dx + dy * dy + dz * dz) - rows[..., RADIUS]

    @staticmethod
    def aabb_half_extents(rows: torch.Tensor) -> torch.Tensor:
        return rows[..., RADIUS : RADIUS + 1].expand(*rows.shape[:-1], 3)

    @staticmethod
    def shape_tensor(rows: torch.Tensor) -> torch.Tensor:
        r = rows[..., RADIUS]
        z = torch.zeros_like(r)
        return torch.stack((r, r, r, z, z, z), dim=-1)

    @classmethod
    def coal_shape(cls, row: np.ndarray):
        import coal

        return coal.Sphere(float(row[RADIUS])), np.eye(3), np.asarray(row[CENTRE], dtype=np.float64)


# --------------------------------------------------------------------------------------------------
# The compiled twin: packed rows are the rows themselves
# --------------------------------------------------------------------------------------------------


@jit
def distance(x, y, z, t, i):
    """Signed distance from the point to sphere ``i`` of table ``t``."""
    dx, dy, dz = x - t[i, 0], y - t[i, 1], z - t[i, 2]
    return math.sqrt(max(dx * dx + dy * dy + dz * dz, TINY)) - t[i, _R]


@jit(inline="always")
def nearest(x, y, z, t, d):
    """min(``d``, the point's signed distance to every sphere of ``t``) (none culled: a sphere's
    distance costs no more than its bounding ball's)."""
    for i in range(t.shape[0]):
        d = min(d, distance(x, y, z, t, i))
    return d


@jit(inline="always")
def nearest_many(X, Y, Z, M, t, out):
    """``out[m] = min(out[m], distance of point m)`` for the first ``M`` points, sphere by sphere (a loop
    the compiler turns into vector instructions)."""
    for i in range(t.shape[0]):
        for m in range(M):
            out[m] = min(out[m], distance(X[m], Y[m], Z[m], t, i))


@jit(inline="always")
def radius(t, i):
    """The radius of the ball about row ``i``'s centre that holds it."""
    return t[i, _R]


@jit(inline="always")
def pack(rows, out):
    """Packed rows ``out (n, 4)`` of rows ``(n, 4)``: the rows themselves."""
    for i in range(rows.shape[0]):
        for j in range(4):
            out[i, j] = rows[i, j]


@jit(inline="always")
def network_count(t):
    """How many rows of the obstacle network's input the packed table ``t`` gives: one per row."""
    return t.shape[0]


@jit(inline="always")
def network_row(t, i, out, r):
    """Row ``r`` of the obstacle network's input (:meth:`~kinlearn.collision.kernel.KernelScene.model_rows`)
    for sphere ``i``: centre, its radius as bounding half extents and as its extent tensor's diagonal."""
    for a in range(3):
        out[r, a] = t[i, a]
        out[r, NET_AABB + a] = t[i, _R]
        out[r, NET_EXTENT + a] = t[i, _R]
    out[r, NET_SPHERE] = 1.0
