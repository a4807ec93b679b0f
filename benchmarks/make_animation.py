"""The README's animation: a plan of the shipped iiwa14 planner, timed with toppra, as a GIF.

    python benchmarks/make_animation.py [--out docs/figures/plan_animation.gif] [--fps 20]
                                        [--speed 0.4] [--hold 0.75]

The plan is ``kinlearn.plan(START, GOAL)`` for the README's quick-start start and goal. Its joint path
is time-parameterised (``kinlearn.planning.timing.time_parameterize``) under the URDF's velocity limits scaled
by ``--speed`` and the default acceleration limits scaled by its square — the time-optimal motion
played ``1 / speed`` times slower — and sampled at the GIF's frame rate; the last configuration is
held for ``--hold`` seconds before the GIF loops. The planner's end-effector waypoints are drawn as orange dots.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np
import torch

import kinlearn
from kinlearn.planning.timing import DEFAULT_ACCELERATION_TIME, time_parameterize
from kinlearn.viz import animate_plan

ROOT = Path(__file__).resolve().parents[1]
START = (0.3, 0.45, 0.0, -1.35, 0.0, 1.05, 0.0)  # the README's quick-start start and goal (rad)
GOAL = (0.6, 1.1, 0.0, -0.7, 0.0, 0.9, 0.0)


def demo_plan():
    """The iiwa14 and the shipped planner's plan from START to GOAL (shared with viewer_screenshot.py)."""
    robot = kinlearn.load_robot("iiwa14")
    plan = kinlearn.plan(torch.tensor(START), torch.tensor(GOAL))
    return robot, plan


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "figures" / "plan_animation.gif")
    ap.add_argument("--fps", type=float, default=20.0)
    ap.add_argument("--speed", type=float, default=0.4, help="fraction of the time-optimal speed")
    ap.add_argument("--hold", type=float, default=0.75, help="seconds to hold the last pose")
    ap.add_argument("--dpi", type=int, default=80)
    args = ap.parse_args()
    torch.set_num_threads(1)

    t0 = time.perf_counter()
    robot, plan = demo_plan()
    acc = args.speed**2 * robot.velocity_limits / DEFAULT_ACCELERATION_TIME
    timed = time_parameterize(
        robot, plan.joints, dt=1.0 / args.fps, velocity_scale=args.speed, acceleration_limits=acc
    )
    hold = round(args.hold * args.fps)
    q = np.concatenate([timed.q, np.repeat(timed.q[-1:], hold, axis=0)])
    times = np.concatenate([timed.t, np.full(hold, timed.duration)])
    out = animate_plan(
        robot,
        q,
        args.out,
        waypoints=plan.waypoints,
        times=times,
        fps=args.fps,
        dpi=args.dpi,
        title=f"iiwa14: a kinlearn plan, timed by toppra ({args.speed:g}× the fastest)",
    )
    goal_ef = kinlearn.kinematics(robot, "fast").position(torch.tensor(GOAL, dtype=torch.float64))
    err = float(np.linalg.norm(timed.q[-1] - plan.joints[-1].double().numpy()))
    print(f"wrote {out} ({out.stat().st_size / 1e6:.2f} MB, {len(q)} frames at {args.fps:g} fps) in "
          f"{time.perf_counter() - t0:.1f} s")  # fmt: skip
    print(f"timed trajectory: {timed.duration:.2f} s ({timed.interpolant}) at {args.speed:g} × time-optimal speed; "
          f"end-effector start → goal {float(torch.linalg.norm(plan.ef[-1].double() - plan.ef[0].double())):.3f} m, "
          f"executed goal error {1e3 * float(torch.linalg.norm(plan.ef[-1].double() - goal_ef)):.1f} mm, "
          f"timed end vs plan end {err:.1e} rad")  # fmt: skip


if __name__ == "__main__":
    main()
