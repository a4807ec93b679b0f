"""The point-cloud kind: a scene's :class:`~kinlearn.collision.cloud.PointCloud` as the compiled kernels
see it, its distance grid packed as one row (:attr:`~kinlearn.collision.cloud.PointCloud.packed`), and
the grid's query (:func:`cloud_distance`, a lower bound on the distance to the point balls).

A cloud is no table of primitives: it is a packed kind (:data:`~kinlearn.collision.kinds.PACKED_KINDS`)
after the scene's tables, whose table is empty for a scene without points. The obstacle network reads
none of it (:func:`network_count` is 0): the planner's learned proposals do not see the points, which
the dense check of every stage does. The grid's layout and how it is built: :mod:`kinlearn.collision.cloud`.
"""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np

from ...body.jit import jit

__all__ = ["HEADER", "Cloud", "cloud_distance"]

# The packed grid (float64): a header, then a lower bound per cell (nx · ny · nz, C order). Header slots:
NX, NY, NZ = 0, 1, 2  # dimensions
ORIGIN = 3  # origin (3): the low corner of cell (0, 0, 0)
EDGE = 6  # cell edge
LO, HI = 7, 10  # the points' bounding box (3 + 3)
RADIUS = 13  # the points' radius
HEADER = 14

_TINY = float(np.finfo(np.float64).tiny)


class Cloud:
    """The packed kind of a scene's point cloud (:attr:`~kinlearn.collision.Scene.cloud`)."""

    kind: ClassVar[str] = "cloud"
    table: ClassVar[str] = "cloud"

    @classmethod
    def kernel_rows(cls, scene) -> np.ndarray:
        """The cloud's packed grid as one row ``(1, G)``, or ``(0, 1)`` for a scene without points."""
        cloud = getattr(scene, "cloud", None)
        if cloud is None:
            return np.empty((0, 1))
        return cloud.packed.reshape(1, -1)

    @classmethod
    def packed_shape(cls, rows: np.ndarray) -> tuple[int, int]:
        return rows.shape[0], rows.shape[1]


@jit(inline="always")
def _corner(i, n):
    """Cell index ``i`` clamped into 0…n−1 (any cell's bound holds everywhere)."""
    return min(max(i, 0), n - 1)


@jit(inline="always")
def cloud_distance(x, y, z, g):
    """A lower bound on the signed distance from the point ``(x, y, z)`` to the point balls of the packed
    grid ``g``: the largest, over the 8 cell centres around the point (outside the grid, the nearest 8
    on its border), of the centre's bound less the centre's distance (the distance is 1-Lipschitz), and
    the distance to the points' bounding box less their radius."""
    ex = max(max(g[LO] - x, x - g[HI]), 0.0)
    ey = max(max(g[LO + 1] - y, y - g[HI + 1]), 0.0)
    ez = max(max(g[LO + 2] - z, z - g[HI + 2]), 0.0)
    d = math.sqrt(max(ex * ex + ey * ey + ez * ez, _TINY)) - g[RADIUS]
    h = g[EDGE]
    nx, ny, nz = int(g[NX]), int(g[NY]), int(g[NZ])
    fx = min(max((x - g[ORIGIN]) / h - 0.5, -1.0), float(nx))
    fy = min(max((y - g[ORIGIN + 1]) / h - 0.5, -1.0), float(ny))
    fz = min(max((z - g[ORIGIN + 2]) / h - 0.5, -1.0), float(nz))
    i0, j0, k0 = math.floor(fx), math.floor(fy), math.floor(fz)
    for a in range(2):
        i = _corner(i0 + a, nx)
        dx = x - (g[ORIGIN] + (i + 0.5) * h)
        for b in range(2):
            j = _corner(j0 + b, ny)
            dy = y - (g[ORIGIN + 1] + (j + 0.5) * h)
            row = HEADER + (i * ny + j) * nz
            for c in range(2):
                k = _corner(k0 + c, nz)
                dz = z - (g[ORIGIN + 2] + (k + 0.5) * h)
                d = max(d, g[row + k] - math.sqrt(max(dx * dx + dy * dy + dz * dz, _TINY)))
    return d


@jit(inline="always")
def nearest(x, y, z, t, d):
    """min(``d``, the point's bound to the cloud of packed table ``t``; none when ``t`` is empty)."""
    if t.shape[0]:
        d = min(d, cloud_distance(x, y, z, t[0]))
    return d


@jit(inline="always")
def nearest_many(X, Y, Z, M, t, out):
    """``out[m] = min(out[m], the bound of point m)`` for the first ``M`` points."""
    if t.shape[0]:
        g = t[0]
        for m in range(M):
            out[m] = min(out[m], cloud_distance(X[m], Y[m], Z[m], g))


@jit(inline="always")
def radius(t, i):
    """No bounding ball: the cloud is never culled (its query costs no more than a ball's)."""
    return np.inf


@jit(inline="always")
def pack(rows, out):
    """The packed table: the grid as it is."""
    for i in range(rows.shape[0]):
        for j in range(rows.shape[1]):
            out[i, j] = rows[i, j]


@jit(inline="always")
def network_count(t):
    """The obstacle network reads no cloud."""
    return 0


@jit(inline="always")
def network_row(t, i, out, r):
    """Never called (:func:`network_count` is 0)."""
    return
