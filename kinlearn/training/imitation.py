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
from dataclasses import asdict
from pathlib import Path
from typing import Literal

import torch

from ..body.kinematics import kinematics
from ..body.robot import load_robot
from ..body.state import StateLayout, straight_line
from ..data.endpoints import EndpointPairs
from ..errors import CheckpointError, ConfigError
from ..io import content_sha256, load_checkpoint, save_checkpoint
from ..models.trajectory import TMConfig, TrajectoryModel
from .loop import OptimConfig, TrainingLoop, _load_to_resume, seed_everything

__all__ = ["IMITATION_KIND", "imitation_loss", "imitation_targets", "load_imitation", "train_imitation"]

#: The checkpoint kind of an imitation TM (not a waypoint TM's ``tm``: it was trained through no FM/IM).
IMITATION_KIND = "tm-imitation"


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
    run_dir: str | Path | None = None,
    resume: bool = True,
) -> TrajectoryModel:
    """Train a TM by supervised regression onto the interpolated trajectories of ``train``.

    ``optim`` defaults to the self-supervised TM's default (RMSprop, lr 1e-3, γ = 0.99) and
    ``schedule`` to its cosine decay, so the two differ only in what they are trained on.
    ``tm_config`` defaults to :class:`TMConfig` for the pairs' robot (the same size as the learned
    TM). When ``history`` is given, the mean training loss of every epoch is appended to it.
    With ``run_dir``, ``run_dir/metrics.jsonl`` and the checkpoint ``run_dir/imitation.pt``
    (:func:`load_imitation`) are written after every epoch and ``resume`` continues from that
    checkpoint (:class:`~kinlearn.CheckpointError` if it was made with other settings or pairs).
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
    n = len(train)
    run = dict(epochs=epochs, batch_size=batch_size, optim=asdict(optim), seed=seed, schedule=schedule)
    identity = {"data_sha256": content_sha256((train.start, train.goal))} if run_dir is not None else {}
    loop = TrainingLoop(
        tm,
        optim,
        total=epochs,
        generator=gen,
        train_config=run,
        schedule=schedule,
        steps_per_unit=math.ceil(n / batch_size),
        run_dir=run_dir,
        checkpoint=Path(run_dir) / "imitation.pt" if run_dir is not None else None,
        save=lambda path, extra: save_checkpoint(
            path,
            kind=IMITATION_KIND,
            robot=robot.name,
            config=tm_config.to_dict(),
            state_dict=tm.state_dict(),
            extra={**extra, **identity},
        ),
        desc="imitation TM training",
        progress=progress,
        postfix=("train/loss",),
    )
    if resume:
        loop.resume(
            lambda path: _load_to_resume(path, IMITATION_KIND, robot.name, tm_config.to_dict(), identity)
        )

    def epoch(_: int) -> dict:
        perm = torch.randperm(n, generator=gen)
        epoch_loss = 0.0
        for i in range(0, n, batch_size):
            idx = perm[i : i + batch_size]
            loss = loop.step((tm(train.start[idx], train.goal[idx]) - targets[idx]).square().mean())
            epoch_loss += float(loss) * idx.numel() / n
        loop.check(epoch_loss)
        return {"train/loss": epoch_loss}

    records = loop.run(epoch)
    if history is not None:
        history.extend(r["train/loss"] for r in records)
    return tm


def load_imitation(path: str | Path, robot: str | None = None) -> TrajectoryModel:
    """The imitation TM of a checkpoint written by :func:`train_imitation` (eval mode)."""
    payload = load_checkpoint(path, kind=IMITATION_KIND, robot=robot)
    try:
        tm = TrajectoryModel(TMConfig(**payload["config"]))
        tm.load_state_dict(payload["state_dict"])
    except (TypeError, KeyError, RuntimeError, ConfigError) as exc:
        raise CheckpointError(f"{path}: the imitation TM does not match this kinlearn ({exc})") from exc
    return tm.eval()
