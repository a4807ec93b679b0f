"""Obstacle primitives as types: one class per kind, one signed distance per sphere–primitive pair.

Each kind is a frozen dataclass (what a user writes: :class:`Sphere`, :class:`Box`, :class:`Cylinder`,
:class:`Plane`) and a row layout (how a :class:`~kinlearn.collision.Scene` stores a batch of them, one
float row per primitive). :data:`KINDS` is the dispatch table: kind name → class, and every class
carries its torch signed distance from points (:meth:`Primitive.point_distance`), batched and
differentiable. A sphere's signed distance to a primitive is the point distance of its centre minus
its radius, exact for these convex shapes both apart and overlapping (then minus the penetration
depth). A new kind is one class here and its row in :data:`KINDS`.

Row layouts (metres; ``R`` a rotation matrix, row-major, whose columns are the primitive's local axes
in the base frame):

=============  =====  ===================================================================================
kind           width  row
=============  =====  ===================================================================================
``sphere``     4      ``[x, y, z, radius]``
``box``        15     ``[cx, cy, cz, hx, hy, hz, R00, R01, …, R22]``: centre, half extents, orientation
``cylinder``   14     ``[cx, cy, cz, radius, half_length, R00, …, R22]``: axis along the local z
``plane``      4      ``[nx, ny, nz, offset]``: a unit normal, solid where n · p ≤ offset
=============  =====  ===================================================================================

A box's first six numbers are those of the axis-aligned layout ``[centre, half extents]`` that scenes
used before, so an axis-aligned box reads the same either way.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import torch

from ..errors import ObstacleError

__all__ = [
    "IDENTITY",
    "KINDS",
    "SCENE_KINDS",
    "Box",
    "Cylinder",
    "Plane",
    "Primitive",
    "Sphere",
    "aabb_half_extents",
    "quaternion_from_rotation",
    "rotation_from_quaternion",
    "safe_sqrt",
]

#: The identity rotation, row-major.
IDENTITY = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
#: How far a rotation may be from orthonormal (‖RᵀR − I‖ max entry) and its determinant from 1.
ROTATION_TOLERANCE = 1e-6


def safe_sqrt(x: torch.Tensor) -> torch.Tensor:
    """sqrt with a finite gradient at 0 (where a distance's direction is undefined, the gradient is 0)."""
    return x.clamp_min(torch.finfo(x.dtype).tiny).sqrt()


def _local(p: torch.Tensor, rows: torch.Tensor, rot: slice) -> tuple[torch.Tensor, ...]:
    """Points ``p (..., 3)`` in the local frames of primitives ``rows (..., width)``: Rᵀ (p − c), per axis.

    Written as sums of products term by term, so that the identity rotation gives exactly p − c.
    """
    dx, dy, dz = p[..., 0] - rows[..., 0], p[..., 1] - rows[..., 1], p[..., 2] - rows[..., 2]
    R = rows[..., rot]
    return tuple(dx * R[..., k] + dy * R[..., 3 + k] + dz * R[..., 6 + k] for k in range(3))


def _rotation(value, what: str) -> tuple[float, ...]:
    R = np.asarray(value, dtype=np.float64)
    if R.shape == (9,):
        R = R.reshape(3, 3)
    if R.shape != (3, 3) or not np.isfinite(R).all():
        raise ObstacleError(f"{what}: a rotation must be a finite 3 × 3 matrix, got shape {R.shape}")
    check_rotations(torch.as_tensor(R.reshape(1, 9)), what)
    return tuple(float(v) for v in R.reshape(-1))


def check_rotations(R: torch.Tensor, what: str) -> None:
    """``R (..., 9)`` row-major rotations: :class:`ObstacleError` unless orthonormal with determinant 1."""
    if R.numel() == 0:
        return
    M = R.reshape(-1, 3, 3).double()
    err = (M.transpose(-1, -2) @ M - torch.eye(3, dtype=M.dtype)).abs().amax()
    det = torch.linalg.det(M)
    if float(err) > ROTATION_TOLERANCE or float((det - 1).abs().max()) > ROTATION_TOLERANCE:
        raise ObstacleError(
            f"{what}: every rotation must be orthonormal with determinant +1 (to {ROTATION_TOLERANCE}); "
            f"found RᵀR − I up to {float(err):.3g} and determinant {float(det.min()):.6g}"
        )


def _vec(value, n: int, what: str) -> tuple[float, ...]:
    a = np.asarray(value, dtype=np.float64).reshape(-1)
    if a.shape != (n,) or not np.isfinite(a).all():
        raise ObstacleError(f"{what} must be {n} finite numbers, got {np.asarray(value).tolist()!r}")
    return tuple(float(v) for v in a)


def _positive(value, what: str) -> float:
    v = float(value)
    if not (np.isfinite(v) and v > 0):
        raise ObstacleError(f"{what} must be a finite number of metres > 0, got {value!r}")
    return v


@dataclass(frozen=True)
class Primitive:
    """One obstacle. Subclasses name their ``kind``, the :class:`Scene` field holding their rows
    (``table``), the row ``width`` and ``layout``, the columns that are sizes (``> 0``), the
    ``rotation`` columns (if any) and a harmless padding row."""

    kind: ClassVar[str]
    table: ClassVar[str]
    width: ClassVar[int]
    layout: ClassVar[str]
    sizes: ClassVar[slice]
    size_name: ClassVar[str]
    rotation_columns: ClassVar[slice | None] = None
    pad: ClassVar[tuple[float, ...]]

    def row(self) -> tuple[float, ...]:
        """The primitive as one row of its kind's layout."""
        raise NotImplementedError

    @classmethod
    def from_row(cls, row: Sequence[float]) -> Primitive:
        raise NotImplementedError

    @staticmethod
    def point_distance(p: torch.Tensor, rows: torch.Tensor) -> torch.Tensor:
        """Signed distance ``(...)`` from points ``p (..., 3)`` to primitives ``rows (..., width)``
        (broadcasting): positive outside, minus the depth to the surface inside."""
        raise NotImplementedError

    @classmethod
    def sphere_distance(cls, spheres: torch.Tensor, rows: torch.Tensor) -> torch.Tensor:
        """Signed distance ``(...)`` between spheres ``(..., 4)`` [x, y, z, r] and primitives ``rows``."""
        return cls.point_distance(spheres[..., :3], rows) - spheres[..., 3]


@dataclass(frozen=True)
class Sphere(Primitive):
    """A ball: ``centre`` (3,) and ``radius``."""

    kind: ClassVar[str] = "sphere"
    table: ClassVar[str] = "spheres"
    width: ClassVar[int] = 4
    layout: ClassVar[str] = "[x, y, z, radius]"
    sizes: ClassVar[slice] = slice(3, 4)
    size_name: ClassVar[str] = "radius"
    pad: ClassVar[tuple[float, ...]] = (0.0, 0.0, 0.0, 1.0)

    centre: tuple[float, float, float]
    radius: float

    def __post_init__(self):
        object.__setattr__(self, "centre", _vec(self.centre, 3, "a sphere's centre"))
        object.__setattr__(self, "radius", _positive(self.radius, "a sphere's radius"))

    def row(self) -> tuple[float, ...]:
        return (*self.centre, self.radius)

    @classmethod
    def from_row(cls, row) -> Sphere:
        return cls(tuple(row[:3]), row[3])

    @staticmethod
    def point_distance(p: torch.Tensor, rows: torch.Tensor) -> torch.Tensor:
        dx, dy, dz = p[..., 0] - rows[..., 0], p[..., 1] - rows[..., 1], p[..., 2] - rows[..., 2]
        return safe_sqrt(dx * dx + dy * dy + dz * dz) - rows[..., 3]


@dataclass(frozen=True)
class Box(Primitive):
    """A box in any orientation: ``centre`` (3,), ``half_extents`` (3,) along its local axes, and
    ``rotation`` (3 × 3 or 9 numbers row-major; its columns are the local axes; default: axis-aligned)."""

    kind: ClassVar[str] = "box"
    table: ClassVar[str] = "boxes"
    width: ClassVar[int] = 15
    layout: ClassVar[str] = "[cx, cy, cz, hx, hy, hz, R00, R01, R02, R10, R11, R12, R20, R21, R22]"
    sizes: ClassVar[slice] = slice(3, 6)
    size_name: ClassVar[str] = "half extent"
    rotation_columns: ClassVar[slice] = slice(6, 15)
    pad: ClassVar[tuple[float, ...]] = (0.0, 0.0, 0.0, 1.0, 1.0, 1.0, *IDENTITY)

    centre: tuple[float, float, float]
    half_extents: tuple[float, float, float]
    rotation: tuple[float, ...] = IDENTITY

    def __post_init__(self):
        object.__setattr__(self, "centre", _vec(self.centre, 3, "a box's centre"))
        h = _vec(self.half_extents, 3, "a box's half extents")
        for v in h:
            _positive(v, "a box's half extent")
        object.__setattr__(self, "half_extents", h)
        object.__setattr__(self, "rotation", _rotation(self.rotation, "a box"))

    def row(self) -> tuple[float, ...]:
        return (*self.centre, *self.half_extents, *self.rotation)

    @classmethod
    def from_row(cls, row) -> Box:
        return cls(tuple(row[:3]), tuple(row[3:6]), tuple(row[6:15]))

    @staticmethod
    def point_distance(p: torch.Tensor, rows: torch.Tensor) -> torch.Tensor:
        x, y, z = _local(p, rows, slice(6, 15))
        qx, qy, qz = x.abs() - rows[..., 3], y.abs() - rows[..., 4], z.abs() - rows[..., 5]
        ox, oy, oz = qx.clamp_min(0.0), qy.clamp_min(0.0), qz.clamp_min(0.0)
        inside = torch.maximum(torch.maximum(qx, qy), qz).clamp_max(0.0)
        return safe_sqrt(ox * ox + oy * oy + oz * oz) + inside


@dataclass(frozen=True)
class Cylinder(Primitive):
    """A solid cylinder: ``centre`` (3,), ``radius``, ``half_length`` along its local z axis, and
    ``rotation`` (as for :class:`Box`; default: the axis along the base frame's z)."""

    kind: ClassVar[str] = "cylinder"
    table: ClassVar[str] = "cylinders"
    width: ClassVar[int] = 14
    layout: ClassVar[str] = "[cx, cy, cz, radius, half_length, R00, …, R22]"
    sizes: ClassVar[slice] = slice(3, 5)
    size_name: ClassVar[str] = "radius and half length"
    rotation_columns: ClassVar[slice] = slice(5, 14)
    pad: ClassVar[tuple[float, ...]] = (0.0, 0.0, 0.0, 1.0, 1.0, *IDENTITY)

    centre: tuple[float, float, float]
    radius: float
    half_length: float
    rotation: tuple[float, ...] = IDENTITY

    def __post_init__(self):
        object.__setattr__(self, "centre", _vec(self.centre, 3, "a cylinder's centre"))
        object.__setattr__(self, "radius", _positive(self.radius, "a cylinder's radius"))
        object.__setattr__(self, "half_length", _positive(self.half_length, "a cylinder's half length"))
        object.__setattr__(self, "rotation", _rotation(self.rotation, "a cylinder"))

    @property
    def axis(self) -> tuple[float, float, float]:
        """The cylinder's axis (its local z) in the base frame."""
        R = self.rotation
        return (R[2], R[5], R[8])

    def row(self) -> tuple[float, ...]:
        return (*self.centre, self.radius, self.half_length, *self.rotation)

    @classmethod
    def from_row(cls, row) -> Cylinder:
        return cls(tuple(row[:3]), row[3], row[4], tuple(row[5:14]))

    @staticmethod
    def point_distance(p: torch.Tensor, rows: torch.Tensor) -> torch.Tensor:
        x, y, z = _local(p, rows, slice(5, 14))
        radial = safe_sqrt(x * x + y * y) - rows[..., 3]
        axial = z.abs() - rows[..., 4]
        o_r, o_a = radial.clamp_min(0.0), axial.clamp_min(0.0)
        return safe_sqrt(o_r * o_r + o_a * o_a) + torch.maximum(radial, axial).clamp_max(0.0)


@dataclass(frozen=True)
class Plane(Primitive):
    """A half-space: unit ``normal`` (3,) and ``offset``; solid where normal · p ≤ offset. A floor at
    height h is ``Plane((0, 0, 1), h)`` (a :class:`Scene` keeps its floor as that height)."""

    kind: ClassVar[str] = "plane"
    table: ClassVar[str] = "planes"
    width: ClassVar[int] = 4
    layout: ClassVar[str] = "[nx, ny, nz, offset]"
    sizes: ClassVar[slice] = slice(0, 0)
    size_name: ClassVar[str] = "size"
    pad: ClassVar[tuple[float, ...]] = (0.0, 0.0, 1.0, -1000.0)

    normal: tuple[float, float, float]
    offset: float

    def __post_init__(self):
        n = np.asarray(_vec(self.normal, 3, "a plane's normal"))
        norm = float(np.linalg.norm(n))
        if not norm > 0:
            raise ObstacleError("a plane's normal must not be zero")
        object.__setattr__(self, "normal", tuple(float(v) for v in n / norm))
        object.__setattr__(self, "offset", float(_vec([self.offset], 1, "a plane's offset")[0]))

    def row(self) -> tuple[float, ...]:
        return (*self.normal, self.offset)

    @classmethod
    def from_row(cls, row) -> Plane:
        return cls(tuple(row[:3]), row[3])

    @staticmethod
    def point_distance(p: torch.Tensor, rows: torch.Tensor) -> torch.Tensor:
        return p[..., 0] * rows[..., 0] + p[..., 1] * rows[..., 1] + p[..., 2] * rows[..., 2] - rows[..., 3]


#: The dispatch table: kind → its class (and so its row layout and signed distance).
KINDS: dict[str, type[Primitive]] = {k.kind: k for k in (Sphere, Box, Cylinder, Plane)}
#: The kinds a :class:`Scene` holds as batched tables, in order (a scene's floor is its plane).
SCENE_KINDS: tuple[type[Primitive], ...] = (Sphere, Box, Cylinder)


def aabb_half_extents(kind: type[Primitive], rows: torch.Tensor) -> torch.Tensor:
    """``(..., 3)``: half extents of each primitive's axis-aligned bounding box (for a sphere its
    radius three times; for an axis-aligned box its own half extents, exactly)."""
    if kind is Sphere:
        return rows[..., 3:4].expand(*rows.shape[:-1], 3)
    if kind is Box:
        R = rows[..., 6:15].unflatten(-1, (3, 3)).abs()
        h = rows[..., 3:6]
        return (R * h.unsqueeze(-2)).sum(-1)
    if kind is Cylinder:
        a = rows[..., [7, 10, 13]]  # the axis: column 2 of R
        r, h = rows[..., 3:4], rows[..., 4:5]
        return r * safe_sqrt(1.0 - a * a) + h * a.abs()
    raise ObstacleError(f"no bounding box for primitives of kind {kind.kind!r}")


def shape_tensor(kind: type[Primitive], rows: torch.Tensor) -> torch.Tensor:
    """``(..., 6)``: each primitive's extent tensor ``L = R diag(e) Rᵀ`` as ``[Lxx, Lyy, Lzz, Lxy, Lxz,
    Lyz]`` (m), ``e`` its half extents in its own frame (a sphere's radius three times, a box's half
    extents, a cylinder's ``(r, r, h)``). One tensor per shape however its frame is written (flipping an
    axis, or turning a cylinder about its own, leaves it unchanged), where a bounding box forgets which
    way a rotated box lies. Summed term by term in a fixed order (as the compiled rows are)."""
    if kind is Sphere:
        r = rows[..., 3]
        z = torch.zeros_like(r)
        return torch.stack((r, r, r, z, z, z), dim=-1)
    if kind is Box:
        e, R = rows[..., 3:6], rows[..., 6:15]
    elif kind is Cylinder:
        e, R = rows[..., [3, 3, 4]], rows[..., 5:14]
    else:
        raise ObstacleError(f"no shape tensor for primitives of kind {kind.kind!r}")

    def L(a: int, b: int) -> torch.Tensor:
        t = [R[..., 3 * a + k] * e[..., k] * R[..., 3 * b + k] for k in range(3)]
        return (t[0] + t[1]) + t[2]

    return torch.stack((L(0, 0), L(1, 1), L(2, 2), L(0, 1), L(0, 2), L(1, 2)), dim=-1)


def rotation_from_quaternion(q: Sequence[float]) -> np.ndarray:
    """``(3, 3)`` rotation of a quaternion ``[x, y, z, w]`` (normalised first; ROS's order)."""
    x, y, z, w = np.asarray(q, dtype=np.float64) / np.linalg.norm(np.asarray(q, dtype=np.float64))
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def quaternion_from_rotation(R) -> np.ndarray:
    """``[x, y, z, w]`` (w ≥ 0) of a rotation matrix ``(3, 3)``."""
    R = np.asarray(R, dtype=np.float64).reshape(3, 3)
    t = np.trace(R)
    if t > 0:
        s = 2.0 * np.sqrt(1.0 + t)
        q = [(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, s / 4]
    else:
        i = int(np.argmax(np.diag(R)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + R[i, i] - R[j, j] - R[k, k])
        q = [0.0, 0.0, 0.0, (R[k, j] - R[j, k]) / s]
        q[i] = s / 4
        q[j] = (R[j, i] + R[i, j]) / s
        q[k] = (R[k, i] + R[i, k]) / s
    q = np.asarray(q)
    return -q if q[3] < 0 else q


def box_faces(row: Sequence[float]) -> list[np.ndarray]:
    """The six faces ``(4, 3)`` of a box row (15 numbers, or 6 for an axis-aligned box), for drawing."""
    row = np.asarray(row, dtype=np.float64)
    R = row[6:15].reshape(3, 3) if row.shape[0] == 15 else np.eye(3)
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)
    corners = row[:3] + (signs * row[3:6]) @ R.T
    quads = ((0, 1, 3, 2), (4, 5, 7, 6), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5))
    return [corners[list(f)] for f in quads]


def cylinder_faces(row: Sequence[float], segments: int = 16) -> list[np.ndarray]:
    """A cylinder row (14 numbers) as ``segments`` side quads and its two caps, for drawing."""
    row = np.asarray(row, dtype=np.float64)
    R, r, h = row[5:14].reshape(3, 3), row[3], row[4]
    a = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    ring = np.stack([r * np.cos(a), r * np.sin(a), np.zeros_like(a)], axis=1)
    up = np.array([0.0, 0.0, h])
    lo = row[:3] + (ring - up) @ R.T
    hi = row[:3] + (ring + up) @ R.T
    sides = [
        np.stack([lo[i], lo[(i + 1) % segments], hi[(i + 1) % segments], hi[i]]) for i in range(segments)
    ]
    return [*sides, lo, hi]
