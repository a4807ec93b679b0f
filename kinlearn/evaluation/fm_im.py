"""Which forward model and which inverse model: the FM × IM ablation, on end-effector position goals and
on the paper's task, every result judged by the analytic FK.

- **FM kinds** (any :class:`~kinlearn.models.interface.ForwardModel`, by name): the paper's or the
  improved MLP FM, the identified chain (:class:`~kinlearn.models.chain.ChainFM`), the chain with a
  residual MLP, the analytic FK.
- **IM kinds**: ``mlp``, the learned IM; ``analytic``, one damped-least-squares step on the true FK;
  ``through``, damped least squares on the FM's own Jacobian (:func:`~kinlearn.models.chain.solve_position`
  for a position goal, :class:`~kinlearn.models.chain.ThroughFMIM` as Algorithm 1's IM). ``mlp`` and
  ``analytic`` reach a position goal by stepping the end effector along the straight line through
  the FM (the planner's method without a chain). ``through`` needs an FM whose end effector is a
  function of the joints (chain, analytic); an MLP FM predicts steps, so its cell is empty.

:func:`fm_im_ablation` gives, per (FM, IM): the share of position goals whose goal joints put the
true end effector within 1 cm and their median error; and, with a waypoint TM, the paper task's
executed success (≤ 1 cm) and median goal error when Algorithm 1 rolls out through that FM and IM.
"""

from __future__ import annotations

from collections.abc import Mapping

import torch

from ..body.kinematics import kinematics
from ..body.robot import Robot
from ..data.endpoints import EndpointPairs
from ..models.chain import ThroughFMIM, solve_position
from ..models.forward_inverse import AnalyticIM, InverseModel
from ..models.interface import ForwardModel
from ..models.trajectory import TrajectoryModel
from ..planning.planner import Planner, step_to_position
from .metrics import plan_metrics

__all__ = ["IM_KINDS", "fm_im_ablation", "fm_im_table"]

#: The IM kinds, in table order: key → label.
IM_KINDS: dict[str, str] = {
    "mlp": "learned MLP IM, stepped through the FM",
    "analytic": "analytic DLS IM, stepped through the FM",
    "through": "DLS on the FM's own Jacobian",
}

#: A goal counts as reached within this distance (m).
SUCCESS_RADIUS = 0.01


def _summary(err: torch.Tensor) -> dict[str, float]:
    err = err.double()
    return {"success": float((err <= SUCCESS_RADIUS).double().mean()), "median": float(err.median())}


def _has_jacobian(fm: ForwardModel) -> bool:
    return hasattr(fm, "position_and_jacobian")


def _position_goals(robot, fm, im_kind, mlp_im, q0, goal) -> torch.Tensor:
    """Goal joints ``(N, dof)`` for end-effector goals through ``fm`` with the IM of ``im_kind``."""
    lo, hi = robot.limits(torch.float64)
    if im_kind == "through":
        theta, _ = solve_position(fm, q0, goal, lo, hi)
        return theta
    im = (mlp_im if im_kind == "mlp" else AnalyticIM(robot)).eval()
    ef0 = kinematics(robot).position(q0)
    theta = step_to_position(
        fm.eval(), im, q0.numpy(), ef0.numpy(), goal.numpy(), lo, hi, max_step=fm.max_step
    )
    return torch.from_numpy(theta)


def fm_im_ablation(
    robot: Robot,
    fms: Mapping[str, ForwardModel],
    mlp_im: InverseModel,
    position_pairs: EndpointPairs,
    *,
    task_pairs: EndpointPairs | None = None,
    waypoint_tm: TrajectoryModel | None = None,
) -> dict:
    """The ablation table's numbers (a JSON-able dict): ``{fm name: {im kind: {"position": …,
    "task": …}}}``, each ``{"success", "median"}`` (share, metres) or ``None`` where the pair does not
    apply. ``position_pairs``: their starts' joints and goals' end effectors are the position goals;
    ``task_pairs`` with ``waypoint_tm``: the paper's task, planned through each FM and IM."""
    dof = robot.dof
    q0 = position_pairs.start[:, :dof].double()
    goal = position_pairs.goal[:, dof:].double()
    fk = kinematics(robot)
    lo, hi = robot.limits(torch.float64)
    out: dict = {}
    with torch.no_grad():
        for name, fm in fms.items():
            row = {}
            for kind in IM_KINDS:
                if kind == "through" and not _has_jacobian(fm):
                    row[kind] = {"position": None, "task": None}
                    continue
                theta = _position_goals(robot, fm, kind, mlp_im, q0, goal)
                cell = {"position": _summary((fk.position(theta) - goal).norm(dim=-1)), "task": None}
                if waypoint_tm is not None and task_pairs is not None:
                    im = (
                        ThroughFMIM(fm, lo, hi, max_step=fm.max_step)
                        if kind == "through"
                        else (mlp_im if kind == "mlp" else AnalyticIM(robot))
                    )
                    plan = Planner(robot, waypoint_tm, fm, im).plan(task_pairs.start, task_pairs.goal)
                    m = plan_metrics(plan, robot)
                    cell["task"] = {
                        "success": float(m["success"].mean()),
                        "median": float(m["goal_error"].median()),
                    }
                row[kind] = cell
            out[name] = row
    return out


def fm_im_table(results: Mapping) -> str:
    """A markdown table of :func:`fm_im_ablation`: one row per FM, a column per IM kind; each cell
    "position goals ≤ 1 cm (median) · paper task ≤ 1 cm (median)"."""

    def cell(c) -> str:
        parts = []
        for key in ("position", "task"):
            v = c.get(key)
            if v is not None:
                parts.append(f"{v['success']:.1%} ({v['median'] * 1e3:.2f} mm)")
        return " · ".join(parts) if parts else "—"

    lines = [
        "| FM | " + " | ".join(IM_KINDS.values()) + " |",
        "|:--|" + "--:|" * len(IM_KINDS),
    ]
    for name, row in results.items():
        lines.append(f"| {name} | " + " | ".join(cell(row[k]) for k in IM_KINDS) + " |")
    return "\n".join(lines)
