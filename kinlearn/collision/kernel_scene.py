"""One :class:`~kinlearn.collision.Scene` packed for the compiled kernels (:class:`KernelScene`): one
float64 buffer holding a table per kind of primitive (:func:`~kinlearn.collision.kinds.pack`), packed
once per scene object, and the scene's distances at points."""

from __future__ import annotations

import math
import weakref

import numpy as np

from ..body.jit import jit
from ..errors import ObstacleError
from .kernel_body import _joints
from .kinds import PACKED_KINDS, network_rows, pack, packed_shapes, sphere_scene, unpack
from .scene import Scene

__all__ = ["KernelScene", "point_distances"]


class KernelScene:
    """One (unbatched) :class:`Scene` packed for the kernels: a float64 table per kind of primitive (in
    :data:`~kinlearn.collision.kinds.PACKED_KINDS` order, padding dropped, each row followed by what its
    kind adds, its bounding radius) and ``floor = [has floor, height]``, all views of one buffer
    (:attr:`packed`). :meth:`of` packs a scene once and reuses it (scenes are immutable). Each table is
    also an attribute by its kind's table name (``spheres``, ``boxes``, ``cylinders``, …)."""

    __slots__ = ("__weakref__", "_buf", "_rows", "floor", "tables")

    @classmethod
    def of(cls, scene: Scene) -> KernelScene:
        """The packed ``scene``, made on the first call for that scene object and kept while it lives."""
        hit = _PACKED.get(scene) if isinstance(scene, Scene) else None
        if hit is None:
            hit = cls(scene)
            _PACKED[scene] = hit
        return hit

    def __init__(self, scene: Scene):
        if not isinstance(scene, Scene):
            raise ObstacleError(f"expected a kinlearn Scene, got {type(scene).__name__}")
        if len(scene.batch_shape):
            raise ObstacleError(
                f"a KernelScene holds one scene, got batch shape {tuple(scene.batch_shape)}; index it first"
            )
        rows = tuple(kind.kernel_rows(scene) for kind in PACKED_KINDS)
        floor = (0.0, 0.0) if scene.floor is None else (1.0, float(scene.floor))
        self._buf = buf = pack(rows, packed_shapes(rows), floor[0], floor[1])
        #: One table per scene kind and the floor, views of the buffer.
        self.tables, self.floor = unpack(buf)
        self._rows = None

    def __getattr__(self, name: str) -> np.ndarray:
        for kind, table in zip(PACKED_KINDS, object.__getattribute__(self, "tables"), strict=True):
            if kind.table == name:
                return table
        raise AttributeError(f"KernelScene has no attribute {name!r}")

    def model_rows(self, reach: float = math.inf) -> np.ndarray:
        """The scene as the obstacle-aware TM reads it, float64 ``(P, 14)``: per primitive its centre, the
        half extents of its axis-aligned bounding box, whether it is a sphere, its extent tensor and
        whether it is a cylinder; kind by kind in :data:`~kinlearn.collision.kinds.PACKED_KINDS` order (the
        rows of :func:`~kinlearn.models.obstacle_path.scene_primitives` without padding, computed from
        this packing: the scene is converted once). ``reach``: only the primitives whose bounding ball
        comes within it of the base's origin (:attr:`~kinlearn.collision.BodySpheres.reach`: those the
        robot can touch)."""
        if self._rows is None:
            self._rows = {}
        rows = self._rows.get(reach)
        if rows is None:  # per reach asked (a planner asks with its body's, every plan)
            rows = self._rows[reach] = network_rows(self.tables, float(reach))
        return rows

    def args(self) -> tuple:
        """``(tables, floor)``, as the kernels take a scene."""
        return self.tables, self.floor

    @property
    def packed(self) -> np.ndarray:
        """The scene in one buffer: [each kind's table's rows and columns…, has floor, height, each kind's
        table…] (:func:`~kinlearn.collision.kinds.pack`)."""
        return self._buf

    def __repr__(self) -> str:
        counts = ", ".join(f"{k.table}={len(t)}" for k, t in zip(PACKED_KINDS, self.tables, strict=True))
        floor = "none" if not self.floor[0] else f"{self.floor[1]:.3f} m"
        return f"KernelScene({counts}, floor={floor})"


#: Scenes packed by :meth:`KernelScene.of`, dropped with their scene.
_PACKED: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


@jit
def _point_distances(points, tables, floor, out):
    for i in range(points.shape[0]):
        out[i] = sphere_scene(points[i, 0], points[i, 1], points[i, 2], 0.0, True, tables, floor)


def point_distances(scene: KernelScene, points) -> np.ndarray:
    """Signed distances ``(N,)`` of points ``(N, 3)`` (m, the robot's base frame) to ``scene``, its floor
    included (negative inside a primitive; +inf for an empty scene without a floor)."""
    if not isinstance(scene, KernelScene):
        raise ObstacleError(f"scene must be a KernelScene (KernelScene(scene)), got {type(scene).__name__}")
    pts = _joints(points, 3, "points", 2)
    out = np.empty(pts.shape[0])
    _point_distances(pts, *scene.args(), out)
    return out
