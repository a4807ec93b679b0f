"""End-effector position inverse kinematics on a robot's model, by damped least squares with restarts."""

from __future__ import annotations

import torch

from ..checks import check_finite, check_last_dim
from ..errors import ConfigError
from .kinematics import dls_step, kinematics
from .robot import Robot

__all__ = ["position_ik"]


def position_ik(
    robot: Robot,
    start_joints: torch.Tensor,
    goal_positions: torch.Tensor,
    *,
    restarts: int = 8,
    tolerance: float = 1e-6,
    damping: float = 1e-2,
    seed: int = 0,
) -> torch.Tensor:
    """Joints ``(..., dof)`` that put ``robot``'s end effector on ``goal_positions (..., 3)``, by DLS IK.

    Damped least squares (:func:`~kinlearn.body.kinematics.dls_step`, clamped to the limits) from the start
    joints; goals not reached within ``tolerance`` metres are tried again by following the straight
    line from the start's end effector, then from up to ``restarts`` random configurations (drawn with
    ``seed``). Each goal keeps its best solution; one that ``robot`` cannot reach ends as close as the
    search came. ``robot`` is the model the IK trusts: pass the believed robot for a model-based
    planner.
    """
    check_last_dim(start_joints, robot.dof, "start joints")
    check_last_dim(goal_positions, 3, "goal positions")
    check_finite(start_joints, "start joints")
    check_finite(goal_positions, "goal positions")
    if isinstance(restarts, bool) or not isinstance(restarts, int) or restarts < 0:
        raise ConfigError(f"restarts must be an integer >= 0, got {restarts!r}")
    if not tolerance > 0.0 or not damping > 0.0:
        raise ConfigError(f"tolerance and damping must be > 0 (metres), got {tolerance!r} and {damping!r}")
    batch = start_joints.shape[:-1]
    q0 = start_joints.reshape(-1, robot.dof)
    p = goal_positions.to(q0.dtype).expand(*batch, 3).reshape(-1, 3)
    kin = kinematics(robot)

    def solve(q: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        for _ in range(10):  # converged goals stay put: DLS steps there are ~0
            q = dls_step(kin, q, target, iterations=10, damping=damping)
        return q

    def error(q: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        return torch.linalg.vector_norm(kin.position(q, validate=False) - target, dim=-1)

    best = solve(q0, p)
    err = error(best, p)
    todo = torch.nonzero(err > tolerance).flatten()
    if todo.numel():  # along the straight line, 20 steps
        q, e0 = q0[todo], kin.position(q0[todo], validate=False)
        for k in range(1, 21):
            q = dls_step(kin, q, e0 + (k / 20) * (p[todo] - e0), iterations=10, damping=damping)
        q = solve(q, p[todo])
        e = error(q, p[todo])
        better = e < err[todo]
        best[todo[better]], err[todo[better]] = q[better], e[better]
    gen = torch.Generator().manual_seed(seed)
    for _ in range(restarts):
        todo = torch.nonzero(err > tolerance).flatten()
        if not todo.numel():
            break
        q = solve(robot.sample(todo.numel(), gen, dtype=q0.dtype).to(q0.device), p[todo])
        e = error(q, p[todo])
        better = e < err[todo]
        best[todo[better]], err[todo[better]] = q[better], e[better]
    return best.reshape(*batch, robot.dof)
