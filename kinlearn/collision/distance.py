"""Signed distances between spheres and obstacles, batched and differentiable in torch.

A signed distance is the gap between two shapes in metres: positive when apart, zero when touching,
negative when overlapping (then minus the penetration depth, exact for every pair here). All functions
broadcast over leading batch dimensions and follow the dtype and device of their inputs. Each
sphere–primitive distance is the primitive kind's own (:mod:`kinlearn.collision.geometry`, dispatched by
:data:`~kinlearn.collision.geometry.KINDS`); this module adds the body-level reductions.

=================================  ==============================================================
:func:`sphere_distance`            spheres against primitives of one kind (the dispatch)
:func:`sphere_sphere_distance`     ‖c₁ − c₂‖ − r₁ − r₂
:func:`sphere_box_distance`        exact signed distance from the sphere's centre to a box in any
                                   orientation (negative inside: minus the depth to the nearest face), − r
:func:`sphere_cylinder_distance`   the same for a cylinder (axis along its local z)
:func:`sphere_plane_distance`      z − h − r for a floor at height h (solid below it)
:func:`body_obstacle_distance`     minimum over a body's spheres and a :class:`Scene`'s obstacles
:func:`self_collision_distance`    minimum over a body's self-collision sphere pairs
=================================  ==============================================================
"""

from __future__ import annotations

import torch

from ..checks import broadcast_shapes
from .geometry import KINDS, SCENE_KINDS, Box, Cylinder, Sphere, safe_sqrt
from .scene import _FIELDS, Scene, _axis_aligned

__all__ = [
    "body_obstacle_distance",
    "self_collision_distance",
    "sphere_box_distance",
    "sphere_cylinder_distance",
    "sphere_distance",
    "sphere_plane_distance",
    "sphere_sphere_distance",
]


def sphere_distance(spheres: torch.Tensor, kind: str, rows: torch.Tensor) -> torch.Tensor:
    """Signed distance ``(...)`` between spheres ``(..., 4)`` [x, y, z, r] and primitives ``rows
    (..., width)`` of ``kind`` (``"sphere"``, ``"box"``, ``"cylinder"``, ``"plane"``), broadcasting."""
    return KINDS[kind].sphere_distance(spheres, rows)


def sphere_sphere_distance(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Signed distance between spheres ``a (..., 4)`` and ``b (..., 4)`` ([x, y, z, r]) → ``(...)``."""
    return Sphere.sphere_distance(a, b)


def sphere_box_distance(s: torch.Tensor, box: torch.Tensor) -> torch.Tensor:
    """Signed distance between spheres ``s (..., 4)`` and boxes ``box (..., 15)`` → ``(...)``.

    ``box`` rows are ``[cx, cy, cz, hx, hy, hz, R (9)]`` (or axis-aligned ``(..., 6)``, centre and half
    extents). With q = |Rᵀ(p − c)| − h per axis, the centre's signed distance to the box is
    ‖max(q, 0)‖ + min(max_i q_i, 0): the Euclidean distance outside, minus the depth to the nearest
    face inside. The sphere's radius is subtracted.
    """
    return Box.sphere_distance(s, _axis_aligned(box) if box.shape[-1] == 6 else box)


def sphere_cylinder_distance(s: torch.Tensor, cylinder: torch.Tensor) -> torch.Tensor:
    """Signed distance between spheres ``s (..., 4)`` and cylinders ``(..., 14)`` [centre, radius,
    half length, R (9)] → ``(...)``: with the centre at radial distance ρ and height z in the cylinder's
    frame, a = ρ − radius, b = |z| − half length, √(max(a, 0)² + max(b, 0)²) + min(max(a, b), 0) − r."""
    return Cylinder.sphere_distance(s, cylinder)


def sphere_plane_distance(s: torch.Tensor, height: torch.Tensor | float) -> torch.Tensor:
    """Signed distance between spheres ``s (..., 4)`` and a floor at z = ``height`` (solid below) → ``(...)``."""
    return s[..., 2] - height - s[..., 3]


#: Large batches are evaluated in chunks of this many configurations, so that the (chunk, M, K)
#: intermediates stay in cache (faster at large batches than one pass: benchmarks/collision_speed.py).
CHUNK = 4096


def _nearest(d: torch.Tensor, mask: torch.Tensor | None) -> torch.Tensor:
    """``(..., M, K)`` → ``(..., M)``: the smallest distance over the obstacles the mask keeps."""
    if mask is not None:
        d = torch.where(mask.unsqueeze(-2), d, torch.full_like(d, torch.inf))
    return d.amin(dim=-1)


def _obstacles(scene: Scene, like: torch.Tensor, batch: torch.Size, flat: bool) -> dict:
    """Every scene field in ``like``'s dtype and device, flattened to one row per configuration
    ``(n, ...)`` over ``batch`` if ``flat`` and batched."""
    out = {}
    for name, tail in _FIELDS:
        t = getattr(scene, name)
        if t is not None:
            t = t.to(device=like.device, dtype=like.dtype if t.is_floating_point() else t.dtype)
            if flat and t.ndim > tail:
                tail_shape = t.shape[t.ndim - tail :]
                t = t.expand(*batch, *tail_shape).reshape(batch.numel(), *tail_shape)  # works when empty
        out[name] = t
    return out


def _slice(t: torch.Tensor | None, tail: int, lo: int, hi: int):
    return t[lo:hi] if t is not None and t.ndim > tail else t


def _per_sphere_core(c, r, fields: dict, floor_mask) -> torch.Tensor:
    p = c.unsqueeze(-2)  # (..., M, 1, 3)
    out = None
    for kind in SCENE_KINDS:
        rows = fields[kind.table]
        if rows.shape[-2]:
            d = _nearest(kind.point_distance(p, rows.unsqueeze(-3)), fields[f"{kind.kind}_mask"])
            out = d if out is None else torch.minimum(out, d)
    out = (torch.full_like(c[..., 0], torch.inf) if out is None else out) - r
    floor = fields["floor"]
    if floor is not None:
        d = c[..., 2] - r - floor.unsqueeze(-1)
        if floor_mask is not None:
            d = torch.where(floor_mask, d, torch.full_like(d, torch.inf))
        out = torch.minimum(out, d)
    return out


def _per_sphere(centres: torch.Tensor, radii: torch.Tensor, scene: Scene, floor_mask) -> torch.Tensor:
    """``(..., M)``: each body sphere's smallest signed distance to the scene (+inf for an empty scene); a
    point cloud's is exact near the points and the grid's lower bound beyond
    (:meth:`~kinlearn.collision.cloud.PointCloud.distance_torch`)."""
    per = _per_sphere_primitives(centres, radii, scene, floor_mask)
    if scene.cloud is not None:
        per = torch.minimum(per, scene.cloud.distance_torch(centres, radii) - radii)
    return per


def _per_sphere_primitives(
    centres: torch.Tensor, radii: torch.Tensor, scene: Scene, floor_mask
) -> torch.Tensor:
    if floor_mask is not None:
        floor_mask = floor_mask.to(centres.device)
    batch = broadcast_shapes(centres.shape[:-2], scene.batch_shape)
    n = batch.numel()
    M = centres.shape[-2]
    if n <= CHUNK:
        return _per_sphere_core(centres, radii, _obstacles(scene, centres, batch, False), floor_mask)
    c = centres.expand(*batch, M, 3).reshape(n, M, 3)
    fields = _obstacles(scene, centres, batch, True)
    tails = dict(_FIELDS)
    parts = [
        _per_sphere_core(
            c[lo : lo + CHUNK],
            radii,
            {k: _slice(t, tails[k], lo, lo + CHUNK) for k, t in fields.items()},
            floor_mask,
        )
        for lo in range(0, n, CHUNK)
    ]
    return torch.cat(parts).reshape(*batch, M)


def body_obstacle_distance(
    centres: torch.Tensor,
    radii: torch.Tensor,
    scene: Scene,
    *,
    per_sphere: bool = False,
    floor_mask: torch.Tensor | None = None,
) -> torch.Tensor | tuple[torch.Tensor, torch.Tensor]:
    """Smallest signed distance between a body of spheres and a scene, per configuration.

    ``centres (..., M, 3)`` (e.g. from :class:`~kinlearn.collision.BodySpheres`), ``radii (M,)``; the
    scene's batch shape broadcasts against ``...``. ``floor_mask (M,)`` (bool) picks the spheres the
    floor applies to (``BodySpheres.floor_mask``: every sphere but the base's); default all. Returns
    ``(...)``, and with ``per_sphere=True`` the pair ``(distance (...), per_sphere (..., M))``. +inf
    where the scene has no obstacle. Differentiable in the centres and in the obstacles.
    """
    per = _per_sphere(centres, radii.to(centres), scene, floor_mask)
    d = per.amin(dim=-1)
    return (d, per) if per_sphere else d


_PAIR_CACHE: dict[tuple, tuple[torch.Tensor, torch.Tensor]] = {}


def _pair_matrix(pairs: torch.Tensor, M: int, like: torch.Tensor) -> torch.Tensor:
    """``(3M, 3P)``: centres ``(N, 3M)`` @ it = the difference vectors of the pairs ``(N, P, 3)``.

    Cached per pairs tensor (kept alive by the cache, so its address identifies it) and version.
    """
    key = (pairs.data_ptr(), tuple(pairs.shape), pairs._version, M, like.dtype, like.device)
    hit = _PAIR_CACHE.get(key)
    if hit is not None:
        return hit[1]
    D = _build_pair_matrix(pairs, M, like)
    if len(_PAIR_CACHE) >= 16:
        _PAIR_CACHE.pop(next(iter(_PAIR_CACHE)))
    _PAIR_CACHE[key] = (pairs, D)
    return D


def _build_pair_matrix(pairs: torch.Tensor, M: int, like: torch.Tensor) -> torch.Tensor:
    P = pairs.shape[0]
    D = like.new_zeros(3 * M, 3 * P)
    cols = torch.arange(3 * P, device=like.device).view(P, 3)
    for k in range(3):
        D[3 * pairs[:, 0] + k, cols[:, k]] = 1.0
        D[3 * pairs[:, 1] + k, cols[:, k]] = -1.0
    return D


def self_collision_distance(
    centres: torch.Tensor, radii: torch.Tensor, pairs: torch.Tensor, *, per_pair: bool = False
) -> torch.Tensor | tuple[torch.Tensor, torch.Tensor]:
    """Smallest signed distance over the sphere pairs ``pairs (P, 2)`` of one body, per configuration.

    ``centres (..., M, 3)``, ``radii (M,)``; use ``BodySpheres.pairs`` (spheres on links at least two
    apart, minus the link pairs the robot's sphere model excludes). Returns ``(...)`` (+inf for no
    pairs), and with ``per_pair=True`` the pair ``(distance (...), per_pair (..., P))``.
    """
    batch, M = centres.shape[:-2], centres.shape[-2]
    pairs = pairs.to(centres.device)
    if pairs.shape[0] == 0:
        d = torch.full(batch, torch.inf, dtype=centres.dtype, device=centres.device)
        return (d, centres.new_zeros(*batch, 0)) if per_pair else d
    r = radii.to(centres)
    reach = r[pairs[:, 0]] + r[pairs[:, 1]]
    D = _pair_matrix(pairs, M, centres)
    flat = centres.reshape(-1, 3 * M)

    def core(c: torch.Tensor) -> torch.Tensor:
        v = (c @ D).view(c.shape[0], -1, 3)
        return safe_sqrt((v * v).sum(dim=-1)) - reach

    per = torch.cat([core(c) for c in flat.split(CHUNK)]) if flat.shape[0] > CHUNK else core(flat)
    per = per.reshape(*batch, -1)
    d = per.amin(dim=-1)
    return (d, per) if per_pair else d
