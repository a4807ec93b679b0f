"""Checks of tensors at the API boundary: shape, dtype, finiteness (typed errors, actionable messages).

On the lowest floor with the errors, so that every layer checks its inputs the same way without
importing the robot.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from .errors import ConfigError, DTypeError, NonFiniteError, ShapeError

__all__ = [
    "as_int",
    "as_real",
    "check_finite",
    "check_last_dim",
    "check_real_dtype",
    "check_region",
    "real_array",
]


def check_last_dim(x: torch.Tensor, n: int | tuple[int, ...], what: str) -> None:
    """Raise :class:`ShapeError` unless ``x`` is a tensor of shape ``(..., n)`` (n may be a tuple of options)."""
    options = (n,) if isinstance(n, int) else tuple(n)
    if not isinstance(x, torch.Tensor):
        raise ShapeError(f"{what} must be a torch.Tensor of shape (..., {n}), got {type(x).__name__}")
    if x.ndim == 0 or x.shape[-1] not in options:
        allowed = " or ".join(f"(..., {k})" for k in options)
        raise ShapeError(f"{what} must have shape {allowed}, got {tuple(x.shape)}")
    if not x.is_floating_point():
        raise DTypeError(f"{what} must be a real floating-point tensor, got {x.dtype}")


def check_real_dtype(x: torch.Tensor, what: str) -> None:
    """Raise :class:`DTypeError` if ``x`` is a bool or complex tensor (or no tensor): such values are not
    angles or lengths, and converting them would silently turn True into 1 rad or drop an imaginary part.
    Integer tensors pass (callers convert or reject them)."""
    if not isinstance(x, torch.Tensor):
        raise ShapeError(f"{what} must be a torch.Tensor, got {type(x).__name__}")
    if x.dtype == torch.bool or x.is_complex():
        raise DTypeError(f"{what} must hold real numbers, got a {x.dtype} tensor")


def real_array(x, what: str) -> np.ndarray:
    """``x`` (an array or nested sequence of numbers, not a tensor) as a NumPy array of real numbers;
    :class:`DTypeError` for anything else (bools, strings, complex numbers, ragged sequences)."""
    try:
        a = np.asarray(x)
    except (TypeError, ValueError) as exc:
        raise DTypeError(f"{what} must be an array of numbers, got {type(x).__name__}") from exc
    if a.dtype.kind not in "fiu":
        raise DTypeError(f"{what} must hold real numbers, got {a.dtype} ({type(x).__name__})")
    return a


def check_finite(x: torch.Tensor, what: str) -> None:
    """Raise :class:`NonFiniteError` if ``x`` holds NaN or infinity."""
    if not bool(torch.isfinite(x).all()):
        n = int((~torch.isfinite(x)).sum())
        raise NonFiniteError(f"{what} holds {n} NaN/inf value(s); all values must be finite")


def check_region(region, what: str = "region") -> tuple[float, ...]:
    """``region`` as 6 floats (m: x_min, x_max, y_min, y_max, z_min, z_max); :class:`ConfigError` unless
    they are 6 finite numbers with each min ≤ max."""
    try:
        r = np.asarray(region, dtype=float)
    except (TypeError, ValueError):
        r = np.full(0, np.nan)
    if r.shape != (6,) or not np.isfinite(r).all() or (r[0::2] > r[1::2]).any():
        raise ConfigError(
            f"{what} must be 6 finite numbers x_min, x_max, y_min, y_max, z_min, z_max with each min ≤ max, "
            f"got {region!r}"
        )
    return tuple(float(v) for v in r)


def _scalar(value, what: str, kinds: str, expected: str):
    """``value`` (a Python, NumPy or 0-d torch number) as a Python number when its kind (NumPy's
    ``dtype.kind``) is one of ``kinds``; :class:`ConfigError` otherwise (bools and complex numbers included:
    True is no count and 1+0j no length)."""
    if isinstance(value, torch.Tensor):
        if value.ndim != 0:
            raise ConfigError(f"{what} must be {expected}, got a tensor of shape {tuple(value.shape)}")
        if value.dtype == torch.bool or value.is_complex():
            raise ConfigError(f"{what} must be {expected}, got a {value.dtype} tensor")
        kind = "f" if value.is_floating_point() else "i"
        value = value.item()
    elif isinstance(value, (bool, np.bool_)):
        raise ConfigError(f"{what} must be {expected}, got {value!r}")
    elif isinstance(value, int):
        kind = "i"
    elif isinstance(value, float):
        kind = "f"
    elif isinstance(value, (np.generic, np.ndarray)) and np.ndim(value) == 0:
        kind = np.asarray(value).dtype.kind
        value = np.asarray(value).item()
    else:
        raise ConfigError(f"{what} must be {expected}, got {type(value).__name__} {value!r}")
    if kind not in kinds:
        raise ConfigError(f"{what} must be {expected}, got {value!r}")
    return value


def as_int(value, what: str, *, minimum: int | None = None, maximum: int | None = None) -> int:
    """``value`` as a Python int: an integer (Python, NumPy or a 0-d integer tensor; not a bool) within
    ``[minimum, maximum]``; :class:`ConfigError` naming ``what`` and the bound otherwise."""
    bounds = (
        f" in [{minimum}, {maximum}]"
        if minimum is not None and maximum is not None
        else (f" ≥ {minimum}" if minimum is not None else (f" ≤ {maximum}" if maximum is not None else ""))
    )
    v = int(_scalar(value, what, "iu", f"an integer{bounds}"))
    if (minimum is not None and v < minimum) or (maximum is not None and v > maximum):
        raise ConfigError(f"{what} must be an integer{bounds}, got {v}")
    return v


def as_real(
    value,
    what: str,
    *,
    minimum: float | None = None,
    maximum: float | None = None,
    open_minimum: bool = False,
    finite: bool = True,
    expected: str | None = None,
) -> float:
    """``value`` as a Python float: a real number (Python, NumPy or a 0-d real tensor; not a bool or a
    complex number), finite unless ``finite=False``, ≥ ``minimum`` (> with ``open_minimum``) and ≤
    ``maximum``; :class:`ConfigError` naming ``what`` and the bound otherwise (``expected``: what the
    message says is allowed, instead of the bounds written out)."""
    low = "" if minimum is None else f"{'>' if open_minimum else '≥'} {minimum:g}"
    high = "" if maximum is None else f"≤ {maximum:g}"
    bounds = " and ".join(b for b in (low, high) if b)
    if expected is None:
        expected = f"a {'finite ' if finite else ''}real number" + (f" {bounds}" if bounds else "")
    v = float(_scalar(value, what, "fiu", expected))
    if math.isnan(v) or (finite and math.isinf(v)):
        raise ConfigError(f"{what} must be {expected}, got {v}")
    if minimum is not None and (v < minimum or (open_minimum and v == minimum)):
        raise ConfigError(f"{what} must be {expected}, got {v:g}")
    if maximum is not None and v > maximum:
        raise ConfigError(f"{what} must be {expected}, got {v:g}")
    return v


def broadcast_shapes(*shapes) -> torch.Size:
    """The shapes broadcast together, as a ``torch.Size``; :class:`ValueError` where they do not.
    NumPy's rule, which is torch's: ``torch.broadcast_shapes`` loads torch's symbolic-shape machinery on
    its first call (about 0.4 s of a fresh process's first plan)."""
    return torch.Size(np.broadcast_shapes(*(tuple(s) for s in shapes)))
