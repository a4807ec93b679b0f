"""The point-cloud kind: a scene's :class:`~kinlearn.collision.cloud.PointCloud` as the compiled kernels
see it, its distance grid and its points packed as one row (:attr:`~kinlearn.collision.cloud.PointCloud.packed`),
the grid's query (:func:`cloud_distance`, a lower bound on the distance to the point balls) and a body
sphere's query (:func:`sphere_distance`), exact wherever the verdict could turn on it.

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

# The packed cloud (float64): a header, then a lower bound per grid cell (nx · ny · nz, C order), then the
# points sorted by block (cubes over the points' bounding box, sized for about BLOCK_POINTS points where a
# surface crosses one): each block's first point (bx · by · bz + 1 offsets), then the points (x, y, z
# each). Header slots:
NX, NY, NZ = 0, 1, 2  # the grid's dimensions
ORIGIN = 3  # origin (3): the low corner of cell (0, 0, 0)
EDGE = 6  # cell edge
LO, HI = 7, 10  # the points' bounding box (3 + 3)
RADIUS = 13  # the points' radius
BX, BY, BZ = 14, 15, 16  # the blocks' dimensions (their origin is LO)
BEDGE = 17  # a block's edge
EXACT = 18  # a sphere's distance is exact up to this far beyond its radius (m)
STARTS = 19  # where the blocks' offsets start in the buffer
POINTS = 20  # where the points start
HEADER = 21
#: Points a block holds where a surface crosses it, about (a sphere's exact query reads the blocks within
#: its reach: fewer points a block read fewer far points, more blocks cost more reads).
BLOCK_POINTS = 16

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
def _scan(x, y, z, g, p0, first, end, best2, best):
    """``(squared distance, index)`` of the nearest of points ``first`` to ``end`` (packed from ``p0``) to
    ``(x, y, z)``, or ``(best2, best)`` where none is as near."""
    for n in range(first, end):
        o = p0 + 3 * n
        dx, dy, dz = x - g[o], y - g[o + 1], z - g[o + 2]
        d2 = dx * dx + dy * dy + dz * dz
        if d2 <= best2:
            best2 = d2
            best = n
    return best2, best


@jit(inline="always")
def nearest_point(x, y, z, reach, g):
    """``(index, distance)`` of the point nearest ``(x, y, z)`` among those within ``reach`` of it, or
    ``(-1, inf)`` when none is: the blocks the ball of ``reach`` touches, point by point."""
    e = g[BEDGE]
    bx, by, bz = int(g[BX]), int(g[BY]), int(g[BZ])
    lx, ly, lz = g[LO], g[LO + 1], g[LO + 2]
    i0 = max(math.floor((x - reach - lx) / e), 0)
    i1 = min(math.floor((x + reach - lx) / e), bx - 1)
    j0 = max(math.floor((y - reach - ly) / e), 0)
    j1 = min(math.floor((y + reach - ly) / e), by - 1)
    k0 = max(math.floor((z - reach - lz) / e), 0)
    k1 = min(math.floor((z + reach - lz) / e), bz - 1)
    best2 = reach * reach
    best = -1
    s0, p0 = int(g[STARTS]), int(g[POINTS])
    # the block holding the point first: its nearest points bound the rest, whose blocks are then passed by
    ci, cj, ck = math.floor((x - lx) / e), math.floor((y - ly) / e), math.floor((z - lz) / e)
    home = -1
    if 0 <= ci < bx and 0 <= cj < by and 0 <= ck < bz:
        home = (ci * by + cj) * bz + ck
        best2, best = _scan(x, y, z, g, p0, int(g[s0 + home]), int(g[s0 + home + 1]), best2, best)
    for i in range(i0, i1 + 1):
        ax = lx + i * e
        ex = max(max(ax - x, x - ax - e), 0.0)
        for j in range(j0, j1 + 1):
            ay = ly + j * e
            ey = max(max(ay - y, y - ay - e), 0.0)
            if ex * ex + ey * ey > best2:
                continue
            row = s0 + (i * by + j) * bz
            for k in range(k0, k1 + 1):
                az = lz + k * e
                ez = max(max(az - z, z - az - e), 0.0)
                if ex * ex + ey * ey + ez * ez > best2 or row - s0 + k == home:
                    continue
                best2, best = _scan(x, y, z, g, p0, int(g[row + k]), int(g[row + k + 1]), best2, best)
    if best < 0:
        return -1, np.inf
    return best, math.sqrt(max(best2, _TINY))


@jit(inline="always")
def sphere_distance(x, y, z, r, g, d):
    """min(``d``, a lower bound on the distance from ``(x, y, z)``, the centre of a sphere of radius ``r``,
    to the point balls of packed cloud ``g``), **exact** wherever the sphere comes within ``g[EXACT]`` of
    them: the grid's bound (:func:`cloud_distance`) first; where it cannot clear the sphere by that much
    (and is below ``d``), the points within reach, one by one."""
    b = cloud_distance(x, y, z, g)
    if b >= d:
        return d
    return min(d, refine(x, y, z, r, b, g)[1])


@jit(inline="always")
def refine(x, y, z, r, b, g):
    """What a sphere's query (centre ``(x, y, z)``, radius ``r``) makes of the grid's bound ``b``:
    ``(-2, b)`` where the bound clears the sphere by ``g[EXACT]``; else the points within that reach read,
    ``(-1, max(b, r + g[EXACT]))`` where none is there, or ``(index, exact distance)`` of the nearest."""
    room = r + g[EXACT]
    if b >= room:
        return -2, b
    n, e = nearest_point(x, y, z, room + g[RADIUS], g)
    if n < 0:
        return -1, max(b, room)
    return n, e - g[RADIUS]


@jit(inline="always")
def nearest(x, y, z, r, ball, t, d):
    """min(``d``, the sphere's (centre ``(x, y, z)``, radius ``r``) :func:`sphere_distance` to the cloud of
    packed table ``t``, or for a link's bounding ``ball`` the grid's bound; none when ``t`` is empty)."""
    if t.shape[0]:
        if ball:
            d = min(d, cloud_distance(x, y, z, t[0]))
        else:
            d = sphere_distance(x, y, z, r, t[0], d)
    return d


@jit(inline="always")
def nearest_many(X, Y, Z, R, ball, M, t, out):
    """``out[m] = min(out[m], the sphere distance of sphere m)`` for the first ``M`` spheres (radii ``R``;
    links' bounding balls where ``ball``: the grid's bound)."""
    if t.shape[0]:
        g = t[0]
        if ball:
            for m in range(M):
                out[m] = min(out[m], cloud_distance(X[m], Y[m], Z[m], g))
        else:
            for m in range(M):
                out[m] = sphere_distance(X[m], Y[m], Z[m], R[m], g, out[m])


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
