"""Batch-1 planning speed against baselines timed in the same run, interleaved, on one thread.

    python benchmarks/batch1_speed.py [--problems 340] [--threads 1]

On the committed held-out obstacle problems (iiwa14; every k-th of the 1,020, seeded order), one
call of each row per problem, the rows taking turns problem by problem (so a busy machine slows every
row alike and the ratios stay meaningful):

- the paper-size TM forward pass (GRU 20 → dense 20 → head 10 → 3, eager torch, batch 1, no grad):
  the baseline the obstacle plan is measured against;
- the whole batch-1 obstacle plan, ``Planner.default("iiwa14").plan(start, goal, obstacles=scene)``
  (refine_steps 0: the learned proposals, the dense check, the verdict);
- the whole batch-1 free-space plan, ``plan(start, goal)`` (the joint-path TM, judge's fast path);
- OMPL RRT-Connect without obstacles, one query (``OmplRrtConnect.solve``: setting the query, the search,
  reading the path back), the space and planner built once: the baseline of the free-space plan.

Times are wall clock per call (µs) and, beside them, the thread's CPU time (``time.thread_time``),
which a machine shared with other work inflates far less. Printed: p50 and p99 per row, the ratios the
geometry issue names, and where the time of an obstacle plan stage 1 clears goes (its parts timed alone,
medians).
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
import torch
from _common import header, show, write_result

from kinlearn.collision import kernel
from kinlearn.collision.ompl import OmplRrtConnect
from kinlearn.data.problems import ProblemSet
from kinlearn.models.trajectory import TMConfig, TrajectoryModel
from kinlearn.planning.planner import Planner

HELDOUT = Path(__file__).resolve().parent / "data" / "obstacle_problems_heldout.npz"


def _pct(a: np.ndarray) -> tuple[float, float]:
    return float(np.median(a)), float(np.percentile(a, 99))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--problems", type=int, default=340)
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    import numba

    numba.set_num_threads(1)
    print(header("Batch-1 planning speed (iiwa14, held-out problems)", args.threads))
    print(f"numba {numba.__version__}; 1-minute load average at the start {os.getloadavg()[0]:.1f}")
    kernel.warm_up()
    ps = ProblemSet.load(HELDOUT, robot="iiwa14")
    step = max(1, len(ps) // args.problems)
    picks = list(range(0, len(ps), step))[: args.problems]
    problems = [ps.problem(i) for i in picks]
    planner = Planner.default("iiwa14")
    robot = planner.robot
    tm = TrajectoryModel(TMConfig(robot=robot.name, dof=robot.dof, normalize=False)).eval()
    s_tm = torch.zeros(1, robot.dof + 3)
    rrt = OmplRrtConnect(robot)
    rrt.solve(problems[0][0], problems[0][1], seed=0)

    rows = {
        "paper-size TM forward (GRU, eager torch)": lambda s, g, sc: tm(s_tm, s_tm),
        "kinlearn obstacle plan (whole call)": lambda s, g, sc: planner.plan(
            s, g, obstacles=sc, refine_steps=0
        ),
        "kinlearn free-space plan (whole call)": lambda s, g, sc: planner.plan(s, g),
        "OMPL RRT-Connect, no obstacles (one query)": lambda s, g, sc: rrt.solve(s, g),
    }
    wall = {k: np.empty(len(problems)) for k in rows}
    cpu = {k: np.empty(len(problems)) for k in rows}
    with torch.no_grad():
        for s, g, sc in problems[:20]:  # warm-up: first calls, caches, compiled kernels loaded
            for fn in rows.values():
                fn(s, g, sc)
        for i, (s, g, sc) in enumerate(problems):
            for name, fn in rows.items():
                c0, t0 = time.thread_time(), time.perf_counter()
                fn(s, g, sc)
                wall[name][i] = time.perf_counter() - t0
                cpu[name][i] = time.thread_time() - c0
    table = []
    for name in rows:
        w50, w99 = _pct(1e6 * wall[name])
        c50, c99 = _pct(1e6 * cpu[name])
        table.append([name, f"{w50:.1f}", f"{w99:.1f}", f"{c50:.1f}", f"{c99:.1f}"])
    caption = f"{len(problems)} held-out problems (every {step}th), each row once per problem, in turn."
    print(f"\n{caption}\n")
    figures: dict = {}
    show(
        figures,
        "batch 1",
        ["batch 1", "p50 (µs)", "p99 (µs)", "CPU p50 (µs)", "CPU p99 (µs)"],
        table,
        caption=caption,
    )

    names = list(rows)
    tm_name, obs, free, ompl = names
    print("\nratios (goal in brackets), wall clock | thread CPU time:")
    for label, a, q, b, goal in (
        ("obstacle plan p50 / TM forward p50", obs, 50, tm_name, "≤ 2"),
        ("obstacle plan p99 / TM forward p50", obs, 99, tm_name, "≤ 4"),
        ("free-space plan p50 / RRT-Connect p50", free, 50, ompl, "≤ 1"),
    ):
        r_wall = np.percentile(wall[a], q) / np.median(wall[b])
        r_cpu = np.percentile(cpu[a], q) / np.median(cpu[b])
        print(f"  {label}: {r_wall:.2f} | {r_cpu:.2f} ({goal})")

    # Where an obstacle plan's time goes, for the plans stage 1 clears (the batch-1 entry: no Problem
    # made): its parts, each timed alone on the same problems (medians).
    parts = {
        name: []
        for name in (
            "the batch-1 entry (start and goal read, the scene packed; their checks, FK and stage 1 in one compiled call)",
            "stage 1 alone, timed again (the line's check; where it collides the network and its candidates' check: one compiled call)",
            "the verdict (judge's rule on the arrays at hand, the Plan)",
        )
    }
    for s, g, sc in problems:
        t0 = time.perf_counter()
        first = planner._batch1(s, g, sc, 0)
        t1 = time.perf_counter()
        if first is None or not first[2][2][0]:
            continue  # left to the later stages, which make a Problem
        q, ef, (paths, pick, _), packed, dtype = first
        t2 = time.perf_counter()
        planner._learned(q[:1], ef[:1], q[1:], ef[1:], [packed], 0)
        t3 = time.perf_counter()
        planner._batch1_plan(q, ef, paths[0, pick[0]], "learned", dtype)
        t4 = time.perf_counter()
        for name, dt in zip(parts, (t1 - t0, t3 - t2, t4 - t3), strict=True):
            parts[name].append(dt)
    n = len(next(iter(parts.values())))
    print(f"\nan obstacle plan's parts, each timed alone ({n} plans stage 1 cleared; median µs):")
    for name, ts in parts.items():
        print(f"  {name}: {1e6 * np.median(ts):.1f}")
    print(f"\n1-minute load average at the end {os.getloadavg()[0]:.1f} (on {os.cpu_count()} logical cores)")
    figures["parts of an obstacle plan"] = {
        "columns": ["part", "median (µs)"],
        "rows": [[name, f"{1e6 * np.median(ts):.1f}"] for name, ts in parts.items()],
        "caption": f"Each timed alone, on the {n} plans stage 1 cleared.",
    }
    write_result(
        "batch1_speed", figures, title="Batch-1 planning speed among obstacles (iiwa14)", threads=args.threads
    )


if __name__ == "__main__":
    main()
