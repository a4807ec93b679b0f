"""The workspace planner judged the way a user calls it: held-out pairs across the joint range.

    python benchmarks/workspace_planner.py [--model DIR] [--n 2000] [--rrt 500] [--threads 1]

Starts and goals uniform within ±90% of each joint's range (the ``workspace`` endpoint preset, a seed
never used in training). Rows: the planner (default: the one shipped with kinlearn) with joint goals;
every free-space baseline of the registry (:mod:`kinlearn.baselines`: joint interpolation; a straight
Cartesian line with damped-least-squares IK, which ends at whatever configuration its IK reaches; the
searches, OMPL RRT-Connect with its path simplification, on the first ``--rrt`` pairs); the planner with end-effector position goals (goal joints from its learned IM and FM).
Then the same planner on held-out pairs of the paper's task. Every path is judged by the analytic FK
of its own joints; the columns are those of :func:`kinlearn.evaluation.workspace.evaluate_workspace`.
"""

from __future__ import annotations

import argparse
import inspect
import time

import torch
from _common import from_markdown, header, write_result

from kinlearn import baselines, load_robot
from kinlearn.data.endpoints import EndpointConfig, make_endpoints
from kinlearn.errors import MissingDependencyError
from kinlearn.evaluation.workspace import POSITION_COLUMNS, evaluate_workspace, heldout_pairs, workspace_table
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
    free = baselines.names(avoids_obstacles=False)
    searches = [name for name in free if baselines.get(name).one_at_a_time]
    rows = {"kinlearn (joint goals)": planner}
    rows.update({baselines.get(n).label: baselines.make(n, robot) for n in free if n not in searches})
    joint = evaluate_workspace(robot, pairs, rows)
    for name in searches if args.rrt else ():
        label = baselines.get(name).label
        try:
            sub = pairs.split(min(args.rrt, len(pairs)))[0]
            simplify = "simplify" in inspect.signature(baselines.get(name)).parameters
            row = baselines.subset_label(f"{label}{' + simplification' if simplify else ''}", len(sub))
            search = baselines.make(name, robot, **({"simplify": True} if simplify else {}))
            joint[row] = evaluate_workspace(robot, sub, {row: search})[row]
        except MissingDependencyError as exc:
            print(f"{label} skipped: {exc}")
    figures: dict = {}
    title = f"Joint goals: {len(pairs)} held-out workspace pairs (±90% of the joint range)"
    print(f"\n## {title}\n")
    print(workspace_table(joint))
    figures["joint goals"] = from_markdown(workspace_table(joint), caption=title)
    if planner.fm is not None and planner.im is not None:
        pos = evaluate_workspace(
            robot,
            pairs,
            {"kinlearn (position goals)": planner},
            goal_kind="position",
        )
        title = "End-effector position goals (same pairs; any configuration)"
        print(f"\n## {title}\n")
        print(workspace_table(pos, POSITION_COLUMNS))
        figures["position goals"] = from_markdown(workspace_table(pos, POSITION_COLUMNS), caption=title)
    paper = make_endpoints(EndpointConfig(robot=robot.name, n=args.n, seed=777))
    task = evaluate_workspace(robot, paper, {"kinlearn (joint goals)": planner})
    title = f"The paper's task: {len(paper)} held-out pairs"
    print(f"\n## {title}\n")
    print(workspace_table(task))
    figures["paper task"] = from_markdown(workspace_table(task), caption=title)
    write_result(
        "workspace_planner" + ("" if robot.name == "iiwa14" else f"_{robot.name}"),
        figures,
        title=f"The workspace planner on held-out pairs ({robot.name})",
        threads=args.threads,
    )
    print(f"\ntook {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
