"""The ur5 with the standard benchmarks' tool: what planning with the arm's body alone would call free.

    python benchmarks/ur5_gripper.py [--threads 1]

kinlearn's ur5 (example-robot-data's) ends at a bare flange; the UR5 of the standard benchmarks and of
the spherized URDF kinlearn's bodies come from carries a force–torque sensor and a Robotiq 2F-85 gripper,
17 more spheres reaching 0.2 m past the flange. The ur5's planner checks its plans with that tool by
default (``kinlearn.collision.planning_body``); ``body_spheres(robot)`` is the arm alone, the body the
scene families are generated and its network trained with.

On the committed held-out scene problems (``benchmarks/data/scene_problems_ur5_arm.npz``, made for the arm
alone), those whose start and goal are free for the arm with the tool too, every plan judged by the
dense check with the tool: the shipped planner checking with the arm alone (plans it calls free that the
tool collides on), and with its default body (fixed time, the default, a deadline of 0.05 s).
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np
import torch
from _common import header, show, write_result

import kinlearn
from kinlearn.collision import body_spheres, kernel, planning_body
from kinlearn.data.problems import ProblemSet

DATA = Path(__file__).parent / "data"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    print(header("The ur5 with its tool (held-out scene problems)", args.threads))
    robot = kinlearn.load_robot("ur5")
    tool, arm = planning_body(robot).double(), body_spheres(robot).double()
    kt = kernel.KernelBody(tool)
    problems = ProblemSet.load(DATA / "scene_problems_ur5_arm.npz", robot="ur5")
    keep = []
    for i in range(len(problems)):
        start, goal, scene = problems.problem(i)
        ends = np.stack((start.double().numpy()[: robot.dof], goal.double().numpy()[: robot.dof]))
        d, own = kernel.clearances(kt, kernel.KernelScene(scene.to(torch.float64)), ends)
        if (np.minimum(d, own) > 0).all():
            keep.append(i)
    caption = (
        f"{tool.num_spheres} spheres with the tool, {arm.num_spheres} without; {len(keep)} of "
        f"{len(problems)} held-out problems have their start and goal free for the arm with the tool."
    )
    print(caption)
    arm_planner = kinlearn.Planner.default("ur5", body=arm)
    planner = kinlearn.Planner.default("ur5")
    rows = {
        "the arm's body alone, fixed time": (arm_planner, {"refine_steps": 0}),
        "the arm's body alone, default": (arm_planner, {}),
        "with the tool (default body), fixed time": (planner, {"refine_steps": 0}),
        "with the tool (default body), default": (planner, {}),
        "with the tool (default body), deadline 0.05 s": (planner, {"deadline": 0.05}),
    }
    table = []
    for name, (pl, options) in rows.items():
        pl.warm_up()
        ok = flagged = 0
        seconds = []
        for i in keep:
            start, goal, scene = problems.problem(i)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                t0 = time.perf_counter()
                plan = pl.plan(start, goal, obstacles=scene, **options)
                seconds.append(time.perf_counter() - t0)
            joints = np.ascontiguousarray(plan.joints.double().numpy())[None]
            free = kernel.first_free(kt, joints, kernel.KernelScene(scene.to(torch.float64))) == 0
            ok += bool(plan.success) and free
            flagged += bool(plan.collision_free) and not free
        t = np.array(seconds) * 1e3
        table.append(
            [
                name,
                f"{ok / len(keep) * 100:.1f}%",
                str(flagged),
                f"{np.median(t):.2f}",
                f"{np.quantile(t, 0.99):.2f}",
            ]
        )
        print(f"  {name}: {table[-1][1]}, flagged free but colliding with the tool {flagged}", flush=True)
    print()
    figures: dict = {}
    show(
        figures,
        "the ur5 judged with its tool",
        [
            "planner",
            "success (judged with the tool)",
            "flagged free but colliding with the tool",
            "p50 ms",
            "p99 ms",
        ],
        table,
        caption=caption,
    )
    write_result(
        "ur5_gripper", figures, title="The ur5 with the standard benchmarks' tool", threads=args.threads
    )


if __name__ == "__main__":
    main()
