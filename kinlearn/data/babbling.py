"""Motor babbling without a simulator: many random walkers in joint space, vectorised over walkers.

Each walker starts at a configuration drawn uniformly within the joint limits and holds an absolute
joint target, also drawn uniformly within the limits. At every step each joint moves toward its
target by at most ``max_step`` rad (the per-joint difference is clipped to ``[-max_step, max_step]``),
which models position control at a bounded joint speed for one control period (REFERENCE #4:
2 rad/s × 41.7 ms ≈ 0.083 rad). A joint that is within ``max_step`` of its target lands on it
exactly. When every joint of a walker has reached its target, the walker draws a new one; with
``retarget_prob > 0`` it also draws a new one with that probability at every step, before it
arrives. States never leave the limits: a step lies between the current state and a target that is
itself within the limits.

The recorded transition is (s(t), a(t), s(t+1)) with s = [θ, ef], ef = FK(θ) by the fast kinematics
path, and a(t) = θ(t+1) − θ(t), the realised joint change. The states of a walk are shared between
consecutive transitions (s(t+1) of one is s(t) of the next), so FK runs once per state, on the whole
batch of states after the walk.

All random numbers come from one ``torch.Generator`` seeded by ``BabblingConfig.seed``: the same
configuration gives the same data bit for bit (on the same torch build and dtype).
"""

from __future__ import annotations

import dataclasses
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
from ..io import load_npz, save_npz

__all__ = [
    "BabblingConfig",
    "Transitions",
    "babble",
    "load_transitions",
    "save_transitions",
]

DTYPES: dict[str, torch.dtype] = {"float32": torch.float32, "float64": torch.float64}


@dataclass(frozen=True)
class BabblingConfig:
    """Settings of one babbling run. ``walkers × steps`` transitions are produced.

    Attributes:
        robot: robot name (see :func:`kinlearn.available_robots`).
        walkers: random walkers run in parallel (independent walks).
        steps: steps per walker.
        max_step: largest joint change per step and joint, rad.
        seed: seeds the one generator all random numbers come from.
        retarget_prob: per-step probability of drawing a new target before the current one is reached.
        dtype: floating-point type of the data.
    """

    robot: str = "iiwa14"
    walkers: int = 1000
    steps: int = 500
    max_step: float = 0.083
    seed: int = 0
    retarget_prob: float = 0.0
    dtype: Literal["float32", "float64"] = "float32"

    def __post_init__(self) -> None:
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

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

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


def babble(config: BabblingConfig | None = None, robot: Robot | None = None) -> Transitions:
    """Run motor babbling; returns ``walkers × steps`` transitions ordered by (step, walker).

    ``robot`` may be given to use an already loaded robot (its name must match ``config.robot``).
    """
    cfg = config or BabblingConfig()
    robot = robot if robot is not None else load_robot(cfg.robot)
    if robot.name != cfg.robot:
        raise ConfigError(f"babbling config names robot {cfg.robot!r}, but {robot.name!r} was given")
    dtype = DTYPES[cfg.dtype]
    gen = torch.Generator().manual_seed(int(cfg.seed))
    theta = _walk(robot, cfg, gen, dtype)
    layout = StateLayout(robot.dof)
    ef = kinematics(robot, "fast").position(theta, validate=False)
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


def load_transitions(path: str | Path, robot: str | None = None) -> Transitions:
    """Load transitions saved by :func:`save_transitions`.

    Raises :class:`~kinlearn.DatasetError` for a missing or corrupt file, a file of another kind, or
    (when ``robot`` is given) a file made for another robot.
    """
    meta, arrays = load_npz(path, kind="babbling", robot=robot)
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
    if robot is not None and load_robot(robot).dof != dof:
        raise DatasetError(f"{path} has {dof} joints, robot {robot!r} has {load_robot(robot).dof}")
    return data
