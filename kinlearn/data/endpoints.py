"""Endpoint pairs [s(0), s(T)] for training and evaluating the trajectory model.

Two presets (``EndpointConfig.preset``):

- ``"workspace"``: starts and goals drawn independently and uniformly within the robot's joint
  limits, shrunk about their middle to ``range_fraction`` of the range; any start–goal distance. This
  is what a user of a planner asks of it, and what the shipped planners are trained and judged on.
- ``"paper-task"`` (the default, kept for reproducing the paper): as in the paper's experiment, starts lie in a fixed neighbourhood of a home configuration and goals
are random reachable configurations whose end effector lies in a task region in front of the robot,
  above the table plane; the goal's joints are given. The paper's own generator is unpublished
  (the paper's Sect. 4 and Fig. 3); ours mirrors its plots: starts around ef ≈ (0.57, 0.2, 0.54) m for the iiwa14
  (the paper's (−0.2, 0.57, 0.54) in a base frame rotated 90° about z) and goals low, near a table.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import torch

from ..body.kinematics import kinematics
from ..body.robot import ROBOTS, Robot, load_robot
from ..body.state import StateLayout
from ..checks import as_real, check_region
from ..errors import ConfigError
from ..io import load_npz, save_npz

__all__ = [
    "ENDPOINT_PRESETS",
    "EndpointConfig",
    "EndpointPairs",
    "load_endpoints",
    "make_endpoints",
    "save_endpoints",
]

#: The ways of drawing endpoint pairs (see the module docstring).
ENDPOINT_PRESETS = ("paper-task", "workspace")

#: Home configurations (rad). iiwa14: end effector at ≈ (0.57, 0.20, 0.54) m, elbow up.
HOMES: dict[str, tuple[float, ...]] = {"iiwa14": (0.32, 0.43, 0.0, -1.35, 0.0, 1.06, 0.0)}
#: Task region of the iiwa14 (m, base frame): x_min, x_max, y_min, y_max, z_min, z_max. For other
#: robots it is scaled by their horizontal reach relative to the iiwa14's.
IIWA14_REGION = (0.3, 0.85, -0.5, 0.5, 0.1, 0.3)
IIWA14_REACH = 0.946  # shoulder-to-end-effector length: 0.42 + 0.40 + 0.126


@dataclass(frozen=True)
class EndpointConfig:
    """How endpoint pairs are drawn.

    ``home``: home configuration (default: :data:`HOMES` or the middle of the joint limits).
    ``start_spread``: starts are home + U(−spread, spread) per joint (rad), clipped to the limits.
    ``region``: goal end-effector box (m); ``None`` for the robot's default.
    ``min_distance``: smallest start–goal end-effector distance (m).
    ``goal_margin``: goal joints keep this far (rad) from the limits.
    ``preset``: ``"paper-task"`` (the fields above) or ``"workspace"``: starts and goals uniform
    within ``range_fraction`` of the joint range about its middle (``home``, ``start_spread``,
    ``region``, ``min_distance`` and ``goal_margin`` are then unused).
    """

    robot: str = "iiwa14"
    n: int = 12_000
    seed: int = 0
    home: tuple[float, ...] | None = None
    start_spread: float = 0.15
    region: tuple[float, float, float, float, float, float] | None = None
    min_distance: float = 0.2
    goal_margin: float = 0.05
    preset: Literal["paper-task", "workspace"] = "paper-task"
    range_fraction: float = 1.0

    def __post_init__(self) -> None:
        if isinstance(self.n, bool) or not isinstance(self.n, (int, np.integer)) or self.n < 1:
            raise ConfigError(f"EndpointConfig.n must be a positive number of pairs, got {self.n!r}")
        for name in ("start_spread", "min_distance", "goal_margin"):
            value = getattr(self, name)
            value = as_real(value, f"EndpointConfig.{name}", minimum=0.0, expected="a finite number ≥ 0")
            object.__setattr__(self, name, value)
        if self.region is not None:
            check_region(self.region, "EndpointConfig.region")


@dataclass
class EndpointPairs:
    """``start`` and ``goal`` states, each ``(N, dof + 3)`` float32, with the config that drew them."""

    start: torch.Tensor
    goal: torch.Tensor
    config: EndpointConfig

    def __len__(self) -> int:
        return self.start.shape[0]

    def split(self, n_first: int) -> tuple[EndpointPairs, EndpointPairs]:
        a = EndpointPairs(self.start[:n_first], self.goal[:n_first], self.config)
        b = EndpointPairs(self.start[n_first:], self.goal[n_first:], self.config)
        return a, b


def default_home(robot: Robot) -> torch.Tensor:
    spec = ROBOTS.get(robot.name)
    if spec is not None and spec.home is not None:
        return torch.tensor(spec.home, dtype=torch.float64)
    if robot.name in HOMES:
        return torch.tensor(HOMES[robot.name], dtype=torch.float64)
    return torch.as_tensor((robot.lower + robot.upper) / 2)


def default_region(robot: Robot) -> tuple[float, ...]:
    spec = ROBOTS.get(robot.name)
    if spec is not None and spec.region is not None:
        return spec.region
    if robot.name == "iiwa14":
        return IIWA14_REGION
    q = robot.sample(50_000, torch.Generator().manual_seed(0), dtype=torch.float64)
    p = kinematics(robot).position(q)
    reach = float(p[:, :2].norm(dim=-1).max())
    scale = reach / (IIWA14_REACH + 0.1)
    return tuple(v * scale for v in IIWA14_REGION)


def workspace_box(
    robot: Robot, range_fraction: float, dtype=torch.float64
) -> tuple[torch.Tensor, torch.Tensor]:
    """The joint box ``(lower, upper)`` holding ``range_fraction`` of each joint's range about its middle."""
    if not 0.0 < range_fraction <= 1.0:
        raise ConfigError(f"range_fraction must lie in (0, 1], got {range_fraction}")
    lo, hi = robot.limits(dtype)
    mid, half = (lo + hi) / 2, (hi - lo) / 2 * range_fraction
    return mid - half, mid + half


def _workspace_pairs(robot: Robot, config: EndpointConfig) -> EndpointPairs:
    lo, hi = workspace_box(robot, config.range_fraction)
    gen = torch.Generator().manual_seed(config.seed)
    q = lo + (hi - lo) * torch.rand(2, config.n, robot.dof, generator=gen, dtype=torch.float64)
    ef = kinematics(robot).position(q, validate=False)
    states = StateLayout(robot.dof).join(q, ef).float()
    return EndpointPairs(states[0], states[1], config)


def make_endpoints(config: EndpointConfig) -> EndpointPairs:
    """Draw ``config.n`` endpoint pairs, reproducibly from ``config.seed``."""
    robot = load_robot(config.robot)
    if config.n <= 0:
        raise ConfigError(f"EndpointConfig.n must be positive, got {config.n}")
    if config.preset not in ENDPOINT_PRESETS:
        raise ConfigError(
            f"unknown endpoint preset {config.preset!r}; choose one of {', '.join(ENDPOINT_PRESETS)}"
        )
    if config.preset == "workspace":
        return _workspace_pairs(robot, config)
    layout = StateLayout(robot.dof)
    kin = kinematics(robot)
    gen = torch.Generator().manual_seed(config.seed)
    home = torch.tensor(config.home, dtype=torch.float64) if config.home is not None else default_home(robot)
    if home.shape != (robot.dof,):
        raise ConfigError(f"home must have {robot.dof} joint values, got {tuple(home.shape)}")
    region = config.region if config.region is not None else default_region(robot)
    lo, hi = robot.limits(torch.float64)
    rlo = torch.tensor(region[0::2], dtype=torch.float64)
    rhi = torch.tensor(region[1::2], dtype=torch.float64)

    starts, goals, have, tries = [], [], 0, 0
    while have < config.n:
        tries += 1
        if tries > 200:
            raise ConfigError(
                f"could not find {config.n} goals in region {region} at ≥ {config.min_distance} m from the "
                f"starts for {robot.name}; widen the region or lower min_distance"
            )
        batch = max(4096, 8 * (config.n - have))
        noise = (
            2 * torch.rand(batch, robot.dof, generator=gen, dtype=torch.float64) - 1
        ) * config.start_spread
        q0 = torch.clamp(home + noise, lo, hi)
        qT = robot.sample(batch, gen, dtype=torch.float64, margin=config.goal_margin)
        p0, pT = kin.position(q0, validate=False), kin.position(qT, validate=False)
        ok = ((pT >= rlo) & (pT <= rhi)).all(dim=-1) & ((pT - p0).norm(dim=-1) >= config.min_distance)
        starts.append(layout.join(q0[ok], p0[ok]))
        goals.append(layout.join(qT[ok], pT[ok]))
        have += int(ok.sum())
    start = torch.cat(starts)[: config.n].float()
    goal = torch.cat(goals)[: config.n].float()
    return EndpointPairs(start, goal, config)


def save_endpoints(pairs: EndpointPairs, path: str | Path) -> Path:
    cfg = asdict(pairs.config)
    return save_npz(
        path,
        kind="endpoints",
        robot=pairs.config.robot,
        config=cfg,
        arrays={"start": pairs.start.numpy(), "goal": pairs.goal.numpy()},
    )


def load_endpoints(path: str | Path, robot: str | None = None) -> EndpointPairs:
    """Load pairs saved by :func:`save_endpoints`. Raises :class:`~kinlearn.errors.DatasetError` for a missing or
    corrupt file, one for another robot, or one whose arrays are missing, misshapen or not finite."""
    from ..errors import DatasetError

    meta, arrays = load_npz(path, kind="endpoints", robot=robot)
    try:
        cfg = dict(meta["config"])
        for key in ("home", "region"):
            if cfg.get(key) is not None:
                cfg[key] = tuple(cfg[key])
        config = EndpointConfig(**cfg)
    except (KeyError, TypeError, ValueError) as exc:
        raise DatasetError(f"{path} records an invalid endpoint config ({exc})") from exc
    missing = {"start", "goal"} - set(arrays)
    if missing:
        raise DatasetError(f"{path} lacks the array(s) {', '.join(sorted(missing))}")
    start = torch.from_numpy(np.asarray(arrays["start"], dtype=np.float32))
    goal = torch.from_numpy(np.asarray(arrays["goal"], dtype=np.float32))
    size = load_robot(config.robot).dof + 3
    for name, t in (("start", start), ("goal", goal)):
        if t.ndim != 2 or t.shape[1] != size or t.shape[0] != start.shape[0]:
            raise DatasetError(
                f"{path}: {name} must have shape (N, {size}) like the other array, got {tuple(t.shape)}"
            )
        bad = int((~torch.isfinite(t)).sum())
        if bad:
            raise DatasetError(
                f"{path}: {name} holds {bad} NaN/inf value(s); the file is corrupt, make the endpoints again"
            )
    return EndpointPairs(start, goal, config)
