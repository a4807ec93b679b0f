"""The result of planning, shared by the learned planner and the baselines."""

from __future__ import annotations

from dataclasses import dataclass

import torch

__all__ = ["Plan"]


@dataclass(frozen=True)
class Plan:
    """A batch of planned trajectories with T steps (T + 1 states, T − 1 intermediate waypoints).

    Attributes (leading batch dimensions ``...`` as in the planner's input):
        start, goal: ``(..., dof + 3)`` the given states s(0) and s(T).
        waypoints: ``(..., T - 1, 3)`` the planner's end-effector waypoints ŝ(1) … ŝ(T−1).
        actions: ``(..., T, dof)`` joint changes a(0) … a(T−1).
        joints: ``(..., T + 1, dof)`` the joint path θ(0) + cumulative actions (joints[..., 0, :] = θ(0)).
        ef: ``(..., T + 1, 3)`` the joint path's true end-effector positions by analytic FK.
    """

    start: torch.Tensor
    goal: torch.Tensor
    waypoints: torch.Tensor
    actions: torch.Tensor
    joints: torch.Tensor
    ef: torch.Tensor

    @property
    def steps(self) -> int:
        """T, the number of steps."""
        return self.actions.shape[-2]

    def __getitem__(self, idx) -> Plan:
        """Index the batch: ``plan[3]``, ``plan[:10]``."""
        return Plan(
            *(getattr(self, f)[idx] for f in ("start", "goal", "waypoints", "actions", "joints", "ef"))
        )
