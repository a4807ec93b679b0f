"""Check that no plan the shipped planner flags collision-free collides under the dense check.

    python benchmarks/obstacle_flags.py [--refine-steps 0 25]

On every held-out obstacle problem (batch 1, as a user calls it) the plan's ``collision_free`` is
compared with :func:`kinlearn.collision.check_path` (torch, 12-sphere body with base, ≤ 1 cm of sphere
travel between checked configurations) on the plan's own joints. Prints the counts of agreement and of
the two kinds of disagreement; exits 1 if any plan is flagged free but collides.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch
from _common import header, table, write_result

from kinlearn.collision import check_path
from kinlearn.data.problems import ProblemSet
from kinlearn.planning.planner import Planner

HELDOUT = Path(__file__).resolve().parent / "data" / "obstacle_problems_heldout.npz"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--refine-steps", type=int, nargs="+", default=[0, 25])
    ap.add_argument("--problems", default=str(HELDOUT))
    args = ap.parse_args()
    torch.set_num_threads(1)
    print(header("collision_free flags against the dense check (iiwa14)", 1))
    problems = ProblemSet.load(args.problems, robot="iiwa14")
    base = Planner.default("iiwa14")
    bad_total = 0
    rows = []
    for steps in args.refine_steps:
        planner = Planner(
            base.robot, base.tm, base.fm, base.im, obstacle_tm=base.obstacle_tm, refine_steps=steps
        )
        flagged_free_collides = flagged_colliding_free = agree = 0
        for i in range(len(problems)):
            start, goal, scene = problems.problem(i)
            plan = planner.plan(start, goal, obstacles=scene)
            truth = bool(check_path(planner.body, plan.joints.double(), scene).collision_free)
            flag = bool(plan.collision_free)
            agree += flag == truth
            flagged_free_collides += flag and not truth
            flagged_colliding_free += truth and not flag
        bad_total += flagged_free_collides
        rows.append([steps, len(problems), agree, flagged_free_collides, flagged_colliding_free])
        print(
            f"refine_steps={steps}: {len(problems)} plans, flag agrees with the dense check on {agree}; "
            f"flagged free but colliding: {flagged_free_collides}; flagged colliding but free: "
            f"{flagged_colliding_free}"
        )
    columns = [
        "refine_steps",
        "plans",
        "flag agrees",
        "flagged free but colliding",
        "flagged colliding but free",
    ]
    write_result(
        "obstacle_flags",
        {"flags": table(columns, rows, caption="Every held-out obstacle problem of the iiwa14, batch 1.")},
        title="collision_free flags against the dense check (iiwa14)",
        threads=1,
    )
    return 1 if bad_total else 0


if __name__ == "__main__":
    sys.exit(main())
