"""A whole plan at batch 1 against the paper's TM forward alone and RRT-Connect, and throughput at batch 4,000.

    python benchmarks/plan_latency.py [--run-dir RUN] [--robot iiwa14] [--threads 1] [--calls 2000] [--batch 4000]

The planner is ``Planner.load(--run-dir)``, else the one shipped with kinlearn. Every row is timed
in this run, on one thread, on held-out workspace pairs (uniform within ±90% of the joint range):

- ``kinlearn.plan``: the whole call a user makes (input checks, inference, joint path, clamp to the
  limits, FK of every configuration, goal errors and success flags, the ``Plan`` of tensors);
- the paper-size TM forward alone (GRU 20 → dense 20 → head 10 → 3, eager torch, batch 1): what the
  paper's planner costs before its rollout;
- OMPL RRT-Connect in joint space without obstacles: OMPL's per-query time (setting start and
  goal, ``solve``, reading the path back), the state space built once;
- joint interpolation (kinlearn's baseline function, torch) for scale.

Batch-1 rows are per-call wall times over ``--calls`` calls on different pairs (median, p95, p99).
Throughput: plans per second of one ``plan`` call on ``--batch`` pairs (best of 3) against
RRT-Connect's, one query after another (its summed per-query times). The ratios the workspace
issue asks for are printed last. Without obstacles RRT-Connect is trivial (the trees meet after a
step or two), so its time here is a floor: the learned planner's claim is a fixed, small time.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch
from _common import header, show, table, write_result

from kinlearn import load_robot
from kinlearn.baselines import joint_line, rrt_connect_timed
from kinlearn.errors import MissingDependencyError
from kinlearn.evaluation.workspace import heldout_pairs
from kinlearn.models.trajectory import TMConfig, TrajectoryModel
from kinlearn.planning.planner import Planner


def per_call(fn, args_list) -> np.ndarray:
    """Wall time of ``fn(*args)`` for each argument tuple, in microseconds (after 50 warm-up calls)."""
    for a in args_list[:50]:
        fn(*a)
    out = np.empty(len(args_list))
    for i, a in enumerate(args_list):
        t0 = time.perf_counter()
        fn(*a)
        out[i] = time.perf_counter() - t0
    return out * 1e6


def stats(us: np.ndarray) -> dict:
    return {
        "p50": float(np.median(us)),
        "p95": float(np.percentile(us, 95)),
        "p99": float(np.percentile(us, 99)),
    }


def breakdown(planner: Planner, s: torch.Tensor, g: torch.Tensor, calls: int) -> list[tuple[str, float]]:
    """Median time (µs) of a batch-1 plan's parts: one problem as two joint vectors takes the batch-1 entry,
    one compiled call from the input to the verdict, then the ``Plan`` of tensors; the same problem as a
    batch of one (``(1, dof)``) takes the general path (a ``Problem``, the TM, ``judge``)."""
    from kinlearn.planning.plan import START_TOLERANCE
    from kinlearn.planning.planner import LIMIT_TOLERANCE, ZERO_MOVE

    kernel, chain, tol = planner._path_kernel, planner._chain_kernel, planner.tolerance
    tols = (LIMIT_TOLERANCE, START_TOLERANCE, tol.position, tol.joints)
    a, b = s.double().numpy(), g.double().numpy()
    parts = [("the whole call (the batch-1 entry)", lambda: planner.plan(s, g))]
    if kernel is not None:
        parts.append(
            (
                "its compiled call (checks, FK, MLP, knots, verdict)",
                lambda: kernel.free_plan(a, b, chain, ZERO_MOVE, tols),
            )
        )
    parts.append(
        ("the same problem as a batch of one (the general path)", lambda: planner.plan(s[None], g[None]))
    )
    out = []
    for name, fn in parts:
        out.append((name, float(np.median(per_call(lambda f=fn: f(), [()] * calls)))))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--run-dir", help="a planner folder (default: the shipped planner)")
    ap.add_argument("--robot", default="iiwa14")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--calls", type=int, default=2000)
    ap.add_argument("--batch", type=int, default=4000)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    print(header("Plan latency (batch 1) and throughput", args.threads))
    robot = load_robot(args.robot)
    planner = Planner.load(args.run_dir) if args.run_dir else Planner.default(args.robot)
    print(f"planner: {args.run_dir or 'Planner.default() (shipped)'}; TM {type(planner.tm).__name__}")
    n = max(args.calls, args.batch)
    pairs = heldout_pairs(robot, n=n)
    start, goal = pairs.start[:, : robot.dof], pairs.goal[:, : robot.dof]
    one = [(start[i], goal[i]) for i in range(args.calls)]

    rows = {}
    rows["kinlearn.plan (whole call)"] = stats(per_call(planner.plan, one))
    paper_tm = TrajectoryModel(TMConfig(robot=robot.name, dof=robot.dof, normalize=False)).eval()
    with torch.no_grad():
        states = [(pairs.start[i : i + 1], pairs.goal[i : i + 1]) for i in range(args.calls)]
        rows["paper-size TM forward alone (eager)"] = stats(per_call(paper_tm, states))
    full = [(pairs.start[i].double(), pairs.goal[i].double()) for i in range(args.calls)]
    rows["joint interpolation (torch)"] = stats(per_call(lambda a, b: joint_line(robot, a, b), full))
    rrt_rate = None
    try:
        _, t = rrt_connect_timed(robot, pairs.start[: args.calls].double(), pairs.goal[: args.calls].double())
        us = t.numpy() * 1e6
        rows["RRT-Connect, no obstacles (OMPL, per query)"] = stats(us)
        rrt_rate = 1e6 / float(us.mean())
    except MissingDependencyError as exc:
        print(f"RRT-Connect skipped: {exc}")
    print()
    figures: dict = {}
    show(
        figures,
        "batch 1",
        ["batch 1", "p50 (µs)", "p95 (µs)", "p99 (µs)"],
        [[name, f"{r['p50']:.1f}", f"{r['p95']:.1f}", f"{r['p99']:.1f}"] for name, r in rows.items()],
        caption=f"{args.calls:,} calls each on held-out workspace pairs.",
    )

    sb, gb = start[: args.batch], goal[: args.batch]
    planner.plan(sb, gb)
    best = min(_timed(lambda: planner.plan(sb, gb)) for _ in range(3))
    rate = args.batch / best
    print(f"\nbatch {args.batch}: {best * 1e3:.1f} ms per call, {rate:,.0f} plans/s")
    if rrt_rate:
        print(f"RRT-Connect one query after another: {rrt_rate:,.0f} plans/s")

    through = [["kinlearn.plan", f"{rate:,.0f}"]]
    if rrt_rate:
        through.append(["RRT-Connect, one query after another (OMPL)", f"{rrt_rate:,.0f}"])
    figures["throughput"] = table(
        ["planner", "plans/s"], through, caption=f"kinlearn.plan at batch {args.batch:,}."
    )

    print("\nbreakdown of a batch-1 plan (median µs):")
    parts = breakdown(planner, start[0], goal[0], min(args.calls, 1000))
    for name, us in parts:
        print(f"  {name}: {us:.1f}")
    figures["breakdown"] = table(
        ["part of a batch-1 plan", "median (µs)"], [[name, f"{us:.1f}"] for name, us in parts]
    )

    plan50 = rows["kinlearn.plan (whole call)"]["p50"]
    tm50 = rows["paper-size TM forward alone (eager)"]["p50"]
    print("\nratios (goal in brackets):")
    print(f"  whole plan / paper-size TM forward alone, p50: {plan50 / tm50:.2f} (≤ 1)")
    if rrt_rate:
        rrt50 = rows["RRT-Connect, no obstacles (OMPL, per query)"]["p50"]
        print(f"  whole plan / RRT-Connect, p50: {plan50 / rrt50:.2f} (≤ 1)")
        print(f"  throughput at batch {args.batch} / RRT-Connect's: {rate / rrt_rate:.1f}× (≥ 10×)")
    write_result(
        "plan_latency",
        figures,
        title=f"Plan latency at batch 1 and throughput ({robot.name}, free space)",
        threads=args.threads,
    )


def _timed(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


if __name__ == "__main__":
    main()
