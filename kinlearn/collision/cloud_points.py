"""Sensed points as they come from a camera, before they become a
:class:`~kinlearn.collision.cloud.PointCloud`: read from a file, checked, and moved into the robot's base
frame.

:func:`read_points` reads ``.npy``, ``.ply`` (``plyfile``) and ``.pcd`` (ASCII and binary; a small strict
reader here, for PCD has no light, well-kept one); :func:`check_points` holds an array to the shape,
numbers and units a cloud takes (NaN rows refused or dropped, millimetres refused); :func:`points_in_base`
moves a camera's points into the base frame given the camera's pose, :func:`views_in_base` several
cameras' points, each with its pose, fused into one cloud; :func:`shadows` fills the space a
camera cannot see behind each point, along its ray. Bad input raises
:class:`~kinlearn.errors.PointCloudError` (a file that cannot be read:
:class:`~kinlearn.errors.PointCloudFileError`).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import torch

from ..errors import PointCloudError, PointCloudFileError
from .geometry import check_rotations, rotation_from_quaternion

__all__ = [
    "MILLIMETRE_NORM",
    "check_points",
    "is_views",
    "points_in_base",
    "read_points",
    "shadows",
    "views_in_base",
]

#: A cloud whose median point lies farther than this (m) from its frame's origin is taken for millimetres.
MILLIMETRE_NORM = 20.0


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


def is_views(points) -> bool:
    """Whether ``points`` are several cameras' clouds (a list or tuple of ``(N, 3)`` arrays or tensors, or of
    files' paths), not one cloud."""
    return (
        isinstance(points, (list, tuple))
        and len(points) > 0
        and all(
            isinstance(p, (str, Path)) or (isinstance(p, (np.ndarray, torch.Tensor)) and p.ndim == 2)
            for p in points
        )
    )


def views_in_base(points, frame=None, drop_nonfinite: bool = False) -> np.ndarray:
    """One cloud ``(N, 3)`` in the robot's base frame: ``points`` (an ``(N, 3)`` array or tensor, or a
    point-cloud file's path) read, checked (:func:`check_points`) and moved from the camera's ``frame``
    (:func:`points_in_base`); or several cameras' clouds (a list of them, :func:`is_views`), each moved from
    its own pose (``frame``: a list as long, None where a cloud is in the base frame already; None for
    all) and fused. A view's bad points or pose raise :class:`PointCloudError` naming the view."""
    if not is_views(points):
        if isinstance(points, (str, Path)):
            points = read_points(points)
        return points_in_base(check_points(points, drop_nonfinite=drop_nonfinite), frame)
    frames = [None] * len(points) if frame is None else frame
    if not isinstance(frames, (list, tuple)) or len(frames) != len(points):
        raise PointCloudError(
            f"{len(points)} views of points take a list of {len(points)} camera poses (None for a view in "
            f"the base frame), got {type(frame).__name__}"
            + (f" of {len(frame)}" if isinstance(frame, (list, tuple)) else "")
        )
    fused = []
    for i, (view, pose) in enumerate(zip(points, frames, strict=True)):
        if isinstance(view, (str, Path)):
            view = read_points(view)
        view = check_points(view, f"view {i}'s points", drop_nonfinite)
        try:
            fused.append(points_in_base(view, pose))
        except PointCloudError as exc:
            raise PointCloudError(f"view {i}: {exc}") from exc
    return np.ascontiguousarray(np.concatenate(fused))
