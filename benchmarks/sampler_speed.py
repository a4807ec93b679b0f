"""The compiled RRT-Connect two ways, on the committed held-out problems of the seven scene families, in
the same run on one thread:

- ``--compare pairs`` (default): every self-collision pair against the pairs proven apart left out
  (:func:`kinlearn.collision.kernel.proven_apart`);
- ``--compare rounds``: one iteration per call from Python against rounds sized to their time (the
  default of :func:`kinlearn.collision.rrt.rrt_connect`, :data:`~kinlearn.collision.rrt.ROUND_SECONDS`).

    python benchmarks/sampler_speed.py [--robot panda] [--compare pairs|rounds] [--seeds 2] [--time-limit 2.0]
        [--threads 1]

Both ways give every search the same path after the same iterations (checked); only its time differs.
The two take turns, problem by problem (which goes first alternates), so that each sees the machine's same
minutes. Reported: per way the median, mean and p90 wall time and the share solved within 10 and 50 ms,
and the median over problems of the per-problem time ratio to the first way (for pairs, also the pairs
proven apart and the proof's time).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import torch
from _common import header, show, write_result

from kinlearn import load_robot
from kinlearn.collision import kernel as K
from kinlearn.collision import planning_body
from kinlearn.collision.rrt import rrt_connect
from kinlearn.collision.rrt import warm_up as rrt_warm_up
from kinlearn.data.problems import ProblemSet

DATA = Path(__file__).parent / "data"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robot", default="panda")
    ap.add_argument("--compare", choices=("pairs", "rounds"), default="pairs")
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--time-limit", type=float, default=2.0)
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    what = {
        "pairs": "every self-collision pair against the pairs proven apart left out",
        "rounds": "one iteration per round against rounds sized to their time",
    }[args.compare]
    print(header(f"RRT-Connect: {what} ({args.robot})", args.threads))
    robot = load_robot(args.robot)
    problems = ProblemSet.load(DATA / f"scene_problems_{args.robot}.npz", robot=args.robot)
    K.warm_up()
    rrt_warm_up()
    body = K.KernelBody(planning_body(robot).double())
    t0 = time.perf_counter()
    apart = body.apart
    proof = time.perf_counter() - t0
    _ = body.packed_within  # made once, outside the timed runs
    lo, hi = np.asarray(robot.lower, np.float64), np.asarray(robot.upper, np.float64)
    scenes = [problems.problem(i) for i in range(len(problems))]
    packed = [K.KernelScene(sc.to(torch.float64)) for _, _, sc in scenes]
    packing = K.KernelBody.packing_of
    if args.compare == "pairs":  # (the packing of the body, the rounds)
        ways = {
            "every pair": (lambda self, a, b: self.packed, None),
            "pairs proven apart left out": (packing, None),
        }
    else:
        ways = {"one iteration per round": (packing, 1), "rounds sized to their time": (packing, None)}
    times = {name: [] for name in ways}
    try:
        for seed in range(args.seeds):
            for i, (start, goal, _) in enumerate(scenes):
                order = list(ways) if (i + seed) % 2 == 0 else list(ways)[::-1]
                found = {}
                for name in order:
                    K.KernelBody.packing_of, rounds = ways[name]
                    path, t, it = rrt_connect(
                        body, packed[i], start.double().numpy(), goal.double().numpy(), lo, hi,
                        time_limit=args.time_limit, seed=1000 * seed + i, rounds=rounds,
                    )  # fmt: skip
                    times[name].append(t if path is not None else np.inf)
                    found[name] = (it, None if path is None else path.tobytes())
                if len(set(found.values())) != 1 and np.isfinite([times[n][-1] for n in ways]).all():
                    raise SystemExit(f"problem {i}, seed {seed}: the two ways found different paths")
    finally:
        K.KernelBody.packing_of = packing
    first = next(iter(ways))
    base = np.array(times[first])
    rows = []
    for name, t in times.items():
        t = np.array(t)
        both = np.isfinite(t) & np.isfinite(base)
        rows.append(
            [
                name,
                f"{1e3 * np.median(t):.2f}",
                f"{1e3 * t[both].mean():.2f}",
                f"{1e3 * np.quantile(t, 0.9):.2f}",
                f"{100 * (t < 0.01).mean():.1f}% / {100 * (t < 0.05).mean():.1f}%",
                f"{np.median(t[both] / base[both]):.3f}",
            ]
        )
    proven = (
        f"; {int(apart.sum())} of {len(apart)} self-collision pairs proven apart in {proof:.2f} s (the planner's body)"
        if args.compare == "pairs"
        else ""
    )
    caption = f"{len(scenes)} held-out problems × {args.seeds} seeds{proven}; the same paths both ways."
    print(f"\n{caption}\n")
    figures: dict = {}
    show(
        figures,
        what,
        [
            "sampler",
            "p50 ms",
            "mean ms (both solved)",
            "p90 ms",
            "within 10 / 50 ms",
            f"time / {first}'s (median)",
        ],
        rows,
        caption=caption,
    )
    write_result(
        f"sampler_speed_{args.compare}_{args.robot}",
        figures,
        title=f"Compiled RRT-Connect: {what} ({args.robot})",
        threads=args.threads,
    )


if __name__ == "__main__":
    main()
