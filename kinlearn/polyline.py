"""Polylines: the paper's trajectory metrics (its Table 2) of a polyline of end-effector points, and
the resampling of any polyline by arc length.

Pure geometry of points, shared by training (held-out metrics after each epoch) and evaluation
(:mod:`kinlearn.evaluation.metrics`, which adds what executing a plan gives). The polyline of T + 1
points is P = [ef(s(0)), ŝ(1), …, ŝ(T−1), ef(s(T))]; see :func:`trajectory_metrics` for the metrics.
:func:`resample` turns a joint path of any number of vertices into a fixed number of points (a
sampler's path as a network's knots).
"""

from __future__ import annotations

import numpy as np
import torch

from .checks import check_finite, check_last_dim
from .errors import ShapeError

__all__ = [
    "ZERO_LENGTH",
    "interior_angles",
    "polyline_metrics",
    "resample",
    "trajectory_metrics",
    "trajectory_points",
]

#: Segments shorter than this (metres) count as zero-length when measuring angles.
ZERO_LENGTH = 1e-9


def trajectory_points(ef_start: torch.Tensor, waypoints: torch.Tensor, ef_goal: torch.Tensor) -> torch.Tensor:
    """The polyline P = [ef(s(0)), ŝ(1) … ŝ(T−1), ef(s(T))]: ``(..., 3)``, ``(..., T−1, 3)``, ``(..., 3)`` →
    ``(..., T+1, 3)``. Checks shapes and finiteness."""
    check_last_dim(ef_start, 3, "ef_start")
    check_last_dim(ef_goal, 3, "ef_goal")
    check_last_dim(waypoints, 3, "waypoints")
    if waypoints.ndim < 2 or waypoints.shape[-2] < 1:
        raise ShapeError(
            f"waypoints must have shape (..., T-1, 3) with T-1 >= 1, got {tuple(waypoints.shape)}"
        )
    batch = ef_start.shape[:-1]
    if ef_goal.shape[:-1] != batch or waypoints.shape[:-2] != batch:
        raise ShapeError(
            "ef_start (..., 3), waypoints (..., T-1, 3) and ef_goal (..., 3) must share their batch shape; "
            f"got {tuple(ef_start.shape)}, {tuple(waypoints.shape)}, {tuple(ef_goal.shape)}"
        )
    for x, what in ((ef_start, "ef_start"), (waypoints, "waypoints"), (ef_goal, "ef_goal")):
        check_finite(x, what)
    return torch.cat((ef_start.unsqueeze(-2), waypoints, ef_goal.unsqueeze(-2)), dim=-2)


def _segments(points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    seg = points[..., 1:, :] - points[..., :-1, :]
    return seg, torch.linalg.vector_norm(seg, dim=-1)


def _angles(seg: torch.Tensor, length: torch.Tensor) -> torch.Tensor:
    u = -seg[..., :-1, :]  # from each interior point back to its predecessor
    v = seg[..., 1:, :]  # from each interior point on to its successor
    cross = torch.linalg.vector_norm(torch.linalg.cross(u, v, dim=-1), dim=-1)
    dot = (u * v).sum(-1)
    angle = torch.rad2deg(torch.atan2(cross, dot))  # in [0, 180], accurate near 0 and 180 too
    degenerate = (length[..., :-1] <= ZERO_LENGTH) | (length[..., 1:] <= ZERO_LENGTH)
    return torch.where(degenerate, torch.full_like(angle, 180.0), angle)


def interior_angles(points: torch.Tensor) -> torch.Tensor:
    """Angle (degrees) at each interior point of polylines ``(..., K, 3)`` → ``(..., K−2)``.

    The angle at P_k is the one between P_{k−1} − P_k and P_{k+1} − P_k: 180° where the path goes
    straight on, 90° at a right-angle corner, 0° where it turns back on itself. Where either segment is
    shorter than :data:`ZERO_LENGTH` (a repeated point) the angle is defined as 180°: a pause is not a
    turn. A turn made *at* a repeated point is therefore invisible to the angles; it shows in the
    spacing metrics instead (a zero spacing among non-zero ones).
    """
    check_last_dim(points, 3, "points")
    if points.ndim < 2 or points.shape[-2] < 3:
        raise ShapeError(f"points must have shape (..., K, 3) with K >= 3, got {tuple(points.shape)}")
    return _angles(*_segments(points))


def polyline_metrics(points: torch.Tensor, prefix: str = "") -> dict[str, torch.Tensor]:
    """Spacing, angle and length metrics of polylines ``(..., K, 3)``, keys prefixed by ``prefix``."""
    seg, d = _segments(points)
    angles = _angles(seg, d)
    avg = d.mean(-1)
    return {
        f"{prefix}init_distance": d[..., 0],
        f"{prefix}final_distance": d[..., -1],
        f"{prefix}avg_spacing": avg,
        f"{prefix}max_spacing_deviation": (d - avg.unsqueeze(-1)).abs().amax(-1),
        f"{prefix}mean_angle": angles.mean(-1),
        f"{prefix}min_angle": angles.amin(-1),
        f"{prefix}path_length": d.sum(-1),
    }


def trajectory_metrics(
    ef_start: torch.Tensor, waypoints: torch.Tensor, ef_goal: torch.Tensor
) -> dict[str, torch.Tensor]:
    """The paper's per-trajectory metrics (the paper's Table 2 and its caption) of waypoints between two endpoints.

    Args:
        ef_start: ``(..., 3)`` end-effector position of the start state s(0).
        waypoints: ``(..., T−1, 3)`` the planned waypoints ŝ(1) … ŝ(T−1).
        ef_goal: ``(..., 3)`` end-effector position of the goal state s(T).

    Returns a dict of ``(...)`` tensors: ``init_distance``, ``final_distance``, ``avg_spacing``,
    ``max_spacing_deviation`` (metres), ``mean_angle``, ``min_angle`` (degrees), ``waypoint_path_length``
    (Σ d_k, metres) and ``endpoint_distance`` (‖ef(s(T)) − ef(s(0))‖; a straight, evenly spaced path has
    every d_k equal to it divided by T). Computed in float64, returned in the input's dtype.
    """
    points = trajectory_points(ef_start, waypoints, ef_goal)
    out = polyline_metrics(points.double())
    out["waypoint_path_length"] = out.pop("path_length")
    out["endpoint_distance"] = torch.linalg.vector_norm(ef_goal.double() - ef_start.double(), dim=-1)
    return {k: v.to(ef_start.dtype) for k, v in out.items()}


def resample(vertices: np.ndarray, count: int) -> np.ndarray:
    """``count`` points equally spaced by arc length along the polyline ``vertices (M, n)`` (its first
    and last vertex among them); a polyline of zero length gives its first vertex ``count`` times."""
    vertices = np.asarray(vertices, dtype=np.float64)
    seg = np.linalg.norm(np.diff(vertices, axis=0), axis=1)
    cum = np.concatenate(([0.0], np.cumsum(seg)))
    if cum[-1] <= 0.0:
        return np.repeat(vertices[:1], count, axis=0)
    u = np.linspace(0.0, cum[-1], count)
    return np.stack([np.interp(u, cum, vertices[:, j]) for j in range(vertices.shape[1])], axis=1)
