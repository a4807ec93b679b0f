"""Obstacle scenes: spheres, axis-aligned boxes and an optional floor, in the robot's base frame.

A :class:`Scene` holds batched tensors (leading batch dimensions ``...``, shared by all of them):

- ``spheres`` ``(..., K, 4)``: ``[x, y, z, radius]``, metres;
- ``boxes`` ``(..., B, 6)``: ``[cx, cy, cz, hx, hy, hz]``, centre and half extents of an axis-aligned box;
- ``floor``: ``None`` or the height ``(...)`` (or a scalar) of a floor plane; everything below it is solid;
- optional masks ``sphere_mask (..., K)`` and ``box_mask (..., B)``: ``False`` marks padding, so that
  scenes with different numbers of obstacles can share one batch (see :meth:`Scene.stack`). Masked
  entries are ignored by validation and by every distance.

K or B may be 0. Batch shapes broadcast against each other and against configurations (right-aligned,
as in torch); :meth:`Scene.unsqueeze` inserts a batch dimension (for example a time axis).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from ..errors import DatasetError, ObstacleError, ShapeError
from ..io import load_npz, save_npz

__all__ = ["SCENE_FORMAT", "Scene", "as_scene"]

#: Version of the scene ``.npz`` layout written by :meth:`Scene.save`.
SCENE_FORMAT = 1

_PAD_SPHERE = (0.0, 0.0, 0.0, 1.0)
_PAD_BOX = (0.0, 0.0, 0.0, 1.0, 1.0, 1.0)


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
        torch.broadcast_shapes(mask.shape, table.shape[:-1])
    except RuntimeError as exc:
        raise ObstacleError(
            f"{what} of shape {tuple(mask.shape)} does not match obstacles of shape {tuple(table.shape)}"
        ) from exc
    return mask.to(table.device)


def _check_values(
    table: torch.Tensor, mask: torch.Tensor | None, size: slice, what: str, size_name: str
) -> None:
    live = table if mask is None else table[torch.broadcast_to(mask, table.shape[:-1])]
    if live.numel() == 0:
        return
    bad = ~torch.isfinite(live)
    if bool(bad.any()):
        raise ObstacleError(f"{what} hold {int(bad.sum())} NaN/inf value(s); all values must be finite")
    small = live[..., size] <= 0
    if bool(small.any()):
        worst = float(live[..., size].min())
        raise ObstacleError(f"every {size_name} in {what} must be > 0 (metres), found {worst:.6g}")


@dataclass(frozen=True, eq=False, init=False, repr=False)
class Scene:
    """Obstacles in the robot's base frame (see the module docstring for every field)."""

    spheres: torch.Tensor
    boxes: torch.Tensor
    floor: torch.Tensor | None = None
    sphere_mask: torch.Tensor | None = None
    box_mask: torch.Tensor | None = None

    def __init__(
        self,
        spheres=None,
        boxes=None,
        floor=None,
        sphere_mask: torch.Tensor | None = None,
        box_mask: torch.Tensor | None = None,
    ):
        ref = (
            spheres
            if isinstance(spheres, torch.Tensor)
            else boxes
            if isinstance(boxes, torch.Tensor)
            else None
        )
        dtype = ref.dtype if ref is not None and ref.is_floating_point() else None
        device = ref.device if ref is not None else None
        s = _tensor(spheres, "spheres", dtype, device) if spheres is not None else None
        b = _tensor(boxes, "boxes", dtype, device) if boxes is not None else None
        dtype = (s if s is not None else b).dtype if (s is not None or b is not None) else None
        if s is None:
            s = torch.zeros(0, 4, dtype=dtype or torch.get_default_dtype(), device=device)
        if b is None:
            b = torch.zeros(0, 6, dtype=s.dtype, device=s.device)
        _check_table(s, 4, "spheres", "[x, y, z, radius]")
        _check_table(b, 6, "boxes", "[cx, cy, cz, hx, hy, hz]")
        if b.dtype != s.dtype or b.device != s.device:
            b = b.to(dtype=s.dtype, device=s.device)
        sm = _check_mask(sphere_mask, s, "sphere_mask")
        bm = _check_mask(box_mask, b, "box_mask")
        _check_values(s, sm, slice(3, 4), "spheres", "radius")
        _check_values(b, bm, slice(3, 6), "boxes", "half extent")
        f = None
        if floor is not None:
            f = _tensor(floor, "floor", s.dtype, s.device)
            if not bool(torch.isfinite(f).all()):
                raise ObstacleError("floor height holds NaN/inf; give a finite height in metres or None")
        self_shape = [s.shape[:-2], b.shape[:-2]]
        if f is not None:
            self_shape.append(f.shape)
        for m in (sm, bm):
            if m is not None:
                self_shape.append(m.shape[:-1])
        try:
            torch.broadcast_shapes(*self_shape)
        except RuntimeError as exc:
            raise ObstacleError(
                f"the scene's batch shapes do not broadcast: spheres {tuple(s.shape)}, boxes {tuple(b.shape)}"
                + (f", floor {tuple(f.shape)}" if f is not None else "")
            ) from exc
        object.__setattr__(self, "spheres", s)
        object.__setattr__(self, "boxes", b)
        object.__setattr__(self, "floor", f)
        object.__setattr__(self, "sphere_mask", sm)
        object.__setattr__(self, "box_mask", bm)

    @classmethod
    def _unchecked(cls, spheres, boxes, floor=None, sphere_mask=None, box_mask=None) -> Scene:
        """A scene from tensors already validated (views or indexing of a valid scene)."""
        out = object.__new__(cls)
        for name, value in (
            ("spheres", spheres),
            ("boxes", boxes),
            ("floor", floor),
            ("sphere_mask", sphere_mask),
            ("box_mask", box_mask),
        ):
            object.__setattr__(out, name, value)
        return out

    # ---------------------------------------------------------------------------------------------
    @classmethod
    def from_spheres(cls, spheres, floor=None) -> Scene:
        """A scene of spheres ``(K, 4)`` or ``(..., K, 4)`` [x, y, z, radius] (and an optional floor)."""
        return cls(spheres=spheres, floor=floor)

    @property
    def batch_shape(self) -> torch.Size:
        shapes = [self.spheres.shape[:-2], self.boxes.shape[:-2]]
        if self.floor is not None:
            shapes.append(self.floor.shape)
        for m in (self.sphere_mask, self.box_mask):
            if m is not None:
                shapes.append(m.shape[:-1])
        return torch.broadcast_shapes(*shapes)

    @property
    def num_spheres(self) -> int:
        return int(self.spheres.shape[-2])

    @property
    def num_boxes(self) -> int:
        return int(self.boxes.shape[-2])

    @property
    def dtype(self) -> torch.dtype:
        return self.spheres.dtype

    @property
    def device(self) -> torch.device:
        return self.spheres.device

    def to(self, dtype: torch.dtype | None = None, device=None) -> Scene:
        """The same scene with float tensors in ``dtype`` and everything on ``device``."""
        if (dtype is None or dtype == self.dtype) and (device is None or torch.device(device) == self.device):
            return self  # immutable: nothing to convert

        def cast(t, is_float=True):
            if t is None:
                return None
            return t.to(
                dtype=dtype if (is_float and dtype is not None) else t.dtype, device=device or t.device
            )

        return Scene(
            cast(self.spheres),
            cast(self.boxes),
            cast(self.floor),
            cast(self.sphere_mask, False),
            cast(self.box_mask, False),
        )

    def expand(self, *batch: int) -> Scene:
        """Every field broadcast to batch shape ``batch`` (views, no copies)."""
        batch = torch.Size(batch)

        def ex(t, tail: int):
            if t is None:
                return None
            return t.expand(*batch, *t.shape[t.ndim - tail :])

        return Scene._unchecked(
            ex(self.spheres, 2),
            ex(self.boxes, 2),
            ex(self.floor, 0),
            ex(self.sphere_mask, 1),
            ex(self.box_mask, 1),
        )

    def reshape(self, *batch: int) -> Scene:
        """The scene with its batch dimensions reshaped to ``batch`` (e.g. ``(2, 3)`` → ``(6,)``)."""
        full = self.expand(*self.batch_shape)
        n = len(self.batch_shape)

        def rs(t):
            return None if t is None else t.reshape(*batch, *t.shape[n:])

        try:
            return Scene._unchecked(
                rs(full.spheres), rs(full.boxes), rs(full.floor), rs(full.sphere_mask), rs(full.box_mask)
            )
        except RuntimeError as exc:
            raise ObstacleError(
                f"cannot reshape a scene of batch {tuple(self.batch_shape)} to {batch}"
            ) from exc

    def __getitem__(self, index) -> Scene:
        """Index the batch dimensions (``scene[3]``, ``scene[:10]``, ``scene[mask]``)."""
        if len(self.batch_shape) == 0:
            raise ObstacleError("an unbatched scene (batch shape ()) cannot be indexed")
        full = self.expand(*self.batch_shape)

        def ix(t):
            return None if t is None else t[index]

        return Scene._unchecked(
            ix(full.spheres), ix(full.boxes), ix(full.floor), ix(full.sphere_mask), ix(full.box_mask)
        )

    def unsqueeze(self, dim: int) -> Scene:
        """Insert a batch dimension of size 1 at ``dim`` of the batch shape (negative: from its end).

        For example a scene of batch ``(N,)`` against paths of batch ``(N, T)``: ``scene.unsqueeze(-1)``.
        """
        nb = len(self.batch_shape)
        if not -nb - 1 <= dim <= nb:
            raise ObstacleError(
                f"dim must be in [{-nb - 1}, {nb}] for a scene of batch shape {tuple(self.batch_shape)}"
            )
        pos = dim if dim >= 0 else nb + 1 + dim
        full = self.expand(*self.batch_shape)

        def un(t):
            return None if t is None else t.unsqueeze(pos)

        return Scene._unchecked(
            un(full.spheres), un(full.boxes), un(full.floor), un(full.sphere_mask), un(full.box_mask)
        )

    @staticmethod
    def stack(scenes: Sequence[Scene]) -> Scene:
        """Unbatched scenes → one scene of batch ``(len(scenes),)``, padded to the largest K and B with masks.

        A floor is kept only if every scene has one (a scene without a floor cannot share a floor tensor).
        """
        scenes = list(scenes)
        if not scenes:
            raise ObstacleError("Scene.stack needs at least one scene")
        if any(len(s.batch_shape) for s in scenes):
            raise ObstacleError(
                "Scene.stack takes unbatched scenes (batch shape ()); index batched ones first"
            )
        ref = scenes[0].spheres
        K = max(s.num_spheres for s in scenes)
        B = max(s.num_boxes for s in scenes)
        sp = ref.new_tensor(_PAD_SPHERE).repeat(len(scenes), K, 1)
        bx = ref.new_tensor(_PAD_BOX).repeat(len(scenes), B, 1)
        sm = torch.zeros(len(scenes), K, dtype=torch.bool, device=ref.device)
        bm = torch.zeros(len(scenes), B, dtype=torch.bool, device=ref.device)
        for i, s in enumerate(scenes):
            k, b = s.num_spheres, s.num_boxes
            sp[i, :k] = s.spheres.to(ref)
            bx[i, :b] = s.boxes.to(ref)
            sm[i, :k] = True if s.sphere_mask is None else s.sphere_mask
            bm[i, :b] = True if s.box_mask is None else s.box_mask
        floors = [s.floor for s in scenes]
        floor = torch.stack([f.to(ref) for f in floors]) if all(f is not None for f in floors) else None
        if floor is None and any(f is not None for f in floors):
            raise ObstacleError(
                "Scene.stack: some scenes have a floor and some do not; give all or none a floor"
            )
        return Scene(sp, bx, floor, sm, bm)

    def unstack(self) -> list[Scene]:
        """A batch ``(n,)`` scene → ``n`` unbatched scenes without their padding."""
        if len(self.batch_shape) != 1:
            raise ObstacleError(f"unstack needs a scene of batch shape (n,), got {tuple(self.batch_shape)}")
        out = []
        full = self.expand(*self.batch_shape)
        for i in range(self.batch_shape[0]):
            s, b = full.spheres[i], full.boxes[i]
            if full.sphere_mask is not None:
                s = s[full.sphere_mask[i]]
            if full.box_mask is not None:
                b = b[full.box_mask[i]]
            out.append(Scene(s, b, None if full.floor is None else full.floor[i]))
        return out

    # ---------------------------------------------------------------------------------------------
    def arrays(self) -> dict[str, np.ndarray]:
        """The scene as numpy arrays (float64 and bool), keyed as :meth:`from_arrays` expects."""
        out = {
            "spheres": self.spheres.detach().cpu().double().numpy(),
            "boxes": self.boxes.detach().cpu().double().numpy(),
        }
        if self.floor is not None:
            out["floor"] = self.floor.detach().cpu().double().numpy()
        if self.sphere_mask is not None:
            out["sphere_mask"] = self.sphere_mask.cpu().numpy()
        if self.box_mask is not None:
            out["box_mask"] = self.box_mask.cpu().numpy()
        return out

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray], dtype: torch.dtype = torch.float64) -> Scene:
        def get(key, cast=True):
            if key not in arrays:
                return None
            a = torch.as_tensor(np.asarray(arrays[key]))
            return a.to(dtype) if cast else a

        return cls(
            get("spheres"), get("boxes"), get("floor"), get("sphere_mask", False), get("box_mask", False)
        )

    def save(self, path: str | Path, robot: str = "") -> Path:
        """Write the scene to ``path`` (``.npz``) atomically; ``robot`` names the robot whose base frame it is in."""
        return save_npz(
            path, kind="scene", robot=robot, config={"scene_format": SCENE_FORMAT}, arrays=self.arrays()
        )

    @classmethod
    def load(cls, path: str | Path, robot: str | None = None, dtype: torch.dtype = torch.float64) -> Scene:
        """Read a scene written by :meth:`save`. Raises :class:`~kinlearn.errors.DatasetError` for a
        missing or unreadable file, a file of another kind, format or robot, or invalid obstacles."""
        meta, arrays = load_npz(path, kind="scene", robot=robot)
        version = meta.get("config", {}).get("scene_format")
        if version != SCENE_FORMAT:
            raise DatasetError(
                f"{path} holds scene format {version!r}; this kinlearn reads scene format {SCENE_FORMAT}"
            )
        try:
            return cls.from_arrays(arrays, dtype)
        except ObstacleError as exc:
            raise DatasetError(f"{path} holds invalid obstacles: {exc}") from exc

    def __repr__(self) -> str:
        floor = (
            "none" if self.floor is None else ("batched" if self.floor.ndim else f"{float(self.floor):.3f} m")
        )
        return (
            f"Scene(batch={tuple(self.batch_shape)}, spheres={self.num_spheres}, boxes={self.num_boxes}, "
            f"floor={floor}, dtype={self.dtype})"
        )


def as_scene(obstacles, batch: tuple | None = None) -> Scene:
    """``obstacles`` as a :class:`Scene`: a Scene as is, or spheres ``(K, 4)`` / ``(..., K, 4)``
    [x, y, z, radius] (m) as a scene of spheres. :class:`ObstacleError` for anything else. With
    ``batch`` (the shape of the problems the scene is for), its batch shape must be ``()`` (one scene
    for all) or ``batch`` (:class:`ShapeError` otherwise)."""
    scene = obstacles if isinstance(obstacles, Scene) else _sphere_scene(obstacles)
    shape = tuple(scene.batch_shape)
    if batch is not None and shape not in ((), tuple(batch)):
        raise ShapeError(
            f"the obstacles' batch shape {shape} must be () (one scene for all problems) or the "
            f"problems' {tuple(batch)}"
        )
    return scene


def _sphere_scene(obstacles) -> Scene:
    if isinstance(obstacles, (str, bytes)) or obstacles is None:
        raise ObstacleError("obstacles must be spheres (K, 4) [x, y, z, radius] or a kinlearn Scene")
    if isinstance(obstacles, torch.Tensor) and (obstacles.dtype == torch.bool or obstacles.is_complex()):
        raise ObstacleError(f"obstacle spheres must hold real numbers, got a {obstacles.dtype} tensor")
    try:
        spheres = torch.as_tensor(np.asarray(obstacles, dtype=np.float64))
    except (TypeError, ValueError) as exc:
        raise ObstacleError(f"obstacles must be numbers of shape (K, 4) or (..., K, 4): {exc}") from exc
    if spheres.ndim < 2 or spheres.shape[-1] != 4:
        raise ObstacleError(
            f"obstacle spheres must have shape (K, 4) or (..., K, 4) [x, y, z, radius], got {tuple(spheres.shape)}"
        )
    return Scene(spheres=spheres)
