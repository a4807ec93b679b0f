"""The workspace planner judged the way a user calls it: held-out pairs across the joint range.

    python benchmarks/workspace_planner.py [--model DIR] [--n 2000] [--rrt 500] [--threads 1]

Starts and goals uniform within ±90% of each joint's range (the ``workspace`` endpoint preset, a seed
never used in training). Rows: the planner (default: the one shipped with kinlearn) with joint goals;
joint interpolation; a straight Cartesian line with damped-least-squares IK (it ends at whatever
configuration its IK reaches); OMPL RRT-Connect with its path simplification on the first ``--rrt``
pairs; the planner with end-effector position goals (goal joints from its learned IM and FM).
Then the same planner on held-out pairs of the paper's task. Every path is judged by the analytic FK
of its own joints; the columns are those of :func:`kinlearn.evaluation.workspace.evaluate_workspace`.
"""

from __future__ import annotations

import argparse
import time

import torch
from _common import header

from kinlearn import load_robot
from kinlearn.data.endpoints import EndpointConfig, make_endpoints
from kinlearn.errors import MissingDependencyError
from kinlearn.evaluation.workspace import POSITION_COLUMNS, evaluate_workspace, heldout_pairs, workspace_table
from kinlearn.planning.baselines import CartesianDLS, JointInterpolation, RRTConnect
from kinlearn.planning.planner import Planner


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model", help="a planner folder (default: the shipped planner)")
    ap.add_argument("--robot", default="iiwa14")
    ap.add_argument("--n", type=int, default=2000, help="held-out pairs")
    ap.add_argument("--rrt", type=int, default=500, help="pairs given to RRT-Connect (0: none)")
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    print(header("The workspace planner on held-out pairs", args.threads))
    t0 = time.perf_counter()
    robot = load_robot(args.robot)
    planner = Planner.load(args.model) if args.model else Planner.default(args.robot)
    pairs = heldout_pairs(robot, n=args.n)
    rows = {
        "kinlearn (joint goals)": planner,
        "joint interpolation": JointInterpolation(robot),
        "Cartesian line + DLS IK": CartesianDLS(robot),
    }
    joint = evaluate_workspace(robot, pairs, rows)
    if args.rrt:
        try:
            sub = pairs.split(min(args.rrt, len(pairs)))[0]
            name = f"RRT-Connect + simplification ({len(sub)} pairs)"
            joint[name] = evaluate_workspace(robot, sub, {name: RRTConnect(robot, simplify=True)})[name]
        except MissingDependencyError as exc:
            print(f"RRT-Connect skipped: {exc}")
    print(f"\n## Joint goals: {len(pairs)} held-out workspace pairs (±90% of the joint range)\n")
    print(workspace_table(joint))
    if planner.fm is not None and planner.im is not None:
        pos = evaluate_workspace(
            robot,
            pairs,
            {"kinlearn (position goals)": planner},
            goal_kind="position",
        )
        print("\n## End-effector position goals (same pairs; any configuration)\n")
        print(workspace_table(pos, POSITION_COLUMNS))
    paper = make_endpoints(EndpointConfig(robot=robot.name, n=args.n, seed=777))
    task = evaluate_workspace(robot, paper, {"kinlearn (joint goals)": planner})
    print(f"\n## The paper's task: {len(paper)} held-out pairs\n")
    print(workspace_table(task))
    print(f"\ntook {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
