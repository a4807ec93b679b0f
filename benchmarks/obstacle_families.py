"""Planning among the seven scene families, per arm: success per family, the hard subset, batch-1 times,
and success against a time budget, for kinlearn and the baselines on the same problems and checker.

    python benchmarks/obstacle_families.py --robot panda [--problems benchmarks/data/scene_problems_panda.npz]
        [--planner DIR] [--kinlearn-only] [--no-floor] [--n 140] [--threads 1] [--out runs/benchmarks/families_panda]

Problems: a held-out set of ``benchmarks/make_obstacle_problems.py --families scenes`` (seeds 1004–1010,
verified solvable by OMPL RRT-Connect within 5 s); a set made with ``--within body`` (the ur5's within the
benchmarks' UR5 limits, ±π) is judged within those limits. Every method runs at batch 1 on one thread, one
untimed warm-up call first, and every path is judged by one rule
(:func:`kinlearn.evaluation.obstacles.obstacle_outcome`: starts at the start, reaches the goal, within
the limits, and the dense check finds no collision with the scene, the floor or itself).

Rows: the straight joint line; kinlearn's fixed-time stages (``refine_steps=0``: the learned
proposals, then the retreat stage, no refinement or sampling), the same with the network alone
(``retreat=False``) and with no network (the straight line, then the retreat stage: a planner trained
on nothing); its default plan (those, then a fixed budget of RRT-Connect iterations where they cleared
nothing; deterministic) and its plan with ``deadline=0.05``; the compiled RRT-Connect and OMPL's
RRT-Connect, each with time limits; the gradient trajectory optimiser. The success-against-budget figure draws, per
sampling planner, the share solved within each budget (its 1 s run's solve times), the kinlearn rows
as points at their p99 time, and the fixed-time rows also as the share of problems it solved within each
budget (its plans' own times, dashed). After every call of every row the paper-size TM's forward pass is
timed once, and each row's p50 and p99 are given over its p50 and p99 (the fixed-time goal's yardstick).

``--no-floor``: every scene planned and judged without its floor plane, as the scene files of the standard
benchmarks come (their obstacles alone, read through ``Scene.from_moveit``); the problems stay solvable (a
floor only narrows the free space).

Leave-one-family-out: ``--planner DIR`` plans with that folder's networks; the families its obstacle
network was not trained on (it records those it was) are marked ``*`` in the table, and the summary
gives their success apart (``left_out_success``).
"""

from __future__ import annotations

import argparse
import dataclasses
import inspect
import json
import time
import warnings
from pathlib import Path

import numpy as np
import torch
from _common import RUNS, from_markdown, header, markdown_table, write_result

import kinlearn
from kinlearn import Scene, load_robot
from kinlearn.data.problems import FAMILIES, ProblemSet
from kinlearn.errors import NoObstacleModelWarning
from kinlearn.evaluation.obstacles import obstacle_outcome
from kinlearn.models.trajectory import TMConfig, TrajectoryModel
from kinlearn.planning.obstacle_baselines import (
    compiled_rrt_connect,
    joint_line_path,
    scene_rrt_connect,
    trajectory_optimiser,
)
from kinlearn.planning.planner import DEFAULT_CHECKPOINTS

DATA = Path(__file__).parent / "data"


def _planner_rows(planner, folder: Path, body) -> dict:
    """kinlearn's plan as path functions, with and without a deadline (if this kinlearn has it); where
    this kinlearn has the retreat stage, its fixed-time stage also without it (the network alone) and
    without the network (the straight line and the retreat stage: what a planner trained on nothing
    clears). ``folder``: the planner's folder (loaded again for those two)."""
    has_deadline = "deadline" in inspect.signature(kinlearn.Planner.plan).parameters
    has_retreat = "retreat" in inspect.signature(kinlearn.Planner.__init__).parameters

    def run(start, goal, scene, planner=planner, **kw):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NoObstacleModelWarning)
            plan = planner.plan(start, goal, obstacles=scene, **kw)
        return torch.as_tensor(plan.joints), (plan.stage, bool(plan.collision_free))

    rows = {"kinlearn fixed time (refine_steps=0)": lambda s, g, sc: run(s, g, sc, refine_steps=0)}
    if has_retreat:
        alone = kinlearn.Planner.load(folder, retreat=False, body=body)
        bare = kinlearn.Planner.load(folder, obstacle_tm=None, body=body)
        rows["kinlearn fixed time, network alone (retreat=False)"] = lambda s, g, sc: run(
            s, g, sc, planner=alone, refine_steps=0
        )
        rows["kinlearn fixed time, no network (line + retreat)"] = lambda s, g, sc: run(
            s, g, sc, planner=bare, refine_steps=0
        )
    rows["kinlearn plan (default)"] = lambda s, g, sc: run(s, g, sc)
    if has_deadline:
        rows["kinlearn plan, deadline 0.05 s"] = lambda s, g, sc: run(s, g, sc, deadline=0.05)
    return rows


def methods(planner, folder, body, budgets, ompl_budgets, opt_steps) -> dict:
    rows = {"joint line": lambda s, g, sc: (joint_line_path(s, g, sc, body=body)[0], None)}
    rows.update(_planner_rows(planner, folder, body))
    for b in budgets:
        rows[f"compiled RRT-Connect, {b:g} s"] = lambda s, g, sc, b=b: (
            compiled_rrt_connect(s, g, sc, time_limit=b, body=body)[0],
            None,
        )
    for b in ompl_budgets:
        rows[f"OMPL RRT-Connect, {b:g} s"] = lambda s, g, sc, b=b: (
            scene_rrt_connect(s, g, sc, time_limit=b, body=body)[0],
            None,
        )
    for k in opt_steps:
        rows[f"optimiser, {k} steps"] = lambda s, g, sc, k=k: (
            trajectory_optimiser(s, g, sc, steps=k, body=body)[0],
            None,
        )
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robot", default="panda")
    ap.add_argument("--problems", type=Path, default=None)
    ap.add_argument(
        "--planner",
        type=Path,
        default=None,
        help="a planner folder (default: the shipped one), e.g. one holding a leave-one-family-out network",
    )
    ap.add_argument("--kinlearn-only", action="store_true", help="only the joint line and kinlearn's rows")
    ap.add_argument("--n", type=int, default=None, help="first n problems (default: all)")
    ap.add_argument("--budgets", type=float, nargs="*", default=[0.001, 0.01, 0.05, 1.0])
    ap.add_argument("--ompl-budgets", type=float, nargs="*", default=[0.05, 1.0])
    ap.add_argument("--opt-steps", type=int, nargs="*", default=[25])
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument(
        "--no-floor",
        action="store_true",
        help="plan and judge every scene without its floor, as a standard benchmark's scene file comes "
        "(boxes, cylinders and spheres; no floor plane)",
    )
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    path = args.problems or DATA / f"scene_problems_{args.robot}.npz"
    out = args.out or RUNS / f"families_{args.robot}"
    out.mkdir(parents=True, exist_ok=True)
    print(header(f"Planning among the scene families ({args.robot}, held-out problems)", args.threads))
    problems = ProblemSet.load(path, robot=args.robot)
    if args.n:
        problems = problems[: args.n]
    if args.no_floor:
        sc = problems.scene
        bare = Scene(
            spheres=sc.spheres, boxes=sc.boxes, cylinders=sc.cylinders,
            sphere_mask=sc.sphere_mask, box_mask=sc.box_mask, cylinder_mask=sc.cylinder_mask,
        )  # fmt: skip
        problems = dataclasses.replace(problems, scene=bare)
        print("scenes planned and judged without their floor (--no-floor)")
    robot = load_robot(args.robot)
    body = problems.body(robot).double()  # the body the problems were made for
    fams = [f for f in FAMILIES if len(problems.of(f))]
    print(f"{len(problems)} problems from {path} ({', '.join(f'{f} {len(problems.of(f))}' for f in fams)})")
    print(f"hard (straight joint line collides): {int(problems.hard.sum())}")
    folder = args.planner or DEFAULT_CHECKPOINTS / args.robot
    # Every row plans and is judged with the body the problems were made for (the ur5's committed set:
    # its arm with the gripper, its planning body; scene_problems_ur5_arm.npz: the arm alone)
    planner = kinlearn.Planner.load(folder, body=body)
    trained = None if planner.obstacle_tm is None else planner.obstacle_tm.families
    left_out = [f for f in fams if trained is not None and f not in trained]
    print(
        "obstacle network: "
        + (
            "none"
            if planner.obstacle_tm is None
            else f"trained on {', '.join(trained) if trained else 'unrecorded families'}"
        )
        + (f"; left out of its training, marked *: {', '.join(left_out)}" if left_out else "")
    )
    budgets, ompl_budgets, opt_steps = (
        ([], [], []) if args.kinlearn_only else (args.budgets, args.ompl_budgets, args.opt_steps)
    )
    rows, summary = [], {"_network": {"trained_on": trained, "left_out": left_out}}
    # The paper-size TM (GRU 20 → dense 20 → head 10 → 3, eager torch, batch 1): the fixed-time goal's
    # yardstick, timed after every call of every row.
    paper_tm = TrajectoryModel(TMConfig(robot=robot.name, dof=robot.dof, normalize=False)).eval()
    tm_state = torch.zeros(1, robot.dof + 3)
    for name, fn in methods(planner, folder, body, budgets, ompl_budgets, opt_steps).items():
        s0, g0, sc0 = problems.problem(0)
        fn(s0, g0, sc0)  # warm-up: compile, load, caches
        paths, seconds, stages, tm_seconds = [], [], [], []
        for i in range(len(problems)):
            start, goal, scene = problems.problem(i)
            t0 = time.perf_counter()
            joints, stage = fn(start, goal, scene)
            seconds.append(time.perf_counter() - t0)
            paths.append(joints)
            stages.append(stage)
            with torch.no_grad():  # the paper-size TM's forward pass, taking turns with the row's calls
                t0 = time.perf_counter()
                paper_tm(tm_state, tm_state)
                tm_seconds.append(time.perf_counter() - t0)
        outcome = obstacle_outcome(body, paths, problems)
        ok = outcome["success"].numpy()
        t = np.array(seconds)
        fam_rate = {f: float(ok[(problems.family == FAMILIES.index(f)).numpy()].mean()) for f in fams}
        hard = problems.hard.numpy()
        flagged = None
        if stages[0] is not None:  # kinlearn's rows: the stage and the plan's own collision_free flag
            flags = np.array([f for _, f in stages])
            stages = [s for s, _ in stages]
            # plans the planner called collision-free that the dense check of their joints finds colliding
            flagged = int((flags & ~outcome["collision_free"].numpy()).sum())
        stage_counts = {str(s): stages.count(s) for s in set(stages)} if stages[0] is not None else None
        tm_t = np.array(tm_seconds)
        summary[name] = {
            "success": float(ok.mean()),
            "p50_over_tm": float(np.median(t) / np.median(tm_t)),
            "p99_over_tm": float(np.quantile(t, 0.99) / np.quantile(tm_t, 0.99)),
            "tm_p50_ms": float(np.median(tm_t) * 1e3),
            "hard_success": float(ok[hard].mean()) if hard.any() else None,
            "by_family": fam_rate,
            "left_out_success": float(np.mean([fam_rate[f] for f in left_out])) if left_out else None,
            "p50_ms": float(np.median(t) * 1e3),
            "p99_ms": float(np.quantile(t, 0.99) * 1e3),
            "max_ms": float(t.max() * 1e3),
            "solve_ms": [float(x * 1e3) if o else None for x, o in zip(t, ok, strict=True)],
            "stages": stage_counts,
            "flagged_free_but_colliding": flagged,
        }
        rows.append(
            [
                name,
                f"{100 * ok.mean():.1f}%",
                f"{100 * ok[hard].mean():.1f}%" if hard.any() else "",
                *(f"{100 * fam_rate[f]:.0f}%" for f in fams),
                f"{np.median(t) * 1e3:.2f}",
                f"{np.quantile(t, 0.99) * 1e3:.2f}",
                f"{summary[name]['p50_over_tm']:.1f}× / {summary[name]['p99_over_tm']:.1f}×",
            ]
        )
        extra = "" if flagged is None else f", stages {stage_counts}, flagged free but colliding: {flagged}"
        print(f"  {name}: {100 * ok.mean():.1f}%, p50 {np.median(t) * 1e3:.2f} ms{extra}", flush=True)
    heads = [f"{f}*" if f in left_out else f for f in fams]
    table = markdown_table(
        ["method", "success", "hard", *heads, "p50 ms", "p99 ms", "p50 / p99 over the TM forward"], rows
    )
    print()
    print(table)
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    (out / "table.md").write_text(table + "\n")
    _figure(summary, out / "success_budget.png", args.robot, len(problems))
    print(f"\nwrote {out}/summary.json, table.md, success_budget.png")
    caption = (
        f"{len(problems)} held-out problems from {path.name}"
        + (", planned and judged without their floor" if args.no_floor else "")
        + f"; hard (straight joint line collides): {int(problems.hard.sum())}"
        + (f"; left out of the network's training, marked *: {', '.join(left_out)}" if left_out else "")
        + "."
    )
    suffix = "".join(
        s
        for s, on in (
            (f"_{path.stem}", args.problems is not None),
            ("_no_floor", args.no_floor),
            ("_kinlearn", args.kinlearn_only),
            ("_planner", args.planner is not None),
        )
        if on
    )
    write_result(
        f"obstacle_families_{args.robot}{suffix}",
        {"success and time": from_markdown(table, caption=caption)},
        title=f"Planning among the seven scene families ({args.robot}{', ' + suffix[1:].replace('_', ' ') if suffix else ''})",
        threads=args.threads,
    )


def _figure(summary: dict, path: Path, robot: str, n: int) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    grid = np.logspace(-4, 0, 200)
    for k, (name, s) in enumerate(summary.items()):
        if name.startswith("_"):
            continue
        color = f"C{k % 10}"
        if ", 1 s" in name or "fixed time" in name:  # solved within each budget (a sampler: its 1 s run)
            solved = np.array([x for x in s["solve_ms"] if x is not None]) / 1e3
            ax.plot(
                grid * 1e3,
                [100 * (solved <= b).sum() / n for b in grid],
                label=name.replace(", 1 s", "") + (" (each plan's own time)" if "fixed time" in name else ""),
                linestyle="--" if "fixed time" in name else "-",
                color=color,
            )
        elif "RRT" not in name:
            ax.scatter(
                [s["p99_ms"]], [100 * s["success"]], label=f"{name} (at its p99)", zorder=3, color=color
            )
    ax.set_xscale("log")
    ax.set_xlabel("time budget per problem (ms, batch 1, one core)")
    ax.set_ylabel("success (%)")
    ax.set_title(f"{robot}: success against time budget ({n} held-out problems)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=130)


if __name__ == "__main__":
    main()
