"""A body model the robot learns: joints → the centres of its collision spheres.

In the spirit of the learned forward model, the robot learns where its body is from babbling: the
configurations it visited (or joints drawn uniformly in its joint box) and, as its vision, the
sphere centres of the analytic collision body (:func:`~kinlearn.collision.body_spheres`) at them.

:class:`LearnedBody` answers like :class:`~kinlearn.collision.BodySpheres` wherever the planner and
the collision functions use a body (``forward(q, validate)``, ``radii_like``, ``radii``, ``link``,
``pairs``, ``floor_mask``, ``lever``, ``robot``, ``num_spheres``), so
:func:`~kinlearn.collision.check_path`, :func:`~kinlearn.collision.clearances` and
:func:`~kinlearn.collision.body_obstacle_distance` take either body. What it learns is the centres
of the moving spheres: an MLP of (sin θ, cos θ) predicts them all at once, its outputs centred per
coordinate and divided by one common scale, so that the loss weighs a millimetre of every sphere
alike (per-coordinate scales gave a lower mean but a higher p99 error: 10.8 vs 9.5 mm after 20k steps).
The base spheres never move and are kept as constants; the geometry that is not learned (radii,
self-collision pairs, the floor mask, the per-joint travel bounds ``lever`` of the dense path check)
is copied from the analytic body it is trained against. The radii can be inflated by a ``margin``
(:meth:`LearnedBody.set_margin`, e.g. the validation p99 centre error) so that a body–obstacle
distance errs on the safe side; it is saved with the weights.

Predicting each link's frame (a 3×4 transform, the centres then fixed linear combinations of it)
instead of the centres was no more accurate for the same steps and width, with more outputs; the
centres are predicted directly.

Training and validation live in :mod:`kinlearn.training.body`; loading and running a body model
needs none of it.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import torch
from torch import nn

from ..body.robot import Robot, load_robot
from ..checks import check_finite, check_last_dim, check_real_dtype
from ..collision import BodySpheres, body_spheres
from ..errors import CheckpointError, ConfigError
from ..io import load_checkpoint, save_checkpoint
from .layers import ACTIVATIONS

__all__ = [
    "BODY_KIND",
    "BODY_MODEL_FORMAT",
    "BodyModelConfig",
    "LearnedBody",
    "load_body_model",
    "save_body_model",
]

#: The ``kind`` of a body model's checkpoint.
BODY_KIND = "body"
#: Version of the body model's checkpoint contents (its config and state dict layout).
BODY_MODEL_FORMAT = 1
Activation = Literal["tanh", "relu", "gelu", "silu", "elu"]


@dataclass(frozen=True)
class BodyModelConfig:
    """A learned body model and how it is trained.

    Attributes:
        robot: the robot (a name with a bundled sphere model).
        dense: learn the 46-sphere body instead of the 12-sphere one (+ the base cover).
        hidden: widths of the MLP's hidden layers.
        activation: of every hidden layer.
        epochs, batch_size: passes over the training configurations and configurations per step.
        lr: Adam's initial learning rate, decayed per step on a cosine to ``lr × min_lr_ratio``.
        samples: configurations drawn uniformly in the joint box when no babbling data are given.
        val_fraction: share of the configurations held out for the per-epoch validation record.
        seed: seeds the uniform sample, the weights, the split and the shuffling.
    """

    robot: str = "iiwa14"
    dense: bool = False
    hidden: tuple[int, ...] = (160, 160, 160)
    activation: Activation = "silu"
    epochs: int = 80
    batch_size: int = 512
    lr: float = 3e-3
    min_lr_ratio: float = 0.003
    samples: int = 400_000
    val_fraction: float = 0.02
    seed: int = 0

    def __post_init__(self) -> None:
        hidden = tuple(self.hidden)
        object.__setattr__(self, "hidden", hidden)
        if not hidden or any(isinstance(w, bool) or not isinstance(w, int) or w < 1 for w in hidden):
            raise ConfigError(f"hidden must be a non-empty tuple of positive layer widths, got {hidden}")
        if self.activation not in ACTIVATIONS:
            raise ConfigError(f"activation must be one of {', '.join(ACTIVATIONS)}, got {self.activation!r}")
        for name in ("epochs", "batch_size", "samples"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ConfigError(f"BodyModelConfig.{name} must be an integer ≥ 1, got {value!r}")
        if not (isinstance(self.lr, (int, float)) and math.isfinite(self.lr) and self.lr > 0):
            raise ConfigError(f"lr must be a finite number > 0, got {self.lr!r}")
        if not 0.0 <= self.min_lr_ratio <= 1.0:
            raise ConfigError(f"min_lr_ratio must lie in [0, 1], got {self.min_lr_ratio!r}")
        if not 0.0 <= self.val_fraction < 1.0:
            raise ConfigError(f"val_fraction must lie in [0, 1), got {self.val_fraction!r}")
        if not isinstance(self.robot, str) or not self.robot:
            raise ConfigError(f"robot must be a robot name, got {self.robot!r}")

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["hidden"] = list(self.hidden)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> BodyModelConfig:
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = set(d) - names
        if unknown:
            raise ConfigError(f"unknown BodyModelConfig field(s): {', '.join(sorted(unknown))}")
        return cls(**{k: tuple(v) if k == "hidden" else v for k, v in d.items()})


def _analytic_body(config: BodyModelConfig) -> BodySpheres:
    return body_spheres(load_robot(config.robot), dense=config.dense)


class LearnedBody(nn.Module):
    """A learned collision body: joints ``(..., dof)`` → sphere centres ``(..., M, 3)``.

    The same spheres, in the same order, as the analytic body of ``config`` (base first); the base
    spheres' centres are constants, the others come from the MLP. Buffers: ``radii`` ``(M,)`` (the
    analytic radii + ``margin``), ``margin`` (metres, 0-d), ``link``, ``pairs``, ``floor_mask`` and
    ``lever`` as in :class:`~kinlearn.collision.BodySpheres` (copied from the analytic body),
    ``base_centres`` ``(M_base, 3)``, and the output statistics ``out_mean`` ``(3 M_moving,)`` and
    ``out_scale`` (0-d). The network's weights are float32 unless converted; the input is cast to
    them and the output follows the input's dtype and device. Differentiable in the joints.
    """

    def __init__(self, config: BodyModelConfig | None = None):
        super().__init__()
        config = config or BodyModelConfig()
        analytic = _analytic_body(config)
        self.config = config
        self.robot: Robot = analytic.robot
        self.name = analytic.name
        link = analytic.link
        self._num_base = int((link == 0).sum())
        n_moving = int(link.shape[0]) - self._num_base
        if n_moving == 0:
            raise ConfigError(f"the {analytic.name!r} body of {config.robot!r} has no moving sphere to learn")
        dof = self.robot.dof
        layers: list[nn.Module] = []
        width = 2 * dof
        for h in config.hidden:
            layers += [nn.Linear(width, h), ACTIVATIONS[config.activation]()]
            width = h
        layers.append(nn.Linear(width, 3 * n_moving))
        self.net = nn.Sequential(*layers)
        geometry = analytic.state_dict()
        self.register_buffer("base_centres", geometry["local"][: self._num_base].clone())
        self.register_buffer("sphere_radii", geometry["radii"].clone(), persistent=False)
        self.register_buffer("margin", torch.zeros((), dtype=geometry["radii"].dtype))
        self.register_buffer("radii", geometry["radii"].clone())
        for key in ("link", "pairs", "floor_mask", "lever"):
            self.register_buffer(key, geometry[key].clone())
        self.register_buffer("out_mean", torch.zeros(3 * n_moving))
        self.register_buffer("out_scale", torch.ones(()))

    @property
    def num_spheres(self) -> int:
        return int(self.radii.shape[0])

    @property
    def num_moving(self) -> int:
        """The number of spheres the network places (all but the base's)."""
        return self.num_spheres - self._num_base

    def extra_repr(self) -> str:
        return (
            f"robot={self.robot.name!r}, set={self.name!r}, spheres={self.num_spheres}, "
            f"learned={self.num_moving}, margin={float(self.margin):.4g} m"
        )

    def _weights_dtype(self) -> torch.dtype:
        return self.net[0].weight.dtype

    def _raw(self, q: torch.Tensor) -> torch.Tensor:
        """The network's output ``(N, 3 M_moving)`` in standardised units for joints ``(N, dof)``."""
        q = q.to(self._weights_dtype())
        return self.net(torch.cat((torch.sin(q), torch.cos(q)), dim=-1))

    def forward(self, q: torch.Tensor, validate: bool = True) -> torch.Tensor:
        """Sphere centres ``(..., M, 3)`` for joints ``q (..., dof)``.

        ``validate=False`` skips the dtype, shape and finiteness checks of ``q``.
        """
        if isinstance(q, np.ndarray):
            q = torch.from_numpy(q)
        if validate:
            check_real_dtype(q, "joint values q")
            check_last_dim(q, self.robot.dof, "joint values q")
            check_finite(q, "joint values q")
        batch = q.shape[:-1]
        flat = q.reshape(-1, self.robot.dof)
        y = self._raw(flat)
        y = y * self.out_scale.to(y.dtype) + self.out_mean.to(y.dtype)
        moving = y.reshape(flat.shape[0], self.num_moving, 3).to(q.dtype)
        base = self.base_centres.to(q.dtype).expand(flat.shape[0], self._num_base, 3)
        return torch.cat((base, moving), dim=1).reshape(*batch, self.num_spheres, 3)

    centres = forward

    def radii_like(self, x: torch.Tensor) -> torch.Tensor:
        """The radii ``(M,)`` (margin included) in ``x``'s dtype and device."""
        return self.radii.to(dtype=x.dtype, device=x.device)

    @torch.no_grad()
    def set_margin(self, margin: float) -> LearnedBody:
        """Inflate every sphere's radius by ``margin`` metres (≥ 0) over the analytic radius; returns self.

        A body–obstacle distance then shrinks by ``margin`` and a self-collision pair's by twice it.
        """
        m = float(margin)
        if not (math.isfinite(m) and m >= 0.0):
            raise ConfigError(f"margin must be a finite number of metres ≥ 0, got {margin!r}")
        self.margin.fill_(m)
        self.radii.copy_(self.sphere_radii.to(self.radii) + m)
        return self

    # ----------------------------------------------------------------------------------------------
    # Training
    # ----------------------------------------------------------------------------------------------

    @torch.no_grad()
    def fit_normalization(self, target: torch.Tensor) -> None:
        """Output statistics from training targets ``(N, 3 M_moving)`` (metres): the mean of each
        coordinate and one scale for all, the root-mean-square deviation from those means."""
        target = target.double()
        mean = target.mean(0)
        self.out_mean.copy_(mean)
        self.out_scale.fill_(float((target - mean).square().mean().sqrt().clamp_min(1e-6)))

    def training_loss(self, q: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        """Mean squared error of the moving centres ``target (N, 3 M_moving)``, in output-scale units."""
        y = (target.to(self._weights_dtype()) - self.out_mean.to(self._weights_dtype())) / self.out_scale
        return (self._raw(q) - y).square().mean()

    def moving_centres(self, centres: torch.Tensor) -> torch.Tensor:
        """``(..., M, 3)`` centres → ``(..., 3 M_moving)``: the training target layout."""
        return centres[..., self._num_base :, :].reshape(*centres.shape[:-2], 3 * self.num_moving)


# --------------------------------------------------------------------------------------------------
# Checkpoints
# --------------------------------------------------------------------------------------------------


def _config_record(config: BodyModelConfig) -> dict:
    return {"body_format": BODY_MODEL_FORMAT, **config.to_dict()}


def save_body_model(model: LearnedBody, path: str | Path, extra: dict | None = None) -> Path:
    """Save a learned body (weights, margin, geometry, config, robot and format version) atomically.

    ``extra`` (tensors and plain values, e.g. training state) is stored beside; leave it out for a
    small weights-only file.
    """
    if not isinstance(model, LearnedBody):
        raise ConfigError(f"save_body_model needs a LearnedBody, got {type(model).__name__}")
    return save_checkpoint(
        path,
        kind=BODY_KIND,
        robot=model.robot.name,
        config=_config_record(model.config),
        state_dict=model.state_dict(),
        extra=extra,
    )


def load_body_model(path: str | Path, robot: Robot | str | None = None) -> LearnedBody:
    """Load a body model saved by :func:`save_body_model`.

    ``robot`` (a :class:`Robot` or its name; ``None``: any) must be the one it was trained for.
    Raises :class:`~kinlearn.CheckpointError` for a missing or corrupt file, another kind of model,
    another robot, another body model format, or a robot whose sphere model changed since training.
    """
    name = robot.name if isinstance(robot, Robot) else robot
    payload = load_checkpoint(path, kind=BODY_KIND, robot=name)
    config = dict(payload.get("config") or {})
    version = config.pop("body_format", None)
    if version != BODY_MODEL_FORMAT:
        raise CheckpointError(
            f"{path} holds body model format {version!r}; this kinlearn reads format {BODY_MODEL_FORMAT}"
        )
    try:
        cfg = BodyModelConfig.from_dict(config)
        model = LearnedBody(cfg)
        model.load_state_dict(payload["state_dict"], strict=True)
    except Exception as exc:
        raise CheckpointError(
            f"{path}: cannot rebuild the body model from its config and weights ({type(exc).__name__}: {exc})"
        ) from exc
    if model.robot.name != payload.get("robot"):
        raise CheckpointError(
            f"{path}: config robot {model.robot.name!r} != checkpoint robot {payload.get('robot')!r}"
        )
    _check_geometry(model, path)
    return model.eval()


def _check_geometry(model: LearnedBody, path) -> None:
    """The loaded geometry must be the robot's current analytic sphere model (+ the saved margin)."""
    ref = _analytic_body(model.config).state_dict()
    same = (
        torch.equal(model.link, ref["link"])
        and torch.equal(model.pairs, ref["pairs"])
        and torch.equal(model.floor_mask, ref["floor_mask"])
        and torch.allclose(model.lever, ref["lever"], rtol=0, atol=1e-9)
        and torch.allclose(model.base_centres, ref["local"][: model._num_base], rtol=0, atol=1e-9)
        and torch.allclose(model.radii, ref["radii"] + model.margin, rtol=0, atol=1e-9)
    )
    if not same:
        raise CheckpointError(
            f"{path} was trained against another sphere model of {model.robot.name!r} than the one this "
            "kinlearn bundles (radii, links, pairs or base spheres differ); train the body model again"
        )
