"""Obstacle scenes: batches of typed primitives (spheres, boxes in any orientation, cylinders) and an
optional floor, in the robot's base frame.

A :class:`Scene` holds one table per kind of :mod:`~kinlearn.collision.geometry` primitive, with
leading batch dimensions ``...`` shared by all of them (the rows' layouts are the kinds'):

- ``spheres`` ``(..., K, 4)``: ``[x, y, z, radius]``, metres;
- ``boxes`` ``(..., B, 15)``: ``[cx, cy, cz, hx, hy, hz, R (9, row-major)]``, centre, half extents and
  orientation; an axis-aligned table ``(..., B, 6)`` ``[centre, half extents]`` is accepted and given
  the identity rotation;
- ``cylinders`` ``(..., C, 14)``: ``[cx, cy, cz, radius, half_length, R (9)]``, axis along the local z;
- ``floor``: ``None`` or the height ``(...)`` (or a scalar) of a floor plane; everything below it is solid;
- optional masks ``sphere_mask (..., K)``, ``box_mask (..., B)``, ``cylinder_mask (..., C)``: ``False``
  marks padding, so that scenes with different numbers of obstacles can share one batch (see
  :meth:`Scene.stack`). Masked entries are ignored by validation and by every distance.

- ``cloud``: None or a :class:`~kinlearn.collision.cloud.PointCloud`, points (each a ball of its radius)
  shared by every scene of the batch, checked through its compiled distance grid;
  :meth:`Scene.from_points` makes one from an array, a file or a camera's cloud, with primitives beside it.

Any count may be 0. Batch shapes broadcast against each other and against configurations
(right-aligned, as in torch); :meth:`Scene.unsqueeze` inserts a batch dimension (for example a time
axis). :meth:`Scene.from_primitives` builds one scene from typed objects, :meth:`Scene.primitives`
gives them back.

Every table is checked where a scene is made (:mod:`kinlearn.collision.scene_tables`: widths, masks,
finite values, sizes, rotations); :meth:`Scene.save` and :meth:`Scene.load` keep a scene in an ``.npz``
file (:mod:`kinlearn.collision.scene_file`). :func:`as_scene` takes what a planner is given as obstacles,
a Scene or an array of spheres, as a Scene.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from functools import cached_property, lru_cache
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import torch

from ..checks import broadcast_shapes
from ..errors import DatasetError, ObstacleError, ShapeError
from .geometry import IDENTITY, SCENE_KINDS, Plane, Primitive
from .moveit import primitives_from_moveit, primitives_to_moveit
from .scene_file import SCENE_FORMAT, cloud_arrays, cloud_from_arrays, read_scene, write_scene
from .scene_file import SCENE_FORMATS as SCENE_FORMATS
from .scene_tables import _FIELDS, _TABLES, _axis_aligned, _check_mask, _check_table, _check_values, _tensor
from .scene_tables import MAX_METRES as MAX_METRES

if TYPE_CHECKING:
    from .cloud import PointCloud

__all__ = ["SCENE_FORMAT", "Scene", "as_scene"]


@dataclass(frozen=True, eq=False, init=False, repr=False)
class Scene:
    """Obstacles in the robot's base frame (see the module docstring for every field)."""

    spheres: torch.Tensor
    boxes: torch.Tensor
    floor: torch.Tensor | None = None
    sphere_mask: torch.Tensor | None = None
    box_mask: torch.Tensor | None = None
    cylinders: torch.Tensor
    cylinder_mask: torch.Tensor | None = None
    cloud: PointCloud | None = None

    def __init__(
        self,
        spheres=None,
        boxes=None,
        floor=None,
        sphere_mask: torch.Tensor | None = None,
        box_mask: torch.Tensor | None = None,
        cylinders=None,
        cylinder_mask: torch.Tensor | None = None,
        cloud=None,
        **more,
    ):
        given = {"spheres": spheres, "boxes": boxes, "cylinders": cylinders}
        # the tables of further kinds (kinlearn.collision.kinds), by their table names
        given |= {k.table: more.pop(k.table, None) for k in SCENE_KINDS if k.table not in given}
        ref = next((t for t in given.values() if isinstance(t, torch.Tensor) and t.is_floating_point()), None)
        ref = (
            ref if ref is not None else next((t for t in given.values() if isinstance(t, torch.Tensor)), None)
        )
        dtype = ref.dtype if ref is not None and ref.is_floating_point() else None
        device = ref.device if ref is not None else None
        tables = {k: (_tensor(v, k, dtype, device) if v is not None else None) for k, v in given.items()}
        first = next((t for t in tables.values() if t is not None), None)
        dtype = first.dtype if first is not None else torch.get_default_dtype()
        device = first.device if first is not None else device
        masks = {"sphere_mask": sphere_mask, "box_mask": box_mask, "cylinder_mask": cylinder_mask}
        masks |= {m: more.pop(m, None) for m in (f"{k.kind}_mask" for k in SCENE_KINDS) if m not in masks}
        if more:
            raise ObstacleError(
                f"a Scene has no field {sorted(more)[0]!r}; its tables are "
                + ", ".join(f"{k.table} ({k.kind}_mask)" for k in SCENE_KINDS)
            )
        checked: dict[str, torch.Tensor] = {}  # every kind's table, an empty one where none was given
        for name, mask_name, kind in _TABLES:
            t = tables[name]
            if t is None:
                t = torch.zeros(0, kind.width, dtype=dtype, device=device)
            if name == "boxes" and t.ndim >= 2 and t.shape[-1] == 6 and t.is_floating_point():
                t = _axis_aligned(t)
            _check_table(t, kind.width, name, kind.layout)
            if t.dtype != dtype or t.device != device:
                t = t.to(dtype=dtype, device=device)
            m = _check_mask(masks[mask_name], t, mask_name)
            _check_values(t, m, kind)
            checked[name], masks[mask_name] = t, m
        f = None
        if floor is not None:
            if isinstance(floor, (bool, np.bool_, complex, np.complexfloating)) or (
                isinstance(floor, torch.Tensor) and (floor.dtype == torch.bool or floor.is_complex())
            ):
                raise ObstacleError(
                    f"the floor height must be a real number of metres or None, got {floor!r}"
                )
            f = _tensor(floor, "floor", dtype, device)
            if not bool(torch.isfinite(f).all()):
                raise ObstacleError("floor height holds NaN/inf; give a finite height in metres or None")
        shapes = [t.shape[:-2] for t in checked.values()]
        shapes += [m.shape[:-1] for m in masks.values() if m is not None]
        if f is not None:
            shapes.append(f.shape)
        try:
            broadcast_shapes(*shapes)
        except ValueError as exc:
            raise ObstacleError(
                "the scene's batch shapes do not broadcast: "
                + ", ".join(f"{k} {tuple(v.shape)}" for k, v in checked.items())
                + (f", floor {tuple(f.shape)}" if f is not None else "")
            ) from exc
        if cloud is not None:
            from .cloud import PointCloud

            if not isinstance(cloud, PointCloud):
                raise ObstacleError(
                    f"a scene's cloud must be a PointCloud (Scene.from_points), got {type(cloud).__name__}"
                )
        for k, v in (*checked.items(), *masks.items(), ("floor", f), ("cloud", cloud)):
            object.__setattr__(self, k, v)

    @classmethod
    def _unchecked(cls, cloud=None, **fields) -> Scene:
        """A scene from tensors already validated (views or indexing of a valid scene)."""
        out = object.__new__(cls)
        for name, _ in _FIELDS:
            object.__setattr__(out, name, fields.get(name))
        object.__setattr__(out, "cloud", cloud)
        return out

    def _map(self, fn) -> Scene:
        """A scene of ``fn(tensor, trailing dims)`` applied to every present field (unchecked); the cloud,
        shared by the whole batch, kept."""
        return Scene._unchecked(
            cloud=self.cloud,
            **{n: (None if (t := getattr(self, n)) is None else fn(t, tail)) for n, tail in _FIELDS},
        )

    # ---------------------------------------------------------------------------------------------
    @classmethod
    def from_spheres(cls, spheres, floor=None) -> Scene:
        """A scene of spheres ``(K, 4)`` or ``(..., K, 4)`` [x, y, z, radius] (and an optional floor)."""
        return cls(spheres=spheres, floor=floor)

    @classmethod
    def from_primitives(
        cls, primitives: Sequence[Primitive], floor=None, dtype: torch.dtype = torch.float64
    ) -> Scene:
        """One (unbatched) scene of typed primitives (:class:`~kinlearn.collision.geometry.Sphere`,
        ``Box``, ``Cylinder``); a horizontal ``Plane`` (normal +z) is taken as the floor."""
        rows: dict[str, list] = {k.table: [] for k in SCENE_KINDS}
        for p in primitives:
            if isinstance(p, Plane):
                if not np.allclose(p.normal, (0.0, 0.0, 1.0), atol=1e-12):
                    raise ObstacleError(
                        f"a scene's plane is its floor: its normal must be +z, got {p.normal}"
                    )
                if floor is not None:
                    raise ObstacleError("a scene has one floor: give floor= or one horizontal Plane")
                floor = p.offset
                continue
            if not isinstance(p, Primitive) or type(p) not in SCENE_KINDS:
                raise ObstacleError(
                    f"a scene holds {', '.join(k.__name__ for k in SCENE_KINDS)} (and a floor Plane), "
                    f"got {type(p).__name__}"
                )
            rows[p.table].append(p.row())
        tables = {k.table: torch.tensor(rows[k.table], dtype=dtype).reshape(-1, k.width) for k in SCENE_KINDS}
        return cls(**tables, floor=floor)

    @classmethod
    def from_moveit(cls, source, base_pose=None, dtype: torch.dtype = torch.float64) -> Scene:
        """The obstacles of a MoveIt ``PlanningScene`` (YAML file path or dict) in the robot's base frame,
        given the base's pose in the scene's frame (4 × 4 or ``[x, y, z, qx, qy, qz, qw]``; default
        identity). See :func:`kinlearn.collision.moveit.primitives_from_moveit`."""
        return cls.from_primitives(primitives_from_moveit(source, base_pose), dtype=dtype)

    @classmethod
    def from_points(
        cls,
        points,
        *,
        radius: float | None = None,
        frame=None,
        resolution: float | None = None,
        cleaning=None,
        self_filter: tuple | None = None,
        drop_nonfinite: bool = False,
        shadow: float = 0.0,
        contact: float | None = None,
        primitives: Scene | Sequence[Primitive] | None = None,
        floor=None,
    ) -> Scene:
        """A scene of sensed points, each an obstacle ball of ``radius`` (m; default
        :data:`~kinlearn.collision.cloud.DEFAULT_RADIUS`, 1 cm), beside optional ``primitives`` (a Scene or
        a list of them) and ``floor``.

        ``points``: an ``(N, 3)`` array or tensor (m), or a ``.npy``, ``.ply`` or ``.pcd`` file's path
        (:func:`~kinlearn.collision.cloud.read_points`). ``frame``: the camera's pose in the robot's base
        frame (4 × 4, ``(position, quaternion xyzw)`` or ``[x, y, z, qx, qy, qz, qw]``) when the points are
        in the camera's frame; None: they are in the base frame. Several cameras' clouds: ``points`` a list
        of them and ``frame`` a list of their poses (None where a cloud is in the base frame), fused into one
        (:func:`~kinlearn.collision.cloud.views_in_base`; what one camera cannot see, another may).
        ``resolution``: the edge of the distance
        grid's cells (default :data:`~kinlearn.collision.cloud.DEFAULT_RESOLUTION`, 2 cm; a speed setting:
        the spheres it cannot clear read the points).
        ``cleaning`` (:class:`~kinlearn.collision.cloud.Cleaning`) and ``self_filter`` ``(body, q)`` (the
        robot's :class:`BodySpheres` or a planner, and its joints when the cloud was taken: points on its own
        body are dropped, and the cloud cropped to its reach) clean the points first;
        ``drop_nonfinite`` drops NaN rows (a depth camera's missing pixels) instead of refusing them.
        ``shadow`` (m, with one camera's ``frame``): the space behind each point left after cleaning, as the
        camera sees it, is taken as occupied that far (:func:`~kinlearn.collision.cloud.shadows`), behind the
        robot's own points too (self-filtering then drops what lies on its body); by default unknown space
        is free.
        ``contact`` (m; default :data:`~kinlearn.collision.cloud.DEFAULT_CONTACT`, 6 mm): a plan's start or
        goal whose body the balls touch, with no point deeper inside it than this, is taken to touch the
        surface the points sample (:mod:`~kinlearn.collision.cloud_contact`); 0 refuses it.

        Raises :class:`~kinlearn.errors.PointCloudError` for points of another shape, NaN rows, no points,
        millimetres, a bad pose or poses not one per view, :class:`~kinlearn.errors.PointCloudFileError`
        for a file it cannot read.
        """
        from .cloud import sensed_cloud

        cloud = sensed_cloud(
            points,
            radius=radius,
            frame=frame,
            resolution=resolution,
            cleaning=cleaning,
            self_filter=self_filter,
            drop_nonfinite=drop_nonfinite,
            shadow=shadow,
            contact=contact,
        )
        if primitives is None:
            base = cls(floor=floor)
        elif isinstance(primitives, Scene):
            if len(primitives.batch_shape) or primitives.cloud is not None:
                raise ObstacleError("from_points adds its points to an unbatched scene of primitives alone")
            if floor is not None and primitives.floor is not None:
                raise ObstacleError("a scene has one floor: give floor= or a scene with a floor, not both")
            base = primitives if floor is None else primitives.with_floor(floor)
        else:
            base = cls.from_primitives(primitives, floor=floor)
        return base.with_cloud(cloud)

    def with_cloud(self, cloud) -> Scene:
        """This scene with ``cloud`` (a :class:`~kinlearn.collision.cloud.PointCloud`, or None) as its points."""
        fields = {n: getattr(self, n) for n, _ in _FIELDS}
        return Scene(**fields, cloud=cloud)

    def with_floor(self, floor) -> Scene:
        """This scene with a floor at height ``floor`` (m, or None)."""
        fields = {n: getattr(self, n) for n, _ in _FIELDS if n != "floor"}
        return Scene(**fields, floor=floor, cloud=self.cloud)

    def to_moveit(self, frame_id: str = "base_link", name: str = "kinlearn") -> dict:
        """This (unbatched) scene as a MoveIt ``PlanningScene`` dict, for ``yaml.safe_dump``. See
        :func:`kinlearn.collision.moveit.primitives_to_moveit`. A scene with a point cloud is refused
        (a planning scene of primitives cannot hold it)."""
        if self.cloud is not None:
            raise ObstacleError(
                "a scene with a point cloud cannot be written as a MoveIt scene of primitives"
            )
        return primitives_to_moveit(self.primitives(), frame_id, name)

    def primitives(self) -> list[Primitive]:
        """The obstacles of an unbatched scene as typed objects, padding left out (the floor, if any,
        last as a :class:`~kinlearn.collision.geometry.Plane`)."""
        if len(self.batch_shape):
            raise ObstacleError(
                f"primitives() takes an unbatched scene, got batch shape {tuple(self.batch_shape)}; "
                "index it (scene[i]) first"
            )
        out: list[Primitive] = []
        for kind, rows, _ in self.tables(live=True):
            out += [kind.from_row(r) for r in rows.detach().cpu().double().tolist()]
        if self.floor is not None:
            out.append(Plane((0.0, 0.0, 1.0), float(self.floor)))
        return out

    def tables(
        self, live: bool = False
    ) -> Iterator[tuple[type[Primitive], torch.Tensor, torch.Tensor | None]]:
        """``(kind, rows, mask)`` per kind of primitive, in :data:`~kinlearn.collision.geometry.SCENE_KINDS`
        order. ``live=True`` (unbatched scenes only): the rows without padding, and mask None."""
        for name, mask_name, kind in _TABLES:
            rows, mask = getattr(self, name), getattr(self, mask_name)
            if live:
                if rows.ndim != 2:
                    raise ObstacleError("tables(live=True) takes an unbatched scene")
                if mask is not None:
                    rows = rows[mask]
                mask = None
            yield kind, rows, mask

    @cached_property
    def batch_shape(self) -> torch.Size:
        """The shape the fields' batch dimensions broadcast to (computed once: a scene is immutable)."""
        shapes = [getattr(self, t).shape[:-2] for t, _, _ in _TABLES]
        shapes += [m.shape[:-1] for _, n, _ in _TABLES if (m := getattr(self, n)) is not None]
        if self.floor is not None:
            shapes.append(self.floor.shape)
        if all(t == shapes[0] for t in shapes):  # most scenes (torch's broadcast costs time on every call)
            return torch.Size(shapes[0])
        return broadcast_shapes(*shapes)

    @property
    def num_spheres(self) -> int:
        return int(self.spheres.shape[-2])

    @property
    def num_boxes(self) -> int:
        return int(self.boxes.shape[-2])

    @property
    def num_cylinders(self) -> int:
        return int(self.cylinders.shape[-2])

    @property
    def num_primitives(self) -> int:
        """Rows over every kind (padding included)."""
        return sum(int(getattr(self, t).shape[-2]) for t, _, _ in _TABLES)

    @property
    def axis_aligned(self) -> bool:
        """True when the scene holds nothing but spheres and boxes, every box with the identity rotation."""
        if any(getattr(self, n).shape[-2] for n, _, k in _TABLES if k.kind not in ("sphere", "box")):
            return False
        R = self.boxes[..., 6:15]
        return bool((R == R.new_tensor(IDENTITY)).all())

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

        def cast(t, tail):
            is_float = t.is_floating_point()
            return t.to(
                dtype=dtype if (is_float and dtype is not None) else t.dtype, device=device or t.device
            )

        return self._map(cast)

    def expand(self, *batch: int) -> Scene:
        """Every field broadcast to batch shape ``batch`` (views, no copies)."""
        batch = torch.Size(batch)
        return self._map(lambda t, tail: t.expand(*batch, *t.shape[t.ndim - tail :]))

    def reshape(self, *batch: int) -> Scene:
        """The scene with its batch dimensions reshaped to ``batch`` (e.g. ``(2, 3)`` → ``(6,)``)."""
        full = self.expand(*self.batch_shape)
        n = len(self.batch_shape)
        try:
            return full._map(lambda t, tail: t.reshape(*batch, *t.shape[n:]))
        except RuntimeError as exc:  # torch's reshape to a shape of another size
            raise ObstacleError(
                f"cannot reshape a scene of batch {tuple(self.batch_shape)} to {batch}"
            ) from exc

    def __getitem__(self, index) -> Scene:
        """Index the batch dimensions (``scene[3]``, ``scene[:10]``, ``scene[mask]``)."""
        if len(self.batch_shape) == 0:
            raise ObstacleError("an unbatched scene (batch shape ()) cannot be indexed")
        return self.expand(*self.batch_shape)._map(lambda t, tail: t[index])

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
        return self.expand(*self.batch_shape)._map(lambda t, tail: t.unsqueeze(pos))

    @staticmethod
    def stack(scenes: Sequence[Scene]) -> Scene:
        """Unbatched scenes → one scene of batch ``(len(scenes),)``, padded to the largest count of each
        kind with masks.

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
        fields = {}
        for name, mask_name, kind in _TABLES:
            n = max(getattr(s, name).shape[-2] for s in scenes)
            rows = ref.new_tensor(kind.pad).repeat(len(scenes), n, 1)
            mask = torch.zeros(len(scenes), n, dtype=torch.bool, device=ref.device)
            for i, s in enumerate(scenes):
                t, m = getattr(s, name), getattr(s, mask_name)
                rows[i, : t.shape[-2]] = t.to(ref)
                mask[i, : t.shape[-2]] = True if m is None else m
            fields[name], fields[mask_name] = rows, mask
        floors = [s.floor for s in scenes if s.floor is not None]
        floor = torch.stack([f.to(ref) for f in floors]) if len(floors) == len(scenes) else None
        if floor is None and floors:
            raise ObstacleError(
                "Scene.stack: some scenes have a floor and some do not; give all or none a floor"
            )
        if any(s.cloud is not scenes[0].cloud for s in scenes):
            raise ObstacleError(
                "Scene.stack: a batch shares one point cloud; these scenes hold different ones (plan them apart)"
            )
        return Scene(**fields, floor=floor, cloud=scenes[0].cloud)

    def unstack(self) -> list[Scene]:
        """A batch ``(n,)`` scene → ``n`` unbatched scenes without their padding."""
        if len(self.batch_shape) != 1:
            raise ObstacleError(f"unstack needs a scene of batch shape (n,), got {tuple(self.batch_shape)}")
        full = self.expand(*self.batch_shape)
        out = []
        for i in range(self.batch_shape[0]):
            one = full[i]
            tables = {kind.table: rows for kind, rows, _ in one.tables(live=True)}
            out.append(Scene(**tables, floor=one.floor, cloud=self.cloud))
        return out

    # ---------------------------------------------------------------------------------------------
    def arrays(self) -> dict[str, np.ndarray]:
        """The scene as numpy arrays (float64 and bool), keyed as :meth:`from_arrays` expects."""
        out = {}
        for name, _ in _FIELDS:
            t = getattr(self, name)
            if t is not None:
                out[name] = t.detach().cpu().double().numpy() if t.is_floating_point() else t.cpu().numpy()
        if self.cloud is not None:
            out |= cloud_arrays(self.cloud)
        return out

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray], dtype: torch.dtype = torch.float64) -> Scene:
        def get(key):
            if key not in arrays:
                return None
            a = torch.as_tensor(np.asarray(arrays[key]))
            return a.to(dtype) if a.dtype != torch.bool else a

        return cls(**{name: get(name) for name, _ in _FIELDS}, cloud=cloud_from_arrays(arrays))

    def save(self, path: str | Path, robot: str = "") -> Path:
        """Write the scene to ``path`` (``.npz``) atomically; ``robot`` names the robot whose base frame it is in."""
        return write_scene(path, self.arrays(), robot)

    @classmethod
    def load(cls, path: str | Path, robot: str | None = None, dtype: torch.dtype = torch.float64) -> Scene:
        """Read a scene written by :meth:`save`. Raises :class:`~kinlearn.errors.DatasetError` for a
        missing or unreadable file, a file of another kind, format or robot, or invalid obstacles."""
        arrays = read_scene(path, robot)
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
            f"cylinders={self.num_cylinders}, "
            f"floor={floor}, "
            + ("" if self.cloud is None else f"points={self.cloud.num_points}, ")
            + f"dtype={self.dtype})"
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
        a = np.asarray(obstacles)
        if a.dtype.kind not in "fiu":  # True is no metre, and 1+0j no radius
            raise TypeError(f"they hold {a.dtype} values, not real numbers")
        spheres = torch.as_tensor(a.astype(np.float64))
    except (TypeError, ValueError) as exc:
        raise ObstacleError(f"obstacles must be numbers of shape (K, 4) or (..., K, 4): {exc}") from exc
    if spheres.ndim < 2 or spheres.shape[-1] != 4:
        raise ObstacleError(
            f"obstacle spheres must have shape (K, 4) or (..., K, 4) [x, y, z, radius], got {tuple(spheres.shape)}"
        )
    if spheres.numel() > _REMEMBERED_FLOATS:
        return Scene(spheres=spheres)
    return _remembered_sphere_scene(tuple(spheres.shape), spheres.numpy().tobytes())


#: Sphere arrays of at most this many numbers are remembered by content (:func:`_remembered_sphere_scene`).
_REMEMBERED_FLOATS = 4096


@lru_cache(maxsize=16)
def _remembered_sphere_scene(shape: tuple[int, ...], data: bytes) -> Scene:
    """The scene of spheres ``(..., K, 4)`` given by their float64 bytes, made once for the last few
    arrays given: a user planning query after query among the same list of balls converts it once, and
    the compiled check packs that scene once (:class:`~kinlearn.collision.kernel.KernelScene` keeps a
    scene's packing while the scene lives). Scenes are immutable, so sharing one is safe; a list that changed is other
    bytes, another scene. A malformed one raises here every time (errors are not remembered)."""
    spheres = torch.from_numpy(np.frombuffer(data, dtype=np.float64).reshape(shape).copy())
    return Scene(spheres=spheres)
