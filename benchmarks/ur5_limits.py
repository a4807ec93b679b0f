"""The ur5's plans within the limits of the benchmarks' UR5: problems whose ends lie within ±π.

    python benchmarks/ur5_limits.py [--deadline 0.05] [--threads 1]

The UR5 of the standard benchmarks (the spherized URDF the ur5's bodies are read from) turns every joint
±π; kinlearn's ur5 (example-robot-data's) turns ±2π but the elbow. A planner keeps its paths among
obstacles within its body's limits (``BodySpheres.limits``) where a problem's start and goal both lie
within them. Problems: the committed held-out scene problems (``benchmarks/data/scene_problems_ur5.npz``,
made within ±2π) with each end's joints wrapped into ±π, the same poses (so still free). Rows: the shipped
planner, and the same with its body's limits widened to the robot's (how it planned before); each in fixed
time (``refine_steps=0``) and with a deadline. A plan succeeds when ``plan.success`` and every knot lies
within ±π (a judge with that model's limits refuses the others); ``beyond ±π`` counts the plans that
succeed but leave ±π.
"""

from __future__ import annotations

import argparse
import copy
import math
import warnings
from pathlib import Path

import numpy as np
import torch
from _common import header, limits_row, plan_cases, show, write_result

import kinlearn
from kinlearn.collision import planning_body
from kinlearn.data.problems import ProblemSet

DATA = Path(__file__).parent / "data"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--deadline", type=float, default=0.05)
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    print(
        header(
            "The ur5's plans within the benchmarks' UR5 limits (held-out, ends wrapped into ±π)", args.threads
        )
    )
    robot = kinlearn.load_robot("ur5")
    problems = ProblemSet.load(DATA / "scene_problems_ur5.npz", robot="ur5")

    def wrap(q: torch.Tensor) -> torch.Tensor:
        return torch.remainder(q.double() + math.pi, 2 * math.pi) - math.pi

    cases = [(wrap(s), wrap(g), sc) for s, g, sc in (problems.problem(i) for i in range(len(problems)))]
    wide = copy.deepcopy(planning_body(robot))
    wide.limits = (robot.lower.astype(np.float64), robot.upper.astype(np.float64))
    planners = {
        "shipped (the body's limits, ±π)": kinlearn.Planner.default("ur5"),
        "the robot's limits (±2π)": kinlearn.Planner.default("ur5", body=wide),
    }
    modes = {"fixed time": {"refine_steps": 0}, f"deadline {args.deadline:g} s": {"deadline": args.deadline}}
    rows = []
    warnings.simplefilter("ignore")
    for pname, planner in planners.items():
        for mname, kw in modes.items():
            s0, g0, sc0 = cases[0]
            planner.plan(s0, g0, obstacles=sc0, **kw)  # warm-up
            ok, beyond, _, times = plan_cases(
                planner, cases, lambda q: np.abs(q).max() <= math.pi + 1e-9, **kw
            )
            rows.append(limits_row(pname, mname, ok, len(cases), beyond, times, digits=1))
    figures: dict = {}
    show(
        figures,
        "within ±π",
        ["planner", "mode", "success within ±π", "beyond ±π", "p50 ms", "p99 ms"],
        rows,
        caption=f"{len(cases)} held-out scene problems with their ends wrapped into ±π.",
    )
    write_result(
        "ur5_limits", figures, title="The ur5 within the benchmarks' UR5 limits (±π)", threads=args.threads
    )


if __name__ == "__main__":
    main()
