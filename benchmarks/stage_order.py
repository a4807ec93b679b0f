"""Which stage runs after the learned one: the sampler first, or the retreat stage first.

    OMP_NUM_THREADS=1 python benchmarks/stage_order.py [--robots iiwa14 panda ur5] [--n 140] [--threads 1]

On the held-out problems of ``benchmarks/data/scene_problems_<arm>.npz`` (never trained or tuned on; the
ur5's with its gripper), default ``plan()`` at batch 1 (a budget of sampler iterations, no deadline), two
planners that differ only in ``sample_first``: ``True`` (after the learned stage, the compiled RRT-Connect
with its shortcut; the retreat stage only where the sampler's budget ran out) and ``False``, the default
(the retreat stage, then the sampler seeded with its retreats). The two take turns problem by problem, in alternating
order, so that both see the machine's same minutes. Every plan is judged by ``judge`` (collision-free
by the dense check, the goal within tolerance). Reported per arm and order: success, p50, p99 and max of
``plan()``; the same over the problems the learned stage leaves colliding (where the orders differ); the
ratio of the p50s and p99s, the median ratio of the joint-space path lengths on the problems the
learned stage leaves colliding; and the stages that made the plans.
"""

from __future__ import annotations

import argparse
import time
import warnings
from collections import Counter
from pathlib import Path

import numpy as np
import torch
from _common import header, show, write_result

import kinlearn
from kinlearn import load_robot
from kinlearn.data.problems import ProblemSet
from kinlearn.planning.planner import DEFAULT_CHECKPOINTS

DATA = Path(__file__).parent / "data"
ORDERS = {"sampler first": True, "retreat first (default)": False}


def _ms(a) -> tuple[float, float, float]:
    a = np.asarray(a) * 1e3
    if a.size == 0:
        return (float("nan"),) * 3
    return float(np.median(a)), float(np.quantile(a, 0.99)), float(a.max())


def run_arm(name: str, n: int | None) -> tuple[list, dict]:
    robot = load_robot(name)
    problems = ProblemSet.load(DATA / f"scene_problems_{name}.npz", robot=name)
    if n:
        problems = problems[:n]
    body = problems.body(robot).double()
    planners = {
        label: kinlearn.Planner.load(DEFAULT_CHECKPOINTS / name, body=body, sample_first=first)
        for label, first in ORDERS.items()
    }
    for p in planners.values():
        p.plan(*problems.problem(0)[:2], obstacles=problems.problem(0)[2])  # kernels loaded
    seconds = {k: [] for k in planners}
    success = {k: [] for k in planners}
    stages = {k: Counter() for k in planners}
    learned = []  # whether the learned stage cleared the problem (the same for both)
    length = {k: [] for k in planners}  # joint-space length of each plan's path
    labels = list(planners)
    for i in range(len(problems)):
        start, goal, scene = problems.problem(i)
        for label in labels if i % 2 == 0 else labels[::-1]:
            t0 = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                plan = planners[label].plan(start, goal, obstacles=scene)
            seconds[label].append(time.perf_counter() - t0)
            success[label].append(bool(plan.success))
            stages[label][str(plan.stage)] += 1
            joints = np.asarray(plan.joints, dtype=np.float64)
            length[label].append(float(np.linalg.norm(np.diff(joints, axis=0), axis=1).sum()))
            if label == labels[0]:
                learned.append(plan.stage == "learned")
    after = ~np.asarray(learned)
    rows, figures = [], {}
    for label in labels:
        s = np.asarray(seconds[label])
        p50, p99, mx = _ms(s)
        a50, a99, amx = _ms(s[after])
        ok = float(np.mean(success[label])) * 100
        stage_text = ", ".join(f"{k} {v}" for k, v in sorted(stages[label].items()))
        rows.append([name, label, f"{ok:.1f}%", f"{p50:.2f}", f"{p99:.2f}", f"{mx:.2f}", int(after.sum()),
                     f"{a50:.2f}", f"{a99:.2f}", stage_text])  # fmt: skip
        figures[label] = {"success_pct": ok, "p50_ms": p50, "p99_ms": p99, "max_ms": mx,
                          "after_learned": {"n": int(after.sum()), "p50_ms": a50, "p99_ms": a99, "max_ms": amx},
                          "stages": dict(stages[label])}  # fmt: skip
    first, second = (figures[k] for k in labels)
    ratio = np.asarray(length[labels[0]])[after] / np.asarray(length[labels[1]])[after]
    figures["ratios"] = {
        "p50": first["p50_ms"] / second["p50_ms"],
        "p99": first["p99_ms"] / second["p99_ms"],
        "after_learned_p50": first["after_learned"]["p50_ms"] / second["after_learned"]["p50_ms"],
        "after_learned_length_p50": float(np.median(ratio)) if ratio.size else None,
    }
    print(f"{name}: sampler-first / retreat-first p50 {figures['ratios']['p50']:.2f}×, "
          f"p99 {figures['ratios']['p99']:.2f}×, joint length where they differ (median ratio) "
          f"{figures['ratios']['after_learned_length_p50']:.2f}×", flush=True)  # fmt: skip
    return rows, figures


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robots", nargs="+", default=["iiwa14", "panda", "ur5"])
    ap.add_argument("--n", type=int, default=None, help="first n problems per arm (default: all)")
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    print(header("The stage after the learned one", args.threads))
    rows, figures = [], {}
    for name in args.robots:
        r, f = run_arm(name, args.n)
        rows += r
        figures[name] = f
    show(
        figures,
        "stage order",
        [
            "arm",
            "order",
            "success",
            "p50 ms",
            "p99 ms",
            "max ms",
            "left by the learned stage",
            "their p50 ms",
            "their p99 ms",
            "stages",
        ],
        rows,
        caption="Default plan() (a sampler budget, no deadline), batch 1, one thread; the two orders by turns "
        "on the same held-out problems.",
    )
    write_result(
        "stage_order",
        figures,
        title="The stage after the learned one",
        notes="Planner(sample_first=True) against the default sample_first=False, by turns in one run.",
        threads=args.threads,
    )


if __name__ == "__main__":
    main()
