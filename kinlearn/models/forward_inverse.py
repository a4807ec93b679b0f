"""Forward and inverse models of a robot, learned (MLPs) or analytic, behind one interface.

=================  ================================================================================
``ForwardModel``   ``forward(s (..., S), a (..., dof)) -> s_next (..., S)``
``InverseModel``   ``forward(s (..., S), ef_target (..., 3)) -> a (..., dof)``
=================  ================================================================================

S = dof + 3 and s = [θ, ef] (:class:`~kinlearn.body.state.StateLayout`). Every model has ``layout`` and
``robot_name``, accepts leading batch dimensions, is differentiable in its inputs and follows the
inputs' dtype (learned models hold float32 weights unless converted with ``.to()``).

Learned models (REFERENCE #5–6):

- :class:`LearnedFM`: input [s, a] → shared dense layer(s) → a joints head (→ θ') and an ef head
  (→ ef'). Paper: shared 30 tanh; heads 20 tanh → 7 linear and 20 tanh → 3 linear.
- :class:`LearnedIM`: input [s, ef_target] → dense 40-60-60-40 tanh → dof linear (the action).

Options beyond the paper (off in the ``paper`` preset): ``normalize`` (inputs and outputs
standardised by buffers fitted on the training data with :meth:`fit_normalization`),
``predict_delta`` (the FM predicts s' − s and adds s) and, for the IM, ``ef_delta_input`` (the IM
sees ef_target − ef instead of ef_target).

Analytic models (for the ablation): :class:`AnalyticFM` (θ' = θ + a, ef' = FK(θ')) and
:class:`AnalyticIM` (damped-least-squares steps toward the target, kept within the joint limits).

Checkpoints: :func:`save_model`, :func:`load_fm`, :func:`load_im` (weights + config + robot + format
version, via :mod:`kinlearn.io`). :func:`kinlearn.training.forward_inverse.validate_models` measures models against
the analytic robot on fresh babbling data.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import torch
from torch import nn

from ..body.kinematics import dls_step, kinematics
from ..body.robot import Robot, load_robot
from ..errors import CheckpointError, ConfigError
from ..io import load_checkpoint, save_checkpoint
from .chain import ChainConfig, ChainFM
from .interface import ForwardModel, InverseModel, config_from_dict, config_to_dict, resolve_robot

__all__ = [
    "ACTIVATIONS",
    "AnalyticFM",
    "AnalyticIM",
    "FMConfig",
    "ForwardModel",
    "IMConfig",
    "InverseModel",
    "LearnedFM",
    "LearnedIM",
    "fm_config",
    "frozen_fm_im",
    "im_config",
    "load_fm",
    "load_im",
    "save_model",
]

Activation = Literal["tanh", "relu", "gelu", "silu", "elu"]
ACTIVATIONS: dict[str, type[nn.Module]] = {
    "tanh": nn.Tanh,
    "relu": nn.ReLU,
    "gelu": nn.GELU,
    "silu": nn.SiLU,
    "elu": nn.ELU,
}


def _mlp(sizes: Sequence[int], activation: str, linear_out: int | None) -> nn.Sequential:
    """Dense layers through ``sizes`` with ``activation`` after each, then an optional linear output."""
    layers: list[nn.Module] = []
    for n_in, n_out in itertools.pairwise(sizes):
        layers += [nn.Linear(n_in, n_out), ACTIVATIONS[activation]()]
    if linear_out is not None:
        layers.append(nn.Linear(sizes[-1], linear_out))
    return nn.Sequential(*layers)


# --------------------------------------------------------------------------------------------------
# Learned models
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FMConfig:
    """Learned forward model. Defaults are the paper's (REFERENCE #5).

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

    def __post_init__(self) -> None:
        _check_widths(self.shared, "shared", allow_empty=False)
        _check_widths(self.joints_head, "joints_head")
        _check_widths(self.ef_head, "ef_head")
        _check_widths(self.fk_hidden, "fk_hidden", allow_empty=False)
        if self.ef_mode not in ("head", "difference"):
            raise ConfigError(f"ef_mode must be 'head' or 'difference', got {self.ef_mode!r}")
        if self.ef_mode == "difference" and not self.predict_delta:
            raise ConfigError("ef_mode='difference' predicts a step, so it needs predict_delta=True")
        _check_common(self)

    def to_dict(self) -> dict:
        return config_to_dict(self)

    @classmethod
    def from_dict(cls, d: dict) -> FMConfig:
        return config_from_dict(cls, d)


@dataclass(frozen=True)
class IMConfig:
    """Learned inverse model. Defaults are the paper's monolithic IM (REFERENCE #6).

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


#: Named model settings. ``paper`` is REFERENCE #5–6 exactly; ``improved`` adds normalisation,
#: delta prediction / ef-displacement input and width; ``tiny`` is ``improved``'s options at the
#: paper's widths (for quick tests).
FM_PRESETS: dict[str, dict] = {
    "paper": {},
    # Normalised, predicting the step; the end-effector step as a difference of a learned function
    # of the joints (see FMConfig.ef_mode); the joints head needs little width (θ' ≈ θ + a).
    "improved": {
        "normalize": True,
        "predict_delta": True,
        "shared": (64,),
        "joints_head": (64,),
        "ef_mode": "difference",
        "fk_hidden": (256, 256, 256),
    },
    "tiny": {"normalize": True, "predict_delta": True},
}
IM_PRESETS: dict[str, dict] = {
    "paper": {},
    "improved": {"normalize": True, "ef_delta_input": True, "hidden": (128, 128, 128)},
    "tiny": {"normalize": True, "ef_delta_input": True},
}


def fm_config(robot: str = "iiwa14", preset: str = "paper", **overrides) -> FMConfig:
    """An :class:`FMConfig` for ``robot`` from a named preset (see :data:`FM_PRESETS`)."""
    if preset not in FM_PRESETS:
        raise ConfigError(f"unknown FM preset {preset!r}; choose one of {', '.join(FM_PRESETS)}")
    return FMConfig(robot=robot, dof=load_robot(robot).dof, **{**FM_PRESETS[preset], **overrides})


def im_config(robot: str = "iiwa14", preset: str = "paper", **overrides) -> IMConfig:
    """An :class:`IMConfig` for ``robot`` from a named preset (see :data:`IM_PRESETS`)."""
    if preset not in IM_PRESETS:
        raise ConfigError(f"unknown IM preset {preset!r}; choose one of {', '.join(IM_PRESETS)}")
    return IMConfig(robot=robot, dof=load_robot(robot).dof, **{**IM_PRESETS[preset], **overrides})


class _Normalizer(nn.Module):
    """Affine standardisation ``(x − mean) / std`` with the statistics held as buffers."""

    def __init__(self, n: int):
        super().__init__()
        self.register_buffer("mean", torch.zeros(n))
        self.register_buffer("std", torch.ones(n))

    @torch.no_grad()
    def fit(self, x: torch.Tensor, min_std: float = 1e-6) -> None:
        x = x.reshape(-1, x.shape[-1]).double()
        self.mean.copy_(x.mean(0))
        self.std.copy_(x.std(0).clamp_min(min_std))

    def encode(self, x: torch.Tensor) -> torch.Tensor:
        return (x - self.mean.to(x.dtype)) / self.std.to(x.dtype)

    def decode(self, y: torch.Tensor) -> torch.Tensor:
        return y * self.std.to(y.dtype) + self.mean.to(y.dtype)


class LearnedFM(ForwardModel):
    """Learned forward model (see :class:`FMConfig`). Loss: sum of the two heads' MSE."""

    def __init__(self, config: FMConfig | None = None):
        config = config or FMConfig()
        super().__init__(config.robot, config.dof)
        self.config = config
        dof, S = config.dof, config.dof + 3
        n_in = S + dof
        self.shared = _mlp((n_in, *config.shared), config.activation, None)
        width = config.shared[-1]
        self.joints_head = _mlp((width, *config.joints_head), config.activation, dof)
        if config.ef_mode == "difference":
            # No output bias: a constant cancels in g(θ + a) − g(θ) and would never train.
            hidden = _mlp((2 * dof, *config.fk_hidden), config.activation, None)
            self.fk = nn.Sequential(*hidden, nn.Linear(config.fk_hidden[-1], 3, bias=False))
        else:
            self.ef_head = _mlp((width, *config.ef_head), config.activation, 3)
        if config.normalize:
            self.in_norm = _Normalizer(n_in)
            self.out_norm = _Normalizer(S)

    def config_dict(self) -> dict:
        return self.config.to_dict()

    def _inputs(self, s: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        x = torch.cat((s, a), dim=-1)
        return self.in_norm.encode(x) if self.config.normalize else x

    def _g(self, theta: torch.Tensor) -> torch.Tensor:
        """The learned function of the joints whose differences are the end-effector steps (metres)."""
        return self.fk(torch.cat((torch.sin(theta), torch.cos(theta)), dim=-1))

    def _raw(self, s: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        """Network output (normalised target space when ``normalize``) ``(..., S)``."""
        h = self.shared(self._inputs(s, a))
        if self.config.ef_mode == "head":
            return torch.cat((self.joints_head(h), self.ef_head(h)), dim=-1)
        theta = s[..., self.layout.joints]
        step = self._g(theta + a) - self._g(theta)
        if self.config.normalize:
            step = (step - self.out_norm.mean[self.layout.ef]) / self.out_norm.std[self.layout.ef]
        return torch.cat((self.joints_head(h), step), dim=-1)

    def ef_along(self, theta: torch.Tensor, ef0: torch.Tensor, every: int = 1) -> torch.Tensor:
        """See :meth:`ForwardModel.ef_along`. With ``ef_mode="difference"`` the rollout telescopes to
        ef(0) + g(θ(k)) − g(θ(0)), computed for the asked k at once (the same numbers as the
        step-by-step rollout, up to rounding)."""
        if self.config.ef_mode != "difference":
            return super().ef_along(theta, ef0, every)
        g = self._g(theta[:, ::every])
        return ef0.unsqueeze(1) + (g - g[:, :1])

    def _target(self, s: torch.Tensor, s_next: torch.Tensor) -> torch.Tensor:
        y = s_next - s if self.config.predict_delta else s_next
        return self.out_norm.encode(y) if self.config.normalize else y

    def _forward(self, s: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        y = self._raw(s, a)
        if self.config.normalize:
            y = self.out_norm.decode(y)
        return s + y if self.config.predict_delta else y

    def training_loss(self, s: torch.Tensor, a: torch.Tensor, s_next: torch.Tensor) -> torch.Tensor:
        """Sum of the joints head's and the ef head's MSE (in normalised units when ``normalize``)."""
        err = self._raw(s, a) - self._target(s, s_next)
        L = self.layout
        return err[..., L.joints].square().mean() + err[..., L.ef].square().mean()

    @torch.no_grad()
    def fit_normalization(self, s: torch.Tensor, a: torch.Tensor, s_next: torch.Tensor) -> None:
        """Fit the input/output statistics on training data (no-op without ``normalize``)."""
        if not self.config.normalize:
            return
        self.in_norm.fit(torch.cat((s, a), dim=-1))
        self.out_norm.fit(s_next - s if self.config.predict_delta else s_next)


class LearnedIM(InverseModel):
    """Learned (monolithic) inverse model (see :class:`IMConfig`). Loss: MSE of the action."""

    def __init__(self, config: IMConfig | None = None):
        config = config or IMConfig()
        super().__init__(config.robot, config.dof)
        self.config = config
        n_in = config.dof + 3 + 3
        self.net = _mlp((n_in, *config.hidden), config.activation, config.dof)
        if config.normalize:
            self.in_norm = _Normalizer(n_in)
            self.out_norm = _Normalizer(config.dof)

    def config_dict(self) -> dict:
        return self.config.to_dict()

    def _inputs(self, s: torch.Tensor, ef_target: torch.Tensor) -> torch.Tensor:
        if self.config.ef_delta_input:
            ef_target = ef_target - s[..., self.layout.ef]
        x = torch.cat((s, ef_target), dim=-1)
        return self.in_norm.encode(x) if self.config.normalize else x

    def _raw(self, s: torch.Tensor, ef_target: torch.Tensor) -> torch.Tensor:
        return self.net(self._inputs(s, ef_target))

    def _forward(self, s: torch.Tensor, ef_target: torch.Tensor) -> torch.Tensor:
        y = self._raw(s, ef_target)
        return self.out_norm.decode(y) if self.config.normalize else y

    def training_loss(self, s: torch.Tensor, a: torch.Tensor, s_next: torch.Tensor) -> torch.Tensor:
        """MSE of the predicted action (in normalised units when ``normalize``)."""
        target = self.out_norm.encode(a) if self.config.normalize else a
        return (self._raw(s, s_next[..., self.layout.ef]) - target).square().mean()

    @torch.no_grad()
    def fit_normalization(self, s: torch.Tensor, a: torch.Tensor, s_next: torch.Tensor) -> None:
        """Fit the input/output statistics on training data (no-op without ``normalize``)."""
        if not self.config.normalize:
            return
        ef_t = s_next[..., self.layout.ef]
        if self.config.ef_delta_input:
            ef_t = ef_t - s[..., self.layout.ef]
        self.in_norm.fit(torch.cat((s, ef_t), dim=-1))
        self.out_norm.fit(a)


# --------------------------------------------------------------------------------------------------
# Analytic models
# --------------------------------------------------------------------------------------------------


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


# --------------------------------------------------------------------------------------------------
# Checkpoints
# --------------------------------------------------------------------------------------------------


def save_model(model: ForwardModel | InverseModel, path: str | Path, extra: dict | None = None) -> Path:
    """Save a model's weights, config, robot name and format version (atomically).

    Analytic models are saved too (no weights; their config rebuilds them), so a planner's FM/IM
    choice is a file either way. ``extra`` (a dict of tensors and plain values) is stored beside.
    """
    if not isinstance(model, (ForwardModel, InverseModel)):
        raise ConfigError(f"save_model needs a ForwardModel or InverseModel, got {type(model).__name__}")
    config = model.config_dict()
    if isinstance(model, (LearnedFM, LearnedIM)):
        config = {"type": "learned", **config}
    elif isinstance(model, ChainFM):
        config = {"type": "chain", **config}
    elif not isinstance(model, (AnalyticFM, AnalyticIM)):
        raise ConfigError(f"save_model cannot save a {type(model).__name__} (it has no checkpoint form)")
    return save_checkpoint(
        path,
        kind=model.kind,
        robot=model.robot_name,
        config=config,
        state_dict=model.state_dict(),
        extra=extra,
    )


def _build(payload: dict, path, kind: str):
    config = dict(payload.get("config") or {})
    mtype = config.pop("type", None)
    try:
        if mtype == "analytic":
            robot = config.pop("robot")
            model = AnalyticFM(robot) if kind == "fm" else AnalyticIM(robot, **config)
        elif mtype == "chain" and kind == "fm":
            model = ChainFM(ChainConfig.from_dict(config))
        elif mtype == "learned":
            cls, cfg_cls = (LearnedFM, FMConfig) if kind == "fm" else (LearnedIM, IMConfig)
            model = cls(cfg_cls.from_dict(config))
        else:
            raise CheckpointError(
                f"{path}: unknown {kind.upper()} type {mtype!r} (expected 'learned', 'chain' or 'analytic')"
            )
        model.load_state_dict(payload["state_dict"], strict=True)
    except CheckpointError:
        raise
    except Exception as exc:
        raise CheckpointError(
            f"{path}: cannot rebuild the {kind.upper()} from its config and weights ({type(exc).__name__}: {exc})"
        ) from exc
    if model.robot_name != payload.get("robot"):
        raise CheckpointError(
            f"{path}: config robot {model.robot_name!r} != checkpoint robot {payload.get('robot')!r}"
        )
    return model.eval()


def load_fm(path: str | Path, robot: str | None = None) -> ForwardModel:
    """Load a forward model saved by :func:`save_model`; ``robot`` (if given) must match the checkpoint's."""
    return _build(load_checkpoint(path, kind="fm", robot=robot), path, "fm")


def load_im(path: str | Path, robot: str | None = None) -> InverseModel:
    """Load an inverse model saved by :func:`save_model`; ``robot`` (if given) must match the checkpoint's."""
    return _build(load_checkpoint(path, kind="im", robot=robot), path, "im")


def frozen_fm_im(
    robot: Robot,
    fm: Literal["learned", "analytic"],
    im: Literal["learned", "analytic"],
    *,
    fm_path: str | Path | None = None,
    im_path: str | Path | None = None,
    im_iterations: int = 1,
    im_damping: float = 1e-2,
) -> tuple[ForwardModel, InverseModel]:
    """The FM and IM a trajectory model is trained or planned through, frozen (eval mode, no gradient
    to their weights): each learned (loaded from its path) or analytic (FK; ``im_iterations`` damped
    least-squares steps of damping ``im_damping``)."""
    f = AnalyticFM(robot) if fm == "analytic" else load_fm(fm_path, robot=robot.name)
    i = (
        AnalyticIM(robot, iterations=im_iterations, damping=im_damping)
        if im == "analytic"
        else load_im(im_path, robot=robot.name)
    )
    for m in (f, i):
        m.eval()
        m.requires_grad_(False)
    return f, i
