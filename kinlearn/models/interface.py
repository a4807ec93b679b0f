"""The two model interfaces every forward and inverse model satisfies (learned, chain or analytic).

=================  ================================================================================
``ForwardModel``   ``forward(s (..., S), a (..., dof)) -> s_next (..., S)``
``InverseModel``   ``forward(s (..., S), ef_target (..., 3)) -> a (..., dof)``
=================  ================================================================================

S = dof + 3 and s = [θ, ef] (:class:`~kinlearn.body.state.StateLayout`). Every model has ``layout`` and
``robot_name``, accepts leading batch dimensions, is differentiable in its inputs and follows the
inputs' dtype.
"""

from __future__ import annotations

import dataclasses

import torch
from torch import nn

from ..body.robot import Robot, load_robot
from ..body.state import StateLayout
from ..checks import broadcast_shapes, check_finite, check_last_dim
from ..data.babbling import MAX_STEP
from ..errors import ConfigError

__all__ = ["ForwardModel", "InverseModel", "config_from_dict", "config_to_dict", "resolve_robot"]


def _is_compiling() -> bool:
    fn = getattr(torch.compiler, "is_compiling", None)  # torch ≥ 2.3
    return bool(fn()) if fn is not None else False


def resolve_robot(robot: Robot | str) -> Robot:
    return robot if isinstance(robot, Robot) else load_robot(robot)


class _RobotModel(nn.Module):
    """Common input checks. ``validate_inputs = False`` skips the finiteness check (a device sync)."""

    kind: str = ""
    validate_inputs: bool = True

    def __init__(self, robot_name: str, dof: int):
        super().__init__()
        self.robot_name = robot_name
        self.layout = StateLayout(dof)

    @property
    def dof(self) -> int:
        return self.layout.dof

    def _check(self, x: torch.Tensor, n: int, what: str) -> None:
        check_last_dim(x, n, what)
        if self.validate_inputs and not _is_compiling():
            check_finite(x, what)

    def config_dict(self) -> dict:
        raise NotImplementedError


class ForwardModel(_RobotModel):
    """``forward(s (..., S), a (..., dof)) -> s_next (..., S)``; attributes ``layout``, ``robot_name``."""

    kind = "fm"
    #: The babbling step bound of the data the model learned from (rad per joint and step): the largest
    #: action it is valid for, and what a planner bounds the IM's actions by. A learned FM records it
    #: (:attr:`~kinlearn.models.configs.FMConfig.max_step`); exact models take the default.
    max_step: float = MAX_STEP

    def forward(self, s: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        self._check(s, self.layout.size, "state s")
        self._check(a, self.dof, "action a")
        s, a = _broadcast_pair(s, a)
        return self._forward(s, a)

    def _forward(self, s: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        raise NotImplementedError

    def ef_along(self, theta: torch.Tensor, ef0: torch.Tensor, every: int = 1) -> torch.Tensor:
        """The end effector the model predicts along a joint path, rolled out from a known start.

        ``theta``: ``(N, L, dof)`` the joint path (θ(0) first); ``ef0``: ``(N, 3)`` the end effector at
        θ(0). Each step's state keeps the path's exact joints and takes its end effector from the
        model: ef(k+1) = FM[[θ(k), ef(k)], θ(k+1) − θ(k)]'s ef. Returns the end effector at every
        ``every``-th configuration (0, every, 2·every, …), ``(N, ⌈L / every⌉, 3)``, ef(0) = ``ef0``.
        The steps should stay within the range the model was trained on (the babbling step bound).
        Models whose end effector is a function of the joints override this with a parallel version
        that evaluates only the configurations asked for.
        """
        efs = [ef0]
        for k in range(theta.shape[1] - 1):
            s = self.layout.join(theta[:, k], efs[-1])
            efs.append(self(s, theta[:, k + 1] - theta[:, k])[..., self.layout.ef])
        return torch.stack(efs[::every], dim=1)


class InverseModel(_RobotModel):
    """``forward(s (..., S), ef_target (..., 3)) -> a (..., dof)``; attributes ``layout``, ``robot_name``."""

    kind = "im"

    def forward(self, s: torch.Tensor, ef_target: torch.Tensor) -> torch.Tensor:
        self._check(s, self.layout.size, "state s")
        self._check(ef_target, 3, "target end-effector position ef_target")
        s, ef_target = _broadcast_pair(s, ef_target)
        return self._forward(s, ef_target)

    def _forward(self, s: torch.Tensor, ef_target: torch.Tensor) -> torch.Tensor:
        raise NotImplementedError


def _broadcast_pair(x: torch.Tensor, y: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Broadcast the leading (batch) dimensions of two ``(..., n)`` tensors."""
    if x.shape[:-1] == y.shape[:-1]:
        return x, y
    batch = broadcast_shapes(x.shape[:-1], y.shape[:-1])
    return x.expand(*batch, x.shape[-1]), y.expand(*batch, y.shape[-1])


def config_to_dict(cfg) -> dict:
    """A model config dataclass as a JSON-able dict (tuples as lists)."""
    d = dataclasses.asdict(cfg)
    return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}


def config_from_dict(cls, d: dict):
    """The config dataclass ``cls`` from :func:`config_to_dict`'s dict; an unknown field is a ConfigError."""
    fields = {f.name for f in dataclasses.fields(cls)}
    unknown = set(d) - fields
    if unknown:
        raise ConfigError(f"unknown {cls.__name__} field(s): {', '.join(sorted(unknown))}")
    return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in d.items()})
