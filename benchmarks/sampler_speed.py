"""The compiled RRT-Connect two ways, on the committed held-out problems of the seven scene families, in
the same run on one thread:

- ``--compare pairs`` (default): every self-collision pair against the pairs proven apart left out
  (:func:`kinlearn.collision.kernel.proven_apart`);
- ``--compare rounds``: one iteration per call from Python against rounds sized to their time (the
  default of :func:`kinlearn.collision.rrt.rrt_connect`, :data:`~kinlearn.collision.rrt.ROUND_SECONDS`);
- ``--compare sampling``: :class:`~kinlearn.collision.rrt.RrtConnect`'s samplings (:data:`SAMPLINGS`):
  uniform random samples of the joint box (its default), dynamic-domain sampling, the Halton and the R2
  sequences, each within the plan's iteration budget (``--budget``, default
  :data:`~kinlearn.planning.planner.DEFAULT_RRT_ITERATIONS`) and ``--time-limit``.

    python benchmarks/sampler_speed.py [--robot panda] [--compare pairs|rounds|sampling] [--seeds 2]
        [--time-limit 2.0] [--budget 20000] [--threads 1]

For pairs and rounds both ways give every search the same path after the same iterations (checked); only its
time differs. The ways take turns, problem by problem (which goes first alternates; for sampling the order
rotates), so that each sees the machine's same minutes. Reported: per way the median, mean and p90 wall time
and the share solved within 10 and 50 ms, and the median over problems of the per-problem time ratio to the
first way (for pairs, also the pairs proven apart and the proof's time). For sampling the paths differ:
reported per way the share solved within the budget, the median, p90 and p99 iterations and wall time (an
unsolved search counts as infinitely long), the mean time over the problems the way and the first both
solved, and the sum of all searches' time (the unsolved ones' included) as a ratio to the first way's.
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
from kinlearn.planning.planner import DEFAULT_RRT_ITERATIONS

DATA = Path(__file__).parent / "data"
#: The samplings ``--compare sampling`` measures: :class:`~kinlearn.collision.rrt.RrtConnect`'s options.
SAMPLINGS = {
    "uniform (default)": {"sampling": "uniform", "domain": 0.0},
    "dynamic domain (2 steps, α = 1e-4)": {"domain": 2.0, "domain_alpha": 1e-4},
    "dynamic domain (2 steps, α = 0.1)": {"domain": 2.0, "domain_alpha": 0.1},
    "Halton": {"sampling": "halton"},
    "R2": {"sampling": "r2"},
}


def _q(x: np.ndarray, p: float, scale: float = 1.0, fmt: str = ".0f") -> str:
    """The ``p`` quantile of ``x`` times ``scale``, or "unsolved" where it is one (infinite)."""
    v = np.quantile(x, p)
    return format(scale * v, fmt) if np.isfinite(v) else "unsolved"


def compare_sampling(args, body, packed, scenes, lo, hi) -> None:
    """``--compare sampling``: the samplings of :data:`SAMPLINGS` by turns, problem by problem."""
    ways = SAMPLINGS
    its = {name: [] for name in ways}
    secs = {name: [] for name in ways}
    for seed in range(args.seeds):
        for i, (start, goal, _) in enumerate(scenes):
            k = (i + seed) % len(ways)
            for name in list(ways)[k:] + list(ways)[:k]:
                path, t, it = rrt_connect(
                    body, packed[i], start.double().numpy(), goal.double().numpy(), lo, hi,
                    time_limit=args.time_limit, max_iterations=args.budget, seed=1000 * seed + i,
                    shortcut=False, **ways[name],
                )  # fmt: skip
                its[name].append(it if path is not None else np.inf)
                secs[name].append(t)
    first = next(iter(ways))
    base_t = np.array(secs[first])
    rows = []
    for name in ways:
        it, t = np.array(its[name]), np.array(secs[name])
        ok = np.isfinite(it)
        both = ok & np.isfinite(its[first])
        tt = np.where(ok, t, np.inf)  # an unsolved search: infinitely long
        rows.append(
            [
                name,
                f"{int(ok.sum())}/{len(ok)} ({100 * ok.mean():.1f}%)",
                _q(it, 0.5),
                _q(it, 0.9),
                _q(it, 0.99),
                _q(tt, 0.5, 1e3, ".2f"),
                _q(tt, 0.9, 1e3, ".2f"),
                _q(tt, 0.99, 1e3, ".2f"),
                f"{1e3 * t[both].mean():.2f}",
                f"{t.sum() / base_t.sum():.3f}",
            ]
        )
    caption = (
        f"{len(scenes)} held-out problems × {args.seeds} seeds; at most {args.budget} iterations and "
        f"{args.time_limit:g} s per search, no shortcut pass; the ways by turns, problem by problem."
    )
    print(f"\n{caption}\n")
    figures: dict = {}
    what = "samplings"
    show(
        figures,
        what,
        [
            "sampling",
            "solved",
            "p50 iterations",
            "p90 iterations",
            "p99 iterations",
            "p50 ms",
            "p90 ms",
            "p99 ms",
            "mean ms (solved by it and uniform)",
            "total time / uniform's",
        ],
        rows,
        caption=caption,
    )
    write_result(
        f"sampler_speed_sampling_{args.robot}",
        figures,
        title=f"Compiled RRT-Connect: uniform samples, dynamic domain, Halton and R2 ({args.robot})",
        notes="The options of kinlearn.collision.rrt.RrtConnect (sampling, domain, domain_alpha; the "
        "dynamic domain's smallest radius half a step); uniform sampling is its default.",
        threads=args.threads,
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robot", default="panda")
    ap.add_argument("--compare", choices=("pairs", "rounds", "sampling"), default="pairs")
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--time-limit", type=float, default=2.0)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--budget", type=int, default=DEFAULT_RRT_ITERATIONS, help="iterations (sampling)")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    what = {
        "pairs": "every self-collision pair against the pairs proven apart left out",
        "rounds": "one iteration per round against rounds sized to their time",
        "sampling": "uniform samples against the dynamic domain and the low-discrepancy sequences",
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
    if args.compare == "sampling":
        compare_sampling(args, body, packed, scenes, lo, hi)
        return
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
