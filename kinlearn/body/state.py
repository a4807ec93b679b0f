"""The state layout s = [θ, ef], named once."""

from __future__ import annotations

from dataclasses import dataclass

import torch

__all__ = ["StateLayout", "straight_line"]


@dataclass(frozen=True)
class StateLayout:
    """State s = [θ (dof joint values), ef (3, end-effector position in the base frame)].

    Use ``layout.joints`` / ``layout.ef`` (slices) or :meth:`split` / :meth:`join` instead of magic indices.
    """

    dof: int

    @property
    def size(self) -> int:
        return self.dof + 3

    @property
    def joints(self) -> slice:
        return slice(0, self.dof)

    @property
    def ef(self) -> slice:
        return slice(self.dof, self.dof + 3)

    def split(self, s: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(..., dof + 3)`` → ``(θ (..., dof), ef (..., 3))``."""
        return s[..., self.joints], s[..., self.ef]

    def join(self, theta: torch.Tensor, ef: torch.Tensor) -> torch.Tensor:
        """``θ (..., dof)``, ``ef (..., 3)`` → ``s (..., dof + 3)``."""
        return torch.cat((theta, ef), dim=-1)


def straight_line(start: torch.Tensor, goal: torch.Tensor, steps: int) -> torch.Tensor:
    """The straight line x(k) = x(0) + (k/T)(x(T) − x(0)), k = 0 … T = ``steps``, in any coordinates
    (joints, end-effector positions): ``start``, ``goal`` ``(..., n)`` → ``(..., T + 1, n)``, ending
    exactly at ``goal``."""
    f = torch.linspace(0.0, 1.0, steps + 1, dtype=start.dtype, device=start.device).unsqueeze(-1)
    line = start.unsqueeze(-2) + f * (goal - start).unsqueeze(-2)
    line[..., -1, :] = goal
    return line
