"""The tables a :class:`~kinlearn.collision.scene.Scene` holds, one per kind of primitive, and their
checks.

Each kind of :mod:`~kinlearn.collision.geometry` primitive (:data:`~kinlearn.collision.geometry.SCENE_KINDS`)
has a table field (rows of the kind's layout, ``(..., n, width)``) and a mask field (``(..., n)``,
``False`` marking padding); :data:`_FIELDS` lists every tensor field of a scene with its number of
trailing (non-batch) dimensions. A table is checked for its width and dtype, its mask for its shape, and
its live rows for finite values, positive sizes, positions and sizes within ±:data:`MAX_METRES` m and
proper rotations; any failure is an :class:`~kinlearn.errors.ObstacleError` naming the field. An
axis-aligned box table ``(..., B, 6)`` is given the identity rotation (:func:`_axis_aligned`).
"""

from __future__ import annotations

import numpy as np
import torch

from ..checks import broadcast_shapes
from ..errors import ObstacleError
from .geometry import IDENTITY, SCENE_KINDS, Primitive, check_rotations

__all__ = ["MAX_METRES"]

#: Per kind: (table field, mask field, primitive class).
_TABLES = tuple((k.table, f"{k.kind}_mask", k) for k in SCENE_KINDS)
#: Every tensor field and its number of trailing (non-batch) dimensions.
_FIELDS = (
    *((t, 2) for t, _, _ in _TABLES),
    ("floor", 0),
    *((m, 1) for _, m, _ in _TABLES),
)


def _tensor(x, what: str, dtype=None, device=None) -> torch.Tensor:
    if isinstance(x, torch.Tensor):
        t = x
    else:
        try:
            t = torch.as_tensor(np.asarray(x, dtype=np.float64))
        except (TypeError, ValueError) as exc:
            raise ObstacleError(
                f"{what} must be a tensor or array of numbers, got {type(x).__name__}"
            ) from exc
        if dtype is None:
            dtype = torch.get_default_dtype()
    if not (t.is_floating_point() or t.dtype == torch.bool):
        t = t.to(torch.get_default_dtype())
    if dtype is not None or device is not None:
        t = t.to(dtype=dtype or t.dtype, device=device or t.device)
    return t


def _check_table(t: torch.Tensor, width: int, what: str, layout: str) -> None:
    if not t.is_floating_point():
        raise ObstacleError(f"{what} must be a floating-point tensor, got {t.dtype}")
    if t.ndim < 2 or t.shape[-1] != width:
        raise ObstacleError(
            f"{what} must have shape (..., n, {width}) with rows {layout}, got {tuple(t.shape)}; "
            f"one obstacle is a (1, {width}) table"
        )


def _check_mask(mask: torch.Tensor | None, table: torch.Tensor, what: str) -> torch.Tensor | None:
    if mask is None:
        return None
    if not isinstance(mask, torch.Tensor) or mask.dtype != torch.bool:
        raise ObstacleError(
            f"{what} must be a bool tensor (True = obstacle present), got {type(mask).__name__}"
        )
    if mask.shape[-1:] != table.shape[-2:-1]:
        raise ObstacleError(
            f"{what} must have one entry per obstacle ({table.shape[-2]}), got {tuple(mask.shape)}"
        )
    try:
        broadcast_shapes(mask.shape, table.shape[:-1])
    except ValueError as exc:
        raise ObstacleError(
            f"{what} of shape {tuple(mask.shape)} does not match obstacles of shape {tuple(table.shape)}"
        ) from exc
    return mask.to(table.device)


#: Obstacles' positions and sizes (m) are refused beyond this magnitude.
MAX_METRES = 1e6


def _check_values(table: torch.Tensor, mask: torch.Tensor | None, kind: type[Primitive]) -> None:
    live = table if mask is None else table[torch.broadcast_to(mask, table.shape[:-1])]
    if live.numel() == 0:
        return
    what = kind.table
    bad = ~torch.isfinite(live)
    if bool(bad.any()):
        raise ObstacleError(f"{what} hold {int(bad.sum())} NaN/inf value(s); all values must be finite")
    far = live.abs().amax(dim=-1) > MAX_METRES  # beyond it, squared distances overflow in float32
    if bool(far.any()):
        worst = float(live.abs().max())
        raise ObstacleError(
            f"{what} hold a position or {kind.size_name} of {worst:.6g} m; an obstacle must lie within "
            f"±{MAX_METRES:g} m of the base (metres, not millimetres?)"
        )
    small = live[..., kind.sizes] <= 0
    if bool(small.any()):
        worst = float(live[..., kind.sizes].min())
        raise ObstacleError(f"every {kind.size_name} in {what} must be > 0 (metres), found {worst:.6g}")
    if kind.rotation_columns is not None:
        check_rotations(live[..., kind.rotation_columns], what)


def _axis_aligned(boxes: torch.Tensor) -> torch.Tensor:
    """Boxes ``(..., B, 6)`` [centre, half extents] → ``(..., B, 15)`` with the identity rotation."""
    eye = boxes.new_tensor(IDENTITY).expand(*boxes.shape[:-1], 9)
    return torch.cat((boxes, eye), dim=-1)
