"""A supervised (imitation) trajectory model: the baseline that learns to copy interpolated trajectories.

The self-supervised TM (:mod:`kinlearn.training.tm`) learns its waypoints through the frozen FM and
IM (Algorithm 1). This baseline instead regresses the same network onto *observed* trajectories:
"imitating observed trajectories" here means, for every endpoint pair [s(0), s(T)], the joint-space
linear interpolation from θ(0) to θ(T) (the baseline :func:`kinlearn.planning.baselines.joint_interpolation`), whose
end-effector waypoints FK(θ(k)), k = 1 … T − 1, are the targets. The loss is the plain mean squared
error between the TM's waypoints ŝ(1) … ŝ(T−1) and those targets; FM and IM play no part in
training.

The result is an ordinary :class:`~kinlearn.models.trajectory.TrajectoryModel` of the same size as the
learned one, so it plans through the very same IM/FM rollout::

    tm = train_imitation(train_pairs, epochs=50)
    plan = Planner(robot, tm, fm, im).plan(start, goal)
"""

from __future__ import annotations

import math
from typing import Literal

import torch
from tqdm.auto import tqdm

from ..body.kinematics import kinematics
from ..body.robot import load_robot
from ..body.state import StateLayout, straight_line
from ..data.endpoints import EndpointPairs
from ..errors import ConfigError
from ..models.trajectory import TMConfig, TrajectoryModel
from .loop import OptimConfig, make_optimizer, make_schedule, seed_everything

__all__ = ["imitation_loss", "imitation_targets", "train_imitation"]


def imitation_targets(pairs: EndpointPairs, steps: int = 11) -> torch.Tensor:
    """The waypoints to imitate, ``(N, steps - 1, 3)``: FK of the joint-space linear interpolation.

    These are the waypoints of ``joint_interpolation(robot, start, goal, steps)``, in the pairs' dtype.
    """
    robot = load_robot(pairs.config.robot)
    lay = StateLayout(robot.dof)
    line = straight_line(pairs.start[..., lay.joints], pairs.goal[..., lay.joints], steps)
    with torch.no_grad():
        return kinematics(robot, "fast").position(line[..., 1:-1, :], validate=False)


@torch.no_grad()
def imitation_loss(
    tm: TrajectoryModel,
    pairs: EndpointPairs,
    targets: torch.Tensor | None = None,
    batch_size: int = 4096,
) -> float:
    """Mean squared error (m²) of ``tm``'s waypoints against the imitation targets on ``pairs``."""
    if targets is None:
        targets = imitation_targets(pairs, tm.config.steps)
    n, total = len(pairs), 0.0
    for i in range(0, n, batch_size):
        wp = tm(pairs.start[i : i + batch_size], pairs.goal[i : i + batch_size])
        total += float((wp - targets[i : i + batch_size]).square().mean()) * wp.shape[0] / n
    return total


def train_imitation(
    train: EndpointPairs,
    epochs: int = 50,
    batch_size: int = 64,
    optim: OptimConfig | None = None,
    seed: int = 0,
    progress: bool = True,
    *,
    tm_config: TMConfig | None = None,
    schedule: Literal["constant", "cosine"] = "cosine",
    history: list[float] | None = None,
) -> TrajectoryModel:
    """Train a TM by supervised regression onto the interpolated trajectories of ``train``.

    ``optim`` defaults to the self-supervised TM's default (RMSprop, lr 1e-3, γ = 0.99) and
    ``schedule`` to its cosine decay, so the two differ only in what they are trained on.
    ``tm_config`` defaults to :class:`TMConfig` for the pairs' robot (the same size as the learned
    TM). When ``history`` is given, the mean training loss of every epoch is appended to it.
    Deterministic for a given ``seed``. Returns the model in eval mode.
    """
    if epochs <= 0 or batch_size <= 0:
        raise ConfigError(f"epochs and batch_size must be positive, got {epochs} and {batch_size}")
    if schedule not in ("constant", "cosine"):
        raise ConfigError(f"schedule must be 'constant' or 'cosine', got {schedule!r}")
    robot = load_robot(train.config.robot)
    if tm_config is None:
        tm_config = TMConfig(robot=robot.name, dof=robot.dof)
    if tm_config.robot != robot.name or tm_config.dof != robot.dof:
        raise ConfigError(
            f"TM config is for {tm_config.robot!r} ({tm_config.dof} joints), the pairs for {robot.name!r}"
        )
    optim = optim or OptimConfig(name="rmsprop", lr=1e-3, alpha=0.99)

    gen = seed_everything(seed)
    tm = TrajectoryModel(tm_config)
    tm.fit_normalization(train.start, train.goal)
    targets = imitation_targets(train, tm_config.steps)
    opt = make_optimizer(optim, tm.parameters())
    n = len(train)
    total = epochs * math.ceil(n / batch_size)
    sched = make_schedule(opt, schedule, total)

    tm.train()
    bar = tqdm(range(epochs), desc="train imitation TM", disable=not progress)
    for _ in bar:
        perm = torch.randperm(n, generator=gen)
        epoch_loss = 0.0
        for i in range(0, n, batch_size):
            idx = perm[i : i + batch_size]
            loss = (tm(train.start[idx], train.goal[idx]) - targets[idx]).square().mean()
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            sched.step()
            epoch_loss += float(loss.detach()) * idx.numel() / n
        if history is not None:
            history.append(epoch_loss)
        bar.set_postfix(mse=f"{epoch_loss:.3g}")
    tm.eval()
    return tm
