"""Checks of tensors at the API boundary: shape, dtype, finiteness (typed errors, actionable messages).

On the lowest floor with the errors, so that every layer checks its inputs the same way without
importing the robot.
"""

from __future__ import annotations

import numpy as np
import torch

from .errors import ConfigError, DTypeError, NonFiniteError, ShapeError

__all__ = ["check_finite", "check_last_dim", "check_real_dtype", "check_region", "real_array"]


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
    r = np.asarray(region, dtype=float)
    if r.shape != (6,) or not np.isfinite(r).all() or (r[0::2] > r[1::2]).any():
        raise ConfigError(
            f"{what} must be 6 finite numbers x_min, x_max, y_min, y_max, z_min, z_max with each min ≤ max, "
            f"got {region!r}"
        )
    return tuple(float(v) for v in r)
