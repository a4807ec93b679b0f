"""What every obstacle kind shares: the :class:`Primitive` base (a frozen dataclass and its row layout),
the checks of a row's numbers, and the compiled pieces every kind's distance uses.

A kind (one module of :mod:`kinlearn.collision.kinds`) is a :class:`Primitive` subclass with its row
layout as named column slices, its torch signed distance (the reference: batched, differentiable), its
compiled twin (numba, one row at a time), the radius of the ball about its centre that holds it (the
kernels cull by it), its features for the obstacle network and its shape in coal (the contract test's
third opinion). :mod:`kinlearn.collision.kinds` holds the table of kinds.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import torch

from ...body.jit import jit
from ...errors import ObstacleError

__all__ = [
    "CENTRE",
    "CULL",
    "IDENTITY",
    "ROTATION_TOLERANCE",
    "TINY",
    "Primitive",
    "beyond",
    "check_rotations",
    "safe_sqrt",
]

#: The identity rotation, row-major.
IDENTITY = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
#: How far a rotation may be from orthonormal (‖RᵀR − I‖ max entry) and its determinant from 1.
ROTATION_TOLERANCE = 1e-6
#: Every kind's row starts with its centre (the kernels' culling ball is centred there).
CENTRE = slice(0, 3)
#: The obstacle network's row of a primitive (:meth:`~kinlearn.collision.kernel.KernelScene.model_rows`,
#: :func:`~kinlearn.models.obstacle_path.scene_primitives`): its first column of each part. Centre (3),
#: the half extents of its axis-aligned bounding box (3), is-sphere (1), its extent tensor (6),
#: is-cylinder (1).
NET_CENTRE, NET_AABB, NET_SPHERE, NET_EXTENT, NET_CYLINDER, NET_WIDTH = 0, 3, 6, 7, 13, 14
#: The smallest positive float64: a distance's square root never sees less (as torch's ``safe_sqrt``).
TINY = float(np.finfo(np.float64).tiny)
#: Metres of slack when a primitive is culled by its bounding ball (far above a distance's rounding).
CULL = 1e-9


def safe_sqrt(x: torch.Tensor) -> torch.Tensor:
    """sqrt with a finite gradient at 0 (where a distance's direction is undefined, the gradient is 0)."""
    return x.clamp_min(torch.finfo(x.dtype).tiny).sqrt()


def local(p: torch.Tensor, rows: torch.Tensor, rot: slice) -> tuple[torch.Tensor, ...]:
    """Points ``p (..., 3)`` in the local frames of primitives ``rows (..., width)`` (rotation columns
    ``rot``): Rᵀ (p − c), per axis. Written as sums of products term by term, so that the identity
    rotation gives exactly p − c."""
    dx, dy, dz = p[..., 0] - rows[..., 0], p[..., 1] - rows[..., 1], p[..., 2] - rows[..., 2]
    R = rows[..., rot]
    return tuple(dx * R[..., k] + dy * R[..., 3 + k] + dz * R[..., 6 + k] for k in range(3))


def rotation(value, what: str) -> tuple[float, ...]:
    """A 3 × 3 rotation (or 9 numbers, row-major) checked and given as 9 floats."""
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


def vec(value, n: int, what: str) -> tuple[float, ...]:
    """``n`` finite numbers as floats, else :class:`ObstacleError` naming ``what``."""
    a = np.asarray(value, dtype=np.float64).reshape(-1)
    if a.shape != (n,) or not np.isfinite(a).all():
        raise ObstacleError(f"{what} must be {n} finite numbers, got {np.asarray(value).tolist()!r}")
    return tuple(float(v) for v in a)


def positive(value, what: str) -> float:
    """A finite number of metres > 0, else :class:`ObstacleError` naming ``what``."""
    v = float(value)
    if not (np.isfinite(v) and v > 0):
        raise ObstacleError(f"{what} must be a finite number of metres > 0, got {value!r}")
    return v


def rotation_matrix(row: np.ndarray, rot: slice | None) -> np.ndarray:
    """``(3, 3)``: a row's rotation (the identity for a kind without one)."""
    return np.eye(3) if rot is None else np.asarray(row[rot], dtype=np.float64).reshape(3, 3)


@dataclass(frozen=True)
class Primitive:
    """One obstacle. Subclasses name their ``kind``, the :class:`~kinlearn.collision.Scene` field holding
    their rows (``table``), the row ``width`` and ``layout``, the columns that are sizes (``> 0``), the
    ``rotation`` columns (if any), a harmless padding row, and how many columns their packed rows
    have in the kernels (``packed_width``: the row, then what the kind adds, its bounding radius)."""

    kind: ClassVar[str]
    table: ClassVar[str]
    width: ClassVar[int]
    layout: ClassVar[str]
    sizes: ClassVar[slice]
    size_name: ClassVar[str]
    rotation_columns: ClassVar[slice | None] = None
    pad: ClassVar[tuple[float, ...]]
    packed_width: ClassVar[int]
    #: How the obstacle network reads the kind (:func:`~kinlearn.models.obstacle_path.scene_primitives`):
    #: its is-sphere and is-cylinder flags.
    network_flags: ClassVar[tuple[float, float]] = (0.0, 0.0)

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

    @staticmethod
    def aabb_half_extents(rows: torch.Tensor) -> torch.Tensor:
        """``(..., 3)``: half extents of each primitive's axis-aligned bounding box."""
        raise NotImplementedError

    @staticmethod
    def shape_tensor(rows: torch.Tensor) -> torch.Tensor:
        """``(..., 6)``: each primitive's extent tensor ``L = R diag(e) Rᵀ`` as ``[Lxx, Lyy, Lzz, Lxy,
        Lxz, Lyz]`` (:func:`~kinlearn.collision.geometry.shape_tensor`)."""
        raise NotImplementedError

    @classmethod
    def kernel_rows(cls, scene) -> np.ndarray:
        """What the kernels pack of ``scene`` (unbatched) for this kind: its rows without padding, as a
        C-contiguous float64 array (a kind a scene holds otherwise gives whatever its ``pack`` reads)."""
        rows, mask = getattr(scene, cls.table), getattr(scene, f"{cls.kind}_mask")
        if mask is not None:
            rows = rows[mask]
        if rows.dtype != torch.float64 or rows.device.type != "cpu" or rows.requires_grad:
            rows = rows.detach().cpu().double()
        return np.ascontiguousarray(rows.numpy())

    @classmethod
    def packed_shape(cls, rows: np.ndarray) -> tuple[int, int]:
        """The shape of the kind's packed table made of ``rows`` (:meth:`kernel_rows`)."""
        return rows.shape[0], cls.packed_width

    @classmethod
    def coal_shape(cls, row: np.ndarray):
        """``(geometry, rotation (3, 3), translation (3,))``: one row as a coal collision shape placed in
        the base frame (coal's distances are the contract test's third opinion)."""
        raise NotImplementedError


def extent_tensor(e: tuple[torch.Tensor, ...], R: torch.Tensor) -> torch.Tensor:
    """``(..., 6)``: ``L = R diag(e) Rᵀ`` of half extents ``e`` (three ``(...)``) and rotations
    ``R (..., 9)`` row-major, each entry summed term by term in a fixed order (as the compiled rows are)."""

    def L(a: int, b: int) -> torch.Tensor:
        t = [R[..., 3 * a + k] * e[k] * R[..., 3 * b + k] for k in range(3)]
        return (t[0] + t[1]) + t[2]

    return torch.stack((L(0, 0), L(1, 1), L(2, 2), L(0, 1), L(0, 2), L(1, 2)), dim=-1)


# --------------------------------------------------------------------------------------------------
# Compiled pieces every kind uses
# --------------------------------------------------------------------------------------------------


@jit
def beyond(x, y, z, t, i, bound, d):
    """Whether primitive ``i`` of packed table ``t`` (centre in its first three columns, held in a ball
    of radius ``bound`` about it) provably lies farther than ``d`` from the point: a convex set inside a
    ball has a signed distance no smaller than the ball's, ‖p − c‖ − bound (compared squared, with
    :data:`CULL` of slack for rounding, so a culled primitive could never have lowered the minimum)."""
    lim = d + bound + CULL
    if not lim > 0.0:  # also d = +inf: nothing to compare with yet
        return False
    dx, dy, dz = x - t[i, 0], y - t[i, 1], z - t[i, 2]
    return dx * dx + dy * dy + dz * dz > lim * lim


@jit
def extent_row(out, r, c, e0, e1, e2, R, o):
    """Columns ``c … c + 5`` of row ``r`` of ``out``: L = R diag(e) Rᵀ of rotation ``R[o:o + 9]``
    (row-major), summed term by term in the order of :func:`extent_tensor`."""
    e = (e0, e1, e2)
    ab = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
    for m in range(6):
        a, b = ab[m]
        t0 = R[o + 3 * a] * e[0] * R[o + 3 * b]
        t1 = R[o + 3 * a + 1] * e[1] * R[o + 3 * b + 1]
        t2 = R[o + 3 * a + 2] * e[2] * R[o + 3 * b + 2]
        out[r, c + m] = (t0 + t1) + t2
