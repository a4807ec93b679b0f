"""Motor babbling without a simulator: many random walkers in joint space, vectorised over walkers.

Each walker starts at a configuration drawn uniformly within the joint limits and holds an absolute
joint target, also drawn uniformly within the limits. At every step each joint moves toward its
target by at most ``max_step`` rad (the per-joint difference is clipped to ``[-max_step, max_step]``),
which models position control at a bounded joint speed for one control period (the earlier paper's babbling, Cibula et al., ICANN 2024, Sect. 4.1, in its
code github.com/Mcibula/causal-learning-arm: 2 rad/s × 41.7 ms ≈ 0.083 rad). A joint that is within ``max_step`` of its target lands on it
exactly. When every joint of a walker has reached its target, the walker draws a new one; with
``retarget_prob > 0`` it also draws a new one with that probability at every step, before it
arrives. States never leave the limits: a step lies between the current state and a target that is
itself within the limits.

The recorded transition is (s(t), a(t), s(t+1)) with s = [θ, ef], ef = FK(θ) by the fast kinematics
path, and a(t) = θ(t+1) − θ(t), the realised joint change. The states of a walk are shared between
consecutive transitions (s(t+1) of one is s(t) of the next), so FK runs once per state, on the whole
batch of states after the walk.

The end effector may be observed with sensor noise, as a camera or motion capture would see it: each
state's ef gets Gaussian noise of ``ef_noise`` m per coordinate, and a share ``outliers`` of the states
is displaced by ``outlier_size`` m in a uniformly random direction. A state is observed once: s(t+1)
of one transition and s(t) of the next carry the same noisy ef. The actions stay the true joint changes
(joint encoders are exact). The true robot is a named one, or any URDF (``urdf`` + ``ee_frame``, its
SHA-256 recorded in the config).

All random numbers come from one ``torch.Generator`` seeded by ``BabblingConfig.seed``: the same
configuration gives the same data bit for bit (on the same torch build and dtype). The noise is drawn
after the walk, so noiseless babbling of a seed is the same with or without these options.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import torch

from ..body.kinematics import kinematics
from ..body.robot import Robot, load_robot
from ..body.state import StateLayout
from ..checks import check_finite, check_last_dim
from ..errors import ConfigError, DatasetError
from ..io import file_sha256, load_npz, save_npz

__all__ = [
    "MAX_STEP",
    "BabblingConfig",
    "Transitions",
    "babble",
    "load_transitions",
    "save_transitions",
]

#: The babbling step bound: the largest joint change per step and joint, rad (Cibula et al., ICANN 2024: 2 rad/s × 41.7 ms).
#: A learned FM is valid for actions within the bound of the data it learned from, which it records
#: (:attr:`kinlearn.models.interface.ForwardModel.max_step`); this is the default everywhere.
MAX_STEP = 0.083

DTYPES: dict[str, torch.dtype] = {"float32": torch.float32, "float64": torch.float64}
#: Fields of :class:`BabblingConfig` that :meth:`~BabblingConfig.to_dict` leaves out at their defaults.
_OBSERVATION_FIELDS = ("ef_noise", "outliers", "outlier_size", "urdf", "ee_frame", "urdf_sha256")


@dataclass(frozen=True)
class BabblingConfig:
    """Settings of one babbling run. ``walkers × steps`` transitions are produced.

    Attributes:
        robot: robot name (see :func:`kinlearn.available_robots`); with ``urdf``, the name the data carry
            (default: the URDF file's stem, as :func:`kinlearn.load_robot` names it). Default ``"iiwa14"``.
        walkers: random walkers run in parallel (independent walks).
        steps: steps per walker.
        max_step: largest joint change per step and joint, rad.
        seed: seeds the one generator all random numbers come from.
        retarget_prob: per-step probability of drawing a new target before the current one is reached.
        dtype: floating-point type of the data.
        ef_noise: standard deviation (m) of the Gaussian noise on each coordinate of each observed ef.
        outliers: share of the observed states, in [0, 1), whose ef is displaced by ``outlier_size``.
        outlier_size: how far (m, > 0) an outlier's ef is displaced, in a uniformly random direction.
        urdf: the true robot's URDF file, instead of the named robot's (needs ``ee_frame``).
        ee_frame: the end-effector link of ``urdf``.
        urdf_sha256: the SHA-256 of ``urdf``'s bytes (taken from the file when not given); babbling
            refuses a file that no longer has it.
    """

    robot: str | None = None
    walkers: int = 1000
    steps: int = 500
    max_step: float = MAX_STEP
    seed: int = 0
    retarget_prob: float = 0.0
    dtype: Literal["float32", "float64"] = "float32"
    ef_noise: float = 0.0
    outliers: float = 0.0
    outlier_size: float = 0.05
    urdf: str | None = None
    ee_frame: str | None = None
    urdf_sha256: str | None = None

    def __post_init__(self) -> None:
        self._check_observation()
        self._check_source()
        if int(self.walkers) < 1 or int(self.steps) < 1:
            raise ConfigError(
                f"walkers and steps must be ≥ 1, got walkers={self.walkers}, steps={self.steps}"
            )
        if not (self.max_step > 0.0 and np.isfinite(self.max_step)):
            raise ConfigError(f"max_step must be a positive number of radians, got {self.max_step}")
        if not 0.0 <= self.retarget_prob <= 1.0:
            raise ConfigError(f"retarget_prob must lie in [0, 1], got {self.retarget_prob}")
        if self.dtype not in DTYPES:
            raise ConfigError(f"dtype must be one of {', '.join(DTYPES)}, got {self.dtype!r}")

    @property
    def transitions(self) -> int:
        return self.walkers * self.steps

    @classmethod
    def for_transitions(cls, n: int, walkers: int = 1000, **kwargs) -> BabblingConfig:
        """A config giving at least ``n`` transitions with ``walkers`` walkers (fewer if ``n`` is small).

        Raises :class:`~kinlearn.ConfigError` unless ``n`` and ``walkers`` are ≥ 1.
        """
        if int(n) < 1 or int(walkers) < 1:
            raise ConfigError(f"need at least 1 transition and 1 walker, got n={n}, walkers={walkers}")
        walkers = min(int(walkers), int(n))
        return cls(walkers=walkers, steps=-(-n // walkers), **kwargs)

    def _check_observation(self) -> None:
        if not (math.isfinite(self.ef_noise) and self.ef_noise >= 0.0):
            raise ConfigError(f"ef_noise must be a finite number of metres ≥ 0, got {self.ef_noise}")
        if not 0.0 <= self.outliers < 1.0:
            raise ConfigError(f"outliers must be a share of the states in [0, 1), got {self.outliers}")
        if not (math.isfinite(self.outlier_size) and self.outlier_size > 0.0):
            raise ConfigError(f"outlier_size must be a positive number of metres, got {self.outlier_size}")

    def _check_source(self) -> None:
        if self.urdf is None:
            if self.ee_frame is not None or self.urdf_sha256 is not None:
                raise ConfigError("ee_frame and urdf_sha256 belong to a urdf; give urdf=<the URDF file> too")
            if self.robot is None:
                object.__setattr__(self, "robot", "iiwa14")
            return
        if not self.ee_frame:
            raise ConfigError(f"urdf={self.urdf!r} needs ee_frame=<the name of its end-effector link>")
        object.__setattr__(self, "urdf", str(self.urdf))
        if self.robot is None:
            object.__setattr__(self, "robot", Path(self.urdf).stem)
        if self.urdf_sha256 is None:
            if not Path(self.urdf).is_file():
                raise ConfigError(f"no URDF file at {self.urdf}")
            object.__setattr__(self, "urdf_sha256", file_sha256(self.urdf))

    def to_dict(self) -> dict:
        """The config as a JSON-able dict. Noiseless babbling of a named robot leaves out the observation
        and URDF fields (all at their defaults), so that its record is what it was before they existed."""
        d = dataclasses.asdict(self)
        defaults = {f.name: f.default for f in dataclasses.fields(self) if f.name in _OBSERVATION_FIELDS}
        if all(d[name] == value for name, value in defaults.items()):
            for name in defaults:
                del d[name]
        return d

    @classmethod
    def from_dict(cls, d: dict) -> BabblingConfig:
        names = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: v for k, v in d.items() if k in names})


@dataclass
class Transitions:
    """A batch of transitions ``s (N, S)``, ``a (N, dof)``, ``s_next (N, S)`` of one robot, S = dof + 3."""

    s: torch.Tensor
    a: torch.Tensor
    s_next: torch.Tensor
    robot: str
    config: dict = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        dof = self.a.shape[-1] if isinstance(self.a, torch.Tensor) and self.a.ndim else 0
        check_last_dim(self.a, dof, "actions a")
        check_last_dim(self.s, dof + 3, "states s")
        check_last_dim(self.s_next, dof + 3, "next states s_next")
        if not (self.s.ndim == self.a.ndim == self.s_next.ndim == 2) or not (
            self.s.shape[0] == self.a.shape[0] == self.s_next.shape[0]
        ):
            raise DatasetError(
                f"transitions need s (N, S), a (N, dof), s_next (N, S) with one N; got "
                f"{tuple(self.s.shape)}, {tuple(self.a.shape)}, {tuple(self.s_next.shape)}"
            )

    @property
    def layout(self) -> StateLayout:
        return StateLayout(self.a.shape[-1])

    def __len__(self) -> int:
        return self.s.shape[0]

    def tensors(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        return self.s, self.a, self.s_next

    def subset(self, idx: torch.Tensor | slice) -> Transitions:
        return Transitions(self.s[idx], self.a[idx], self.s_next[idx], self.robot, self.config)

    def to(self, dtype: torch.dtype | None = None, device=None) -> Transitions:
        return Transitions(
            *(t.to(dtype=dtype, device=device) for t in self.tensors()), robot=self.robot, config=self.config
        )

    def split(self, val_fraction: float, seed: int = 0) -> tuple[Transitions, Transitions]:
        """A random (seeded) split into training and held-out transitions."""
        if not 0.0 <= val_fraction < 1.0:
            raise ConfigError(f"val_fraction must lie in [0, 1), got {val_fraction}")
        n = len(self)
        n_val = round(n * val_fraction)
        perm = torch.randperm(n, generator=torch.Generator().manual_seed(seed))
        return self.subset(perm[n_val:]), self.subset(perm[:n_val])

    def save(self, path: str | Path) -> Path:
        return save_transitions(self, path)


def _walk(robot: Robot, cfg: BabblingConfig, gen: torch.Generator, dtype: torch.dtype) -> torch.Tensor:
    """Joint values of every walker at every time: ``(steps + 1, walkers, dof)``."""
    lo, hi = robot.limits(dtype)
    span = hi - lo
    w, dof = cfg.walkers, robot.dof
    theta = torch.empty((cfg.steps + 1, w, dof), dtype=dtype)
    theta[0] = lo + span * torch.rand((w, dof), generator=gen, dtype=dtype)
    target = lo + span * torch.rand((w, dof), generator=gen, dtype=dtype)
    m = float(cfg.max_step)
    for t in range(cfg.steps):
        cur = theta[t]
        d = target - cur
        near = d.abs() <= m
        nxt = torch.where(near, target, cur + d.clamp(-m, m))
        theta[t + 1] = nxt
        # Draw new targets for every walker (a fixed number of random numbers per step keeps the
        # stream independent of the walk), keep them where the walker arrived or retargets.
        fresh = lo + span * torch.rand((w, dof), generator=gen, dtype=dtype)
        redraw = near.all(dim=-1, keepdim=True)
        if cfg.retarget_prob > 0.0:
            redraw = redraw | (torch.rand((w, 1), generator=gen, dtype=dtype) < cfg.retarget_prob)
        target = torch.where(redraw, fresh, target)
    return theta


def _observe(ef: torch.Tensor, cfg: BabblingConfig, gen: torch.Generator) -> torch.Tensor:
    """The end effectors ``(steps + 1, walkers, 3)`` as observed: Gaussian noise, then the outliers.
    Draws nothing without noise or outliers."""
    if cfg.ef_noise > 0.0:
        ef = ef + cfg.ef_noise * torch.randn(ef.shape, generator=gen, dtype=ef.dtype)
    if cfg.outliers > 0.0:
        flat = ef.reshape(-1, 3).clone()
        n = round(cfg.outliers * flat.shape[0])
        idx = torch.randperm(flat.shape[0], generator=gen)[:n]
        direction = torch.randn((n, 3), generator=gen, dtype=ef.dtype)
        flat[idx] += cfg.outlier_size * direction / direction.norm(dim=-1, keepdim=True)
        ef = flat.reshape(ef.shape)
    return ef


def _true_robot(cfg: BabblingConfig) -> Robot:
    """The robot babbled with: the named one, or the config's URDF, checked against its recorded hash."""
    if cfg.urdf is None:
        return load_robot(cfg.robot)
    path = Path(cfg.urdf)
    if not path.is_file():
        raise ConfigError(f"no URDF file at {path} (the babbling config's urdf)")
    urdf = path.read_bytes()
    sha = hashlib.sha256(urdf).hexdigest()
    if sha != cfg.urdf_sha256:
        raise ConfigError(
            f"{path} has sha256 {sha}, the babbling config records {cfg.urdf_sha256}: the URDF changed; "
            "babble from the file recorded, or make a new config"
        )
    return Robot(cfg.robot, urdf, cfg.ee_frame, path)


def babble(config: BabblingConfig | None = None, robot: Robot | None = None) -> Transitions:
    """Run motor babbling; returns ``walkers × steps`` transitions ordered by (step, walker).

    ``robot`` may be given to use an already loaded robot (its name must match ``config.robot``; with
    ``config.urdf``, its URDF must be that file's bytes).
    """
    cfg = config or BabblingConfig()
    robot = robot if robot is not None else _true_robot(cfg)
    if robot.name != cfg.robot:
        raise ConfigError(f"babbling config names robot {cfg.robot!r}, but {robot.name!r} was given")
    if cfg.urdf is not None and (
        hashlib.sha256(robot.urdf).hexdigest() != cfg.urdf_sha256 or robot.ee_frame != cfg.ee_frame
    ):
        raise ConfigError(
            f"the robot given is not the babbling config's URDF {cfg.urdf} (sha256 {cfg.urdf_sha256}, "
            f"end effector {cfg.ee_frame!r})"
        )
    dtype = DTYPES[cfg.dtype]
    gen = torch.Generator().manual_seed(int(cfg.seed))
    theta = _walk(robot, cfg, gen, dtype)
    layout = StateLayout(robot.dof)
    ef = _observe(kinematics(robot, "fast").position(theta, validate=False), cfg, gen)
    states = layout.join(theta, ef)  # (steps + 1, walkers, S)
    S = layout.size
    s = states[:-1].reshape(-1, S)
    s_next = states[1:].reshape(-1, S)
    a = (theta[1:] - theta[:-1]).reshape(-1, robot.dof)
    return Transitions(s, a, s_next, robot.name, cfg.to_dict())


def save_transitions(data: Transitions, path: str | Path) -> Path:
    """Save transitions as ``.npz`` with their robot name and config (atomically)."""
    arrays = {k: t.detach().cpu().numpy() for k, t in zip(("s", "a", "s_next"), data.tensors(), strict=True)}
    return save_npz(path, kind="babbling", robot=data.robot, config=data.config, arrays=arrays)


def load_transitions(path: str | Path, robot: str | Robot | None = None) -> Transitions:
    """Load transitions saved by :func:`save_transitions`.

    Raises :class:`~kinlearn.errors.DatasetError` for a missing or corrupt file, a file of another kind, or
    (when ``robot`` is given: a name or a :class:`~kinlearn.Robot`) a file made for another robot.
    """
    name = robot.name if isinstance(robot, Robot) else robot
    meta, arrays = load_npz(path, kind="babbling", robot=name)
    missing = {"s", "a", "s_next"} - set(arrays)
    if missing:
        raise DatasetError(f"{path} lacks the array(s) {', '.join(sorted(missing))}")
    tensors = [torch.from_numpy(np.ascontiguousarray(arrays[k])) for k in ("s", "a", "s_next")]
    try:
        data = Transitions(*tensors, robot=meta.get("robot", ""), config=meta.get("config", {}))
    except Exception as exc:
        raise DatasetError(f"{path} holds inconsistent transitions: {exc}") from exc
    for t, what in zip(tensors, ("s", "a", "s_next"), strict=True):
        try:
            check_finite(t, f"{path}: {what}")
        except Exception as exc:
            raise DatasetError(str(exc)) from exc
    dof = data.layout.dof
    if robot is not None:
        robot = robot if isinstance(robot, Robot) else load_robot(robot)
        if robot.dof != dof:
            raise DatasetError(f"{path} has {dof} joints, robot {name!r} has {robot.dof}")
    return data
