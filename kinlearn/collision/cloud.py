"""Point-cloud obstacles: what a depth camera sees, as a :class:`PointCloud` a :class:`~kinlearn.collision.Scene`
holds beside its primitives, checked through a compiled distance grid, then the points themselves.

Each point is an obstacle ball of ``radius`` (m) in the robot's base frame. :attr:`PointCloud.packed`
builds (once, on first use) one buffer: a distance grid whose query is a **lower bound** on the signed
distance from a point in space to the union of those balls, so that a body sphere found clear of the grid
is clear of every point ball (*free under the structure is free under the points*), and the points
sorted into blocks (cubes sized to hold a few points each where a surface crosses them). A body sphere's query (:func:`sphere_distance`, what every
collision kernel takes) asks the grid first; a sphere the grid cannot clear by :data:`EXACT` beyond its
radius reads the points of the blocks within reach, and its distance is then exact: the verdicts are the
points' own, not the grid's (which would keep a sphere up to a cell's diagonal farther away). The grid:

- the **grid** (cells of edge ``resolution``, default 2 cm) spans the points' bounding box and
  :data:`PAD` cells around it; each cell holds the exact Euclidean distance from its centre to the
  nearest cell holding a point (Felzenszwalb and Huttenlocher's separable transform: a scan along z, then
  the lower envelope of parabolas along y and x, many lines side by side so that every access is
  contiguous), less half a cell's diagonal (a point lies anywhere in its cell) and ``radius``: a lower
  bound at the centre;
- a **query** at ``p`` takes, over the 8 cell centres around it (outside the grid, the nearest 8 on its
  border), the largest of a centre's bound less ``‖p − centre‖`` (the distance is 1-Lipschitz, so each
  is a bound at ``p``), and the points' bounding box's distance.

The grid's bound is below the truth by at most a cell's diagonal for the point's place in its cell and
the query's (2√3 · ``resolution``, 7 cm at the default 2 cm), by about a cell's edge typically (the best of
the 8 centres lies nearly behind ``p``); beyond the grid's :data:`PAD` it loosens with the
angle to its border. That slack costs only time: the spheres within it read the points.

:meth:`PointCloud.distance` is the compiled query, :meth:`PointCloud.distance_torch` its torch twin
(the same numbers, for :func:`~kinlearn.collision.body_obstacle_distance` and batches), and
:func:`cloud_distance` the inline function the collision kernels call with :attr:`PointCloud.packed`.

Before a cloud is made, its points are read and checked (:mod:`kinlearn.collision.cloud_points`:
:func:`read_points`, :func:`check_points`, :func:`points_in_base`, :func:`views_in_base`, :func:`shadows`)
and optionally cleaned
(:mod:`kinlearn.collision.cloud_cleaning`: :class:`Cleaning`, :func:`clean_points`); both are importable
from here. Bad input raises :class:`~kinlearn.errors.PointCloudError` (a file that cannot be read:
:class:`~kinlearn.errors.PointCloudFileError`).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import torch

from ..body.jit import jit
from ..errors import PointCloudError
from .cloud_cleaning import Cleaning, _outside_spheres, body_of, clean_points
from .cloud_points import MILLIMETRE_NORM as MILLIMETRE_NORM
from .cloud_points import check_points, is_views, points_in_base, read_points, shadows, views_in_base
from .kinds import cloud as _k
from .kinds.cloud import EDGE as _H
from .kinds.cloud import HEADER as _HEADER
from .kinds.cloud import HI as _HI
from .kinds.cloud import LO as _LO
from .kinds.cloud import NX as _NX
from .kinds.cloud import NY as _NY
from .kinds.cloud import NZ as _NZ
from .kinds.cloud import ORIGIN as _OX
from .kinds.cloud import RADIUS as _R
from .kinds.cloud import cloud_distance, refine, sphere_distance

__all__ = [
    "DEFAULT_CONTACT",
    "DEFAULT_RADIUS",
    "DEFAULT_RESOLUTION",
    "PAD",
    "Cleaning",
    "PointCloud",
    "check_points",
    "clean_points",
    "cloud_distance",
    "points_in_base",
    "read_points",
    "sensed_cloud",
    "shadows",
    "views_in_base",
]

#: Default radius (m) of the ball each point stands for: a surface sampled every centimetre is covered
#: by balls of half the diagonal of its spacing and then some (sensor noise).
DEFAULT_RADIUS = 0.01
#: Default depth (m) to which points may lie inside the arm's body at a plan's start or goal and be taken
#: as the surface it touches (:mod:`~kinlearn.collision.cloud_contact`): three standard deviations of a
#: depth camera's 2 mm noise. On the tuning problems' surface clouds (seeds 3004–3010, 140 per arm,
#: 2 mm noise) the deepest point at a goal the balls touch lay 4.2 mm (panda) and 2.5 mm (ur5) inside.
DEFAULT_CONTACT = 0.006
#: Default edge (m) of the grid's cells: a speed setting, not an accuracy one (the spheres the grid cannot
#: clear read the points). 2 cm builds a grid of 10⁵ points in milliseconds and plans as fast as 1 cm
#: (``benchmarks/clouds.py``).
DEFAULT_RESOLUTION = 0.02
#: Metres of grid around the points' bounding box (beyond it, the border cells' bounds less the way
#: there): about a body sphere's radius and a clearance, where the bounds matter most.
PAD = 0.04
#: The most fine cells a grid may have (a float64 each): a larger cloud extent asks for a crop
#: (:attr:`Cleaning.reach`) or a coarser resolution.
MAX_CELLS = 1 << 26
#: A body sphere's distance to the points is exact up to this far (m) beyond its radius (and a lower bound
#: beyond): the verdict of every check with a margin below it is the points' own.
EXACT = 0.01
#: Where :meth:`PointCloud.without_near` moves the points it drops (m): beyond any query's reach.
_GONE = 1e9
#: Metres taken off every bound for the rounding of the arithmetic that made it.
_ROUNDING = 1e-9

# --------------------------------------------------------------------------------------------------
# The distance grid
# --------------------------------------------------------------------------------------------------

_NONE = 1e30  # a cell's squared distance before the transform: no point there


@jit
def _bounds(points):
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for i in range(points.shape[0]):
        for a in range(3):
            v = points[i, a]
            lo[a] = min(lo[a], v)
            hi[a] = max(hi[a], v)
    return lo, hi


@jit
def _lines(g, base, n, step, m, v, z, top, site, at, scale=0.0, less=0.0):
    """Felzenszwalb and Huttenlocher's 1-D squared distance transform, in place, of ``m`` lines side by side:
    line c holds ``g[base + q · step + c]`` for q = 0…n−1 (cells of value ≥ :data:`_NONE` hold no site).
    Walking the lines together, q by q, keeps every access contiguous (``v``, ``z``, ``site``: ``(n + 1, m)``
    work space, ``top``, ``at``: ``(m,)``). Exact on these integer values: an envelope's breakpoint lies
    between integers unless two parabolas tie there. With ``scale`` > 0 (the last pass) each result is
    written as ``scale · √value − less`` instead."""
    for c in range(m):
        top[c] = -1
    for q in range(n):
        o = base + q * step
        for c in range(m):
            fq = g[o + c]
            if fq >= _NONE:
                continue
            fq2 = fq + q * q
            k = top[c]
            while k >= 0:  # pop the parabolas the new one hides (compared without dividing)
                p = v[k, c]
                if fq2 - site[k, c] <= z[k, c] * (2.0 * (q - p)):
                    k -= 1
                else:
                    break
            if k < 0:
                k = 0
                z[0, c] = -np.inf
            else:
                p = v[k, c]
                k += 1
                z[k, c] = (fq2 - site[k - 1, c]) / (2.0 * (q - p))
            v[k, c], site[k, c] = q, fq2  # the parabola (x − q)² + fq as x² − 2qx + fq2
            top[c] = k
    for c in range(m):
        at[c] = 0
    for q in range(n):
        o = base + q * step
        for c in range(m):
            last = top[c]
            if last < 0:
                continue
            k = at[c]
            while k < last and z[k + 1, c] < q:
                k += 1
            at[c] = k
            p = v[k, c]
            value = site[k, c] - 2.0 * q * p + q * q
            g[o + c] = scale * math.sqrt(value) - less if scale > 0.0 else value


@jit
def _build(points, radius, h, pad, exact, out_header):
    """The packed cloud of ``points (N, 3)`` (see the module docstring): header filled (also into
    ``out_header``), the cells' lower bounds after it, then the points by block, one buffer."""
    lo, hi = _bounds(points)
    ox, oy, oz = lo[0] - pad * h, lo[1] - pad * h, lo[2] - pad * h
    nx = int((hi[0] - ox) / h) + pad + 1
    ny = int((hi[1] - oy) / h) + pad + 1
    nz = int((hi[2] - oz) / h) + pad + 1
    P = ny * nz
    N = nx * P
    cells = np.full(N, _NONE)
    filled = np.zeros(nx, dtype=np.bool_)
    occupied = 0
    for i in range(points.shape[0]):
        a = int((points[i, 0] - ox) / h)
        b = int((points[i, 1] - oy) / h)
        c = int((points[i, 2] - oz) / h)
        k = (a * ny + b) * nz + c
        if cells[k] != 0.0:
            occupied += 1
        cells[k] = 0.0
        filled[a] = True
    # the points' blocks: about BLOCK_POINTS points in a block a surface crosses (a surface's points in a
    # block grow with the square of its edge), from one to four cells a side (smaller blocks cost more
    # reads than the points they spare)
    per_cell = points.shape[0] / max(occupied, 1)
    e = h * min(max(math.sqrt(_k.BLOCK_POINTS / per_cell), 1.0), 4.0)
    bx = int((hi[0] - lo[0]) / e) + 1
    by = int((hi[1] - lo[1]) / e) + 1
    bz = int((hi[2] - lo[2]) / e) + 1
    B = bx * by * bz
    s0 = _HEADER + N
    p0 = s0 + B + 1
    buf = np.empty(p0 + 3 * points.shape[0])
    g = buf[_HEADER:s0]
    g[:] = cells
    # z: the nearest site along each row, scanning both ways
    for r in range(nx * ny):
        o = r * nz
        last = -1
        for c in range(nz):
            if g[o + c] == 0.0:
                last = c
            elif last >= 0:
                g[o + c] = float((c - last) * (c - last))
        last = -1
        for c in range(nz - 1, -1, -1):
            if g[o + c] == 0.0:
                last = c
            elif last >= 0:
                g[o + c] = min(g[o + c], float((last - c) * (last - c)))
    n = max(nx, ny) + 1
    v, z = np.empty((n, nz), dtype=np.int64), np.empty((n, nz))
    site, top, at = np.empty((n, nz)), np.empty(nz, dtype=np.int64), np.empty(nz, dtype=np.int64)
    for a in range(nx):  # y: plane a's lines, nz side by side (a plane without a point stays empty)
        if filled[a]:
            _lines(g, a * P, ny, nz, nz, v, z, top, site, at)
    # x: row b of every plane, nz side by side (every such line holds a site: each plane with a point is
    # filled by now), written as lower bounds in metres: the centres' distance less half a cell's
    # diagonal (a point lies anywhere in its cell) and the radius
    less = 0.5 * math.sqrt(3.0) * h + radius + _ROUNDING
    for b in range(ny):
        _lines(g, b * nz, nx, P, nz, v, z, top, site, at, h, less)
    hd = buf[:_HEADER]
    hd[_NX], hd[_NY], hd[_NZ] = nx, ny, nz
    hd[_OX], hd[_OX + 1], hd[_OX + 2] = ox, oy, oz
    hd[_H] = h
    for a2 in range(3):
        hd[_LO + a2], hd[_HI + a2] = lo[a2], hi[a2]
    hd[_R] = radius
    hd[_k.BX], hd[_k.BY], hd[_k.BZ], hd[_k.BEDGE] = bx, by, bz, e
    hd[_k.EXACT] = exact
    hd[_k.STARTS], hd[_k.POINTS] = s0, p0
    _sort_points(points, lo, e, bx, by, bz, buf[s0:p0], buf[p0:])
    out_header[:] = hd
    return buf


@jit
def _sort_points(points, lo, e, bx, by, bz, starts, out):
    """``points`` sorted by block (a counting sort) into ``out`` (x, y, z each), block b's first at
    ``starts[b]`` (``starts[-1]``: their number)."""
    n = points.shape[0]
    block = np.empty(n, dtype=np.int64)
    count = np.zeros(bx * by * bz + 1, dtype=np.int64)
    for i in range(n):
        a = min(max(int((points[i, 0] - lo[0]) / e), 0), bx - 1)
        b = min(max(int((points[i, 1] - lo[1]) / e), 0), by - 1)
        c = min(max(int((points[i, 2] - lo[2]) / e), 0), bz - 1)
        block[i] = (a * by + b) * bz + c
        count[block[i] + 1] += 1
    for b in range(bx * by * bz):
        count[b + 1] += count[b]
    for b in range(bx * by * bz + 1):
        starts[b] = count[b]
    for i in range(n):
        o = 3 * count[block[i]]
        out[o], out[o + 1], out[o + 2] = points[i, 0], points[i, 1], points[i, 2]
        count[block[i]] += 1


@jit
def _distances(points, g, out):
    for i in range(points.shape[0]):
        out[i] = cloud_distance(points[i, 0], points[i, 1], points[i, 2], g)


@jit
def _sphere_distances(centres, radii, g, out):
    for i in range(centres.shape[0]):
        out[i] = sphere_distance(centres[i, 0], centres[i, 1], centres[i, 2], radii[i], g, np.inf)


@jit
def _refinements(centres, radii, g, bound, out):
    """What :func:`sphere_distance` made of each sphere (:func:`refine`'s first value): the index of the
    nearest point it read (≥ 0), −1 where it found none within reach, −2 where the grid's ``bound`` decided
    alone."""
    for i in range(centres.shape[0]):
        out[i] = refine(centres[i, 0], centres[i, 1], centres[i, 2], radii[i], bound[i], g)[0]


class PointCloud:
    """Points ``(N, 3)`` (m, the robot's base frame), each an obstacle ball of ``radius``, with the
    compiled distance grid of cell edge ``resolution`` they are checked through (:attr:`packed`, built on
    first use). ``contact`` (m): how deep points may lie inside the arm's body at a plan's start or goal
    and be taken as the surface it touches, within the sensor's noise (:mod:`~kinlearn.collision.cloud_contact`;
    0: an end the balls touch is refused). Immutable: its points are a read-only float64 array."""

    __slots__ = ("__weakref__", "_header", "_packed", "_torch", "contact", "points", "radius", "resolution")

    def __init__(
        self,
        points,
        radius: float = DEFAULT_RADIUS,
        resolution: float = DEFAULT_RESOLUTION,
        contact: float = DEFAULT_CONTACT,
    ):
        pts = check_points(points)
        for name, v in (("radius", radius), ("resolution", resolution), ("contact", contact)):
            ok = isinstance(v, (int, float, np.floating)) and not isinstance(v, bool) and math.isfinite(v)
            if not ok or v < 0 or (name == "resolution" and v == 0):
                raise PointCloudError(
                    f"a point cloud's {name} must be a finite number of metres "
                    f"{'> 0' if name == 'resolution' else '>= 0'}, got {v!r}"
                )
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        cells = np.prod(np.floor((hi - lo) / resolution) + 2 * math.ceil(PAD / resolution) + 2)
        if cells > MAX_CELLS:
            raise PointCloudError(
                f"the cloud spans {np.round(hi - lo, 3).tolist()} m: {cells:.3g} grid cells of {resolution} m, "
                f"more than {MAX_CELLS:,}; crop it (Cleaning(reach=...), or self-filtering with the robot's "
                "body, which crops to its reach) or give a coarser resolution"
            )
        pts.flags.writeable = False
        self.points = pts
        self.radius = float(radius)
        self.resolution = float(resolution)
        self.contact = float(contact)
        self._packed = None
        self._header = None
        self._torch = {}

    @property
    def num_points(self) -> int:
        return int(self.points.shape[0])

    def without_near(self, centres: np.ndarray, reach: np.ndarray) -> PointCloud | None:
        """This cloud without the points within ``reach (M,)`` (m) of ``centres (M, 3)`` (its sizes and contact
        the same; its points in its grid's block order), or None where none is left. Its grid is this one's,
        copied: the bounds of a cloud that held more points still bound its distances from below, and the
        points dropped are moved out of every query's reach in its blocks (:data:`_GONE`), so it costs a
        copy, not a build."""
        g = self.packed
        p0 = int(g[_k.POINTS])
        keep = np.empty((g.shape[0] - p0) // 3, dtype=np.bool_)
        _outside_spheres(
            g[p0:].reshape(-1, 3),
            np.ascontiguousarray(centres, dtype=np.float64),
            np.ascontiguousarray(reach, dtype=np.float64),
            keep,
        )
        if keep.all():
            return self
        if not keep.any():
            return None
        g = np.array(g)
        blocks = g[p0:].reshape(-1, 3)  # the points in the blocks' order
        out = object.__new__(PointCloud)
        out.points = blocks[keep]
        out.points.flags.writeable = False
        blocks[~keep] = _GONE
        g.flags.writeable = False
        out.radius, out.resolution, out.contact = self.radius, self.resolution, self.contact
        out._packed, out._header, out._torch = g, self._header, {}
        return out

    @property
    def packed(self) -> np.ndarray:
        """The distance grid in one float64 buffer (header, fine values, coarse values), built on first use."""
        if self._packed is None:
            header = np.empty(_HEADER)
            pad = math.ceil(PAD / self.resolution)
            buf = _build(self.points, self.radius, self.resolution, pad, EXACT, header)
            buf.flags.writeable = False
            self._header = header
            self._packed = buf
        return self._packed

    @property
    def shape(self) -> tuple[int, int, int]:
        """The fine grid's dimensions (cells along x, y, z)."""
        g = self.packed
        return int(g[_NX]), int(g[_NY]), int(g[_NZ])

    def distance(self, points, radii=None) -> np.ndarray:
        """``(N,)``: the compiled lower bound on each point's (``(N, 3)``, base frame) signed distance to
        the cloud's balls, the grid's (:func:`cloud_distance`); with ``radii (N,)``, the distance of the
        centres of spheres of those radii, exact up to :data:`EXACT` beyond them (:func:`sphere_distance`:
        what the collision kernels take; subtract ``radii`` for the spheres' own)."""
        p = np.ascontiguousarray(np.asarray(points, dtype=np.float64))
        if p.ndim != 2 or p.shape[1] != 3:
            raise PointCloudError(f"query points must have shape (N, 3), got {p.shape}")
        out = np.empty(p.shape[0])
        if radii is None:
            _distances(p, self.packed, out)
        else:
            _sphere_distances(p, self._radii(radii, p.shape[0]), self.packed, out)
        return out

    @staticmethod
    def _radii(radii, n: int) -> np.ndarray:
        r = np.ascontiguousarray(np.broadcast_to(np.asarray(radii, dtype=np.float64), (n,)))
        if not np.isfinite(r).all() or (r < 0).any():
            raise PointCloudError("sphere radii must be finite and >= 0")
        return r

    def distance_torch(self, p: torch.Tensor, radii: torch.Tensor | None = None) -> torch.Tensor:
        """The torch twin of :meth:`distance`: ``(...)`` for points ``p (..., 3)`` (with ``radii``, sphere
        centres and their radii ``(...)``) in their dtype and device, differentiable in ``p`` (the gradient
        of the bound taken: away from the best cell centre; of an exact distance: away from its point)."""
        bound = self._bound_torch(p)
        if radii is None:
            return bound
        radii = torch.as_tensor(radii, dtype=p.dtype, device=p.device).expand(bound.shape)
        flat = p.detach().reshape(-1, 3).cpu().double().numpy()
        r = self._radii(radii.detach().reshape(-1).cpu().double().numpy(), flat.shape[0])
        found = np.empty(flat.shape[0], dtype=np.int64)
        _refinements(flat, r, self.packed, bound.detach().reshape(-1).cpu().double().numpy(), found)
        found_t = torch.from_numpy(found).to(p.device).reshape(bound.shape)
        pts = self._points_torch(p.dtype, p.device)
        exact = _norm(p - pts[found_t.clamp_min(0)]) - self.radius
        room = torch.maximum(bound, radii + self.packed[_k.EXACT])
        return torch.where(found_t >= 0, exact, torch.where(found_t == -1, room, bound))

    def _points_torch(self, dtype: torch.dtype, device) -> torch.Tensor:
        """The points in the packed order, as a tensor (kept)."""
        key = ("points", dtype, device)
        t = self._torch.get(key)
        if t is None:
            g = self.packed
            p0 = int(g[_k.POINTS])
            t = self._torch[key] = torch.from_numpy(np.array(g[p0:]).reshape(-1, 3)).to(
                dtype=dtype, device=device
            )
        return t

    def _bound_torch(self, p: torch.Tensor) -> torch.Tensor:
        g = self.packed
        key = (p.dtype, p.device)
        gt = self._torch.get(key)
        if gt is None:
            gt = self._torch[key] = torch.from_numpy(np.array(g)).to(dtype=p.dtype, device=p.device)
        h = float(g[_H])
        o = p.new_tensor(g[_OX : _OX + 3])
        lo, hi = p.new_tensor(g[_LO : _LO + 3]), p.new_tensor(g[_HI : _HI + 3])
        e = torch.maximum(torch.maximum(lo - p, p - hi), torch.zeros_like(p))
        d = _norm(e) - float(g[_R])
        dims = [int(g[_NX]), int(g[_NY]), int(g[_NZ])]
        f = (p.detach() - o) / h - 0.5
        f = torch.minimum(f.clamp_min(-1.0), f.new_tensor(dims))
        base = f.floor().long()
        top = torch.tensor(dims, device=p.device) - 1
        for a in range(2):
            for b in range(2):
                for c in range(2):
                    idx = torch.minimum(torch.clamp_min(base + base.new_tensor([a, b, c]), 0), top)
                    L = gt[_HEADER + (idx[..., 0] * dims[1] + idx[..., 1]) * dims[2] + idx[..., 2]]
                    centre = o + (idx.to(p.dtype) + 0.5) * h
                    d = torch.maximum(d, L - _norm(p - centre))
        return d

    def __repr__(self) -> str:
        return (
            f"PointCloud(points={self.num_points}, radius={self.radius:g} m, resolution={self.resolution:g} m, "
            f"contact={self.contact:g} m)"
        )


def sensed_cloud(
    points,
    *,
    radius: float | None = None,
    frame=None,
    resolution: float | None = None,
    cleaning: Cleaning | None = None,
    self_filter: tuple | None = None,
    drop_nonfinite: bool = False,
    shadow: float = 0.0,
    contact: float | None = None,
) -> PointCloud:
    """The :class:`PointCloud` of sensed ``points`` (an ``(N, 3)`` array or tensor, or a point-cloud file's
    path; or a list of them, one per camera, with ``frame`` a list of their poses: :func:`views_in_base`):
    checked, moved into the base frame from the camera's ``frame``, cleaned (``cleaning``,
    ``self_filter``), its shadows added (``shadow`` m behind each point, seen from ``frame``), with the
    default radius, resolution and contact where they are None. The arguments are
    :meth:`~kinlearn.collision.Scene.from_points`', which adds primitives beside the cloud."""
    if shadow and is_views(points):
        raise PointCloudError(
            "shadow= takes one camera's view (the space one camera cannot see, another may see free): fuse "
            "several views without it"
        )
    pts = views_in_base(points, frame, drop_nonfinite)
    radius = DEFAULT_RADIUS if radius is None else radius
    resolution = DEFAULT_RESOLUTION if resolution is None else resolution
    contact = DEFAULT_CONTACT if contact is None else contact
    if shadow and frame is None:
        raise PointCloudError("shadow= needs the camera's pose (frame=): the rays run from it")
    if shadow and self_filter is not None:
        # the arm's own points cast their shadows too, and self-filtering comes after them: the space the
        # arm hides from the camera is occupied up to its body
        if not (isinstance(self_filter, (tuple, list)) and len(self_filter) == 2):
            raise PointCloudError("self_filter must be a pair (body, joints)")
        c = cleaning or Cleaning()
        if c.reach is None:
            c = replace(c, reach=body_of(self_filter[0]).reach + c.self_margin)
        pts = clean_points(pts, float(radius), c)
        pts = shadows(pts, points_in_base(np.zeros((1, 3)), frame)[0], float(shadow), float(resolution))
        pts = clean_points(
            pts,
            float(radius),
            Cleaning(reach=c.reach, self_margin=c.self_margin, vouch_margin=c.vouch_margin),
            self_filter,
        )
        return PointCloud(pts, radius, resolution, contact)
    if cleaning is not None or self_filter is not None:
        pts = clean_points(pts, float(radius), cleaning, self_filter)
    if shadow:
        pts = shadows(pts, points_in_base(np.zeros((1, 3)), frame)[0], float(shadow), float(resolution))
    return PointCloud(pts, radius, resolution, contact)


def _norm(v: torch.Tensor) -> torch.Tensor:
    """‖v‖ over the last axis, with a finite gradient at 0 (the compiled twin's sqrt of the same sum)."""
    s = v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1] + v[..., 2] * v[..., 2]
    return s.clamp_min(torch.finfo(v.dtype).tiny).sqrt()
