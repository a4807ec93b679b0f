"""Trajectory-model training time per epoch: kinlearn's batched rectification against a per-sample loop.

    python benchmarks/tm_training_speed.py [--threads 1] [--pairs 12000] [--per-sample 200] [--analytic]

The per-sample loop is written here, not in kinlearn, to reproduce the structure of the authors'
code (github.com/Mcibula/traj-planning-icann2025): one endpoint pair at a time (batch 1), the TM's forward pass, then Algorithm 1
as 22 separate model calls (IM then FM for each of the T = 11 steps), the loss (paper Eq. 4, with
rectified targets computed without gradient), backward and an optimiser step per sample. kinlearn's
batched training step does the same computation for a whole batch: one IM and one FM call per time
step. Both run in the same process on the same pairs with the same frozen FM and IM (learned MLPs of
the paper's sizes, untrained, whose cost does not depend on their weights; analytic FK/DLS with
``--analytic``), with the FM/IM input finiteness checks switched off in every row (the authors' code
had none). The per-sample loop is timed on ``--per-sample`` pairs and the batched step on
``--batched-samples`` pairs; both are extrapolated to an epoch of ``--pairs`` pairs (the time per
sample is constant in both). The last row is one real epoch of ``train_tm`` at its default batch
size (default preset: the smooth loss, cosine schedule, checkpoint written after the epoch).
"""

from __future__ import annotations

import argparse
import tempfile
import time

import torch
from _common import header, show, write_result

from kinlearn import load_robot
from kinlearn.data.endpoints import EndpointConfig, make_endpoints
from kinlearn.models.forward_inverse import (
    AnalyticFM,
    AnalyticIM,
    FMConfig,
    IMConfig,
    LearnedFM,
    LearnedIM,
)
from kinlearn.models.rollout import LossConfig, rectify, tm_loss
from kinlearn.models.trajectory import TMConfig, TrajectoryModel
from kinlearn.training.loop import OptimConfig, make_optimizer
from kinlearn.training.tm import tm_preset, train_tm


def per_sample_epoch(tm, fm, im, start, goal, loss_cfg, opt) -> float:
    """The authors' structure: batch 1, 22 model calls per trajectory. Returns seconds per sample."""
    layout = tm.layout
    ef = layout.ef
    steps = tm.config.steps
    t0 = time.perf_counter()
    for i in range(start.shape[0]):
        s0, sT = start[i : i + 1], goal[i : i + 1]
        waypoints = tm(s0, sT)
        with torch.no_grad():
            s, rectified = s0, []
            for t in range(steps):
                target = waypoints[:, t] if t < steps - 1 else sT[:, ef]
                a = im(s, target)  # one IM call ...
                s = fm(s, a)  # ... and one FM call per time step and sample
                rectified.append(s)
            rectified = torch.stack(rectified, dim=1)
        loss, _ = tm_loss(waypoints, rectified, s0, sT, layout, loss_cfg)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
    return (time.perf_counter() - t0) / start.shape[0]


def batched_epoch(tm, fm, im, start, goal, loss_cfg, opt, batch_size: int) -> float:
    """kinlearn's batched rectification (one IM and one FM call per time step). Seconds per sample."""
    t0 = time.perf_counter()
    for i in range(0, start.shape[0], batch_size):
        s0, sT = start[i : i + batch_size], goal[i : i + batch_size]
        waypoints = tm(s0, sT)
        with torch.no_grad():
            rectified, _ = rectify(waypoints.detach(), s0, sT, fm, im, tm.layout)
        loss, _ = tm_loss(waypoints, rectified, s0, sT, tm.layout, loss_cfg)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
    return (time.perf_counter() - t0) / start.shape[0]


def fmt_time(seconds: float) -> str:
    if seconds >= 3600:
        return f"{seconds / 3600:.2f} h"
    if seconds >= 60:
        return f"{seconds / 60:.1f} min"
    return f"{seconds:.2f} s"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robot", default="iiwa14")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--pairs", type=int, default=12_000, help="pairs per epoch")
    ap.add_argument("--per-sample", type=int, default=200, help="pairs timed in the per-sample loop")
    ap.add_argument("--batched-samples", type=int, default=4096, help="pairs timed per batched row")
    ap.add_argument("--analytic", action="store_true", help="analytic FM/IM instead of learned MLPs")
    ap.add_argument("--epochs", type=int, default=50, help="epochs for the 'per training run' column")
    ap.add_argument("--no-train-tm", action="store_true", help="skip the full train_tm epoch")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    robot = load_robot(args.robot)
    print(header(f"TM training speed: {robot.name} ({robot.dof} joints)", args.threads))

    pairs = make_endpoints(EndpointConfig(robot=robot.name, n=args.pairs, seed=0))
    if args.analytic:
        fm, im, kind = AnalyticFM(robot), AnalyticIM(robot), "analytic FM (FK) and IM (1 DLS step)"
    else:
        fm = LearnedFM(FMConfig(robot=robot.name, dof=robot.dof))
        im = LearnedIM(IMConfig(robot=robot.name, dof=robot.dof))
        kind = "learned FM (17-30-{20,20}-{7,3}) and IM (13-40-60-60-40-7), paper sizes, untrained"
    for m in (fm, im):
        m.eval()
        m.requires_grad_(False)
        m.validate_inputs = False
    print(f"FM/IM: {kind}; TM: default size (GRU 20, T = 11); loss: paper Eq. 4; optimiser: RMSprop 1e-3")

    loss_cfg = LossConfig.preset("paper")
    optim = OptimConfig(name="rmsprop", lr=1e-3, alpha=0.99)

    def fresh():
        torch.manual_seed(0)
        tm = TrajectoryModel(TMConfig(robot=robot.name, dof=robot.dof))
        tm.fit_normalization(pairs.start, pairs.goal)
        tm.train()
        return tm, make_optimizer(optim, tm.parameters())

    n_ps = min(args.per_sample, args.pairs)
    n_b = min(args.batched_samples, args.pairs)
    rows_raw: list[tuple[str, float]] = []

    tm, opt = fresh()
    per_sample_epoch(tm, fm, im, pairs.start[:5], pairs.goal[:5], loss_cfg, opt)  # warm-up
    rows_raw.append(
        (
            f"per-sample loop (authors' structure, batch 1, {2 * tm.config.steps} model calls per pair); "
            f"{n_ps} pairs timed",
            per_sample_epoch(tm, fm, im, pairs.start[:n_ps], pairs.goal[:n_ps], loss_cfg, opt),
        )
    )
    for bs in (64, 256):
        tm, opt = fresh()
        batched_epoch(tm, fm, im, pairs.start[: 2 * bs], pairs.goal[: 2 * bs], loss_cfg, opt, bs)  # warm-up
        rows_raw.append(
            (
                f"kinlearn batched rectification, batch {bs}; {n_b} pairs timed",
                batched_epoch(tm, fm, im, pairs.start[:n_b], pairs.goal[:n_b], loss_cfg, opt, bs),
            )
        )

    ref = rows_raw[0][1]
    rows = []
    for name, per in rows_raw:
        epoch = per * args.pairs
        rows.append(
            [
                name,
                f"{per * 1e6:,.0f}",
                fmt_time(epoch),
                fmt_time(epoch * args.epochs),
                f"{ref / per:,.0f}×",
            ]
        )

    if not args.no_train_tm:
        config = tm_preset("default", robot=robot.name, fm="analytic", im="analytic", epochs=1)
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            train_tm(config, tmp, pairs, fm=fm, im=im, progress=False)
            wall = time.perf_counter() - t0
        rows.append(
            [
                f"one real epoch of train_tm (default preset, batch {config.batch_size}, {args.pairs:,} pairs, "
                "measured, not extrapolated)",
                f"{wall / args.pairs * 1e6:,.0f}",
                fmt_time(wall),
                fmt_time(wall * args.epochs),
                f"{ref * args.pairs / wall:,.0f}×",
            ]
        )

    print()
    caption = (
        f"Time per training sample (forward, rectification, loss, backward, optimiser step), per epoch of "
        f"{args.pairs:,} pairs and per {args.epochs}-epoch run; speed-up = per-sample loop time / row time, "
        f"measured in the same run. FM/IM: {kind}."
    )
    print(caption)
    figures: dict = {}
    show(
        figures,
        "training speed",
        ["method", "µs per sample", "per epoch", f"per {args.epochs} epochs", "speed-up vs per-sample"],
        rows,
        caption=caption,
    )
    write_result(
        "tm_training_speed" + ("_analytic" if args.analytic else ""),
        figures,
        title=f"TM training time: batched rectification against a per-sample loop ({kind} FM/IM)",
        threads=args.threads,
    )


if __name__ == "__main__":
    main()
