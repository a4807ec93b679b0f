"""The fixed-time stage's check: which of the planner's candidates is the first free one, per held-out
problem, by the compiled probe-then-walk (``first_free``) against the walk alone and the exact check of
every sub-step, timed in the same run on one thread.

    python benchmarks/candidate_check_speed.py [--robot panda] [--repeats 5] [--threads 1]

The candidates are those ``plan(..., refine_steps=0)`` checks (the straight line and the obstacle
network's paths both ways, shortest first) on the committed held-out problems of the seven scene families
(``benchmarks/data/scene_problems_{robot}.npz``). Four ways to the same answer:

- ``first_free``: each candidate probed first where the last candidates hit the scene (where a probe
  or a walk found their collision), then at spread
  grid configurations, scene only, link by link behind a ball per link (a hit is a collision; a clear
  one proves a window around it clear), then walked with budgets for self-collision and the rest of the
  grid proven clear of the scene, without the self-collision pairs proven apart (the planner's check); also with
  every pair, and without the places of the last hits;
- the walk alone: the budgeted verdict of each candidate in order until one is free;
- exact: every sub-step of every candidate evaluated (``check_paths``), the first free one taken.

Times per problem: the minimum over ``--repeats`` rounds (the machine's speed drifts between minutes),
then mean, p50 and p99 over the problems; every way must pick the same candidate.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import torch
from _common import header, show, write_result

import kinlearn
from kinlearn.collision import kernel as K
from kinlearn.data.problem import positions
from kinlearn.data.problems import ProblemSet
from kinlearn.models.obstacle_path import scene_primitives

DATA = Path(__file__).parent / "data"
TRAVEL = 0.01


def candidates(planner, problems):
    out = []
    for i in range(len(problems)):
        start, goal, scene = problems.problem(i)
        ef = positions(planner.robot, torch.stack((start, goal)).double().numpy())
        rows, _, floor = (t.numpy() for t in scene_primitives(scene, 1, torch.float64))
        paths, order = planner._proposals(
            start.double().numpy()[None],
            ef[:1],
            goal.double().numpy()[None],
            ef[1:],
            [(rows[0], floor[0])],
            0,
        )
        out.append((np.ascontiguousarray(paths[0]), np.ascontiguousarray(order[0], dtype=np.int64)))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robot", default="panda")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    print(header(f"The fixed-time stage's candidate check ({args.robot})", args.threads))
    problems = ProblemSet.load(DATA / f"scene_problems_{args.robot}.npz", robot=args.robot)
    planner = kinlearn.Planner.default(args.robot)
    kb = K.KernelBody(planner.body)
    f, n = kb.packed_within  # the candidates keep within the limits
    f_all, n_all = kb.packed
    cands = candidates(planner, problems)
    scenes = [K.KernelScene(problems.problem(i)[2].to(torch.float64)) for i in range(len(problems))]

    def probe_then_walk(paths, order, ks):
        return int(K._first_free_packed(paths, order, TRAVEL, 0.0, f, n, ks.packed))

    def every_pair(paths, order, ks):
        return int(K._first_free_packed(paths, order, TRAVEL, 0.0, f_all, n_all, ks.packed))

    def unhinted(paths, order, ks):
        return int(K._first_free_packed(paths, order, TRAVEL, 0.0, f, n, ks.packed, 0))

    def walk(paths, order, ks):
        for k in order:
            if K._verdict_packed(paths[k], TRAVEL, 0.0, f, n, ks.packed)[0] < 0:
                return int(k)
        return -1

    def exact(paths, order, ks):
        free = K.check_paths(kb, paths, ks, max_travel=TRAVEL)[0]
        return next((int(k) for k in order if free[k]), -1)

    ways = {
        "first_free (probe where the last candidates hit, then spread; then walk)": probe_then_walk,
        "first_free with every self-collision pair": every_pair,
        "probe spread only, then walk": unhinted,
        "the walk alone": walk,
        "exact": exact,
    }
    best, picks = {}, {}
    for fn in ways.values():
        fn(*cands[0], scenes[0])  # compile or load
    for _ in range(args.repeats):
        for name, fn in ways.items():  # the ways take turns: each sees the machine's same minutes
            t = []
            for (paths, order), ks in zip(cands, scenes, strict=True):
                t0 = time.perf_counter()
                pick = fn(paths, order, ks)
                t.append(time.perf_counter() - t0)
                picks.setdefault(name, []).append(pick)
            best[name] = np.minimum(best[name], t) if name in best else np.array(t)
    n_prob = len(cands)
    first = picks["exact"][:n_prob]
    for name in ways:
        if picks[name][:n_prob] != first:
            raise SystemExit(f"{name} picks other candidates than the exact check")
    base = best["the walk alone"]
    rows = [
        [
            name,
            f"{t.mean() * 1e3:.3f}",
            f"{np.median(t) * 1e3:.3f}",
            f"{np.quantile(t, 0.99) * 1e3:.3f}",
            f"{t.mean() / base.mean():.2f}× / {np.quantile(t, 0.99) / np.quantile(base, 0.99):.2f}×",
        ]
        for name, t in best.items()
    ]
    caption = (
        f"{n_prob} problems, {sum(len(o) for _, o in cands)} candidates, "
        f"{sum(p >= 0 for p in first)} problems with a free one; the same picks every way."
    )
    print(caption)
    figures: dict = {}
    show(
        figures,
        "candidate check",
        ["check", "mean ms", "p50 ms", "p99 ms", "mean / p99 against the walk alone"],
        rows,
        caption=caption,
    )
    write_result(
        f"candidate_check_speed_{args.robot}",
        figures,
        title=f"The fixed-time stage's candidate check ({args.robot})",
        threads=args.threads,
    )


if __name__ == "__main__":
    main()
