"""End-effector position goals through the learned models alone, the way a user calls them:
``kinlearn.plan(start, goal_position=p, robot=NAME)`` on held-out pairs within ±90% of the joint
ranges, judged by the analytic FK of each plan's own joints.

    python benchmarks/position_goals.py [--robots iiwa14 panda ur5 xarm7 z1] [--n 1000] [--threads 1]

Per arm, the shipped planner (its identified chain, ``chain.pt``, solves the goal joints; the analytic
FK only judges): the share within 1 cm, the median and p99 goal error, joint-limit violations; the
batch-1 latency of a position-goal plan as a ratio to a joint-goal plan's, timed in the same run
(medians over 300 plans each, interleaved); and the IM through the chain, executed through the
analytic FK on babbling-sized actions (mean error, mm).
"""

from __future__ import annotations

import argparse
import statistics
import time
import warnings

import torch
from _common import header, table, write_result

from kinlearn.body.kinematics import kinematics
from kinlearn.body.robot import load_robot
from kinlearn.errors import DomainWarning
from kinlearn.evaluation.workspace import heldout_pairs
from kinlearn.models.chain import ThroughFMIM
from kinlearn.planning.planner import Planner


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robots", nargs="+", default=["iiwa14", "panda", "ur5", "xarm7", "z1"])
    ap.add_argument("--n", type=int, default=1000)
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    warnings.simplefilter("ignore", DomainWarning)
    print(header("Position goals through the learned models alone", args.threads))
    print(f"{args.n:,} held-out pairs per arm within ±90% of the joint ranges\n")
    columns = ["arm", "≤ 1 cm", "median (mm)", "p99 (mm)", "limit violations",
               "batch-1 position / joint plan", "IM through the chain, executed (mm, mean)"]  # fmt: skip
    print("| " + " | ".join(columns) + " |")
    print("|:--|--:|--:|--:|--:|--:|--:|")
    rows = []
    for name in args.robots:
        robot = load_robot(name)
        planner = Planner.default(name)
        if planner.chain is None:
            rows.append([name, "no chain.pt shipped", "", "", "", "", ""])
            print(f"| {name} | no chain.pt shipped | | | | | |")
            continue
        pairs = heldout_pairs(robot, args.n)
        start, goal = pairs.start[:, : robot.dof].double(), pairs.goal[:, robot.dof :].double()
        plan = planner.plan(start, goal_position=goal)
        err = plan.goal_error.double() * 1e3
        lo, hi = robot.limits(torch.float64)
        joints = plan.joints.double()
        violations = int((~((joints >= lo - 1e-9) & (joints <= hi + 1e-9)).all(-1).all(-1)).sum())
        # Batch-1 latency, position goals against joint goals, interleaved in one loop.
        goal_q = pairs.goal[:, : robot.dof].double()
        t_pos, t_joint = [], []
        for k in range(300):
            t0 = time.perf_counter()
            planner.plan(start[k], goal_position=goal[k])
            t1 = time.perf_counter()
            planner.plan(start[k], goal_q[k])
            t_pos.append(t1 - t0)
            t_joint.append(time.perf_counter() - t1)
        ratio = statistics.median(t_pos) / statistics.median(t_joint)
        # The IM through the chain on babbling-sized actions, executed through the analytic FK.
        gen = torch.Generator().manual_seed(5)
        q = robot.sample(5000, gen, dtype=torch.float64)
        step = planner.chain.max_step  # the babbling step bound (data.babbling.MAX_STEP)
        a = (2 * torch.rand(q.shape, generator=gen, dtype=torch.float64) - 1) * step
        fk = kinematics(robot)
        target = fk.position((q + a).clamp(lo, hi))
        im = ThroughFMIM(planner.chain, lo, hi, iterations=3, max_step=step)
        with torch.no_grad():
            act = im(im.layout.join(q, fk.position(q)), target)
        im_err = float((fk.position(q + act) - target).norm(dim=-1).mean()) * 1e3
        row = [
            name,
            f"{float((err <= 10).double().mean()):.1%}",
            f"{err.median():.3f}",
            f"{err.quantile(0.99):.3f}",
            violations,
            f"{ratio:.2f}× ({statistics.median(t_pos) * 1e6:.0f} / {statistics.median(t_joint) * 1e6:.0f} µs)",
            f"{im_err:.3f}",
        ]
        rows.append(row)
        print("| " + " | ".join(str(c) for c in row) + " |", flush=True)
    write_result(
        "position_goals",
        {
            "position goals": table(
                columns, rows, caption=f"{args.n:,} held-out pairs per arm within ±90% of the joint ranges."
            )
        },
        title="End-effector position goals through the learned models alone",
        threads=args.threads,
    )


if __name__ == "__main__":
    main()
