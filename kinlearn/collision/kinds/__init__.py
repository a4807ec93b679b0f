"""The table of obstacle kinds: one module per kind (:mod:`~kinlearn.collision.kinds.sphere`,
:mod:`~kinlearn.collision.kinds.box`, :mod:`~kinlearn.collision.kinds.cylinder`, …, each its dataclass,
row layout, torch distance and compiled twin), listed here once for torch (:data:`KINDS`,
:data:`SCENE_KINDS`) and once for the compiled kernels (the functions below, one line per kind).

A scene packed for the kernels is one float64 buffer ``[rows and columns of each kind's packed table…,
has floor, height, each kind's packed table…]`` (:func:`pack`); :func:`unpack` gives its ``tables`` (one
2-D view per kind of :data:`PACKED_KINDS`, in order) and ``floor = [has floor, height]``, which every
kernel takes.

A new kind: its module (a :class:`Primitive` subclass with its torch distance, row layout and
``coal_shape``; the compiled ``distance``, ``nearest``, ``nearest_many``, ``radius``, ``pack``,
``network_count`` and ``network_row``), then its class in :data:`SCENE_KINDS` (or, for an obstacle a
scene holds otherwise, :data:`PACKED_KINDS`) and one line in each compiled function below.
The contract test (``tests/test_collision_kinds.py``) holds every kind of :data:`SCENE_KINDS` to coal and
its torch distance to its compiled one.
"""

from __future__ import annotations

import math

import numpy as np

from ...body.jit import jit
from . import box, capsule, cloud, cylinder, sphere
from .box import Box
from .capsule import Capsule
from .cloud import Cloud
from .cylinder import Cylinder
from .plane import Plane
from .primitive import IDENTITY, NET_WIDTH, Primitive, check_rotations, safe_sqrt
from .sphere import Sphere

__all__ = [
    "IDENTITY",
    "KINDS",
    "PACKED_KINDS",
    "SCENE_KINDS",
    "Box",
    "Capsule",
    "Cylinder",
    "Plane",
    "Primitive",
    "Sphere",
    "check_rotations",
    "network_rows",
    "pack",
    "packed_shapes",
    "safe_sqrt",
    "sphere_scene",
    "spheres_scene",
    "unpack",
]

#: The kinds a :class:`~kinlearn.collision.Scene` holds as batched tables, in order (a scene's floor is
#: its plane).
SCENE_KINDS: tuple[type[Primitive], ...] = (Sphere, Box, Cylinder, Capsule)
#: The dispatch table: kind → its class (and so its row layout and signed distance).
KINDS: dict[str, type[Primitive]] = {k.kind: k for k in (*SCENE_KINDS, Plane)}
#: What the compiled kernels pack of a scene, in order: every kind's :meth:`Primitive.kernel_rows`
#: (a table kind's rows; an obstacle a scene holds otherwise gives its own). The compiled functions
#: below list the same kinds in the same order, one line each.
PACKED_KINDS: tuple[type, ...] = (*SCENE_KINDS, Cloud)

_S = len(PACKED_KINDS)
#: The packed buffer's header: each kind's packed rows and columns, has floor, height.
HEADER = 2 * _S + 2


@jit(inline="always")
def _table(buf, k):
    """Kind ``k``'s packed table, a view of ``buf``."""
    o = HEADER
    for j in range(k):
        o += int(buf[2 * j]) * int(buf[2 * j + 1])
    n, w = int(buf[2 * k]), int(buf[2 * k + 1])
    return buf[o : o + n * w].reshape(n, w)


@jit
def unpack(buf):
    """A packed scene → (its tables, one per packed kind, views of ``buf``; ``floor = [has floor, height]``)."""
    tables = (_table(buf, 0), _table(buf, 1), _table(buf, 2), _table(buf, 3), _table(buf, 4))
    return tables, buf[2 * _S : HEADER]


def packed_shapes(rows: tuple[np.ndarray, ...]) -> np.ndarray:
    """``(S, 2)`` int64: each packed kind's packed table shape (:meth:`Primitive.packed_shape`) of its
    :meth:`Primitive.kernel_rows` ``rows``."""
    return np.array([k.packed_shape(r) for k, r in zip(PACKED_KINDS, rows, strict=True)], dtype=np.int64)


@jit
def pack(rows, shapes, has_floor, height):
    """A scene's rows (``rows``, a tuple: each packed kind's :meth:`Primitive.kernel_rows`) in one buffer
    (see the module docstring), each kind's table of shape ``shapes[k]`` made by the kind's own ``pack``
    (a primitive's row, then its bounding radius)."""
    total = HEADER
    for k in range(_S):
        total += shapes[k, 0] * shapes[k, 1]
    buf = np.empty(total)
    for k in range(_S):
        buf[2 * k], buf[2 * k + 1] = shapes[k, 0], shapes[k, 1]
    buf[2 * _S], buf[2 * _S + 1] = has_floor, height
    tables, _ = unpack(buf)
    sphere.pack(rows[0], tables[0])
    box.pack(rows[1], tables[1])
    cylinder.pack(rows[2], tables[2])
    capsule.pack(rows[3], tables[3])
    cloud.pack(rows[4], tables[4])
    return buf


@jit
def sphere_scene(x, y, z, r, on_floor, tables, floor, ball=False):
    """One sphere's signed distance to the scene (+inf when empty): its centre's to every primitive
    (each kind culls by its bounding balls: the minimum is the same, to the bit), less its radius, and to
    the floor where ``on_floor``. ``ball``: the sphere is a link's bounding ball, which only culls (its
    spheres are looked at where it is near): a kind may give a looser lower bound for it (a point cloud
    gives its grid's)."""
    d = np.inf
    d = sphere.nearest(x, y, z, tables[0], d)
    d = box.nearest(x, y, z, tables[1], d)
    d = cylinder.nearest(x, y, z, tables[2], d)
    d = capsule.nearest(x, y, z, tables[3], d)
    d = cloud.nearest(x, y, z, r, ball, tables[4], d)
    d = d - r
    if floor[0] > 0.5 and on_floor:
        d = min(d, z - r - floor[1])
    return d


@jit
def spheres_scene(c, radii, on_floor, tables, floor, xyz, out, ball=False):
    """Every sphere's signed distance to the scene, ``out (M,)`` for centres ``c (M, 3)`` (``xyz (3, M)``:
    work space): :func:`sphere_scene`'s values to the bit, primitive by primitive over all the spheres,
    loops the compiler turns into vector instructions (the faster where many spheres are wanted)."""
    M = c.shape[0]
    X, Y, Z = xyz[0], xyz[1], xyz[2]
    for m in range(M):
        X[m], Y[m], Z[m] = c[m, 0], c[m, 1], c[m, 2]
        out[m] = np.inf
    sphere.nearest_many(X, Y, Z, M, tables[0], out)
    box.nearest_many(X, Y, Z, M, tables[1], out)
    cylinder.nearest_many(X, Y, Z, M, tables[2], out)
    capsule.nearest_many(X, Y, Z, M, tables[3], out)
    cloud.nearest_many(X, Y, Z, radii, ball, M, tables[4], out)
    for m in range(M):
        out[m] = out[m] - radii[m]
    if floor[0] > 0.5:
        for m in range(M):
            if on_floor[m]:
                out[m] = min(out[m], Z[m] - radii[m] - floor[1])


@jit
def network_rows(tables, reach):
    """The obstacle network's rows ``(P, 14)`` of packed tables (see
    :meth:`~kinlearn.collision.kernel.KernelScene.model_rows`): every primitive's, kind by kind in
    :data:`PACKED_KINDS` order, whose bounding ball comes within ``reach`` of the origin (a kind the
    network does not read, none)."""
    counts = (
        sphere.network_count(tables[0]),
        box.network_count(tables[1]),
        cylinder.network_count(tables[2]),
        capsule.network_count(tables[3]),
        cloud.network_count(tables[4]),
    )
    n = 0
    for k in range(_S):
        n += counts[k]
    out = np.zeros((n, NET_WIDTH))
    bound = np.empty(n)
    r = 0
    for i in range(counts[0]):
        sphere.network_row(tables[0], i, out, r)
        bound[r] = sphere.radius(tables[0], i)
        r += 1
    for i in range(counts[1]):
        box.network_row(tables[1], i, out, r)
        bound[r] = box.radius(tables[1], i)
        r += 1
    for i in range(counts[2]):
        cylinder.network_row(tables[2], i, out, r)
        bound[r] = cylinder.radius(tables[2], i)
        r += 1
    for i in range(counts[3]):
        capsule.network_row(tables[3], i, out, r)
        bound[r] = capsule.radius(tables[3], i)
        r += 1
    for i in range(counts[4]):
        cloud.network_row(tables[4], i, out, r)
        bound[r] = cloud.radius(tables[4], i)
        r += 1
    if reach == np.inf:
        return out
    kept = 0  # the rows of the primitives within reach, moved up in place
    for r in range(n):
        if math.sqrt(out[r, 0] ** 2 + out[r, 1] ** 2 + out[r, 2] ** 2) - bound[r] <= reach:
            out[kept] = out[r]
            kept += 1
    return out[:kept].copy()
