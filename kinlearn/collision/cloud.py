"""Point-cloud obstacles: what a depth camera sees, as a :class:`PointCloud` a :class:`~kinlearn.collision.Scene`
holds beside its primitives, checked through a compiled distance grid.

Each point is an obstacle ball of ``radius`` (m) in the robot's base frame. The kernels never look at the
points themselves: :attr:`PointCloud.packed` builds (once, on first use) a distance grid whose query is
a **lower bound** on the signed distance from a point in space to the union of those balls, so that a
body sphere found clear of the grid is clear of every point ball (*free under the structure is free
under the points*):

- the **grid** (cells of edge ``resolution``, default 1 cm) spans the points' bounding box and
  :data:`PAD` cells around it; each cell holds the exact Euclidean distance from its centre to the
  nearest cell holding a point (Felzenszwalb and Huttenlocher's separable transform: a scan along z, then
  the lower envelope of parabolas along y and x, many lines side by side so that every access is
  contiguous), less half a cell's diagonal (a point lies anywhere in its cell) and ``radius``: a lower
  bound at the centre;
- a **query** at ``p`` takes, over the 8 cell centres around it (outside the grid, the nearest 8 on its
  border), the largest of a centre's bound less ``‖p − centre‖`` (the distance is 1-Lipschitz, so each
  is a bound at ``p``), and the points' bounding box's distance.

The conservative margin is the price of the cells: within the grid a sphere may be judged colliding
before it touches a point ball by at most a cell's diagonal for the point's place in its cell and the
query's (2√3 · ``resolution``, 3.5 cm at the default 1 cm), by about 1 cm typically at the default (the
best of the 8 centres lies nearly behind ``p``), and never after; beyond the grid's :data:`PAD` the
bound loosens with the angle to its border.

:meth:`PointCloud.distance` is the compiled query, :meth:`PointCloud.distance_torch` its torch twin
(the same numbers, for :func:`~kinlearn.collision.body_obstacle_distance` and batches), and
:func:`cloud_distance` the inline function the collision kernels call with :attr:`PointCloud.packed`.

Reading and cleaning: :func:`read_points` reads ``.npy``, ``.ply`` (``plyfile``) and ``.pcd`` (ASCII and
binary; a small strict reader here, for PCD has no light, well-kept one); :func:`points_in_base` moves a
camera's points into the base frame; :class:`Cleaning` names the optional steps (dropping points beyond
the robot's reach, on the robot's own body at its configuration, voxel down-sampling, radius or
statistical outlier removal), applied by :func:`clean_points`. Bad input raises
:class:`~kinlearn.errors.PointCloudError` (a file that cannot be read: :class:`~kinlearn.errors.PointCloudFileError`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import torch

from ..body.jit import jit
from ..errors import PointCloudError, PointCloudFileError
from .geometry import check_rotations, rotation_from_quaternion
from .kinds.cloud import EDGE as _H
from .kinds.cloud import HEADER as _HEADER
from .kinds.cloud import HI as _HI
from .kinds.cloud import LO as _LO
from .kinds.cloud import NX as _NX
from .kinds.cloud import NY as _NY
from .kinds.cloud import NZ as _NZ
from .kinds.cloud import ORIGIN as _OX
from .kinds.cloud import RADIUS as _R
from .kinds.cloud import cloud_distance

__all__ = [
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
    "shadows",
]

#: Default radius (m) of the ball each point stands for: a surface sampled every centimetre is covered
#: by balls of half the diagonal of its spacing and then some (sensor noise).
DEFAULT_RADIUS = 0.01
#: Default edge (m) of the fine grid's cells.
DEFAULT_RESOLUTION = 0.01
#: Metres of grid around the points' bounding box (beyond it, the border cells' bounds less the way
#: there): about a body sphere's radius and a clearance, where the bounds matter most.
PAD = 0.04
#: The most fine cells a grid may have (a float64 each): a larger cloud extent asks for a crop
#: (:attr:`Cleaning.reach`) or a coarser resolution.
MAX_CELLS = 1 << 26
#: A cloud whose median point lies farther than this (m) from its frame's origin is taken for millimetres.
MILLIMETRE_NORM = 20.0
#: Metres taken off every bound for the rounding of the arithmetic that made it.
_ROUNDING = 1e-9

# --------------------------------------------------------------------------------------------------
# Checking and reading points
# --------------------------------------------------------------------------------------------------


def check_points(points, what: str = "points", drop_nonfinite: bool = False) -> np.ndarray:
    """``points`` as a C-contiguous float64 ``(N, 3)`` array: :class:`PointCloudError` for another shape, a
    non-numeric type, no points, NaN or infinite rows (dropped instead with ``drop_nonfinite``, as a depth
    camera's organised cloud marks its missing pixels) or values that look like millimetres."""
    if isinstance(points, torch.Tensor):
        points = points.detach().cpu().numpy()
    try:
        a = np.asarray(points)
    except (TypeError, ValueError) as exc:
        raise PointCloudError(
            f"{what} must be an array of numbers (N, 3), got {type(points).__name__}"
        ) from exc
    if a.dtype.kind not in "fiu":
        raise PointCloudError(f"{what} must hold real numbers (metres), got dtype {a.dtype}")
    if a.ndim != 2 or a.shape[1] != 3:
        hint = (
            " (an organised cloud (H, W, 3): reshape it to (-1, 3))"
            if a.ndim == 3 and a.shape[-1] == 3
            else ""
        )
        raise PointCloudError(f"{what} must have shape (N, 3) [x, y, z], got {a.shape}{hint}")
    a = np.ascontiguousarray(a, dtype=np.float64)
    bad = ~np.isfinite(a).all(axis=1)
    if bad.any():
        if not drop_nonfinite:
            raise PointCloudError(
                f"{what} hold {int(bad.sum())} row(s) with NaN or infinity (first: row {int(np.flatnonzero(bad)[0])}); "
                "pass drop_nonfinite=True to drop them (a depth camera's missing pixels)"
            )
        a = np.ascontiguousarray(a[~bad])
    if a.shape[0] == 0:
        raise PointCloudError(f"{what} hold no point" + (" with finite values" if bad.any() else ""))
    median = float(np.median(np.linalg.norm(a, axis=1)))
    if median > MILLIMETRE_NORM:
        raise PointCloudError(
            f"{what}: the median point lies {median:.4g} from the origin; kinlearn takes metres and this "
            f"looks like millimetres (more than {MILLIMETRE_NORM:g}): divide by 1000"
        )
    return a


def read_points(path: str | Path) -> np.ndarray:
    """The points ``(N, 3)`` of a ``.npy`` (an ``(N, 3)`` array, or a structured one with fields x, y, z),
    ``.ply`` (its ``vertex`` element's x, y, z; ASCII or binary, read by ``plyfile``) or ``.pcd`` file
    (fields x, y, z; ``DATA ascii`` or ``binary``), as float64, unchecked (NaN rows kept: see
    :func:`check_points`). :class:`PointCloudFileError` for a missing, unreadable or malformed file or
    another suffix."""
    p = Path(path)
    if not p.is_file():
        raise PointCloudFileError(f"{p}: no such point-cloud file")
    suffix = p.suffix.lower()
    readers = {".npy": _read_npy, ".ply": _read_ply, ".pcd": _read_pcd}
    if suffix not in readers:
        raise PointCloudFileError(
            f"{p}: kinlearn reads point clouds from .npy, .ply and .pcd files, not {suffix!r}"
        )
    try:
        out = readers[suffix](p)
    except PointCloudFileError:
        raise
    except (OSError, ValueError, TypeError, KeyError, IndexError, EOFError) as exc:
        raise PointCloudFileError(f"{p}: not a readable {suffix} point cloud: {exc}") from exc
    if out.ndim != 2 or out.shape[1] != 3:
        raise PointCloudFileError(f"{p}: expected points (N, 3), read shape {out.shape}")
    return np.ascontiguousarray(out, dtype=np.float64)


def _xyz_fields(names, p: Path) -> None:
    missing = [f for f in "xyz" if f not in names]
    if missing:
        raise PointCloudFileError(
            f"{p}: the cloud has no field {', '.join(missing)} (fields: {', '.join(names)})"
        )


def _read_npy(p: Path) -> np.ndarray:
    a = np.load(p, allow_pickle=False)
    if a.dtype.names:
        _xyz_fields(a.dtype.names, p)
        return np.stack([a[f].astype(np.float64).reshape(-1) for f in "xyz"], axis=1)
    if a.dtype.kind not in "fiu":
        raise PointCloudFileError(f"{p}: holds {a.dtype} values, not numbers")
    if a.ndim == 3 and a.shape[-1] == 3:  # an organised cloud (H, W, 3)
        a = a.reshape(-1, 3)
    if a.ndim != 2 or a.shape[1] != 3:
        raise PointCloudFileError(f"{p}: expected an (N, 3) array of points, found shape {a.shape}")
    return a.astype(np.float64)


def _read_ply(p: Path) -> np.ndarray:
    try:
        from plyfile import PlyData, PlyHeaderParseError
    except ImportError as exc:  # pragma: no cover - a dependency
        from ..errors import MissingDependencyError

        raise MissingDependencyError("reading .ply files needs plyfile: pip install plyfile") from exc
    try:
        ply = PlyData.read(str(p))
    except PlyHeaderParseError as exc:
        raise PointCloudFileError(f"{p}: not a PLY file: {exc}") from exc
    except Exception as exc:  # plyfile raises several kinds on truncated or malformed bodies
        raise PointCloudFileError(f"{p}: a malformed PLY file: {exc}") from exc
    names = [e.name for e in ply.elements]
    if "vertex" not in names:
        raise PointCloudFileError(f"{p}: a PLY file without a vertex element (elements: {', '.join(names)})")
    v = ply["vertex"].data
    _xyz_fields(v.dtype.names or (), p)
    return np.stack([np.asarray(v[f], dtype=np.float64) for f in "xyz"], axis=1)


#: PCD types and sizes → NumPy type characters.
_PCD_TYPES = {("F", 4): "f4", ("F", 8): "f8", ("I", 1): "i1", ("I", 2): "i2", ("I", 4): "i4", ("I", 8): "i8",
              ("U", 1): "u1", ("U", 2): "u2", ("U", 4): "u4", ("U", 8): "u8"}  # fmt: skip
_PCD_KEYS = ("VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS", "DATA")


def _read_pcd(p: Path) -> np.ndarray:
    """A strict reader of the Point Cloud Library's format (v0.7): the header's lines in order, then the
    data, ``ascii`` (one point per line) or ``binary`` (packed records); ``binary_compressed`` refused."""
    raw = p.read_bytes()
    header: dict[str, list[str]] = {}
    pos = 0
    while "DATA" not in header:
        end = raw.find(b"\n", pos)
        if end < 0:
            raise PointCloudFileError(f"{p}: a PCD header without a DATA line")
        line = raw[pos:end].decode("ascii", errors="replace").strip()
        pos = end + 1
        if not line or line.startswith("#"):
            continue
        key, *values = line.split()
        if key not in _PCD_KEYS:
            raise PointCloudFileError(f"{p}: not a PCD header line: {line[:60]!r}")
        header[key] = values
    for key in ("FIELDS", "SIZE", "TYPE", "POINTS"):
        if key not in header:
            raise PointCloudFileError(f"{p}: the PCD header has no {key} line")
    fields, sizes, types = header["FIELDS"], header["SIZE"], header["TYPE"]
    counts = header.get("COUNT", ["1"] * len(fields))
    if not (len(fields) == len(sizes) == len(types) == len(counts)):
        raise PointCloudFileError(f"{p}: FIELDS, SIZE, TYPE and COUNT name different numbers of fields")
    _xyz_fields(fields, p)
    try:
        n = int(header["POINTS"][0])
        dtype = np.dtype(
            [
                (f, _PCD_TYPES[(t, int(s))], (int(c),))
                for f, s, t, c in zip(fields, sizes, types, counts, strict=True)
            ]
        )
    except (KeyError, ValueError, IndexError) as exc:
        raise PointCloudFileError(f"{p}: a PCD header with an unknown size, type or count ({exc})") from exc
    data = header["DATA"][0] if header["DATA"] else ""
    if data == "ascii":
        rows = [r.split() for r in raw[pos:].decode("ascii", errors="replace").splitlines() if r.strip()]
        width = sum(int(c) for c in counts)
        if len(rows) != n or any(len(r) != width for r in rows):
            raise PointCloudFileError(
                f"{p}: the PCD header says {n} points of {width} values; the data has {len(rows)} lines"
                + ("" if len(rows) != n else " of another length")
            )
        try:
            table = np.array(rows, dtype=np.float64)
        except ValueError as exc:
            raise PointCloudFileError(f"{p}: a PCD data line that is not numbers: {exc}") from exc
        offsets = np.cumsum([0] + [int(c) for c in counts])
        return np.stack([table[:, offsets[fields.index(f)]] for f in "xyz"], axis=1)
    if data == "binary":
        body = raw[pos:]
        if len(body) < n * dtype.itemsize:
            raise PointCloudFileError(
                f"{p}: the PCD header says {n} points of {dtype.itemsize} bytes; the data holds {len(body)} bytes"
            )
        table = np.frombuffer(body, dtype=dtype, count=n)
        return np.stack([table[f][:, 0].astype(np.float64) for f in "xyz"], axis=1)
    if data == "binary_compressed":
        raise PointCloudFileError(
            f"{p}: binary_compressed PCD is not read; save the cloud as ascii or binary"
        )
    raise PointCloudFileError(f"{p}: unknown PCD DATA {data!r} (ascii or binary)")


def shadows(points: np.ndarray, origin, length: float, step: float) -> np.ndarray:
    """``points (N, 3)`` and, behind each as seen from ``origin`` (the camera), points every ``step`` (m) along
    its ray for ``length`` (m) further: the space a depth camera cannot see behind a surface, taken as
    occupied that far (beyond it, and outside the camera's view, unknown space stays free)."""
    if not (math.isfinite(length) and length >= 0 and math.isfinite(step) and step > 0):
        raise PointCloudError(
            f"a shadow's length must be >= 0 and its step > 0 (m), got {length!r}, {step!r}"
        )
    n = math.floor(length / step)
    if n == 0:
        return points
    ray = points - np.asarray(origin, dtype=np.float64)
    ray /= np.maximum(np.linalg.norm(ray, axis=1, keepdims=True), 1e-12)
    steps = step * np.arange(1, n + 1)
    behind = points[:, None, :] + steps[None, :, None] * ray[:, None, :]
    return np.ascontiguousarray(np.concatenate([points, behind.reshape(-1, 3)]))


def points_in_base(points: np.ndarray, frame) -> np.ndarray:
    """Points ``(N, 3)`` given in a camera's frame, moved to the robot's base frame: ``frame`` is the
    camera's pose in the base frame, a 4 × 4 transform, a pair ``(position (3,), quaternion (4,) x, y, z, w)``
    or seven numbers ``[x, y, z, qx, qy, qz, qw]``; None: the points are in the base frame already."""
    if frame is None:
        return points
    try:
        if isinstance(frame, (tuple, list)) and len(frame) == 2:
            t = np.asarray(frame[0], dtype=np.float64).reshape(-1)
            q = np.asarray(frame[1], dtype=np.float64).reshape(-1)
            if t.shape != (3,) or q.shape != (4,):
                raise ValueError(f"position {t.shape}, quaternion {q.shape}")
        else:
            T = np.asarray(
                frame.detach().cpu() if isinstance(frame, torch.Tensor) else frame, dtype=np.float64
            )
            if T.shape == (7,):
                t, q = T[:3], T[3:]
            elif T.shape == (4, 4):
                if not np.allclose(T[3], (0.0, 0.0, 0.0, 1.0)):
                    raise ValueError("its last row must be [0, 0, 0, 1]")
                t, q = T[:3, 3], None
                R = T[:3, :3]
            else:
                raise ValueError(f"shape {T.shape}")
    except (TypeError, ValueError) as exc:
        raise PointCloudError(
            "frame must be the camera's pose in the base frame: a 4 × 4 transform, (position (3,), "
            f"quaternion (4,) [x, y, z, w]) or [x, y, z, qx, qy, qz, qw]; got {exc}"
        ) from exc
    if q is not None:
        if not (np.isfinite(q).all() and np.linalg.norm(q) > 0):
            raise PointCloudError(f"frame: the quaternion must be finite and non-zero, got {q.tolist()}")
        R = rotation_from_quaternion(q)
    if not (np.isfinite(t).all() and np.isfinite(R).all()):
        raise PointCloudError("frame holds NaN or infinity")
    try:
        check_rotations(torch.as_tensor(R.reshape(1, 9)), "frame")
    except Exception as exc:
        raise PointCloudError(str(exc)) from exc
    return np.ascontiguousarray(points @ R.T + t)


# --------------------------------------------------------------------------------------------------
# Cleaning
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Cleaning:
    """Optional steps that clean a cloud before it becomes obstacles (:func:`clean_points`), applied in
    this order:

    - ``reach``: drop points farther than this (m) from the base's origin, less their radius (none of
      those can touch the robot: with a body, its :attr:`~kinlearn.collision.BodySpheres.reach` is taken
      when this is None). Keeps the grid small where a camera sees the room behind the robot.
    - self-filtering (given a body and its configuration to :func:`clean_points`): drop every point whose
      ball comes within ``self_margin`` (m) of one of the body's spheres there, the robot seeing itself.
    - ``voxel``: one point per occupied cube of this edge (m), their centroid. The grid is an occupancy
      grid, so this mainly saves reading time; a voxel larger than the grid's resolution moves the
      surface by up to half its diagonal (give ``radius`` room for it).
    - ``outliers``: ``"radius"`` drops points with fewer than ``min_neighbours`` others within
      ``outlier_radius`` (m); ``"statistical"`` drops points whose mean distance to their ``neighbours``
      nearest (searched within the 27 cells of edge ``outlier_radius`` around them; those not found count
      as ``outlier_radius``) exceeds the cloud's mean by ``std_ratio`` standard deviations. Speckle a
      depth camera leaves at depth edges; each removed point is an obstacle less, so keep it off where a
      thin real obstacle is sampled sparsely.
    """

    reach: float | None = None
    self_margin: float = 0.02
    voxel: float | None = None
    outliers: Literal["none", "radius", "statistical"] = "none"
    outlier_radius: float = 0.03
    min_neighbours: int = 3
    neighbours: int = 8
    std_ratio: float = 2.0

    def __post_init__(self):
        for name in ("reach", "voxel"):
            v = getattr(self, name)
            if v is not None and not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise PointCloudError(f"Cleaning.{name} must be None or a number of metres > 0, got {v!r}")
        for name in ("self_margin", "outlier_radius", "std_ratio"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise PointCloudError(f"Cleaning.{name} must be a finite number >= 0, got {v!r}")
        if self.outliers not in ("none", "radius", "statistical"):
            raise PointCloudError(
                f"Cleaning.outliers must be 'none', 'radius' or 'statistical', got {self.outliers!r}"
            )
        for name in ("min_neighbours", "neighbours"):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= 1):
                raise PointCloudError(f"Cleaning.{name} must be an integer >= 1, got {v!r}")
        if self.outliers != "none" and not self.outlier_radius > 0:
            raise PointCloudError("Cleaning.outlier_radius must be > 0 to remove outliers")


def _body_of(body):
    """A :class:`~kinlearn.collision.BodySpheres`, or the ``body`` of a planner."""
    from .body import BodySpheres

    if isinstance(body, BodySpheres):
        return body
    inner = getattr(body, "body", None)
    if isinstance(inner, BodySpheres):
        return inner
    raise PointCloudError(
        f"self-filtering takes the robot's BodySpheres (or a planner) and its joints, got {type(body).__name__}"
    )


def clean_points(
    points: np.ndarray, radius: float, cleaning: Cleaning | None = None, self_filter: tuple | None = None
) -> np.ndarray:
    """The points ``(N, 3)`` (base frame, checked) after the steps of ``cleaning`` (see :class:`Cleaning`);
    ``self_filter``: ``(body, q)``, a :class:`~kinlearn.collision.BodySpheres` (or a planner) and the
    robot's joints ``(dof,)`` when the cloud was taken: the points on its own body are dropped.
    :class:`PointCloudError` if nothing is left."""
    cleaning = cleaning or Cleaning()
    pts = points
    reach = cleaning.reach
    centres = None
    if self_filter is not None:
        try:
            body, q = self_filter
        except (TypeError, ValueError) as exc:
            raise PointCloudError("self_filter must be a pair (body, joints)") from exc
        body = _body_of(body)
        q = torch.as_tensor(np.asarray(q, dtype=np.float64)).to(body.radii)
        if q.shape != (body.robot.dof,):
            raise PointCloudError(
                f"self_filter's joints must have shape ({body.robot.dof},), got {tuple(q.shape)}"
            )
        with torch.no_grad():
            centres = body(q[None])[0].detach().cpu().double().numpy()
            radii = body.radii.detach().cpu().double().numpy()
        if reach is None:
            reach = body.reach + cleaning.self_margin
    if reach is not None:
        pts = pts[np.linalg.norm(pts, axis=1) - radius <= reach]
    if centres is not None and len(pts):
        keep = np.empty(len(pts), dtype=np.bool_)
        _outside_spheres(pts, np.ascontiguousarray(centres), radii + radius + cleaning.self_margin, keep)
        pts = pts[keep]
    if cleaning.voxel is not None and len(pts):
        pts = _voxel_centroids(pts, cleaning.voxel)
    if cleaning.outliers != "none" and len(pts):
        keep = _inliers(pts, cleaning)
        pts = pts[keep]
    if len(pts) == 0:
        raise PointCloudError("no point is left after cleaning (reach, self-filtering, outliers)")
    return np.ascontiguousarray(pts)


@jit
def _outside_spheres(points, centres, reach, keep):
    """``keep[i]``: point i lies farther than ``reach[m]`` from every centre m."""
    for i in range(points.shape[0]):
        ok = True
        for m in range(centres.shape[0]):
            dx = points[i, 0] - centres[m, 0]
            dy = points[i, 1] - centres[m, 1]
            dz = points[i, 2] - centres[m, 2]
            if dx * dx + dy * dy + dz * dz <= reach[m] * reach[m]:
                ok = False
                break
        keep[i] = ok


def _cell_keys(points: np.ndarray, edge: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Integer cell coordinates ``(N, 3)`` of cubes of ``edge``, one int64 key per cell, and the dims."""
    lo = points.min(axis=0)
    cell = np.floor((points - lo) / edge).astype(np.int64)
    dims = cell.max(axis=0) + 3  # room for the neighbours' offsets (cells shifted by one below)
    cell += 1
    key = (cell[:, 0] * dims[1] + cell[:, 1]) * dims[2] + cell[:, 2]
    return cell, key, dims


def _voxel_centroids(points: np.ndarray, edge: float) -> np.ndarray:
    _, key, _ = _cell_keys(points, edge)
    uniq, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    out = np.empty((len(uniq), 3))
    for a in range(3):
        out[:, a] = np.bincount(inverse, weights=points[:, a], minlength=len(uniq)) / counts
    return out


def _inliers(points: np.ndarray, cleaning: Cleaning) -> np.ndarray:
    cell, key, dims = _cell_keys(points, cleaning.outlier_radius)
    order = np.argsort(key, kind="stable")
    sorted_keys = np.ascontiguousarray(key[order])
    pts = np.ascontiguousarray(points[order])
    stat = np.empty(len(points))
    k = cleaning.neighbours if cleaning.outliers == "statistical" else 0
    _neighbourhoods(
        pts, np.ascontiguousarray(cell[order]), sorted_keys, dims, cleaning.outlier_radius, k, stat
    )
    if cleaning.outliers == "radius":
        keep_sorted = stat >= cleaning.min_neighbours
    else:
        keep_sorted = stat <= stat.mean() + cleaning.std_ratio * stat.std()
    keep = np.empty(len(points), dtype=bool)
    keep[order] = keep_sorted
    return keep


@jit
def _neighbourhoods(points, cell, keys, dims, radius, k, out):
    """Per point (sorted by cell key): with ``k`` = 0 the number of other points within ``radius``; else
    the mean distance to its ``k`` nearest among the 27 cells around it (``radius`` for each not found)."""
    n = points.shape[0]
    best = np.empty(max(k, 1))
    r2 = radius * radius
    for i in range(n):
        count = 0
        for t in range(k):
            best[t] = radius
        for da in range(-1, 2):
            for db in range(-1, 2):
                for dc in range(-1, 2):
                    key = ((cell[i, 0] + da) * dims[1] + cell[i, 1] + db) * dims[2] + cell[i, 2] + dc
                    j = np.searchsorted(keys, key)
                    while j < n and keys[j] == key:
                        if j != i:
                            dx = points[j, 0] - points[i, 0]
                            dy = points[j, 1] - points[i, 1]
                            dz = points[j, 2] - points[i, 2]
                            d2 = dx * dx + dy * dy + dz * dz
                            if k == 0:
                                if d2 <= r2:
                                    count += 1
                            else:
                                d = math.sqrt(d2)
                                if d < best[k - 1]:  # insert into the sorted k best
                                    t = k - 1
                                    while t > 0 and best[t - 1] > d:
                                        best[t] = best[t - 1]
                                        t -= 1
                                    best[t] = d
                        j += 1
        if k == 0:
            out[i] = count
        else:
            s = 0.0
            for t in range(k):
                s += best[t]
            out[i] = s / k


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
def _build(points, radius, h, pad, out_header):
    """The packed grid of ``points (N, 3)`` (see the module docstring): header filled (also into
    ``out_header``), the cells' lower bounds after it, one buffer."""
    lo, hi = _bounds(points)
    ox, oy, oz = lo[0] - pad * h, lo[1] - pad * h, lo[2] - pad * h
    nx = int((hi[0] - ox) / h) + pad + 1
    ny = int((hi[1] - oy) / h) + pad + 1
    nz = int((hi[2] - oz) / h) + pad + 1
    P = ny * nz
    N = nx * P
    buf = np.empty(_HEADER + N)
    g = buf[_HEADER:]
    g[:] = _NONE
    filled = np.zeros(nx, dtype=np.bool_)
    for i in range(points.shape[0]):
        a = int((points[i, 0] - ox) / h)
        b = int((points[i, 1] - oy) / h)
        c = int((points[i, 2] - oz) / h)
        g[(a * ny + b) * nz + c] = 0.0
        filled[a] = True
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
    out_header[:] = hd
    return buf


@jit
def _distances(points, g, out):
    for i in range(points.shape[0]):
        out[i] = cloud_distance(points[i, 0], points[i, 1], points[i, 2], g)


class PointCloud:
    """Points ``(N, 3)`` (m, the robot's base frame), each an obstacle ball of ``radius``, with the
    compiled distance grid of cell edge ``resolution`` they are checked through (:attr:`packed`, built on
    first use). Immutable: its points are a read-only float64 array."""

    __slots__ = ("__weakref__", "_header", "_packed", "_torch", "points", "radius", "resolution")

    def __init__(self, points, radius: float = DEFAULT_RADIUS, resolution: float = DEFAULT_RESOLUTION):
        pts = check_points(points)
        for name, v in (("radius", radius), ("resolution", resolution)):
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
        self._packed = None
        self._header = None
        self._torch = {}

    @property
    def num_points(self) -> int:
        return int(self.points.shape[0])

    @property
    def packed(self) -> np.ndarray:
        """The distance grid in one float64 buffer (header, fine values, coarse values), built on first use."""
        if self._packed is None:
            header = np.empty(_HEADER)
            pad = math.ceil(PAD / self.resolution)
            buf = _build(self.points, self.radius, self.resolution, pad, header)
            buf.flags.writeable = False
            self._header = header
            self._packed = buf
        return self._packed

    @property
    def shape(self) -> tuple[int, int, int]:
        """The fine grid's dimensions (cells along x, y, z)."""
        g = self.packed
        return int(g[_NX]), int(g[_NY]), int(g[_NZ])

    def distance(self, points) -> np.ndarray:
        """``(N,)``: the compiled lower bound on each point's (``(N, 3)``, base frame) signed distance to
        the cloud's balls (:func:`cloud_distance`)."""
        p = np.ascontiguousarray(np.asarray(points, dtype=np.float64))
        if p.ndim != 2 or p.shape[1] != 3:
            raise PointCloudError(f"query points must have shape (N, 3), got {p.shape}")
        out = np.empty(p.shape[0])
        _distances(p, self.packed, out)
        return out

    def distance_torch(self, p: torch.Tensor) -> torch.Tensor:
        """The torch twin of :meth:`distance`: ``(...)`` for points ``p (..., 3)`` in their dtype and device,
        differentiable in ``p`` (the gradient of the bound taken: away from the best cell centre)."""
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
        return f"PointCloud(points={self.num_points}, radius={self.radius:g} m, resolution={self.resolution:g} m)"


def _norm(v: torch.Tensor) -> torch.Tensor:
    """‖v‖ over the last axis, with a finite gradient at 0 (the compiled twin's sqrt of the same sum)."""
    s = v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1] + v[..., 2] * v[..., 2]
    return s.clamp_min(torch.finfo(v.dtype).tiny).sqrt()
