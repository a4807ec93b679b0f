"""Planning around obstacles: every method on the held-out obstacle problems, one problem at a time.

    python benchmarks/obstacle_planner.py [--n 150] [--families tabletop shelf barrier]
        [--methods NAME ...] [--rrt-time 1.0] [--opt-steps 25 100 400] [--out runs/obstacle_benchmark]

Problems: ``benchmarks/data/obstacle_problems_heldout.npz`` (iiwa14; tabletop, shelf and barrier scenes;
``hard``: the straight joint line collides). ``--n`` keeps the first ⌈n / families⌉ problems of each
chosen family (a deterministic subset; the problems of a family are independent draws, so the first k
are as good a sample as any k). Every method plans at batch 1 on one torch thread and is timed per
problem by wall clock around its call, after one untimed warm-up call on the first problem.

Rows (the registry :func:`methods`: ``name -> callable(start, goal, scene) -> joints (K, dof) or None``):
the straight joint line and the Cartesian line with DLS IK (both obstacle-unaware), OMPL RRT-Connect
on the dense 1 cm checker without and with OMPL's path simplification (the ``--rrt-time`` limit covers
both), the gradient trajectory optimiser at each ``--opt-steps`` (one curve in the figure), and the
learned planner through ``Planner.default("iiwa14").plan(start, goal, obstacles=scene, refine_steps=k)``
(its fixed-time stages: the proposals and k refinement steps, no sampling; skipped with a note where
that call raises TypeError: a planner without the obstacle argument).

Every path is judged by :func:`kinlearn.evaluation.obstacles.obstacle_outcome`: starts at the start, ends
within 0.05 rad and 1 cm (analytic FK) of the goal, stays within the joint limits, and passes the dense
check (≤ 1 cm of sphere travel between checked configurations) against the scene, the floor and
itself with the 12-sphere body. Writes into ``--out``: ``obstacle_benchmark.json`` (per problem and per
method), ``obstacle_benchmark.md`` (the table), ``success_latency.png`` and ``obstacle_plans.png``.
"""

from __future__ import annotations

import argparse
import math
import os
import shlex
import sys
import time
import warnings
from collections.abc import Callable
from pathlib import Path

import torch
from _common import from_markdown, header, write_result

from kinlearn.data.problems import FAMILIES, ProblemSet
from kinlearn.errors import KinlearnError, MissingDependencyError
from kinlearn.evaluation.obstacles import (
    OUTCOME_KEYS,
    format_table,
    obstacle_outcome,
    plot_obstacle_plans,
    plot_success_latency,
    summarize_outcome,
)
from kinlearn.io import atomic_write, write_json
from kinlearn.planning.obstacle_baselines import (
    OptimiserConfig,
    cartesian_line_path,
    default_body,
    joint_line_path,
    scene_rrt_connect,
    trajectory_optimiser,
)

HELDOUT = Path(__file__).resolve().parent / "data" / "obstacle_problems_heldout.npz"
ROBOT = "iiwa14"

Method = Callable[[torch.Tensor, torch.Tensor, object], "torch.Tensor | None"]


class LearnedPlanner:
    """The shipped planner with obstacles (or its models with another obstacle-aware TM), loaded on its
    first call (the untimed warm-up)."""

    def __init__(self, robot: str = ROBOT, refine_steps: int = 0, obstacle_tm: str | None = None):
        self.robot, self.refine_steps, self.obstacle_tm = robot, refine_steps, obstacle_tm
        self.planner = None

    def __call__(self, start, goal, scene):
        if self.planner is None:
            from kinlearn.models.obstacle_path import load_obstacle_model
            from kinlearn.planning.planner import Planner

            base = Planner.default(self.robot)
            otm = load_obstacle_model(self.obstacle_tm) if self.obstacle_tm else base.obstacle_tm
            self.planner = Planner(
                base.robot, base.tm, base.fm, base.im, obstacle_tm=otm, refine_steps=self.refine_steps
            )
        # refine_steps given: the fixed-time stages alone (without it, a plan left colliding is sampled for)
        return self.planner.plan(start, goal, obstacles=scene, refine_steps=self.refine_steps).joints


def optimiser_name(steps: int) -> str:
    return f"optimiser, {steps} steps"


def methods(
    rrt_time: float = 1.0,
    opt_steps: tuple[int, ...] = (25, 100, 400),
    refine_steps: tuple[int, ...] = (25,),
    obstacle_tms: dict[str, str] | None = None,
) -> dict[str, Method]:
    """The rows of the benchmark, in table order. Add a planner with one entry."""
    body = default_body(ROBOT)
    rows: dict[str, Method] = {
        "joint line": lambda s, g, sc: joint_line_path(s, g, sc, body=body)[0],
        "Cartesian line + DLS": lambda s, g, sc: cartesian_line_path(s, g, sc, body=body)[0],
        f"RRT-Connect ({rrt_time:g} s)": lambda s, g, sc: scene_rrt_connect(
            s, g, sc, time_limit=rrt_time, simplify=False, body=body
        )[0],
        f"RRT-Connect + simplify ({rrt_time:g} s)": lambda s, g, sc: scene_rrt_connect(
            s, g, sc, time_limit=rrt_time, simplify=True, body=body
        )[0],
    }
    for k in opt_steps:
        rows[optimiser_name(k)] = lambda s, g, sc, k=k: trajectory_optimiser(s, g, sc, steps=k, body=body)[0]
    rows["kinlearn"] = LearnedPlanner(ROBOT)
    for k in refine_steps:
        rows[f"kinlearn + {k} refinement steps"] = LearnedPlanner(ROBOT, refine_steps=k)
    for name, path in (obstacle_tms or {}).items():
        rows[name] = LearnedPlanner(ROBOT, obstacle_tm=path)
    return rows


def _optional(name: str) -> bool:
    """Rows skipped with a note (not an error) when their first call raises TypeError or a kinlearn error
    (e.g. a planner folder without an obstacle-aware model): kinlearn's own rows."""
    return name.startswith("kinlearn")


def _named_path(text: str) -> tuple[str, str]:
    name, sep, path = text.partition("=")
    if not sep or not name or not path:
        raise argparse.ArgumentTypeError(f"expected NAME=PATH, got {text!r}")
    return name, path


def select(problems: ProblemSet, n: int | None, families: list[str]) -> torch.Tensor:
    """Indices into ``problems``: the first ⌈n / len(families)⌉ of each family (all of them if n is None)."""
    per = None if n is None else math.ceil(n / len(families))
    picks = []
    for name in families:
        idx = torch.nonzero(problems.family == FAMILIES.index(name)).reshape(-1)
        picks.append(idx if per is None else idx[:per])
    return torch.cat(picks)


def _plain(x):
    """JSON-able: tensors to lists, NaN/inf to None."""
    if isinstance(x, torch.Tensor):
        x = x.tolist()
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, list):
        return [_plain(v) for v in x]
    if isinstance(x, dict):
        return {k: _plain(v) for k, v in x.items()}
    return x


class Skipped(Exception):
    """An optional row whose warm-up call failed."""


def run_method(
    name: str, fn: Method, problems: ProblemSet, log, optional: bool = False
) -> tuple[list, torch.Tensor, int]:
    """Plan every problem once (after a warm-up on the first); paths, seconds per problem, errors.

    Raises :class:`Skipped` for an ``optional`` row whose warm-up raises TypeError or a kinlearn error.
    """
    s, g, sc = problems.problem(0)
    try:
        fn(s, g, sc)  # warm-up: lazy imports, loading, first-call allocations
    except (TypeError, KinlearnError) as exc:
        if not optional:
            raise
        raise Skipped(f"{type(exc).__name__}: {exc}") from exc
    paths, seconds, errors = [], torch.empty(len(problems), dtype=torch.float64), 0
    t_start = time.perf_counter()
    for i in range(len(problems)):
        s, g, sc = problems.problem(i)
        t0 = time.perf_counter()
        try:
            path = fn(s, g, sc)
        except KinlearnError as exc:  # a typed planning failure counts as no path, and is reported
            path = None
            errors += 1
            if errors <= 3:
                log(f"  {name}: problem {i}: {type(exc).__name__}: {exc}")
        seconds[i] = time.perf_counter() - t0
        paths.append(None if path is None else torch.as_tensor(path).detach().cpu().double())
        if (i + 1) % 25 == 0:
            log(f"  {name}: {i + 1}/{len(problems)} problems, {time.perf_counter() - t_start:.0f} s")
    return paths, seconds, errors


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--problems", default=str(HELDOUT), help="an obstacle problem set (.npz)")
    ap.add_argument("--n", type=int, default=None, help="problems in all (default: every one)")
    ap.add_argument(
        "--families", nargs="+", choices=FAMILIES, default=None, help="default: every family in the set"
    )
    ap.add_argument("--methods", nargs="+", default=None, help="row names to run (default: all)")
    ap.add_argument("--rrt-time", type=float, default=1.0, help="RRT-Connect's limit per problem (s)")
    ap.add_argument("--opt-steps", type=int, nargs="+", default=[25, 100, 400])
    ap.add_argument(
        "--refine-steps",
        type=int,
        nargs="*",
        default=[25],
        help="rows of kinlearn with this many plan-time refinement steps where no proposal is free",
    )
    ap.add_argument(
        "--obstacle-tm",
        type=_named_path,
        action="append",
        default=[],
        metavar="NAME=PATH",
        help="a row planning with the shipped models and another obstacle-aware TM (tm_obstacles.pt)",
    )
    ap.add_argument("--out", default="runs/obstacle_benchmark")
    args = ap.parse_args()
    torch.set_num_threads(1)
    out = Path(args.out)
    t_all = time.perf_counter()
    load_start = os.getloadavg()[0]  # the machine may be shared: latencies are wall time
    head = header("Planning around obstacles (iiwa14, held-out problems)", 1)
    print(head, flush=True)

    def log(msg: str) -> None:
        print(msg, flush=True)

    everything = ProblemSet.load(args.problems, robot=ROBOT)
    args.families = args.families or [f for f in FAMILIES if len(everything.of(f))]
    chosen = select(everything, args.n, args.families)
    problems = everything[chosen]
    log(
        f"{len(problems)} problems ({', '.join(f'{f}: {len(problems.of(f))}' for f in args.families)}), "
        f"{int(problems.hard.sum())} hard"
    )
    rows = methods(args.rrt_time, tuple(args.opt_steps), tuple(args.refine_steps), dict(args.obstacle_tm))
    if args.methods:
        unknown = [m for m in args.methods if m not in rows]
        if unknown:
            ap.error(f"unknown methods {unknown}; choose from {list(rows)}")
        rows = {m: rows[m] for m in args.methods}
    body = default_body(ROBOT)
    warnings.simplefilter("once")

    summaries, per_problem, paths_of, skipped, errors = {}, {}, {}, {}, {}
    command = "python " + shlex.join(sys.argv)
    record = {  # the dicts fill in as methods finish; written after each one
        "benchmark": "obstacle_planner",
        "command": command,
        "header": head,
        "problems": str(args.problems),
        "indices": chosen,
        "family": [FAMILIES[int(f)] for f in problems.family],
        "hard": problems.hard,
        "rrt_time_limit_s": args.rrt_time,
        "optimiser_config": OptimiserConfig().to_dict(),
        "summaries": summaries,
        "per_problem": per_problem,
        "errors": errors,
        "skipped": skipped,
    }
    for name, fn in rows.items():
        t0 = time.perf_counter()
        try:
            paths, seconds, n_err = run_method(name, fn, problems, log, optional=_optional(name))
        except Skipped as exc:
            skipped[name] = str(exc)
            log(f"{name}: skipped, its first call raised {exc}")
            continue
        except MissingDependencyError as exc:
            skipped[name] = str(exc)
            log(f"{name}: skipped ({exc})")
            continue
        outcome = obstacle_outcome(body, paths, problems)
        summaries[name] = summarize_outcome(outcome, seconds, problems)
        per_problem[name] = {"seconds": seconds, **{k: outcome[k] for k in OUTCOME_KEYS}}
        paths_of[name], errors[name] = paths, n_err
        s = summaries[name]
        log(
            f"{name}: success {100 * s['success']:.1f}% (hard {100 * (s['success_hard'] or 0):.1f}%), "
            f"p50 {s['latency_ms']['p50']:.3g} ms, {time.perf_counter() - t0:.0f} s"
        )
        write_json(out / "obstacle_benchmark.json", _plain({**record, "complete": False}))
    if not summaries:
        raise SystemExit("no method ran")

    wall = time.perf_counter() - t_all
    load = (load_start, os.getloadavg()[0])
    table = format_table(summaries)
    curves = {"trajectory optimiser": [m for m in summaries if m.startswith("optimiser, ")]}
    curves = {k: v for k, v in curves.items() if len(v) > 1}
    plot_success_latency(summaries, out / "success_latency.png", curves=curves)

    # One problem per family for the 3-D figure: the first hard one (the first one if none is hard).
    picks = []
    for name in args.families:
        fam = torch.nonzero(problems.family == FAMILIES.index(name)).reshape(-1)
        hard = fam[problems.hard[fam]]
        if fam.numel():
            picks.append(int((hard if hard.numel() else fam)[0]))
    shown = [m for m in summaries if not m.startswith("optimiser, ") and not m.startswith("RRT-Connect (")]
    shown += (
        [curves["trajectory optimiser"][-1]]
        if curves
        else [m for m in summaries if m.startswith("optimiser, ")][-1:]
    )
    plot_obstacle_plans(
        problems,
        picks,
        {m: [paths_of[m][i] for i in picks] for m in shown},
        body,
        out / "obstacle_plans.png",
        success={m: [bool(per_problem[m]["success"][i]) for i in picks] for m in shown},
        titles=[
            f"held-out problem {int(chosen[i])} ({FAMILIES[int(problems.family[i])]}"
            f"{', hard' if bool(problems.hard[i]) else ''})"
            for i in picks
        ],
    )

    final = {**record, "wall_time_s": wall, "load_average_1min": load, "complete": True}
    write_json(out / "obstacle_benchmark.json", _plain(final))
    n_fam = ", ".join(
        f"{f} {len(problems.of(f))} ({int(problems.of(f).hard.sum())} hard)" for f in args.families
    )
    md = [
        "# Planning around obstacles (iiwa14, held-out problems)",
        "",
        "```",
        *head.splitlines()[1:],  # the hardware and versions (the title is above)
        "```",
        "",
        f"Command: `{command}` — wall time {wall / 60:.1f} min; 1-minute load average "
        f"{load[0]:.1f} at the start, {load[1]:.1f} at the end (on {os.cpu_count()} logical cores).",
        "",
        f"{len(problems)} problems: {n_fam}. Batch 1, one torch thread, wall time per problem after one "
        "untimed warm-up call. Success: starts at the start; ends within 0.05 rad (every joint) and 1 cm "
        "(end effector, analytic FK) of the goal; within the joint limits; collision-free under the dense "
        "check (≤ 1 cm of sphere travel between checked configurations; 12-sphere body with base; scene, "
        "floor and self-collision). Hard: the straight joint line collides. Joint length / line: median "
        "over the successful paths of the joint-space path length over ‖θ_goal − θ_start‖. Rates are over "
        "all problems: a method that returned no path fails every criterion.",
        "",
        table,
        "",
    ]
    if skipped:
        md += ["Skipped rows:", ""] + [f"- {m}: {why}" for m, why in skipped.items()] + [""]
    if any(errors.values()):
        md += [
            "Typed errors counted as no path: " + ", ".join(f"{m} {k}" for m, k in errors.items() if k),
            "",
        ]
    atomic_write(out / "obstacle_benchmark.md", lambda p: p.write_text("\n".join(md)))
    write_result(
        "obstacle_planner",
        {"every method": from_markdown(table, caption=f"{len(problems)} problems: {n_fam}.")},
        title="Planning around obstacles: every method (iiwa14, tabletop, shelf and barrier)",
        notes="Batch 1, one torch thread, wall time per problem after one untimed warm-up call. Success: starts "
        "at the start; ends within 0.05 rad (every joint) and 1 cm (end effector) of the goal; within the "
        "joint limits; collision-free under the dense check. Hard: the straight joint line collides.",
        threads=1,
    )
    print("\n" + table, flush=True)
    print(
        f"\nwrote {out}/obstacle_benchmark.{{json,md}}, success_latency.png, obstacle_plans.png; {wall:.0f} s"
    )


if __name__ == "__main__":
    main()
