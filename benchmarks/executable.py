"""What a robot executes among obstacles: kinlearn's timed plans beside a sampler's, checked as executed.

    OMP_NUM_THREADS=1 python benchmarks/executable.py [--robots iiwa14 panda ur5] [--n 140] [--rrt-iterations 100000]
    OMP_NUM_THREADS=1 python benchmarks/executable.py --robots xarm7 z1 --per-family 6 --result executable_onboarded
    OMP_NUM_THREADS=1 python benchmarks/executable.py --robots --onboarded runs/onboard/ur10 --per-family 10 \
        --rrt-iterations 20000 --result executable_ur10

Per arm and scene family, on the held-out problems of ``benchmarks/data/scene_problems_<arm>.npz``
(made by ``benchmarks/make_obstacle_problems.py --families scenes``, never trained or tuned on; the
ur5's with its gripper), or, for an arm without such a file (the onboarded xarm7 and z1), on held-out
problems made for it as ``benchmarks/onboard.py`` makes them, at batch 1 on one thread:

- **kinlearn**: default ``plan()`` (deterministic), then ``plan.timed()`` (the executed motion verified
  against the plan's scene and body, repaired where it leaves the checked corridor);
- **baseline**: the compiled RRT-Connect (:func:`kinlearn.collision.rrt.rrt_connect`, an iteration budget,
  seed 0), then the same shortcut pass (:func:`kinlearn.collision.shortcut.shorten`) and the same
  verified timing (:func:`kinlearn.planning.timing.time_parameterize`), on the same problems.

Every timed trajectory is checked **as executed** by an implementation other than the compiled kernel
that planned and verified it: the torch reference (:func:`kinlearn.collision.clearances`: the body's
torch FK and the primitives' torch distances) on the timed samples, linearly densified to at most 5 mrad
per joint; a trajectory collides where a sphere sinks more than 1 mm into the scene, the floor or the
body itself. Reported: success, plans that cannot be timed, executed trajectories that collide,
median executed duration and joint path length (of the timed samples) and their ratios to the baseline's
on the problems both solve, and the p50 of ``plan()`` with and without the shortcut stage, timed by
turns in the same run.
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np
import torch
from _common import RUNS, header, show, write_result

import kinlearn
from kinlearn import load_robot
from kinlearn.collision import kernel
from kinlearn.collision.check import clearances
from kinlearn.collision.rrt import rrt_connect
from kinlearn.collision.shortcut import shorten
from kinlearn.data.problems import FAMILIES, ProblemSet
from kinlearn.errors import TimingError
from kinlearn.planning.plan import CHECK_TRAVEL, executed_check
from kinlearn.planning.planner import DEFAULT_CHECKPOINTS
from kinlearn.planning.timing import time_parameterize

#: Executed motion judged colliding where a sphere sinks deeper than this (m).
DEPTH = 1e-3
#: The executed samples are densified to at most this much joint motion (rad) between checks.
DENSE = 0.005


def executed_depth(body, q: np.ndarray, scene) -> float:
    """The deepest penetration (m; negative: the clearance) of the timed samples ``q (K, dof)``, densified
    to :data:`DENSE` rad per joint, by the torch reference check."""
    step = np.abs(np.diff(q, axis=0)).max(1)
    pieces = [q[:1]]
    for a, b, m in zip(q[:-1], q[1:], np.maximum(1, np.ceil(step / DENSE)).astype(int), strict=True):
        pieces.append(a + (np.arange(1, m + 1)[:, None] / m) * (b - a))
    dense = torch.from_numpy(np.concatenate(pieces))
    worst = -np.inf
    for chunk in dense.split(20_000):
        d, s = clearances(body, chunk, scene, validate=False)
        worst = max(worst, -float(torch.minimum(d, s).min()))
    return worst


def length(q: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(q, axis=0), axis=1).sum())


def problem_set(arm: str, per_family: int) -> ProblemSet:
    """The committed held-out problems of ``arm`` where there are (``benchmarks/data``), else held-out problems
    of the seven families made for it as ``benchmarks/onboard.py`` makes them (held-out seeds, unverified:
    some may have no solution), kept under ``runs/benchmarks``."""
    committed = Path(DATA) / f"scene_problems_{arm}.npz"
    if committed.is_file():
        return ProblemSet.load(committed, robot=arm)
    from onboard import heldout

    RUNS.mkdir(parents=True, exist_ok=True)
    return ProblemSet.load(heldout(load_robot(arm), per_family, RUNS), robot=arm)


def run_arm(arm: str, n: int | None, iterations: int, figures: dict, per_family: int = 6) -> dict:
    problems = problem_set(arm, per_family)
    if n:
        problems = problems[np.linspace(0, len(problems) - 1, min(n, len(problems))).astype(int)]
    robot = load_robot(arm)
    body = problems.body(robot).double()
    folder = getattr(robot, "planner_dir", None) or DEFAULT_CHECKPOINTS / arm  # an onboarded arm's own
    planner = kinlearn.Planner.load(folder, body=body)
    raw = kinlearn.Planner.load(folder, body=body, shortcut=False)
    kb = kernel.KernelBody.of(body)
    start, goal, scene = problems.problem(0)
    for p in (planner, raw):
        p.plan(start, goal, obstacles=scene)  # warm-up: compile, load, caches
    rows = []
    per: dict[str, list] = {k: [] for k in ("family", "ok", "untimed", "hit", "dur", "len", "t", "t_raw")}
    base: dict[str, list] = {k: [] for k in ("ok", "untimed", "hit", "dur", "len")}
    for i in range(len(problems)):
        start, goal, scene = problems.problem(i)
        fam = FAMILIES[int(problems.family[i])]
        per["family"].append(fam)
        # plan() with and without the shortcut stage, by turns (the order alternating)
        for which in (planner, raw) if i % 2 else (raw, planner):
            t0 = time.perf_counter()
            plan = which.plan(start, goal, obstacles=scene)
            per["t" if which is planner else "t_raw"].append(time.perf_counter() - t0)
            if which is planner:
                kept = plan
        plan = kept
        ok = bool(plan.success)
        per["ok"].append(ok)
        untimed, hit, dur, ln = False, False, np.nan, np.nan
        if ok:
            try:
                traj = plan.timed()
                dur, ln = traj.duration, length(traj.q)
                hit = executed_depth(body, traj.q, scene) > DEPTH
            except TimingError:
                untimed = True
        per["untimed"].append(untimed)
        per["hit"].append(hit)
        per["dur"].append(dur)
        per["len"].append(ln)
        # the baseline: compiled RRT-Connect, the same shortcut, the same verified timing
        ks = kernel.KernelScene.of(scene)
        q0, q1 = start.numpy()[: robot.dof], goal.numpy()[: robot.dof]
        path, _, _ = rrt_connect(
            kb, ks, q0, q1, robot.lower, robot.upper, time_limit=float("inf"), seed=0,
            max_travel=CHECK_TRAVEL, max_iterations=iterations, shortcut=False,
        )  # fmt: skip
        bok, buntimed, bhit, bdur, bln = path is not None, False, False, np.nan, np.nan
        if bok:
            short = shorten(kb, ks, path, max_travel=CHECK_TRAVEL)
            try:
                traj = time_parameterize(robot, short, verify=executed_check(body, scene))
                bdur, bln = traj.duration, length(traj.q)
                bhit = executed_depth(body, traj.q, scene) > DEPTH
            except TimingError:
                buntimed = True
        for k, v in zip(
            ("ok", "untimed", "hit", "dur", "len"), (bok, buntimed, bhit, bdur, bln), strict=True
        ):
            base[k].append(v)
    fam = np.array(per["family"])
    arr = {k: np.array(v) for k, v in per.items() if k != "family"}
    barr = {k: np.array(v) for k, v in base.items()}
    both = arr["ok"] & barr["ok"] & np.isfinite(arr["dur"]) & np.isfinite(barr["dur"])

    def ratio(a, b, m):
        return float(np.median(a[m]) / np.median(b[m])) if m.any() else float("nan")

    for f in [*[f for f in FAMILIES if (fam == f).any()], "all"]:
        m = np.ones(len(fam), bool) if f == "all" else fam == f
        rows.append(
            [
                f, int(m.sum()), f"{100 * arr['ok'][m].mean():.1f}", int(arr["untimed"][m].sum()),
                int(arr["hit"][m].sum()), f"{100 * barr['ok'][m].mean():.1f}", int(barr["hit"][m].sum()),
                f"{ratio(arr['dur'], barr['dur'], m & both):.2f}", f"{ratio(arr['len'], barr['len'], m & both):.2f}",
            ]
        )  # fmt: skip
    show(
        figures,
        f"{arm}: executed trajectories",
        [
            "family", "problems", "kinlearn success %", "not timed", "executed colliding",
            "baseline success %", "baseline colliding", "duration ÷ baseline", "joint length ÷ baseline",
        ],
        rows,
        caption=(
            f"{arm}: default plan() then plan.timed(), beside compiled RRT-Connect ({iterations:,} iterations) + "
            "the same shortcut + the same verified timing; colliding: > 1 mm deep on the timed samples "
            "densified to 5 mrad, torch reference check; ratios of medians on problems both solve"
        ),
    )  # fmt: skip
    t, t_raw = np.array(per["t"]), np.array(per["t_raw"])
    summary = {
        "success": float(arr["ok"].mean()),
        "not_timed": int(arr["untimed"].sum()),
        "executed_colliding": int(arr["hit"].sum()),
        "baseline_success": float(barr["ok"].mean()),
        "baseline_executed_colliding": int(barr["hit"].sum()),
        "duration_ratio": ratio(arr["dur"], barr["dur"], both),
        "length_ratio": ratio(arr["len"], barr["len"], both),
        "median_duration_s": float(np.median(arr["dur"][both])) if both.any() else None,
        "plan_p50_ms": 1e3 * float(np.median(t)),
        "plan_p50_ms_without_shortcut": 1e3 * float(np.median(t_raw)),
        "plan_p50_ratio_shortcut": float(np.median(t) / np.median(t_raw)),
        "plan_p99_ms": 1e3 * float(np.percentile(t, 99)),
        "problems": len(problems),
    }
    print(
        f"{arm}: plan() p50 {summary['plan_p50_ms']:.2f} ms with the shortcut stage, "
        f"{summary['plan_p50_ms_without_shortcut']:.2f} ms without ({summary['plan_p50_ratio_shortcut']:.2f}×)"
    )
    return summary


DATA = "benchmarks/data"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--robots", nargs="*", default=["iiwa14", "panda", "ur5"])
    ap.add_argument(
        "--n", type=int, default=None, help="problems per arm, spread over the set (default: all)"
    )
    ap.add_argument("--rrt-iterations", type=int, default=100_000, help="the baseline sampler's budget")
    ap.add_argument(
        "--per-family", type=int, default=6, help="problems per family for an arm without a committed set"
    )
    ap.add_argument("--result", default="executable", help="the result file's name")
    ap.add_argument(
        "--onboarded",
        nargs="*",
        type=Path,
        default=[],
        help="run directories of `kinlearn onboard` (their arms)",
    )
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    warnings.simplefilter("ignore")
    print(header("Executed trajectories among obstacles (held-out scene problems)", args.threads))
    figures: dict = {}
    from kinlearn.training.onboard import load_onboarded

    arms = list(args.robots) + [load_onboarded(d).name for d in args.onboarded]
    for arm in arms:
        figures[f"{arm} summary"] = run_arm(arm, args.n, args.rrt_iterations, figures, args.per_family)
    write_result(
        args.result,
        figures,
        title="Executed trajectories among obstacles"
        + ("" if args.result == "executable" else f" ({', '.join(arms)})"),
        notes=(
            "What a robot executes: plan.timed() of default plans, checked as executed (timed samples "
            "densified to 5 mrad per joint, the torch reference check, > 1 mm deep counts), beside the "
            "compiled RRT-Connect with the same shortcut pass and the same verified timing."
        ),
        threads=args.threads,
    )


if __name__ == "__main__":
    main()
