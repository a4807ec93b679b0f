"""The joint-path trajectory model: a TM that predicts whole states, joints included.

The paper's TM (:mod:`kinlearn.models.trajectory`) has one prediction head, the end effector of each
intermediate waypoint, and leaves the joints to the IM/FM rollout; its future work asks to model
the joint configuration directly. This TM has both heads: for each of the T − 1 intermediate
waypoints it predicts the joints θ̂(t) and the end effector ê(t), i.e. the whole state ŝ(t).

The joint head is a correction of the straight joint-space line, θ̂(t) = θ(0) + (t/T)(θ(T) − θ(0)) +
h ⊙ r(t) with h the joints' half ranges, so a plan starts and ends exactly at the given joints and
an untrained model is joint interpolation. The end-effector head is likewise ê(t) = ef(0) +
(t/T)(ef(T) − ef(0)) + e(t). The decoder is a multilayer perceptron over the problem's features:
the paper's GRU receives the same input at every step, so it is a fixed-length decoder too, and an
MLP emits all waypoints in one pass, which is what makes a batch-1 plan cheap
(:mod:`kinlearn.planning.inference`).

The problem's features are [s(0), s(T), θ(T) − θ(0)], standardised; further inputs (goal kinds,
obstacles) join by extending :meth:`JointPathModel.features`.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import torch
from torch import nn

from ..body.state import StateLayout
from ..errors import CheckpointError, ConfigError
from ..io import load_checkpoint, resolve_dependency, save_checkpoint

__all__ = [
    "JointPathConfig",
    "JointPathModel",
    "PathOutput",
    "RobotModelConfig",
    "densify",
    "load_path_model",
    "save_path_model",
]


class RobotModelConfig:
    """What the model configs that carry a robot's joint limits share (fields ``robot``, ``dof``,
    ``lower``, ``upper``): building one for a robot, the limits' check, and a JSON-able dict."""

    def _check_limits(self) -> None:
        if len(self.lower) != self.dof or len(self.upper) != self.dof:
            raise ConfigError(
                f"lower and upper must hold the {self.dof} joint limits (use {type(self).__name__}.for_robot)"
            )
        if any(lo >= hi for lo, hi in zip(self.lower, self.upper, strict=True)):
            raise ConfigError("every lower joint limit must be below its upper limit")

    @classmethod
    def for_robot(cls, robot, **fields):
        """A config for a :class:`~kinlearn.body.robot.Robot`, its joint limits filled in (lists become tuples)."""
        fields = {k: tuple(v) if isinstance(v, list) else v for k, v in fields.items()}
        return cls(
            robot=robot.name,
            dof=robot.dof,
            lower=tuple(float(v) for v in robot.lower),
            upper=tuple(float(v) for v in robot.upper),
            **fields,
        )

    def to_dict(self) -> dict:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(self).items()}

    @classmethod
    def from_dict(cls, d: dict):
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = set(d) - names
        if unknown:
            raise ConfigError(f"unknown {cls.__name__} field(s): {', '.join(sorted(unknown))}")
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in d.items()})


@dataclass(frozen=True)
class JointPathConfig(RobotModelConfig):
    """Architecture of the joint-path TM.

    ``steps`` is T: T − 1 intermediate waypoints (the paper's T = 11). ``hidden``: widths of the MLP's
    hidden layers. ``activation``: ``"tanh"`` or ``"silu"``. ``modes``: 0 for a free joint correction
    r(t) at every waypoint; k > 0 for a smooth one, r(t) = Σ_{j=1..k} c_j sin(jπt/T), the network
    predicting the coefficients c_j (k · dof numbers): a path without joint-space kinks by
    construction. ``lower``/``upper``: the robot's joint limits (the joint head's scale and the
    planner's clamp); filled by :meth:`for_robot`.
    """

    robot: str = "iiwa14"
    dof: int = 7
    steps: int = 11
    hidden: tuple[int, ...] = (256, 256, 256)
    activation: Literal["tanh", "silu"] = "silu"
    modes: int = 0
    lower: tuple[float, ...] = ()
    upper: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        if int(self.steps) < 2:
            raise ConfigError(f"steps (T) must be ≥ 2, got {self.steps}")
        if int(self.dof) < 1:
            raise ConfigError(f"dof must be ≥ 1, got {self.dof}")
        if not self.hidden or any(int(w) < 1 for w in self.hidden):
            raise ConfigError(f"hidden must be a non-empty tuple of positive widths, got {self.hidden}")
        if isinstance(self.modes, bool) or not isinstance(self.modes, int) or self.modes < 0:
            raise ConfigError(f"modes must be an integer ≥ 0, got {self.modes!r}")
        if self.activation not in ("tanh", "silu"):
            raise ConfigError(f"activation must be 'tanh' or 'silu', got {self.activation!r}")
        self._check_limits()


@dataclass(frozen=True)
class PathOutput:
    """The TM's prediction for a batch: ``joints (N, T − 1, dof)`` θ̂(1) … θ̂(T−1) (not yet clamped to
    the limits) and ``ef (N, T − 1, 3)`` ê(1) … ê(T−1)."""

    joints: torch.Tensor
    ef: torch.Tensor


def mlp_layers(sizes, activation: str) -> list[nn.Module]:
    """Linear layers between consecutive ``sizes``, each followed by the activation (``"tanh"``/``"silu"``)."""
    act = {"tanh": nn.Tanh, "silu": nn.SiLU}[activation]
    layers: list[nn.Module] = []
    for a, b in itertools.pairwise(sizes):
        layers += [nn.Linear(a, b), act()]
    return layers


def register_path_buffers(module: nn.Module, config) -> None:
    """The buffers of a TM whose joint paths bend the straight joint line with sine modes: ``lower``,
    ``upper`` and ``half_range`` of the joint limits, ``fractions`` t/T of the intermediate knots and
    (not saved: derived from the config) ``basis`` ``(T − 1, modes)``, sin(jπt/T) at each knot."""
    lower = torch.tensor(config.lower, dtype=torch.float64)
    upper = torch.tensor(config.upper, dtype=torch.float64)
    module.register_buffer("lower", lower.float())
    module.register_buffer("upper", upper.float())
    module.register_buffer("half_range", ((upper - lower) / 2).float())
    module.register_buffer("fractions", torch.arange(1, config.steps, dtype=torch.float32) / config.steps)
    t = torch.arange(1, config.steps, dtype=torch.float64) / config.steps
    k = torch.arange(1, config.modes + 1, dtype=torch.float64)
    module.register_buffer("basis", torch.sin(torch.pi * t[:, None] * k).float(), persistent=False)


class JointPathModel(nn.Module):
    """``forward(s0 (N, S), sT (N, S)) -> PathOutput``; see the module docstring."""

    #: Checkpoint kind, distinct from the paper's waypoint TM.
    kind = "tm-joint-path"

    def __init__(self, config: JointPathConfig):
        super().__init__()
        self.config = config
        self.layout = StateLayout(config.dof)
        dof, S, W = config.dof, self.layout.size, config.steps - 1
        n_in = self.n_features
        layers = mlp_layers((n_in, *config.hidden), config.activation)
        n_joint_out = config.modes * dof if config.modes else W * dof
        out = nn.Linear(config.hidden[-1], n_joint_out + W * 3)
        with torch.no_grad():  # start as the straight joint line: small corrections only
            out.weight.mul_(0.01)
            out.bias.zero_()
        self.net = nn.Sequential(*layers, out)
        register_path_buffers(self, config)
        self.register_buffer("in_mean", torch.zeros(n_in))
        self.register_buffer("in_std", torch.ones(n_in))
        #: Box of the training problems' features [s(0), s(T)] (the domain the planner warns outside of).
        self.register_buffer("domain_lo", torch.full((2 * S,), -torch.inf))
        self.register_buffer("domain_hi", torch.full((2 * S,), torch.inf))
        #: Scale of the end-effector head's correction (m).
        self.ef_scale = 0.1

    @property
    def robot_name(self) -> str:
        return self.config.robot

    @property
    def n_features(self) -> int:
        return 2 * self.layout.size + self.config.dof

    def features(self, s0: torch.Tensor, sT: torch.Tensor) -> torch.Tensor:
        """Unstandardised input features ``(N, n_features)`` of a batch of problems."""
        J = self.layout.joints
        return torch.cat((s0, sT, sT[:, J] - s0[:, J]), dim=-1)

    @torch.no_grad()
    def fit_normalization(self, s0: torch.Tensor, sT: torch.Tensor, domain: tuple | None = None) -> None:
        """Standardise the features with statistics of training problems; record their domain.

        ``domain``: ``(lower, upper)`` of [s(0), s(T)] (each ``(2·S,)``), by default the problems'
        own per-coordinate minimum and maximum.
        """
        x = self.features(s0.double(), sT.double())
        self.in_mean.copy_(x.mean(0))
        self.in_std.copy_(x.std(0).clamp_min(1e-3))
        if domain is None:
            both = torch.cat((s0, sT), dim=-1).double()
            domain = (both.min(0).values, both.max(0).values)
        self.domain_lo.copy_(torch.as_tensor(domain[0]))
        self.domain_hi.copy_(torch.as_tensor(domain[1]))

    def forward(self, s0: torch.Tensor, sT: torch.Tensor) -> PathOutput:
        J, E = self.layout.joints, self.layout.ef
        n, W, dof = s0.shape[0], self.config.steps - 1, self.config.dof
        y = self.net((self.features(s0, sT) - self.in_mean) / self.in_std)
        f = self.fractions[:, None]
        theta0, ef0 = s0[:, None, J], s0[:, None, E]
        nj = self.config.modes * dof if self.config.modes else W * dof
        r = y[:, :nj].reshape(n, -1, dof)
        if self.config.modes:
            r = self.basis @ r
        joints = theta0 + f * (sT[:, None, J] - theta0) + self.half_range * r
        ef = ef0 + f * (sT[:, None, E] - ef0) + self.ef_scale * y[:, nj:].reshape(n, W, 3)
        return PathOutput(joints=joints, ef=ef)


def substeps(step: float, max_step: float, multiple_of: int = 1) -> int:
    """The number m of equal sub-steps that splits a joint step of ``step`` rad into steps ≤ ``max_step``
    (rounded up to a multiple of ``multiple_of``)."""
    m = max(1, math.ceil(step / max_step - 1e-9))
    return -(-m // multiple_of) * multiple_of


def densify(knots: torch.Tensor, max_step: float, multiple_of: int = 1) -> tuple[torch.Tensor, int]:
    """Refine a joint path so that no joint moves more than ``max_step`` (rad) per step.

    ``knots``: ``(N, K + 1, dof)``. Every segment is split into the same number m of equal steps, the
    smallest that keeps the whole batch within the bound (rounded up to a multiple of
    ``multiple_of``). Returns the path ``(N, K·m + 1, dof)`` (knot k at index k·m) and m.
    """
    step = float((knots[:, 1:] - knots[:, :-1]).detach().abs().amax()) if knots.numel() else 0.0
    m = substeps(step, max_step, multiple_of)
    if m == 1:
        return knots, 1
    f = torch.arange(m, dtype=knots.dtype, device=knots.device)[:, None] / m
    seg = knots[:, :-1, None] + f * (knots[:, 1:, None] - knots[:, :-1, None])
    dense = torch.cat((seg.reshape(knots.shape[0], -1, knots.shape[-1]), knots[:, -1:]), dim=1)
    return dense, m


def save_path_model(
    tm: JointPathModel, path: str | Path, extra: dict | None = None, depends: dict | None = None
) -> Path:
    """Save a joint-path TM: weights, its own config, robot and format version (atomically).

    ``depends``: the models a planner folder holds beside it, ``{"fm": path, "im": path}``, recorded by
    relative path and content hash (:func:`kinlearn.io.save_checkpoint`).
    """
    return save_checkpoint(
        path,
        kind=JointPathModel.kind,
        robot=tm.robot_name,
        config=tm.config.to_dict(),
        state_dict=tm.state_dict(),
        extra=extra or {},
        depends=depends,
    )


def load_path_model(
    path: str | Path,
    robot: str | None = None,
    *,
    with_dependencies: bool = False,
    payload: dict | None = None,
):
    """Load a joint-path TM saved by :func:`save_path_model` (training state, if any, is ignored).

    With ``with_dependencies`` also return ``{"fm": Path, "im": Path}``: the models it records, found and
    hash-checked (:func:`kinlearn.io.resolve_dependency`), or, where it records none, the ``fm.pt``/``im.pt``
    beside it. ``payload``: the file's content as :func:`~kinlearn.io.load_checkpoint` already read and
    verified it (the file is then not read again); its kind and robot are checked here.
    """
    path = Path(path)
    if payload is None:
        payload = load_checkpoint(path, kind=JointPathModel.kind, robot=robot)
    elif payload.get("kind") != JointPathModel.kind or (robot is not None and payload.get("robot") != robot):
        raise CheckpointError(
            f"{path} holds a {payload.get('kind')!r} checkpoint for {payload.get('robot')!r}, not a "
            f"{JointPathModel.kind!r} for {robot or 'any robot'!r}"
        )
    try:
        tm = JointPathModel(JointPathConfig.from_dict(payload["config"]))
        state = dict(payload["state_dict"])
        state.pop("basis", None)  # derived from the config (stored by early checkpoints)
        tm.load_state_dict(state)
    except (TypeError, KeyError, RuntimeError, ConfigError) as exc:
        raise CheckpointError(
            f"{path}: the joint-path TM checkpoint does not match this kinlearn ({exc})"
        ) from exc
    tm.eval()
    if not with_dependencies:
        return tm
    sources = {}
    for kind in ("fm", "im"):
        if kind in payload.get("depends", {}):
            sources[kind] = resolve_dependency(path, payload, kind)
        elif (path.parent / f"{kind}.pt").is_file():
            sources[kind] = path.parent / f"{kind}.pt"
    return tm, sources
