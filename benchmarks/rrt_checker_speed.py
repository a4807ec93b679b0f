"""OMPL RRT-Connect on the held-out obstacle problems with its validity checks answered by the compiled
kernels against the torch checker they replace, in the same run on one thread.

    python benchmarks/rrt_checker_speed.py [--problems 30] [--time-limit 2.0] [--threads 1]

Both checkers give the same answers (tests/test_collision_kernel.py), and OMPL is seeded the same way
for both, so each problem's search is the same one: only the time it takes, and so what a time limit
cuts off, differs. Reported per checker: share solved within the limit, median and p99 wall time
(solved or not), and validity checks per second.
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

from kinlearn import load_robot
from kinlearn.collision import body_spheres
from kinlearn.collision.ompl import OmplRrtConnect, RrtChecker
from kinlearn.data.problems import ProblemSet

HELDOUT = Path(__file__).resolve().parent / "data" / "obstacle_problems_heldout.npz"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--problems", type=int, default=30)
    ap.add_argument("--time-limit", type=float, default=2.0)
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    print(header("RRT-Connect: compiled vs torch validity checks (iiwa14)", args.threads))
    from kinlearn.collision import kernel

    kernel.warm_up()
    body = body_spheres(load_robot("iiwa14")).double()
    problems = ProblemSet.load(HELDOUT)
    step = max(1, len(problems) // args.problems)
    picks = list(range(0, step * args.problems, step))[: args.problems]
    rows = []
    for compiled in (True, False):
        times, solved, checks, busy = [], 0, 0, 0.0
        for i in picks:
            start, goal, scene = problems.problem(i)
            rrt = OmplRrtConnect(body.robot, body, scene, compiled=compiled)
            path, t = rrt.solve(start, goal, time_limit=args.time_limit, seed=i)
            times.append(t)
            solved += path is not None
            # Validity checks per second, on this problem's own kinds of queries.
            checker = RrtChecker(body, scene, compiled=compiled)
            q = np.stack([start.double().numpy(), goal.double().numpy()])
            t0 = time.perf_counter()
            for _ in range(20):
                checker.state_valid(q[0])
                checker.motion_valid(q[0], q[0] + 0.05 * (q[1] - q[0]))
            busy += time.perf_counter() - t0
            checks += 40
        t = np.array(times)
        rows.append(
            [
                "compiled kernels" if compiled else "torch",
                f"{100 * solved / len(picks):.0f}%",
                f"{1e3 * np.median(t):.1f}",
                f"{1e3 * np.percentile(t, 99):.1f}",
                f"{checks / busy:,.0f}",
            ]
        )
    caption = f"{len(picks)} held-out problems (every {step}th), time limit {args.time_limit} s, seed = problem index."
    print(f"\n{caption}\n")
    figures: dict = {}
    show(
        figures,
        "checkers",
        ["checker", "solved", "median (ms)", "p99 (ms)", "checks / s"],
        rows,
        caption=caption,
    )
    write_result(
        "rrt_checker_speed",
        figures,
        title="OMPL RRT-Connect: compiled against torch validity checks (iiwa14)",
        threads=args.threads,
    )


if __name__ == "__main__":
    main()
