"""The fields of MoveIt messages, each checked where it is read: a value that is not what its field
holds is a :class:`~kinlearn.errors.SceneFormatError` naming its key path
(``world.collision_objects[3].pose.position.x (object 'shelf')``), never a plain Python error.

:class:`_At` is where a value lies in the document (its key path, built only when a message needs it);
the readers take real numbers (Python, NumPy, 0-d tensors, or strings holding one, as YAML may quote
them), lists, mappings and names, and poses (:func:`pose_matrix`: a MoveIt pose mapping, seven numbers
or a 4 × 4 matrix). Positions and sizes must lie within ±:data:`MAX_METRES` m; a pose's quaternion must
have a norm within [:data:`QUATERNION_NORM`] (it is normalised within it; a norm far from 1 is a garbled
pose, refused rather than normalised). The messages built from these fields, scenes and plan requests,
are read in :mod:`kinlearn.collision.moveit`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
import torch

from ..errors import SceneFormatError
from .geometry import quaternion_from_rotation, rotation_from_quaternion

__all__ = ["MAX_METRES", "QUATERNION_NORM", "pose_matrix"]

#: Positions and sizes (m) beyond this magnitude are refused (no workcell is 1,000 km across).
MAX_METRES = 1e6
#: The norms a pose's orientation quaternion may have (it is normalised); others are refused.
QUATERNION_NORM = (0.5, 2.0)


class _At:
    """Where a value lies in the document: its key path (built only when a message needs it) and the
    collision object it belongs to."""

    __slots__ = ("key", "label", "parent")

    def __init__(self, key: str | int = "", label: str = "", parent: _At | None = None):
        self.key, self.label, self.parent = key, label, parent

    def __truediv__(self, key: str | int) -> _At:
        return _At(key, self.label, self)

    def labelled(self, label: str) -> _At:
        return _At(self.key, label, self.parent)

    @property
    def path(self) -> str:
        parts, at = [], self
        while at is not None:
            parts.append(at.key)
            at = at.parent
        out = ""
        for key in reversed(parts):
            if isinstance(key, int):
                out += f"[{key}]"
            elif key:
                out += f".{key}" if out else key
        return out

    def __str__(self) -> str:
        where = self.path or "the document"
        return f"{where} (object {self.label!r})" if self.label else where


def _describe(value) -> str:
    text = repr(value)
    return f"{type(value).__name__} {text if len(text) <= 60 else text[:57] + '...'}"


def _number(value, at: _At, *, metres: bool = False) -> float:
    """A real number (Python, NumPy, a 0-d tensor, or a string holding one, as YAML may quote it), finite,
    within ±:data:`MAX_METRES` when it is a length or position."""
    if isinstance(value, torch.Tensor) and value.ndim == 0 and not value.is_complex():
        value = value.item()
    elif isinstance(value, np.ndarray) and value.ndim == 0:
        value = value.item()
    if isinstance(value, (bool, np.bool_)) or not isinstance(
        value, (int, float, str, np.integer, np.floating)
    ):
        raise SceneFormatError(f"{at} must be a number, got {_describe(value)}")
    try:
        v = float(value)
    except (ValueError, OverflowError):
        raise SceneFormatError(f"{at} must be a number, got {_describe(value)}") from None
    if not math.isfinite(v):
        raise SceneFormatError(f"{at} must be finite, got {value!r}")
    if metres and abs(v) > MAX_METRES:
        raise SceneFormatError(
            f"{at} is {v:g} m; positions and sizes must lie within ±{MAX_METRES:g} m (metres, not millimetres?)"
        )
    return v


def _list(value, at: _At, what: str, *, optional: bool = True) -> list:
    """A list (or tuple, 1-d array or tensor) as a list; ``None`` as [] where the field is optional."""
    if value is None and optional:
        return []
    if isinstance(value, (list, tuple)):
        return list(value)
    if isinstance(value, (np.ndarray, torch.Tensor)) and value.ndim >= 1:
        return list(value)
    raise SceneFormatError(f"{at} must be a list of {what}, got {_describe(value)}")


def _mapping(value, at: _At, what: str, *, optional: bool = True) -> Mapping:
    if value is None and optional:
        return {}
    if not isinstance(value, Mapping):
        raise SceneFormatError(f"{at} must be a mapping ({what}), got {_describe(value)}")
    return value


def _name(value, at: _At) -> str:
    """A name (a string; an integer, as YAML reads ``id: 5``, is its digits)."""
    if isinstance(value, str):
        return value
    if isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_)):
        return str(value)
    raise SceneFormatError(f"{at} must be a name (a string), got {_describe(value)}")


def _components(value, names: str, at: _At, *, metres: bool) -> list[float]:
    """A point (``names`` "xyz") or a quaternion ("xyzw") of a pose: a mapping by name (ROS messages as
    YAML; a missing name is 0, a missing w 1) or a list in that order (as robowflex, and so
    MotionBenchMaker's scene files, write them). ``None``: the origin, or the identity rotation."""
    if value is None:
        value = {}
    if isinstance(value, Mapping):
        return [_number(value.get(k, 1.0 if k == "w" else 0.0), at / k, metres=metres) for k in names]
    if not isinstance(value, (str, bytes, Mapping)):
        try:
            items = _list(value, at, "numbers", optional=False)
        except SceneFormatError:
            items = None
        if items is not None and len(items) == len(names):
            return [_number(v, at / k, metres=metres) for k, v in zip(names, items, strict=True)]
    raise SceneFormatError(
        f"{at} must be a mapping ({', '.join(names)}) or a list [{', '.join(names)}], got {_describe(value)}"
    )


def _rotation(q: list[float], at: _At) -> np.ndarray:
    scale = max(abs(v) for v in q)
    norm = 0.0 if scale == 0 else scale * math.sqrt(sum((v / scale) ** 2 for v in q))
    if norm == 0:
        raise SceneFormatError(f"{at}: the orientation quaternion is zero")
    low, high = QUATERNION_NORM
    if not low <= norm <= high:
        raise SceneFormatError(
            f"{at}: the orientation quaternion has norm {norm:.6g}; a rotation's has norm 1 (norms within "
            f"[{low:g}, {high:g}] are normalised; one this far is a garbled pose, not normalised silently)"
        )
    return rotation_from_quaternion(q)


def _matrix(value, at: _At) -> np.ndarray | None:
    """``value`` as a float64 array when it is an array, tensor or nested list of numbers; None otherwise."""
    if isinstance(value, torch.Tensor):
        if value.dtype == torch.bool or value.is_complex():
            return None
        return value.detach().cpu().double().numpy()
    try:
        a = np.asarray(value)
    except (ValueError, TypeError):
        return None
    if a.dtype.kind not in "fiu":
        return None
    return a.astype(np.float64)


def pose_matrix(pose, where: str = "pose") -> np.ndarray:
    """A 4 × 4 transform from a MoveIt pose mapping (``position`` x, y, z; ``orientation`` x, y, z, w; each
    a mapping by name or a list in that order), a sequence ``[x, y, z, qx, qy, qz, qw]``, or a 4 × 4
    matrix (a list, an array or a tensor). ``None`` is the identity. A malformed pose is a
    :class:`~kinlearn.errors.SceneFormatError` naming ``where``."""
    return _pose(pose, where if isinstance(where, _At) else _At(str(where)))


def _pose(pose, at: _At) -> np.ndarray:
    T = np.eye(4)
    if pose is None:
        return T
    if isinstance(pose, Mapping):
        p = _components(pose.get("position"), "xyz", at / "position", metres=True)
        q = _components(pose.get("orientation"), "xyzw", at / "orientation", metres=False)
    else:
        a = None if isinstance(pose, (str, bytes)) else _matrix(pose, at)
        if a is not None and a.shape == (4, 4):
            if not np.isfinite(a).all() or not np.allclose(a[3], [0, 0, 0, 1]):
                raise SceneFormatError(f"{at}: a 4 × 4 pose must be finite with last row [0, 0, 0, 1]")
            if np.abs(a[:3, 3]).max() > MAX_METRES:
                raise SceneFormatError(f"{at}: its position must lie within ±{MAX_METRES:g} m")
            R = a[:3, :3]
            if np.abs(R.T @ R - np.eye(3)).max() > 1e-6 or abs(np.linalg.det(R) - 1) > 1e-6:
                raise SceneFormatError(f"{at}: the 4 × 4 pose's rotation is not a rotation")
            return a.copy()
        if a is None or a.shape != (7,):
            shape = f"shape {a.shape}" if a is not None else _describe(pose)
            raise SceneFormatError(
                f"{at} must be a mapping (position, orientation), [x, y, z, qx, qy, qz, qw] or a 4 × 4 "
                f"matrix, got {shape}"
            )
        p = [_number(v, at / k, metres=True) for k, v in zip("xyz", a[:3].tolist(), strict=True)]
        q = [
            _number(v, at / k, metres=False)
            for k, v in zip(("qx", "qy", "qz", "qw"), a[3:].tolist(), strict=True)
        ]
    T[:3, :3] = _rotation(q, at / "orientation" if isinstance(pose, Mapping) else at)
    T[:3, 3] = p
    return T


def _pose_dict(T: np.ndarray) -> dict:
    q = quaternion_from_rotation(T[:3, :3])
    return {
        "position": {k: float(v) for k, v in zip("xyz", T[:3, 3], strict=True)},
        "orientation": {k: float(v) for k, v in zip("xyzw", q, strict=True)},
    }
