"""The configurations of the learned FM and IM (:class:`FMConfig`, :class:`IMConfig`): their layers'
widths, activation and options beyond the paper; each is what its checkpoint records to rebuild it."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from ..data.babbling import MAX_STEP
from ..errors import ConfigError
from .interface import config_from_dict, config_to_dict
from .layers import ACTIVATIONS, Activation

__all__ = ["FMConfig", "IMConfig"]


@dataclass(frozen=True)
class FMConfig:
    """Learned forward model. Defaults are the paper's (Sect. 4; Cibula et al., ICANN 2024, Sect. 4.1).

    Attributes:
        robot, dof: the robot the model belongs to (state size dof + 3).
        shared: widths of the shared dense layers.
        joints_head, ef_head: hidden widths of the two heads (each then a linear output layer).
        activation: of every hidden layer.
        normalize: standardise inputs and outputs with statistics fitted on the training data.
        predict_delta: predict s' − s (then add s) instead of s'.
        ef_mode: ``"head"`` (the paper's: an ef head on the shared layers) or ``"difference"``: the
            end-effector step is g(θ + a) − g(θ) for one learned function g of the joints alone (an
            MLP of width ``fk_hidden`` on (sin θ, cos θ)). The end effector of a rigid arm is a
            function of its joints, so g learns the forward kinematics up to a constant, and a
            rollout telescopes to ef(0) + g(θ(t)) − g(θ(0)): its error stays bounded instead of
            adding up over the steps. Needs ``predict_delta``.
        fk_hidden: hidden widths of g.
        max_step: the babbling step bound of the data the model learns from (rad): the largest action
            it is valid for (:attr:`~kinlearn.models.interface.ForwardModel.max_step`). Recorded only
            where it is not the default, so a checkpoint without it (all older ones) reads the default.
    """

    robot: str = "iiwa14"
    dof: int = 7
    shared: tuple[int, ...] = (30,)
    joints_head: tuple[int, ...] = (20,)
    ef_head: tuple[int, ...] = (20,)
    activation: Activation = "tanh"
    normalize: bool = False
    predict_delta: bool = False
    ef_mode: Literal["head", "difference"] = "head"
    fk_hidden: tuple[int, ...] = (256, 256, 256)
    max_step: float = MAX_STEP

    def __post_init__(self) -> None:
        _check_widths(self.shared, "shared", allow_empty=False)
        _check_widths(self.joints_head, "joints_head")
        _check_widths(self.ef_head, "ef_head")
        _check_widths(self.fk_hidden, "fk_hidden", allow_empty=False)
        if self.ef_mode not in ("head", "difference"):
            raise ConfigError(f"ef_mode must be 'head' or 'difference', got {self.ef_mode!r}")
        if self.ef_mode == "difference" and not self.predict_delta:
            raise ConfigError("ef_mode='difference' predicts a step, so it needs predict_delta=True")
        if isinstance(self.max_step, bool) or not (
            isinstance(self.max_step, (int, float)) and math.isfinite(self.max_step) and self.max_step > 0
        ):
            raise ConfigError(f"max_step must be a positive number of radians, got {self.max_step!r}")
        _check_common(self)

    def to_dict(self) -> dict:
        """The config as a JSON-able dict; ``max_step`` is left out at the default (the record of every
        model babbled with the default bound stays what it was before the field existed)."""
        d = config_to_dict(self)
        if d["max_step"] == MAX_STEP:
            del d["max_step"]
        return d

    @classmethod
    def from_dict(cls, d: dict) -> FMConfig:
        return config_from_dict(cls, d)


@dataclass(frozen=True)
class IMConfig:
    """Learned inverse model. Defaults are the paper's monolithic IM (Sect. 4; Cibula et al., ICANN 2024, Sect. 4.1).

    Attributes:
        robot, dof: the robot the model belongs to.
        hidden: widths of the dense hidden layers (then a linear layer with dof outputs).
        activation: of every hidden layer.
        normalize: standardise inputs and outputs with statistics fitted on the training data.
        ef_delta_input: feed ef_target − ef instead of ef_target.
    """

    robot: str = "iiwa14"
    dof: int = 7
    hidden: tuple[int, ...] = (40, 60, 60, 40)
    activation: Activation = "tanh"
    normalize: bool = False
    ef_delta_input: bool = False

    def __post_init__(self) -> None:
        _check_widths(self.hidden, "hidden", allow_empty=False)
        _check_common(self)

    def to_dict(self) -> dict:
        return config_to_dict(self)

    @classmethod
    def from_dict(cls, d: dict) -> IMConfig:
        return config_from_dict(cls, d)


def _check_widths(widths, name: str, allow_empty: bool = True) -> None:
    widths = tuple(widths)
    if (not widths and not allow_empty) or any(int(w) < 1 for w in widths):
        raise ConfigError(f"{name} must be a tuple of positive layer widths, got {widths}")


def _check_common(cfg) -> None:
    if cfg.activation not in ACTIVATIONS:
        raise ConfigError(f"activation must be one of {', '.join(ACTIVATIONS)}, got {cfg.activation!r}")
    if int(cfg.dof) < 1:
        raise ConfigError(f"dof must be ≥ 1, got {cfg.dof}")
