"""Judging planners on the workspace task: held-out start/goal configurations across the joint range.

Every planner gets the same held-out pairs (the ``workspace`` endpoint preset, by default uniform
within ±90% of each joint's range about its middle) and is judged by the analytic FK of its own
joint path: goal state reached (end effector ≤ 1 cm **and** every joint ≤ 0.05 rad), end-effector
goal error, joint-limit violations, sharp turns of the executed path, and the length of the end
effector's executed path (sampled densely) against joint interpolation's on the same pair.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Literal

import torch

from ..body.robot import Robot
from ..body.state import straight_line
from ..data.endpoints import EndpointConfig, EndpointPairs, make_endpoints
from ..data.problem import GOAL_KINDS, Problem
from ..errors import ConfigError
from ..planning.plan import PlannerLike
from .metrics import dense_path_length, plan_metrics

__all__ = ["POSITION_COLUMNS", "WORKSPACE_COLUMNS", "evaluate_workspace", "heldout_pairs", "workspace_table"]

#: Seed of the held-out workspace pairs (training draws its problems from other seeds).
HELDOUT_SEED = 12345


def heldout_pairs(
    robot: Robot, n: int = 2000, range_fraction: float = 0.9, seed: int = HELDOUT_SEED
) -> EndpointPairs:
    """``n`` held-out workspace pairs for ``robot``."""
    cfg = EndpointConfig(robot=robot.name, n=n, seed=seed, preset="workspace", range_fraction=range_fraction)
    return make_endpoints(cfg)


def evaluate_workspace(
    robot: Robot,
    pairs: EndpointPairs,
    planners: Mapping[str, PlannerLike],
    *,
    goal_kind: Literal["state", "position"] = "state",
    batch_size: int = 1000,
) -> dict[str, dict[str, float]]:
    """Run each planner on ``pairs`` (in batches) and summarise what executing its plans gives.

    ``planners``: name → a planner of the planner protocol (``plan(problem) -> Plan``: the learned
    :class:`~kinlearn.planning.planner.Planner`, :class:`~kinlearn.planning.baselines.JointInterpolation`,
    …). ``goal_kind``: the pairs' goal states (``"state"``) or only their end-effector positions
    (``"position"``) are the goals. Returns, per planner:
    ``state_success`` (share), ``ef_success`` (share within 1 cm), ``goal_error_median``/``_p95`` (m),
    ``joint_goal_error_median`` (rad), ``limit_violation`` and ``sharp_turn`` (shares; turns of the
    executed path sharper than 90°), ``path_ratio_median`` (the dense executed end-effector path over
    joint interpolation's, per pair, median), ``path_median`` (m) and ``seconds`` (wall time).
    """
    if goal_kind not in GOAL_KINDS:
        raise ConfigError(f"goal_kind must be one of {GOAL_KINDS}, got {goal_kind!r}")
    for name, planner in planners.items():
        if not isinstance(planner, PlannerLike):
            raise ConfigError(f"planner {name!r} has no plan(problem) method (the planner protocol)")
    start, goal = pairs.start.double(), pairs.goal.double()
    problems = Problem.from_pairs(pairs)
    if goal_kind == "position":
        problems = problems.position_goals()
    lerp_len = dense_path_length(robot, straight_line(start[:, : robot.dof], goal[:, : robot.dof], 11))
    out: dict[str, dict[str, float]] = {}
    for name, planner in planners.items():
        per: dict[str, list[torch.Tensor]] = {}
        t0 = time.perf_counter()
        plans = [planner.plan(problems[i : i + batch_size]) for i in range(0, len(pairs), batch_size)]
        seconds = time.perf_counter() - t0
        for p in plans:
            m = plan_metrics(p, robot)
            m["dense_path_length"] = dense_path_length(robot, p.joints)
            for k, v in m.items():
                per.setdefault(k, []).append(v.double())
        m = {k: torch.cat(v) for k, v in per.items()}
        ratio = m["dense_path_length"] / lerp_len.clamp_min(1e-9)
        out[name] = {
            "state_success": float(m["state_success"].mean()),
            "ef_success": float(m["success"].mean()),
            "goal_error_median": float(m["goal_error"].median()),
            "goal_error_p95": float(m["goal_error"].quantile(0.95)),
            "joint_goal_error_median": float(m["joint_goal_error"].median()),
            "limit_violation": float(m["limit_violation"].mean()),
            "sharp_turn": float(m["executed_sharp_turn"].mean()),
            "path_ratio_median": float(ratio.median()),
            "path_median": float(m["dense_path_length"].median()),
            "seconds": seconds,
        }
    return out


#: Columns of :func:`workspace_table`: key, header, scale, decimals.
WORKSPACE_COLUMNS = (
    ("state_success", "goal state reached", 100, 1),
    ("ef_success", "ef ≤ 1 cm", 100, 1),
    ("goal_error_median", "ef error median (mm)", 1000, 2),
    ("goal_error_p95", "ef error p95 (mm)", 1000, 1),
    ("joint_goal_error_median", "joint error median (rad)", 1, 3),
    ("limit_violation", "limit violations", 100, 1),
    ("sharp_turn", "turn < 90°", 100, 1),
    ("path_ratio_median", "ef path / joint lerp (median)", 1, 3),
)


#: The columns that mean something for end-effector position goals (no goal joints to reach).
POSITION_COLUMNS = tuple(
    c for c in WORKSPACE_COLUMNS if c[0] not in ("state_success", "joint_goal_error_median")
)


def workspace_table(results: Mapping[str, Mapping[str, float]], columns=WORKSPACE_COLUMNS) -> str:
    """A markdown table of :func:`evaluate_workspace` results (rates in percent)."""
    head = "| planner | " + " | ".join(h for _, h, _, _ in columns) + " |"
    rule = "|:--|" + "--:|" * len(columns)
    rows = [head, rule]
    for name, r in results.items():
        cells = []
        for key, _, scale, dec in columns:
            v = r.get(key, float("nan"))
            cells.append("—" if v != v else f"{v * scale:.{dec}f}" + ("%" if scale == 100 else ""))
        rows.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(rows)
