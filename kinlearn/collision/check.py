"""Collision checks of configurations and of joint paths, dense between waypoints.

:func:`check_path` interpolates each segment θ(k) → θ(k+1) of a joint path linearly in joint space and
checks configurations close enough that **no sphere centre moves more than** ``max_travel`` (1 cm by
default) between two checked ones. The number of checks per segment comes from a bound, not from
sampling: along a straight joint-space segment a point on link l moves at most
Σ_j |Δθ_j| · (its largest possible distance from joint j's axis), and ``BodySpheres.lever`` holds that
distance bound per sphere and joint (:func:`~kinlearn.collision.body._lever_arms`). A segment whose
largest sphere bound is L metres gets ⌈L / max_travel⌉ sub-steps.

Between two checked configurations a sphere stays within ``max_travel`` of where it was checked, so a
collision can hide there only if it is shallower than ``max_travel / 2``: pass ``margin=max_travel / 2``
to make a clean result a guarantee for the sphere body.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from ..checks import as_real, broadcast_shapes, check_finite, check_last_dim
from ..errors import ConfigError, ShapeError
from .body import BodySpheres
from .distance import body_obstacle_distance, self_collision_distance
from .scene import Scene

__all__ = ["PathCheck", "check_path", "clearances", "in_collision", "segment_steps"]


@dataclass(frozen=True)
class PathCheck:
    """Result of :func:`check_path` for paths of batch shape ``(...)``.

    - ``collision_free`` ``(...)`` bool: no checked configuration is within ``margin`` of the scene or
      has a self-collision.
    - ``clearance`` ``(...)``: the smallest body–scene signed distance over the checked configurations
      (metres; +inf for an empty scene).
    - ``self_collision`` ``(...)`` bool and ``self_clearance`` ``(...)``: the same for self-collision.
    - ``first_collision`` ``(...)`` int64: the index k of the waypoint that starts the segment
      [θ(k), θ(k+1)) holding the first colliding checked configuration (k = T: θ(T) itself); −1 if free.
    - ``checked`` ``(...)`` int64: how many configurations were checked on each path.
    """

    collision_free: torch.Tensor
    clearance: torch.Tensor
    self_collision: torch.Tensor
    self_clearance: torch.Tensor
    first_collision: torch.Tensor
    checked: torch.Tensor


def _scene_for(scene: Scene, batch: torch.Size, what: str) -> Scene:
    try:
        shape = broadcast_shapes(scene.batch_shape, batch)
    except ValueError as exc:
        raise ShapeError(
            f"the scene's batch shape {tuple(scene.batch_shape)} does not broadcast against {what} {tuple(batch)}"
        ) from exc
    if shape != batch:
        raise ShapeError(
            f"the scene's batch shape {tuple(scene.batch_shape)} would enlarge {what} {tuple(batch)}; "
            "give one scene per path (or one scene for all)"
        )
    return scene


def clearances(body: BodySpheres, q: torch.Tensor, scene: Scene, validate: bool = True):
    """``(scene clearance (...), self clearance (...))`` of configurations ``q (..., dof)``: signed
    distances in metres, negative when overlapping; +inf where there is nothing to collide with."""
    c = body(q, validate=validate)
    r = body.radii_like(c)
    d = body_obstacle_distance(c, r, scene, floor_mask=body.floor_mask)
    s = self_collision_distance(c, r, body.pairs)
    return d, s


def in_collision(body: BodySpheres, q: torch.Tensor, scene: Scene, margin: float = 0.0) -> torch.Tensor:
    """``(...)`` bool: configuration ``q (..., dof)`` is within ``margin`` of the scene, or self-collides.

    Touching (distance exactly ``margin``) counts as a collision.
    """
    d, s = clearances(body, q, scene)
    return (d <= margin) | (s <= 0.0)


def segment_steps(body: BodySpheres, joints: torch.Tensor, max_travel: float = 0.01) -> torch.Tensor:
    """``(..., T)`` int64: sub-steps per segment of ``joints (..., T+1, dof)`` so that no sphere centre
    moves more than ``max_travel`` metres between checked configurations (at least 1)."""
    delta = (joints[..., 1:, :] - joints[..., :-1, :]).abs()
    bound = (delta.unsqueeze(-2) * body.lever.to(delta)).sum(dim=-1).amax(dim=-1)  # (..., T) metres
    return torch.ceil(bound / max_travel).clamp_min(1).to(torch.int64)


#: The most configurations one :func:`check_path` call looks at (about 1 GB of intermediate tensors).
MAX_CHECKED = 10_000_000


@torch.no_grad()
def check_path(
    body: BodySpheres,
    joints: torch.Tensor,
    scene: Scene,
    max_travel: float = 0.01,
    margin: float = 0.0,
    chunk: int = 65536,
) -> PathCheck:
    """Check joint paths ``joints (..., T+1, dof)`` against ``scene`` and self-collision, densely.

    Each segment is cut into :func:`segment_steps` equal sub-steps; every sub-step's start and the
    path's last configuration are checked (``checked`` counts them). The scene's batch shape must
    broadcast to the paths' batch ``(...)`` (one scene per path, or one for all). Not differentiable
    (use the distance functions on chosen configurations for gradients). Configurations are evaluated
    in chunks of ``chunk`` to bound memory.
    """
    check_last_dim(joints, body.robot.dof, "joint paths")
    if joints.ndim < 2:
        raise ShapeError(
            f"joint paths must have shape (..., T+1, {body.robot.dof}), got {tuple(joints.shape)}"
        )
    check_finite(joints, "joint paths")
    max_travel = as_real(
        max_travel, "max_travel", minimum=0.0, open_minimum=True, expected="a finite number of metres > 0"
    )
    batch = joints.shape[:-2]
    scene = _scene_for(scene, batch, "paths of batch shape")
    n_wp, dof = joints.shape[-2], joints.shape[-1]
    flat = joints.reshape(-1, n_wp, dof)
    n_paths = flat.shape[0]
    dev = joints.device

    # The configurations to check: sub-step starts of every segment, then each path's last waypoint.
    if n_wp > 1:
        steps = segment_steps(body, flat, max_travel).reshape(-1)  # (n_paths · T,)
        total = int(steps.sum())
        if total > MAX_CHECKED:  # refused before the configurations are made (tens of bytes each)
            raise ConfigError(
                f"checking these {n_paths} path(s) every {max_travel:g} m of sphere travel would take {total:,} "
                f"configurations, more than the {MAX_CHECKED:,} a call checks (MAX_CHECKED); pass a larger "
                "max_travel or fewer paths per call"
            )
        seg = torch.repeat_interleave(torch.arange(steps.shape[0], device=dev), steps)
        first = torch.cumsum(steps, 0) - steps
        frac = (torch.arange(seg.shape[0], device=dev) - first[seg]).to(joints.dtype) / steps[seg].to(
            joints.dtype
        )
        start = flat[:, :-1, :].reshape(-1, dof)
        delta = (flat[:, 1:, :] - flat[:, :-1, :]).reshape(-1, dof)
        q = torch.cat((start[seg] + frac.unsqueeze(-1) * delta[seg], flat[:, -1, :]))
        T = n_wp - 1
        path = torch.cat((seg // T, torch.arange(n_paths, device=dev)))
        where = torch.cat(
            (
                (seg % T).to(joints.dtype) + frac,
                torch.full((n_paths,), float(T), dtype=joints.dtype, device=dev),
            )
        )
    else:
        q = flat[:, 0, :]
        path = torch.arange(n_paths, device=dev)
        where = torch.zeros(n_paths, dtype=joints.dtype, device=dev)

    batched = len(scene.batch_shape) > 0
    flat_scene = scene.expand(*batch).reshape(n_paths) if batched else scene
    d = torch.empty(q.shape[0], dtype=joints.dtype, device=dev)
    s = torch.empty_like(d)
    for lo in range(0, q.shape[0], chunk):
        hi = min(lo + chunk, q.shape[0])
        sc = flat_scene[path[lo:hi]] if batched else flat_scene
        d[lo:hi], s[lo:hi] = clearances(body, q[lo:hi], sc, validate=False)

    bad = (d <= margin) | (s <= 0.0)
    inf = torch.full((n_paths,), torch.inf, dtype=joints.dtype, device=dev)
    clearance = inf.scatter_reduce(0, path, d, "amin")
    self_clear = inf.clone().scatter_reduce(0, path, s, "amin")
    hit = inf.clone().scatter_reduce(
        0, path, torch.where(bad, where, torch.full_like(where, torch.inf)), "amin"
    )
    first = torch.where(torch.isfinite(hit), hit.floor(), torch.full_like(hit, -1.0)).to(torch.int64)
    checked = torch.bincount(path, minlength=n_paths)
    return PathCheck(
        collision_free=(first < 0).reshape(batch),
        clearance=clearance.reshape(batch),
        self_collision=(self_clear <= 0.0).reshape(batch),
        self_clearance=self_clear.reshape(batch),
        first_collision=first.reshape(batch),
        checked=checked.reshape(batch),
    )
