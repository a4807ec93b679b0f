"""The panda's problems whose goal lies beyond its Franka datasheet limits but within the benchmarks' panda's.

    python benchmarks/panda_limits.py [--deadline 0.05] [--threads 1]

The panda of the standard benchmarks (MoveIt's, the spherized URDF the panda's body is read from) turns
every joint up to 0.07 rad further than kinlearn's panda (example-robot-data's: the Franka datasheet's
limits; its fourth joint 0.157 rad further). A problem among obstacles whose start or goal lies in that band is
planned within the model's limits (``BodySpheres.outer_limits``), with a ``BeyondLimitsWarning``; before,
it raised ``JointLimitError``. Problems: the committed held-out scene problems
(``benchmarks/data/scene_problems_panda.npz``) with each goal's last joint (the hand's turn) moved into
the band, to ±2.9323 rad (halfway between 2.8973 and 2.9671, on the side of its sign), kept where that
goal is still free. Rows: the shipped planner, and the same with its body's outer limits narrowed to the
robot's (how it planned before); each in fixed time (``refine_steps=0``) and with a deadline. A plan
succeeds when ``plan.success`` and every knot lies within the model's limits; ``refused`` counts the
problems the planner raised ``JointLimitError`` for.
"""

from __future__ import annotations

import argparse
import copy
import warnings
from pathlib import Path

import numpy as np
import torch
from _common import header, limits_row, plan_cases, show, write_result

import kinlearn
from kinlearn.collision import planning_body
from kinlearn.collision.kernel import KernelBody, KernelScene, clearances
from kinlearn.collision.scene import as_scene
from kinlearn.data.problems import ProblemSet

DATA = Path(__file__).parent / "data"
#: Where each goal's last joint is put: halfway into the band between the two models' limits.
BAND = (2.8973 + 2.9671) / 2


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--deadline", type=float, default=0.05)
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    print(
        header(
            "The panda's held-out problems with each goal's hand turned into the benchmarks' band",
            args.threads,
        )
    )
    robot = kinlearn.load_robot("panda")
    problems = ProblemSet.load(DATA / "scene_problems_panda.npz", robot="panda")
    body = planning_body(robot).double()
    packed_body = KernelBody(body)
    lo, hi = body.outer_limits
    cases = []
    for i in range(len(problems)):
        s, g, sc = problems.problem(i)
        g = g.double().clone()
        g[6] = BAND if float(g[6]) >= 0 else -BAND
        q = np.ascontiguousarray(g.numpy()[None])
        d, sd = clearances(packed_body, KernelScene.of(as_scene(sc)), q)[:2]
        if d[0] > 0 and sd[0] > 0:  # the turned hand still free
            cases.append((s, g, sc))
    print(f"{len(cases)} of {len(problems)} problems keep a free goal with the hand turned into the band")
    narrow = copy.deepcopy(body)
    narrow.outer_limits = (robot.lower.astype(np.float64), robot.upper.astype(np.float64))
    planners = {
        "shipped (the model's limits where an end needs them)": kinlearn.Planner.default("panda"),
        "the robot's limits only": kinlearn.Planner.default("panda", body=narrow),
    }
    modes = {"fixed time": {"refine_steps": 0}, f"deadline {args.deadline:g} s": {"deadline": args.deadline}}

    def inside(q):  # every knot within the model's limits
        return ((q >= lo - 1e-9) & (q <= hi + 1e-9)).all()

    rows = []
    warnings.simplefilter("ignore")
    for pname, planner in planners.items():
        planner.warm_up()
        for mname, kw in modes.items():
            ok, _, refused, times = plan_cases(planner, cases, inside, **kw)
            rows.append(limits_row(pname, mname, ok, len(cases), refused, times, digits=2))
    figures: dict = {}
    show(
        figures,
        "goals in the band",
        ["planner", "mode", "success", "refused", "p50 ms", "p99 ms"],
        rows,
        caption=f"{len(cases)} of {len(problems)} held-out problems keep a free goal with the hand turned into the band.",
    )
    write_result(
        "panda_limits",
        figures,
        title="The panda's goals beyond its datasheet limits, within the benchmarks' panda's",
        threads=args.threads,
    )


if __name__ == "__main__":
    main()
