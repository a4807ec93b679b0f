"""One or two balls across the end effector's straight path: the obstacle planner on a user's first scene.

    python benchmarks/ball_problems.py --robot panda [--n 120] [--seed 7] [--floor] [--out DIR]

The test a new user runs first (the obstacle issue's own opening test; the README's ball): start and
goal joints drawn uniformly within the robot's limits, end effectors at least 0.3 m apart (for an arm of
the iiwa14's reach; scaled by the arm's), one ball or two (each one problem in two) of radius 5–15 cm
(scaled) centred on the end effector's path along the straight joint line between them (25–75% of the
way), given as a list of balls ``[x, y, z, r]`` (no floor; ``--floor``: a floor at z = 0 as well, and
ends whose body is below it redrawn). Kept: problems whose start and goal are free (scene and the body
itself, with the robot's planning body), whose straight joint line collides (the ball is across the
path), and which the compiled RRT-Connect solves within 20,000 iterations (many of the ur5's pairs are
in parts of its ±2π joint space that do not connect). None of these scenes is a training family's: no
network was trained on a ball in the open.

Rows: the straight joint line; kinlearn's network alone (``retreat=False, refine_steps=0``), its fixed-time
stages (``refine_steps=0``) and its plan under ``deadline=0.05``; every path judged by
:func:`kinlearn.evaluation.obstacles.obstacle_outcome` (the dense check of its joints against the balls and
itself, the goal, the limits). Times are wall clock at batch 1 on one thread, with the paper-size TM's
forward pass timed after every call (p50 over its p50, as ``obstacle_families.py``).
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from pathlib import Path

import numpy as np
import torch
from _common import RUNS, header, markdown_table, table, write_result

import kinlearn
from kinlearn import Scene
from kinlearn.collision.rrt import rrt_connect
from kinlearn.data.scenes import scene_scale
from kinlearn.evaluation.obstacles import obstacle_outcome
from kinlearn.models.trajectory import TMConfig, TrajectoryModel
from kinlearn.planning.plan import CHECK_TRAVEL
from kinlearn.planning.planner import DEFAULT_CHECKPOINTS


def make_problems(planner: kinlearn.Planner, n: int, seed: int, floor: bool) -> list[tuple]:
    """``n`` problems ``(start (dof,), goal (dof,), balls (B, 4))`` as the module docstring says."""
    from kinlearn.collision import kernel as k

    body, chain = planner._np_body, k.KernelChain.of(planner.robot)
    lo, hi = planner._lo_np, planner._hi_np
    scale = scene_scale(planner.robot)
    rng = np.random.default_rng(seed)
    out, tries = [], 0
    while len(out) < n:
        tries += 1
        if tries > 200 * n:
            raise RuntimeError(f"only {len(out)} of {n} ball problems found in {tries} draws")
        s, g = rng.uniform(lo, hi), rng.uniform(lo, hi)
        line = s + np.linspace(0.0, 1.0, 41)[:, None] * (g - s)
        ef = chain.position(line)
        if np.linalg.norm(ef[-1] - ef[0]) < 0.3 * scale:
            continue
        balls = [
            [*ef[rng.integers(10, 31)], rng.uniform(0.05, 0.15) * scale]
            for _ in range(1 + int(rng.random() < 0.5))
        ]
        scene = k.KernelScene.of(Scene.from_spheres(torch.tensor(balls), floor=0.0 if floor else None))
        d, selfd = k.clearances(body, scene, np.stack((s, g)))  # both ends free (touching collides)
        if (d <= 0.0).any() or (selfd <= 0.0).any():
            continue
        if k.first_free(body, line[None], scene, max_travel=CHECK_TRAVEL) == 0:  # the line is free
            continue
        box_lo, box_hi = planner.body.joint_box(s[None], g[None])
        path, _, _ = rrt_connect(
            body, scene, s, g, box_lo[0], box_hi[0], time_limit=float("inf"), seed=len(out),
            max_travel=CHECK_TRAVEL, max_iterations=20_000,
        )  # fmt: skip
        if path is None:
            continue
        out.append((torch.from_numpy(s), torch.from_numpy(g), np.array(balls)))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robot", default="panda")
    ap.add_argument("--n", type=int, default=120)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--floor", action="store_true", help="a floor at z = 0 as well")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    warnings.simplefilter("ignore", kinlearn.DomainWarning)
    out = args.out or RUNS / f"balls_{args.robot}"
    out.mkdir(parents=True, exist_ok=True)
    print(header(f"Balls across the straight path ({args.robot})", args.threads))
    folder = DEFAULT_CHECKPOINTS / args.robot
    planner = kinlearn.Planner.load(folder)
    alone = kinlearn.Planner.load(folder, retreat=False)
    problems = make_problems(planner, args.n, args.seed, args.floor)
    print(f"{len(problems)} problems (seed {args.seed}, {'a floor at z = 0' if args.floor else 'no floor'})")
    rows = {
        "joint line": lambda s, g, b: None,
        "kinlearn network alone (retreat=False, refine_steps=0)": lambda s, g, b: alone.plan(
            s, g, obstacles=b, refine_steps=0
        ),
        "kinlearn fixed time (refine_steps=0)": lambda s, g, b: planner.plan(
            s, g, obstacles=b, refine_steps=0
        ),
        "kinlearn plan, deadline 0.05 s": lambda s, g, b: planner.plan(s, g, obstacles=b, deadline=0.05),
    }
    paper_tm = TrajectoryModel(
        TMConfig(robot=planner.robot.name, dof=planner.robot.dof, normalize=False)
    ).eval()
    tm_state = torch.zeros(1, planner.robot.dof + 3)
    table_rows, summary = [], {}
    for name, fn in rows.items():
        s0, g0, b0 = problems[0]
        fn(s0, g0, b0)  # warm-up
        ok, seconds, tm_seconds, stages, flagged = [], [], [], [], 0
        for s, g, b in problems:
            t0 = time.perf_counter()
            plan = fn(s, g, b)
            seconds.append(time.perf_counter() - t0)
            with torch.no_grad():
                t0 = time.perf_counter()
                paper_tm(tm_state, tm_state)
                tm_seconds.append(time.perf_counter() - t0)
            joints = torch.stack((s, g)) if plan is None else plan.joints
            scene = Scene.from_spheres(torch.tensor(b), floor=0.0 if args.floor else None)
            outcome = obstacle_outcome(planner.body, [joints], (s[None], g[None], scene))
            ok.append(bool(outcome["success"][0]))
            if plan is not None:
                stages.append(plan.stage)
                flagged += bool(plan.collision_free) and not bool(outcome["collision_free"][0])
        t, tm_t = np.array(seconds), np.array(tm_seconds)
        counts = {s: stages.count(s) for s in sorted(set(stages))}
        summary[name] = {
            "success": float(np.mean(ok)),
            "p50_ms": float(np.median(t) * 1e3),
            "p99_ms": float(np.quantile(t, 0.99) * 1e3),
            "p50_over_tm": float(np.median(t) / np.median(tm_t)),
            "stages": counts,
            "flagged": flagged,
        }
        times = (
            [
                f"{np.median(t) * 1e3:.2f}",
                f"{np.quantile(t, 0.99) * 1e3:.2f}",
                f"{np.median(t) / np.median(tm_t):.1f}×",
            ]
            if stages
            else ["", "", ""]  # the joint line: nothing planned
        )
        table_rows.append(
            [name, f"{100 * np.mean(ok):.1f}%", *times, str(counts) if counts else "", str(flagged)]
        )
        print(
            f"  {name}: {100 * np.mean(ok):.1f}%, stages {counts}, flagged free but colliding: {flagged}",
            flush=True,
        )
    text = markdown_table(
        ["method", "success", "p50 ms", "p99 ms", "p50 over the TM", "stages", "flagged"], table_rows
    )
    print("\n" + text)
    (out / "table.md").write_text(text + "\n")
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    print(f"wrote {out}/summary.json, table.md")
    caption = (
        f"{len(problems)} problems (seed {args.seed}, {'a floor at z = 0' if args.floor else 'no floor'})."
    )
    columns = ["method", "success", "p50 ms", "p99 ms", "p50 over the TM", "stages", "flagged"]
    write_result(
        f"ball_problems_{args.robot}" + ("_floor" if args.floor else ""),
        {"balls": table(columns, table_rows, caption=caption)},
        title=f"One or two balls across the straight path ({args.robot})",
        threads=args.threads,
    )


if __name__ == "__main__":
    main()
