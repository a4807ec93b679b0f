"""How fast kinlearn plans among obstacles, per arm and scene family, against a yardstick measured in the
same run, so that figures taken on different machines compare.

    OMP_NUM_THREADS=1 python benchmarks/obstacle_speed.py [--robots iiwa14 panda ur5] [--n 140]
        [--time-limit 1.0] [--no-ompl]

Per arm (the iiwa14, the panda and the ur5 with its gripper: ``benchmarks/data/scene_problems_<arm>.npz``,
the held-out problems of the seven scene families, planned and judged with the body they were made for)
and family, at batch 1 on one thread, one untimed warm-up call first: the p50, p99 and max wall time of
``Planner.plan(start, goal, obstacles=scene)`` (the shipped planner's default: learned proposals, the
retreat stage, then the compiled sampler where those cleared nothing), beside the compiled RRT-Connect
alone (:func:`~kinlearn.planning.obstacle_baselines.compiled_rrt_connect`) and OMPL's RRT-Connect on the
same dense checker (:func:`~kinlearn.planning.obstacle_baselines.scene_rrt_connect`, its setup per
scene included, as a user calls it), each with ``--time-limit``; every path judged by one rule
(:func:`~kinlearn.evaluation.obstacles.obstacle_outcome`).

The yardstick: OMPL's RRT-Connect query on 300 obstacle-free iiwa14 pairs uniform within ±90% of its
limits (``numpy.random.default_rng(6060)``, the start array then the goal array), timed around setting
the states, ``solve`` and reading the path back (:meth:`~kinlearn.collision.ompl.OmplRrtConnect.solve`'s
own clock); its median in µs. Every time is also given as a ratio to it. Free space: the same 300 pairs
planned by ``Planner.plan(start, goal)`` (no obstacles), its median over the yardstick's.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import torch
from _common import header, show, write_result

import kinlearn
from kinlearn import load_robot
from kinlearn.data.problems import FAMILIES, ProblemSet
from kinlearn.evaluation.obstacles import obstacle_outcome
from kinlearn.planning.obstacle_baselines import compiled_rrt_connect, scene_rrt_connect
from kinlearn.planning.planner import DEFAULT_CHECKPOINTS

DATA = Path(__file__).parent / "data"


def yardstick_pairs(robot) -> tuple[np.ndarray, np.ndarray]:
    """300 start and goal joint vectors uniform within ±90% of ``robot``'s limits (seed 6060: starts, then goals)."""
    rng = np.random.default_rng(6060)
    lo, hi = 0.9 * np.asarray(robot.lower), 0.9 * np.asarray(robot.upper)
    starts = rng.uniform(lo, hi, (300, robot.dof))
    goals = rng.uniform(lo, hi, (300, robot.dof))
    return starts, goals


def yardstick() -> tuple[float, list[float]]:
    """OMPL RRT-Connect's median query time (s) on the 300 free iiwa14 pairs, and every query's."""
    from kinlearn.collision.ompl import OmplRrtConnect

    robot = load_robot("iiwa14")
    starts, goals = yardstick_pairs(robot)
    rrt = OmplRrtConnect(robot)
    rrt.solve(starts[0], goals[0], seed=1)  # warm-up
    times = []
    for i in range(len(starts)):
        path, seconds = rrt.solve(starts[i], goals[i], time_limit=1.0, seed=i + 1)
        if path is None:
            raise RuntimeError(f"the yardstick's query {i} found no path in free space")
        times.append(seconds)
    return float(np.median(times)), times


def free_space(planner) -> list[float]:
    """``Planner.plan(start, goal)`` on the yardstick's pairs, no obstacles: each call's seconds."""
    starts, goals = yardstick_pairs(planner.robot)
    planner.plan(starts[0], goals[0])  # warm-up
    times = []
    for i in range(len(starts)):
        t0 = time.perf_counter()
        planner.plan(starts[i], goals[i])
        times.append(time.perf_counter() - t0)
    return times


#: A fresh process's first plan among obstacles: import, load the shipped panda planner, plan problem 0.
_FIRST_PLAN = """
import torch
torch.set_num_threads(1)
import kinlearn
from kinlearn.data.problems import ProblemSet
from kinlearn.planning.planner import DEFAULT_CHECKPOINTS
problems = ProblemSet.load({path!r}, robot="panda")
planner = kinlearn.Planner.load(DEFAULT_CHECKPOINTS / "panda", body=problems.body(kinlearn.load_robot("panda")).double())
plan = planner.plan(*problems.problem(0)[:2], obstacles=problems.problem(0)[2])
assert plan.collision_free is not None
import time
print(time.time())
"""


def cold_start() -> dict:
    """Wall seconds from starting a fresh Python process to its first plan among obstacles (it imports
    kinlearn, loads the panda's planner and plans one problem; its own exit not counted): with an empty
    numba cache (every kernel it needs compiled: the first-ever plan after install), then twice with that
    cache warm (every later process)."""
    script = _FIRST_PLAN.format(path=str(DATA / "scene_problems_panda.npz"))
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache, "OMP_NUM_THREADS": "1"}
        times = []
        for _ in range(3):
            t0 = time.time()
            out = subprocess.run(
                [sys.executable, "-c", script], env=env, check=True, capture_output=True, text=True
            )
            times.append(float(out.stdout.split()[-1]) - t0)
    bare = time.perf_counter()
    subprocess.run([sys.executable, "-c", "import torch, kinlearn"], env=env, check=True)
    bare = time.perf_counter() - bare
    return {"first_ever_s": times[0], "warm_cache_s": min(times[1:]), "import_torch_kinlearn_s": bare}


def check_rate(n: int = 20_000) -> dict:
    """Configurations checked per second on the panda among problem 0's scene (``n`` uniform within its
    limits): :func:`~kinlearn.collision.kernel.free_configurations` (one call) against the dense check on
    the same configurations as one-configuration paths (:func:`~kinlearn.collision.kernel.check_paths`,
    ``exact=False``) and the walk's clearances (:func:`~kinlearn.collision.kernel.clearances`); the
    verdicts are asserted equal."""
    from kinlearn.collision import kernel as K

    robot = load_robot("panda")
    problems = ProblemSet.load(DATA / "scene_problems_panda.npz", robot="panda")
    kb = K.KernelBody.of(problems.body(robot).double())
    ks = K.KernelScene.of(problems.problem(0)[2])
    q = np.random.default_rng(7).uniform(robot.lower, robot.upper, (n, robot.dof))
    out = {}
    for label, fn in (
        ("free_configurations", lambda: K.free_configurations(kb, ks, q)),
        ("check_paths (one-configuration paths)", lambda: K.check_paths(kb, q[:, None], ks, exact=False)[0]),
        ("clearances", lambda: np.logical_and(*(np.asarray(v) > 0 for v in K.clearances(kb, ks, q)))),
    ):
        fn()
        t0 = time.perf_counter()
        verdict = fn()
        out[label] = {"per_second": n / (time.perf_counter() - t0), "free": float(np.mean(verdict))}
    return out


def stats(seconds, yard: float) -> dict:
    a = np.asarray(seconds)
    return {
        "p50_ms": float(np.median(a) * 1e3),
        "p99_ms": float(np.quantile(a, 0.99) * 1e3),
        "max_ms": float(a.max() * 1e3),
        "p50_x": float(np.median(a) / yard),
        "p99_x": float(np.quantile(a, 0.99) / yard),
    }


def run_arm(name: str, n: int | None, time_limit: float, ompl: bool, yard: float) -> dict:
    robot = load_robot(name)
    problems = ProblemSet.load(DATA / f"scene_problems_{name}.npz", robot=name)
    if n:
        problems = problems[:n]
    body = problems.body(robot).double()
    planner = kinlearn.Planner.load(DEFAULT_CHECKPOINTS / name, body=body)

    def plan(s, g, sc):
        return torch.as_tensor(planner.plan(s, g, obstacles=sc).joints)

    methods = {
        "kinlearn plan": plan,
        "compiled RRT-Connect": lambda s, g, sc: compiled_rrt_connect(
            s, g, sc, time_limit=time_limit, body=body
        )[0],
    }
    if ompl:
        methods["OMPL RRT-Connect (same checker)"] = lambda s, g, sc: scene_rrt_connect(
            s, g, sc, time_limit=time_limit, body=body
        )[0]
    fam = np.asarray(problems.family)
    out = {}
    for label, fn in methods.items():
        fn(*problems.problem(0))  # warm-up: kernels loaded, caches
        seconds, paths = [], []
        for i in range(len(problems)):
            start, goal, scene = problems.problem(i)
            t0 = time.perf_counter()
            joints = fn(start, goal, scene)
            seconds.append(time.perf_counter() - t0)
            paths.append(joints)
        ok = obstacle_outcome(body, paths, problems)["success"].numpy()
        seconds = np.asarray(seconds)
        row = {"all": {**stats(seconds, yard), "success": float(ok.mean()), "n": len(seconds)}}
        for f, family in enumerate(FAMILIES):
            sel = fam == f
            if sel.any():
                row[family] = {
                    **stats(seconds[sel], yard),
                    "success": float(ok[sel].mean()),
                    "n": int(sel.sum()),
                }
        out[label] = row
        a = row["all"]
        print(
            f"{name:7s} {label:32s} success {a['success']:.3f}  p50 {a['p50_ms']:.3f} ms ({a['p50_x']:.0f}×)  "
            f"p99 {a['p99_ms']:.3f} ms ({a['p99_x']:.0f}×)  max {a['max_ms']:.2f} ms",
            flush=True,
        )
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robots", nargs="*", default=["iiwa14", "panda", "ur5"])
    ap.add_argument("--n", type=int, default=None, help="first n problems per arm (default: all)")
    ap.add_argument("--time-limit", type=float, default=1.0, help="the samplers' time limit (s)")
    ap.add_argument("--no-ompl", action="store_true")
    ap.add_argument("--no-cold", action="store_true", help="leave out the fresh processes' first plans")
    ap.add_argument("--name", default="obstacle_speed", help="the result file's name")
    args = ap.parse_args()
    torch.set_num_threads(1)
    warnings.simplefilter("ignore")
    print(header("Planning among obstacles against the yardstick (batch 1, one thread)", 1))
    yard, _ = yardstick()
    print(f"yardstick: OMPL RRT-Connect, 300 free iiwa14 pairs, median {yard * 1e6:.1f} µs", flush=True)
    figures: dict = {"yardstick_us": yard * 1e6}
    if not args.no_cold:
        figures["cold_start"] = cold = cold_start()
        print(
            f"first plan in a fresh process (panda, among obstacles): {cold['first_ever_s']:.1f} s with an empty "
            f"numba cache, {cold['warm_cache_s']:.2f} s with it warm (import torch and kinlearn alone: "
            f"{cold['import_torch_kinlearn_s']:.2f} s)",
            flush=True,
        )
    figures["checks_per_second"] = rate = check_rate()
    for label, r in rate.items():
        print(f"panda, {label}: {r['per_second']:,.0f} configurations/s ({r['free']:.3f} free)", flush=True)
    free_planner = kinlearn.Planner.load(DEFAULT_CHECKPOINTS / "iiwa14")
    free = np.asarray(free_space(free_planner))
    figures["free_space_plan"] = {
        "p50_us": float(np.median(free) * 1e6),
        "p50_x": float(np.median(free) / yard),
    }
    print(f"free-space plan (iiwa14, the yardstick's pairs): median {np.median(free) * 1e6:.1f} µs "
          f"({np.median(free) / yard:.2f}× the yardstick)", flush=True)  # fmt: skip
    rows = []
    for name in args.robots:
        per = run_arm(name, args.n, args.time_limit, not args.no_ompl, yard)
        figures[name] = per
        for label, row in per.items():
            for family, s in row.items():
                rows.append([
                    name, label, family, s["n"], f"{s['success']:.3f}", f"{s['p50_ms']:.3f}",
                    f"{s['p99_ms']:.3f}", f"{s['max_ms']:.2f}", f"{s['p50_x']:.0f}", f"{s['p99_x']:.0f}",
                ])  # fmt: skip
    cols = ["arm", "method", "family", "n", "success", "p50 ms", "p99 ms", "max ms", "p50 ×yard", "p99 ×yard"]
    show(figures, "per arm and family", cols, rows)
    write_result(
        args.name,
        figures,
        title="Planning among obstacles against the yardstick",
        notes="Batch 1, one thread; the yardstick (OMPL RRT-Connect on 300 free iiwa14 pairs) measured in the "
        "same run. Targets of issue 53: plan() p50 ≤ 13× and p99 ≤ 90× the yardstick on every arm; free-space "
        "plan() ≤ 1.0×.",
        threads=1,
    )


if __name__ == "__main__":
    main()
