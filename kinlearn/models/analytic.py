"""The analytic forward and inverse models (the ablation's): :class:`AnalyticFM` (θ' = θ + a, ef' = FK(θ'))
and :class:`AnalyticIM` (damped-least-squares steps toward the target, kept within the joint limits)."""

from __future__ import annotations

import torch

from ..body.kinematics import dls_step, kinematics
from ..body.robot import Robot
from ..errors import ConfigError
from .interface import ForwardModel, InverseModel, resolve_robot

__all__ = ["AnalyticFM", "AnalyticIM"]


class AnalyticFM(ForwardModel):
    """θ' = θ + a, ef' = FK(θ') by the fast kinematics path: exactly the robot's forward kinematics.

    No limits are applied: an action leaving the limits gives a state outside them.
    """

    def __init__(self, robot: Robot | str = "iiwa14"):
        robot = resolve_robot(robot)
        super().__init__(robot.name, robot.dof)
        self.robot = robot
        self.kin = kinematics(robot, "fast")

    def config_dict(self) -> dict:
        return {"type": "analytic", "robot": self.robot_name}

    def _forward(self, s: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        theta = s[..., self.layout.joints] + a
        return self.layout.join(theta, self.kin.position(theta, validate=False))

    def ef_along(self, theta: torch.Tensor, ef0: torch.Tensor, every: int = 1) -> torch.Tensor:
        """See :meth:`ForwardModel.ef_along`: the exact FK of the configurations (``ef0`` is FK(θ(0)))."""
        return self.kin.position(theta[:, ::every], validate=False)

    def position(self, theta: torch.Tensor) -> torch.Tensor:
        """The end effector ``(..., 3)`` of joint values ``theta (..., dof)`` (the FK)."""
        return self.kin.position(theta, validate=False)

    def position_and_jacobian(self, theta: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The FK and its Jacobian ``(..., 3, dof)``: what solving through an FM needs (as for a chain)."""
        return self.kin.position_and_jacobian(theta, validate=False)


class AnalyticIM(InverseModel):
    """``iterations`` damped-least-squares steps from θ toward ``ef_target``; returns a = θ_new − θ.

    θ_new is kept within the joint limits (:func:`kinlearn.body.kinematics.dls_step`); ``damping`` is λ
    in metres. Differentiable in ``s`` and ``ef_target``.
    """

    def __init__(self, robot: Robot | str = "iiwa14", iterations: int = 1, damping: float = 1e-2):
        robot = resolve_robot(robot)
        if int(iterations) < 1:
            raise ConfigError(f"iterations must be ≥ 1, got {iterations}")
        if not damping >= 0.0:
            raise ConfigError(f"damping must be ≥ 0 (metres), got {damping}")
        super().__init__(robot.name, robot.dof)
        self.robot = robot
        self.kin = kinematics(robot, "fast")
        self.iterations = int(iterations)
        self.damping = float(damping)

    def config_dict(self) -> dict:
        return {
            "type": "analytic",
            "robot": self.robot_name,
            "iterations": self.iterations,
            "damping": self.damping,
        }

    def _forward(self, s: torch.Tensor, ef_target: torch.Tensor) -> torch.Tensor:
        theta = s[..., self.layout.joints]
        new = dls_step(self.kin, theta, ef_target, iterations=self.iterations, damping=self.damping)
        return new - theta
