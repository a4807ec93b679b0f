"""Rectification (paper Algorithm 1) and the trajectory model's loss (paper Eq. 4 and variants).

Both are batched over samples and loop over time only: one IM call and one FM call per time step
for the whole batch (the authors' code made 22 separate model calls per trajectory: the authors' code, github.com/Mcibula/traj-planning-icann2025).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Literal

import torch

from ..body.state import StateLayout
from ..errors import ConfigError

__all__ = ["LOSS_PRESETS", "LossConfig", "rectify", "tm_loss"]


def rectify(
    waypoints: torch.Tensor,
    s0: torch.Tensor,
    sT: torch.Tensor,
    fm: torch.nn.Module,
    im: torch.nn.Module,
    layout: StateLayout,
    *,
    refine: int = 0,
    exact_joints: bool = False,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Algorithm 1: roll the frozen IM and FM through the TM's waypoints from the true start.

    ``waypoints``: ``(N, T - 1, 3)`` the TM's ŝ(1) … ŝ(T−1) (end-effector positions);
    ``s0``, ``sT``: ``(N, S)``. For t = 1 … T: â(t−1) = IM[s̃(t−1), ef target(t)],
    s̃(t) = FM[s̃(t−1), â(t−1)], with s̃(0) = s(0) and the last target the goal's end effector.

    Two options go beyond the paper (both off by default, which is Algorithm 1 as published):

    - ``refine``: after the IM proposes â, correct it that many times with the models alone:
      â ← â + IM[FM[s̃, â], target], the IM's action from where the FM says â leads. Like a Newton
      step with the IM as the approximate inverse.
    - ``exact_joints``: keep the joints of s̃(t) at θ(0) + Σ â (an action *is* a joint change), and
      take only the end effector from the FM, instead of the FM's learned joint prediction.

    Returns ``(states, actions)``: s̃(1) … s̃(T) as ``(N, T, S)`` and â(0) … â(T−1) as ``(N, T, dof)``.
    """
    targets = torch.cat((waypoints, sT[:, None, layout.ef]), dim=1)
    s = s0
    states, actions = [], []
    for t in range(targets.shape[1]):
        target = targets[:, t]
        a = im(s, target)
        for _ in range(refine):
            a = a + im(fm(s, a), target)
        nxt = fm(s, a)
        s = layout.join(s[:, layout.joints] + a, nxt[:, layout.ef]) if exact_joints else nxt
        actions.append(a)
        states.append(s)
    return torch.stack(states, dim=1), torch.stack(actions, dim=1)


@dataclass(frozen=True)
class LossConfig:
    """Weights of the trajectory model's loss terms.

    - ``rectification``: mean over t of L[ŝ(t), s̃(t)], the paper's first term (L = MSE over the
      end-effector coordinates, the TM's one output head).
    - ``start`` / ``goal``: L[ŝ(1), target] and L[ŝ(T−1), target]. With ``endpoint_target="on"`` the
      targets are s(0) and s(T) themselves (paper Eq. 4); with ``"one_spacing"`` they are one
      uniform spacing from them along the start–goal segment, where the metrics want the
      extreme waypoints (measured: docs/results.md).
    - ``smoothness``: mean squared second difference of the points [ef(s(0)), ŝ(1) … ŝ(T−1), ef(s(T))],
      times T²: zero exactly for evenly spaced points on a straight line.
    - ``gradient``: ``"stop"`` computes the rectified states without gradient (detached targets, as
      the authors did); ``"through"`` back-propagates through the frozen FM and IM.
    """

    rectification: float = 1.0
    start: float = 0.0
    goal: float = 0.0
    endpoint_target: Literal["on", "one_spacing"] = "on"
    smoothness: float = 1.0
    gradient: Literal["stop", "through"] = "stop"

    def __post_init__(self) -> None:
        if self.endpoint_target not in ("on", "one_spacing"):
            raise ConfigError(f"endpoint_target must be 'on' or 'one_spacing', got {self.endpoint_target!r}")
        if self.gradient not in ("stop", "through"):
            raise ConfigError(f"gradient must be 'stop' or 'through', got {self.gradient!r}")
        for name in ("rectification", "start", "goal", "smoothness"):
            if getattr(self, name) < 0:
                raise ConfigError(f"loss weight {name} must be ≥ 0, got {getattr(self, name)}")

    @classmethod
    def preset(cls, name: str) -> LossConfig:
        if name not in LOSS_PRESETS:
            raise ConfigError(f"unknown loss preset {name!r}; choose one of {', '.join(LOSS_PRESETS)}")
        return cls(**LOSS_PRESETS[name])

    def to_dict(self) -> dict:
        return asdict(self)


LOSS_PRESETS: dict[str, dict] = {
    # Paper Eq. 4: rectification term + ŝ(1) on s(0) + ŝ(T−1) on s(T).
    "paper": dict(rectification=1.0, start=1.0, goal=1.0, endpoint_target="on", smoothness=0.0),
    # The authors' released script: the endpoint terms only (the authors' code, github.com/Mcibula/traj-planning-icann2025).
    "released": dict(rectification=0.0, start=1.0, goal=1.0, endpoint_target="on", smoothness=0.0),
    # kinlearn's default: the robot-model term plus what the metrics ask for.
    "smooth": dict(rectification=1.0, start=1.0, goal=1.0, endpoint_target="one_spacing", smoothness=1.0),
}


def _mse(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    return ((a - b) ** 2).mean()


def tm_loss(
    waypoints: torch.Tensor,
    rectified: torch.Tensor,
    s0: torch.Tensor,
    sT: torch.Tensor,
    layout: StateLayout,
    config: LossConfig,
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """The configured loss and its terms (detached), including ``paper_l_tm``, Eq. 4's value.

    ``waypoints``: ``(N, T - 1, 3)``; ``rectified``: ``(N, T, S)`` from :func:`rectify`.
    """
    ef0, efT = s0[:, layout.ef], sT[:, layout.ef]
    T = waypoints.shape[1] + 1
    rect = _mse(waypoints, rectified[:, :-1, layout.ef])
    on_start, on_goal = _mse(waypoints[:, 0], ef0), _mse(waypoints[:, -1], efT)
    if config.endpoint_target == "on":
        start, goal = on_start, on_goal
    else:
        step = (efT - ef0) / T
        start, goal = _mse(waypoints[:, 0], ef0 + step), _mse(waypoints[:, -1], efT - step)
    points = torch.cat((ef0[:, None], waypoints, efT[:, None]), dim=1)
    accel = points[:, 2:] - 2 * points[:, 1:-1] + points[:, :-2]
    smooth = (accel**2).mean() * T**2
    loss = (
        config.rectification * rect + config.start * start + config.goal * goal + config.smoothness * smooth
    )
    terms = {
        "rectification": rect.detach(),
        "start": start.detach(),
        "goal": goal.detach(),
        "smoothness": smooth.detach(),
        "paper_l_tm": (rect + on_start + on_goal).detach(),
    }
    return loss, terms
