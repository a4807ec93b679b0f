"""Trajectory quality metrics of the paper (its Table 2 and Fig. 4) and what a planner's user needs.

The paper's metrics look at the polyline of T + 1 points

    P = [ef(s(0)), ŝ(1), …, ŝ(T−1), ef(s(T))]

made of the given endpoints and the planner's T − 1 end-effector waypoints. With d_k = ‖P_{k+1} − P_k‖
(k = 0 … T−1):

- ``init_distance`` = d_0 = ‖ŝ(1) − ef(s(0))‖, ``final_distance`` = d_{T−1} = ‖ŝ(T−1) − ef(s(T))‖;
- ``avg_spacing`` = mean_k d_k, ``max_spacing_deviation`` = max_k |d_k − avg_spacing|;
- the angle at each interior point P_k (k = 1 … T−1) between its two segments, in degrees, 180° for a
  straight continuation, 0° for a full reversal; ``mean_angle`` and ``min_angle`` per trajectory.
  A zero-length segment has no direction: the angle at either of its ends is defined as 180°
  (see :func:`interior_angles`), so repeated points never give NaN.

:func:`plan_metrics` adds what executing a :class:`~kinlearn.planning.plan.Plan` gives: the error between
the true end-effector position at the end of the joint path and the goal, success within a radius,
path lengths, joint-limit violations and sharp turns. :func:`summarize` turns per-trajectory values
into mean ± std (over trajectories, population std) and rates; :func:`format_table` prints rows of
summaries as a markdown table, with the paper's numbers (:data:`PAPER_TABLE2`) as one more row.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import torch

from ..body.kinematics import kinematics
from ..body.robot import Robot
from ..body.state import StateLayout
from ..checks import check_finite, check_last_dim
from ..errors import ConfigError, ShapeError
from ..models.joint_path import densify
from ..planning.plan import Plan
from ..polyline import ZERO_LENGTH, interior_angles, polyline_metrics, trajectory_metrics, trajectory_points

__all__ = [
    "INDICATORS",
    "METRICS",
    "PAPER_MIN_ANGLE",
    "PAPER_TABLE2",
    "SHARP_ANGLE",
    "TABLE2_COLUMNS",
    "ZERO_LENGTH",
    "MetricInfo",
    "dense_path_length",
    "format_table",
    "interior_angles",
    "plan_metrics",
    "summarize",
    "trajectory_metrics",
    "trajectory_points",
]

#: A turn sharper than this (minimum interior angle below it, degrees) counts as a sharp turn.
SHARP_ANGLE = 90.0
#: The paper's mean of the per-trajectory minimum angle (degrees); 54% of its trajectories fall below it.
PAPER_MIN_ANGLE = 69.9


@dataclass(frozen=True)
class MetricInfo:
    """How a metric is shown: a label with its unit and the number of decimals."""

    label: str
    decimals: int
    indicator: bool = False  # a 0/1 value per trajectory, summarised as a rate (percent)


METRICS: dict[str, MetricInfo] = {
    "init_distance": MetricInfo("init. dist. (m)", 3),
    "final_distance": MetricInfo("final dist. (m)", 3),
    "avg_spacing": MetricInfo("avg. spacing (m)", 3),
    "max_spacing_deviation": MetricInfo("max. sp. dev. (m)", 3),
    "mean_angle": MetricInfo("avg. angle (°)", 1),
    "min_angle": MetricInfo("min. angle (°)", 1),
    "waypoint_path_length": MetricInfo("waypoint path (m)", 3),
    "endpoint_distance": MetricInfo("start–goal dist. (m)", 3),
    "goal_error": MetricInfo("goal error (m)", 4),
    "start_error": MetricInfo("start error (m)", 4),
    "tracking_error": MetricInfo("tracking error (m)", 4),
    "path_length": MetricInfo("executed path (m)", 3),
    "executed_avg_spacing": MetricInfo("exec. avg. spacing (m)", 3),
    "executed_max_spacing_deviation": MetricInfo("exec. max. sp. dev. (m)", 3),
    "executed_mean_angle": MetricInfo("exec. avg. angle (°)", 1),
    "executed_min_angle": MetricInfo("exec. min. angle (°)", 1),
    "success": MetricInfo("success ≤ 1 cm", 1, indicator=True),
    "joint_goal_error": MetricInfo("joint goal error (rad)", 4),
    "state_success": MetricInfo("goal state reached", 1, indicator=True),
    "executed_sharp_turn": MetricInfo("exec. turn < 90°", 1, indicator=True),
    "dense_path_length": MetricInfo("executed path, dense (m)", 3),
    "path_ratio": MetricInfo("path / joint lerp", 3),
    "limit_violation": MetricInfo("limit violations", 1, indicator=True),
    "sharp_turn": MetricInfo("min. angle < 90°", 1, indicator=True),
    "sharp_turn_paper": MetricInfo("min. angle < 69.9°", 1, indicator=True),
}

#: Per-trajectory values that are 0 or 1; their mean is a rate.
INDICATORS: frozenset[str] = frozenset(k for k, v in METRICS.items() if v.indicator)

#: The columns of the paper's Table 2 plus its minimum-angle figures.
TABLE2_COLUMNS: tuple[str, ...] = (
    "init_distance",
    "final_distance",
    "avg_spacing",
    "max_spacing_deviation",
    "mean_angle",
    "min_angle",
    "sharp_turn_paper",
)


def _row(init, final, spacing, dev, angle) -> dict[str, dict[str, float]]:
    values = zip(TABLE2_COLUMNS[:5], (init, final, spacing, dev, angle), strict=True)
    return {k: {"mean": m, "std": s} for k, (m, s) in values}


#: The paper's Table 2 (12,000 trajectories, the six optimiser configurations of its Table 1), in the
#: shape :func:`summarize` returns so that a row can be passed to :func:`format_table` as is. Row 4
#: (RMSprop, lr 1e-3) is the paper's best; only for it does the text give the minimum angle
#: (69.9 ± 1.3°) and the share of trajectories below that mean (6,477 of 12,000).
PAPER_TABLE2: dict[int, dict[str, dict[str, float]]] = {
    1: _row((0.429, 0.064), (0.247, 0.066), (0.078, 0.014), (0.352, 0.054), (153.4, 7.4)),
    2: _row((0.632, 0.129), (0.296, 0.083), (0.110, 0.027), (0.522, 0.104), (150.3, 4.3)),
    3: _row((0.265, 0.039), (0.202, 0.081), (0.064, 0.013), (0.214, 0.037), (142.3, 8.3)),
    4: {
        **_row((0.134, 0.108), (0.139, 0.051), (0.061, 0.014), (0.127, 0.083), (153.0, 8.8)),
        "min_angle": {"mean": 69.9, "std": 1.3},
        "sharp_turn_paper": {"mean": 6477 / 12000, "rate": 6477 / 12000},
    },
    5: _row((0.183, 0.071), (0.239, 0.084), (0.063, 0.012), (0.194, 0.075), (157.5, 9.3)),
    6: _row((0.311, 0.052), (0.197, 0.062), (0.069, 0.012), (0.244, 0.051), (156.2, 8.3)),
}


def plan_metrics(
    plan: Plan,
    robot: Robot,
    success_radius: float = 0.01,
    limit_tol: float = 1e-6,
    joint_tolerance: float = 0.05,
) -> dict[str, torch.Tensor]:
    """Every per-trajectory metric of a batch of plans: the paper's and those of executing the plan.

    The paper's metrics (:func:`trajectory_metrics`) are computed on ``plan.waypoints`` between the
    end-effector positions of ``plan.start`` and ``plan.goal``. Executing the plan means following
    its joint path ``plan.joints``, whose true end-effector positions are ``plan.ef``; from them:

    - ``goal_error`` = ‖plan.ef[..., T, :] − ef(s(T))‖ (m), ``success`` = goal_error ≤ ``success_radius``;
    - ``start_error`` = ‖plan.ef[..., 0, :] − ef(s(0))‖ (m; ≈ 0 unless the start state is inconsistent);
    - ``tracking_error`` = mean over k = 1 … T−1 of ‖plan.ef[..., k, :] − ŝ(k)‖ (m): how closely the
      executed path passes through the waypoints;
    - ``path_length`` = Σ_k ‖plan.ef[..., k+1, :] − plan.ef[..., k, :]‖ (m);
    - ``executed_avg_spacing``, ``executed_max_spacing_deviation``, ``executed_mean_angle``,
      ``executed_min_angle``: the paper's spacing and angle metrics of the executed path itself;
    - ``joint_goal_error`` = max over joints of |plan.joints[..., T, :] − θ(s(T))| (rad); ``state_success``:
      1 where the goal *state* is reached, goal_error ≤ ``success_radius`` and joint_goal_error ≤
      ``joint_tolerance``;
    - ``executed_sharp_turn``: 1 where the executed path (``plan.ef``) turns sharper than 90° anywhere;
    - ``limit_violation``: 1 where any joint value of the path leaves ``robot``'s position limits by more
      than ``limit_tol`` rad, else 0;
    - ``sharp_turn``: 1 where ``min_angle`` < 90°; ``sharp_turn_paper``: 1 where ``min_angle`` < 69.9°.

    Returns a dict of ``(...)`` tensors (indicators as 0.0/1.0, see :data:`INDICATORS`).
    """
    if not isinstance(plan, Plan):
        raise ShapeError(f"plan must be a kinlearn.Plan, got {type(plan).__name__}")
    layout = StateLayout(robot.dof)
    check_last_dim(plan.start, layout.size, "plan.start")
    check_last_dim(plan.goal, layout.size, "plan.goal")
    check_last_dim(plan.joints, robot.dof, "plan.joints")
    check_last_dim(plan.ef, 3, "plan.ef")
    steps = plan.joints.shape[-2] - 1
    batch = plan.start.shape[:-1]
    expected = {
        "plan.goal": (plan.goal.shape, (*batch, layout.size)),
        "plan.waypoints": (plan.waypoints.shape, (*batch, steps - 1, 3)),
        "plan.joints": (plan.joints.shape, (*batch, steps + 1, robot.dof)),
        "plan.ef": (plan.ef.shape, (*batch, steps + 1, 3)),
    }
    for what, (got, want) in expected.items():
        if tuple(got) != tuple(want):
            raise ShapeError(f"{what} must have shape {want} for a plan of {steps} steps, got {tuple(got)}")
    check_finite(plan.joints, "plan.joints")
    check_finite(plan.ef, "plan.ef")

    _, ef_start = layout.split(plan.start)
    ef_goal = plan.target  # the goal state's end effector, or the position asked for
    out = trajectory_metrics(ef_start, plan.waypoints, ef_goal)
    dtype = out["init_distance"].dtype

    ef = plan.ef.double()
    executed = polyline_metrics(ef, prefix="executed_")
    goal_error = torch.linalg.vector_norm(ef[..., -1, :] - ef_goal.double(), dim=-1)
    joint_goal_error = (plan.joints[..., -1, :] - plan.goal[..., : robot.dof]).double().abs().amax(-1)
    within = robot.within_limits(plan.joints, limit_tol).all(-1)
    extra = {
        "goal_error": goal_error,
        "success": (goal_error <= success_radius).double(),
        "joint_goal_error": joint_goal_error,
        "state_success": ((goal_error <= success_radius) & (joint_goal_error <= joint_tolerance)).double(),
        "executed_sharp_turn": (executed["executed_min_angle"] < SHARP_ANGLE).double(),
        "start_error": torch.linalg.vector_norm(ef[..., 0, :] - ef_start.double(), dim=-1),
        "tracking_error": torch.linalg.vector_norm(ef[..., 1:-1, :] - plan.waypoints.double(), dim=-1).mean(
            -1
        ),
        "path_length": executed.pop("executed_path_length"),
        "executed_avg_spacing": executed["executed_avg_spacing"],
        "executed_max_spacing_deviation": executed["executed_max_spacing_deviation"],
        "executed_mean_angle": executed["executed_mean_angle"],
        "executed_min_angle": executed["executed_min_angle"],
        "limit_violation": (~within).double(),
        "sharp_turn": (out["min_angle"] < SHARP_ANGLE).double(),
        "sharp_turn_paper": (out["min_angle"] < PAPER_MIN_ANGLE).double(),
    }
    out.update({k: v.to(dtype) for k, v in extra.items()})
    return out


# --------------------------------------------------------------------------------------------------
# Summaries and tables
# --------------------------------------------------------------------------------------------------


def dense_path_length(robot: Robot, joints: torch.Tensor, max_step: float = 0.01) -> torch.Tensor:
    """Length (m) of the end-effector path that executing ``joints (..., T+1, dof)`` draws: the joint path
    is followed linearly between consecutive configurations, sampled so that no joint moves more than
    ``max_step`` rad between samples, and the samples' exact FK positions are joined. ``(...)``, float64.
    """
    check_last_dim(joints, robot.dof, "joints")
    dense, _ = densify(joints.double().reshape(-1, *joints.shape[-2:]), max_step)
    kin = kinematics(robot)
    lengths = []
    for chunk in dense.split(max(1, 2_000_000 // dense.shape[1])):
        ef = kin.position(chunk, validate=False)
        lengths.append((ef[:, 1:] - ef[:, :-1]).norm(dim=-1).sum(-1))
    return torch.cat(lengths).reshape(joints.shape[:-2])


def summarize(per_traj: Mapping[str, torch.Tensor]) -> dict[str, dict[str, float]]:
    """Mean, std (population, over trajectories), median, p95, min and max of each per-trajectory metric.

    Every value is a plain ``float`` (JSON-able). For an indicator (:data:`INDICATORS`) the mean is a
    rate, also given as ``"rate"``; the number of trajectories is ``"n"``.
    """
    out: dict[str, dict[str, float]] = {}
    for key, value in per_traj.items():
        if not isinstance(value, torch.Tensor) or value.numel() == 0:
            raise ShapeError(f"metric {key!r} must be a non-empty tensor of per-trajectory values")
        x = value.detach().reshape(-1).double().cpu()
        check_finite(x, f"metric {key!r}")
        s = {
            "mean": float(x.mean()),
            "std": float(x.std(correction=0)),
            "median": float(x.median()),
            "p95": float(torch.quantile(x, 0.95)),
            "min": float(x.min()),
            "max": float(x.max()),
            "n": float(x.numel()),
        }
        if key in INDICATORS:
            s["rate"] = s["mean"]
        out[key] = s
    return out


def _cell(key: str, summary: Mapping[str, float] | None) -> str:
    if not summary or "mean" not in summary or not math.isfinite(summary["mean"]):
        return "—"
    info = METRICS.get(key)
    if info is not None and info.indicator:
        return f"{100 * summary.get('rate', summary['mean']):.{info.decimals}f}%"
    if info is None:
        text = f"{summary['mean']:.4g}"
        return f"{text} ± {summary['std']:.4g}" if "std" in summary else text
    text = f"{summary['mean']:.{info.decimals}f}"
    return f"{text} ± {summary['std']:.{info.decimals}f}" if "std" in summary else text


def format_table(
    rows: Mapping[str, Mapping[str, Mapping[str, float]]], columns: Sequence[str] = TABLE2_COLUMNS
) -> str:
    """A markdown table: one row per ``name → summary`` (as :func:`summarize` returns), one column per metric.

    Values show as ``mean ± std`` with the metric's decimals, indicators as percentages, and a metric a
    row lacks as ``—``. Put the paper beside ours with ``{"paper (Table 2, #4)": PAPER_TABLE2[4], ...}``.
    """
    columns = list(columns)
    if not columns:
        raise ConfigError("format_table needs at least one column")
    known = set(METRICS) | {k for summary in rows.values() for k in summary}
    unknown = [c for c in columns if c not in known]
    if unknown:
        raise ConfigError(f"unknown metric column(s) {unknown}; choose from {sorted(known)}")
    header = ["", *(METRICS[c].label if c in METRICS else c for c in columns)]
    lines = [
        "| " + " | ".join(header) + " |",
        "|" + "|".join([":--", *["--:"] * len(columns)]) + "|",
    ]
    for name, summary in rows.items():
        lines.append("| " + " | ".join([str(name), *(_cell(c, summary.get(c)) for c in columns)]) + " |")
    return "\n".join(lines) + "\n"
