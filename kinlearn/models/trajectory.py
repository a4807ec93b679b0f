"""The trajectory model (TM): a GRU decoder mapping [s(0), s(T)] to T − 1 end-effector waypoints.

Paper Sect. 3 and Fig. 1; default sizes from Sect. 4: one GRU layer of 20 units run for
T − 1 = 10 steps with the same input at every step, a shared dense tanh layer of 20 units, and one
head (10 tanh → 3 linear) giving the end-effector position ŝ(t) of every intermediate waypoint. The
joints of each waypoint are not predicted: they come from the forward model during rectification.

Unlike the authors' code (github.com/Mcibula/traj-planning-icann2025) every sub-module is registered, so all of them train,
and the initial hidden state is deterministic (zeros or learned); ``h0="random"`` exists only to
reproduce the authors' behaviour.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Literal

import torch
from torch import nn

from ..body.robot import load_robot
from ..body.state import StateLayout
from ..checks import check_finite, check_last_dim
from ..errors import CheckpointError, ConfigError
from ..io import load_checkpoint, resolve_dependency
from .forward_inverse import ForwardModel, InverseModel, frozen_fm_im

__all__ = ["TMConfig", "TrajectoryModel", "load_trajectory_model"]


@dataclass(frozen=True)
class TMConfig:
    """Architecture of the trajectory model.

    ``steps`` is T: the model predicts T − 1 waypoints. ``normalize`` standardises the 2·(dof + 3)
    inputs and scales the output by statistics fitted on the training pairs (the paper used none).
    """

    robot: str = "iiwa14"
    dof: int = 7
    steps: int = 11
    gru_layers: int = 1
    gru_hidden: int = 20
    shared_hidden: int = 20
    head_hidden: int = 10
    h0: Literal["zeros", "learned", "random"] = "zeros"
    normalize: bool = True

    def __post_init__(self) -> None:
        if self.steps < 2:
            raise ConfigError(f"steps (T) must be ≥ 2, got {self.steps}")
        if self.h0 not in ("zeros", "learned", "random"):
            raise ConfigError(f"h0 must be 'zeros', 'learned' or 'random', got {self.h0!r}")
        for name in ("dof", "gru_layers", "gru_hidden", "shared_hidden", "head_hidden"):
            if getattr(self, name) <= 0:
                raise ConfigError(f"{name} must be positive, got {getattr(self, name)}")

    def to_dict(self) -> dict:
        return asdict(self)


class TrajectoryModel(nn.Module):
    """TM: ``forward(s0 (..., S), sT (..., S)) -> waypoints (..., T - 1, 3)`` (end-effector positions)."""

    def __init__(self, config: TMConfig):
        super().__init__()
        self.config = config
        self.layout = StateLayout(config.dof)
        S = self.layout.size
        self.gru = nn.GRU(2 * S, config.gru_hidden, num_layers=config.gru_layers, batch_first=True)
        self.shared = nn.Sequential(nn.Linear(config.gru_hidden, config.shared_hidden), nn.Tanh())
        self.head = nn.Sequential(
            nn.Linear(config.shared_hidden, config.head_hidden),
            nn.Tanh(),
            nn.Linear(config.head_hidden, 3),
        )
        if config.h0 == "learned":
            self.h0 = nn.Parameter(torch.zeros(config.gru_layers, 1, config.gru_hidden))
        else:
            self.register_parameter("h0", None)
        self.register_buffer("in_mean", torch.zeros(2 * S))
        self.register_buffer("in_std", torch.ones(2 * S))
        self.register_buffer("out_mean", torch.zeros(3))
        self.register_buffer("out_std", torch.ones(3))
        #: Box of the training pairs' [s(0), s(T)] (the domain the planner warns outside of); ±inf: unknown.
        self.register_buffer("domain_lo", torch.full((2 * S,), -torch.inf))
        self.register_buffer("domain_hi", torch.full((2 * S,), torch.inf))

    @property
    def robot_name(self) -> str:
        return self.config.robot

    @torch.no_grad()
    def fit_normalization(self, start: torch.Tensor, goal: torch.Tensor) -> None:
        """Record the training pairs' domain; set input/output statistics from them when
        ``config.normalize``."""
        x = torch.cat((start, goal), dim=-1).reshape(-1, 2 * self.layout.size).double()
        self.domain_lo.copy_(x.min(0).values)
        self.domain_hi.copy_(x.max(0).values)
        if not self.config.normalize:
            return
        self.in_mean.copy_(x.mean(0))
        self.in_std.copy_(x.std(0).clamp_min(1e-3))
        ef = torch.cat((start[..., self.layout.ef], goal[..., self.layout.ef])).reshape(-1, 3).double()
        self.out_mean.copy_(ef.mean(0))
        self.out_std.copy_(ef.std(0).clamp_min(1e-3))

    def forward(self, s0: torch.Tensor, sT: torch.Tensor) -> torch.Tensor:
        S = self.layout.size
        batch = s0.shape[:-1]
        x = (torch.cat((s0, sT), dim=-1).reshape(-1, 2 * S) - self.in_mean) / self.in_std
        n, steps = x.shape[0], self.config.steps - 1
        x = x.unsqueeze(1).expand(n, steps, 2 * S)
        if self.config.h0 == "random":  # parity with the authors' code only: not deterministic
            h0 = torch.randn(
                self.config.gru_layers, n, self.config.gru_hidden, dtype=x.dtype, device=x.device
            )
        elif self.h0 is not None:
            h0 = self.h0.expand(-1, n, -1).contiguous()
        else:
            h0 = x.new_zeros(self.config.gru_layers, n, self.config.gru_hidden)
        out, _ = self.gru(x, h0)
        ef = self.head(self.shared(out)) * self.out_std + self.out_mean
        return ef.reshape(*batch, steps, 3)

    def _load_from_state_dict(self, state_dict, prefix, *args, **kwargs):
        # Checkpoints written before the domain was recorded: the domain is unknown (no warnings).
        for name, fill in (("domain_lo", -torch.inf), ("domain_hi", torch.inf)):
            state_dict.setdefault(prefix + name, torch.full_like(getattr(self, name), fill))
        super()._load_from_state_dict(state_dict, prefix, *args, **kwargs)

    def check_inputs(self, s0: torch.Tensor, sT: torch.Tensor) -> None:
        for what, s in (("start state s0", s0), ("goal state sT", sT)):
            check_last_dim(s, self.layout.size, what)
            check_finite(s, what)


def load_trajectory_model(
    path: str | Path, robot: str | None = None
) -> tuple[TrajectoryModel, ForwardModel, InverseModel]:
    """The waypoint TM in ``tm.pt`` (eval mode) and the frozen FM and IM it was trained through.

    Reads only what a planner needs from the checkpoint: the TM's architecture and weights, whether
    each of the FM/IM is learned or analytic (with the analytic IM's iterations and damping), and the
    learned ones by the identity the checkpoint records (relative path and hash,
    :func:`kinlearn.io.resolve_dependency`); a run written before identities were recorded finds
    them beside ``tm.pt``. No training code is involved. Raises :class:`CheckpointError` when the file
    does not fit this kinlearn or a model it needs is missing or was replaced.
    """
    path = Path(path)
    payload = load_checkpoint(path, kind="tm", robot=robot)
    config = payload["config"]
    try:
        tm = TrajectoryModel(TMConfig(**config["tm"]))
        tm.load_state_dict(payload["state_dict"])
    except (TypeError, KeyError, RuntimeError, ConfigError) as exc:
        raise CheckpointError(f"{path}: the TM checkpoint does not match this kinlearn ({exc})") from exc
    arm = load_robot(tm.config.robot)
    paths = {}
    for kind in ("fm", "im"):
        if config.get(kind, "learned") == "analytic":
            continue
        if kind in (payload.get("depends") or {}):
            paths[kind] = resolve_dependency(path, payload, kind)
        else:  # checkpoint format 1: the models beside tm.pt, or in the folder its run named
            folders = [path.parent] + ([Path(config["models_dir"])] if config.get("models_dir") else [])
            found = [f / f"{kind}.pt" for f in folders if (f / f"{kind}.pt").is_file()]
            if not found:
                raise CheckpointError(f"{path}: cannot find the {kind}.pt it was trained through")
            paths[kind] = found[0]
    fm, im = frozen_fm_im(
        arm,
        config.get("fm", "learned"),
        config.get("im", "learned"),
        fm_path=paths.get("fm"),
        im_path=paths.get("im"),
        im_iterations=config.get("im_iterations", 1),
        im_damping=config.get("im_damping", 1e-2),
    )
    return tm.eval(), fm, im
