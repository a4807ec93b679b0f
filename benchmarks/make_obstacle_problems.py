"""Generate the committed held-out obstacle benchmark sets.

    python benchmarks/make_obstacle_problems.py [--per-family 340] [--budget 900] \\
        [--out benchmarks/data/obstacle_problems_heldout.npz]            # iiwa14, the first three families
    python benchmarks/make_obstacle_problems.py --robot panda --families scenes --per-family 20 \\
        [--out benchmarks/data/scene_problems_panda.npz]                 # the seven scene families
    python benchmarks/make_obstacle_problems.py --robot ur5 --families scenes --per-family 20 \\
        --sphere-set spherized --out benchmarks/data/scene_problems_ur5_arm.npz  # the ur5 without its tool
    python benchmarks/make_obstacle_problems.py --robot R --families bookcase cubby cage bin \\
        --hand grasp --per-family 20 [--out benchmarks/data/grasp_problems_R.npz]  # hands held as grasps
    python benchmarks/make_obstacle_problems.py --robot ur5 --families scenes --per-family 20 --within body \
        [--out benchmarks/data/scene_problems_ur5_within.npz]  # within the benchmarks' UR5 limits (±π)
    python benchmarks/make_obstacle_problems.py --robot R --families scenes --per-family 20 --seeds tuning \
        --budget 3600 [--out runs/tune/R_scenes.npz]  # the tuning problems (seeds 3004–3010), not committed

Families: tabletop, shelf, barrier (the default set), or the seven of ``kinlearn/data/scenes.py``
(``--families scenes``), or any names (see ``kinlearn/data/problems.py``), each from a fixed
seed (held-out seeds below; training sets use other seeds). Problems are made round-robin, one of
each family in turn, so that a time budget cuts every family at the same count; problem i of a
family is the same whatever the budget (its sub-seed depends on (seed, i) only). Every problem is
verified solvable by OMPL RRT-Connect within 5 s on kinlearn's checker (a wall-clock limit: on a machine busy
with other work a verification can fail and its problem be replaced by the next attempt, so remake a set
on an idle one to get it to the bit; the tuning sets' first problems came back identical there, and one
differed under two trainings' load). Prints the generation time,
the rate and, per family, the number of problems, the share of hard ones (straight joint-space line
collides) and RRT-Connect's verification times.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import time
from pathlib import Path

import torch
from _common import header, markdown_table

from kinlearn import load_robot
from kinlearn.data.problems import (
    FAMILIES,
    HANDS,
    LEGACY_FAMILIES,
    ProblemConfig,
    ProblemSet,
    make_problems,
    select_families,
)

#: Held-out seeds, one per family (tabletop 1001, shelf 1002, barrier 1003, bookcase 1004, …). Training
#: scenes use others (kinlearn.training.obstacle_path.TRAINING_SEEDS: 2001, …).
HELDOUT_SEEDS = {name: 1001 + k for k, name in enumerate(FAMILIES)}
#: Held-out seeds of the sets with the hand held as a grasp (``--hand grasp``): 1104, … (other scenes
#: than the free sets').
GRASP_SEEDS = {name: 1101 + k for k, name in enumerate(FAMILIES)}
#: Held-out seeds of the sets made within the body's limits (``--within body``): 1204, … (other scenes again).
WITHIN_SEEDS = {name: 1201 + k for k, name in enumerate(FAMILIES)}
#: Seeds of the tuning problems (``--seeds tuning``: bookcase 3004, …, clutter 3010), apart from the
#: held-out and the training seeds: every constant of the planner's fixed-time stages was chosen on these.
TUNING_SEEDS = {name: 3001 + k for k, name in enumerate(FAMILIES)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--per-family", type=int, default=340)
    ap.add_argument("--budget", type=float, default=900.0, help="stop after this many seconds (whole rounds)")
    ap.add_argument("--robot", default="iiwa14")
    ap.add_argument(
        "--families",
        nargs="+",
        default=["legacy"],
        help="family names, or 'legacy' (the first three) or 'scenes'",
    )
    ap.add_argument(
        "--sphere-set",
        default=None,
        help="the sphere set problems are made for (default: the robot's planning body, the ur5's with its gripper)",
    )
    ap.add_argument(
        "--hand",
        choices=HANDS,
        default="free",
        help="'grasp': in the families with cells the hand points into the cell (ProblemConfig.hand)",
    )
    ap.add_argument(
        "--within",
        choices=("robot", "body"),
        default="robot",
        help="'body': starts, goals and the verifying search within the body's joint limits (the ur5's tool "
        "model: ±π, the benchmarks' UR5) (ProblemConfig.within)",
    )
    ap.add_argument(
        "--seeds",
        choices=("heldout", "tuning"),
        default="heldout",
        help="'tuning': the tuning problems' seeds (TUNING_SEEDS), written to runs/tune/ by default",
    )
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    families = list(select_families(args.families))
    if args.out is None:
        legacy = families == list(LEGACY_FAMILIES) and args.robot == "iiwa14"
        name = "obstacle_problems_heldout.npz" if legacy else f"scene_problems_{args.robot}.npz"
        if args.hand == "grasp":
            name = f"grasp_problems_{args.robot}.npz"
        if args.within == "body":
            name = name.replace(".npz", "_within.npz")
        args.out = Path(__file__).parent / "data" / name
        if args.seeds == "tuning":
            args.out = Path("runs") / "tune" / f"{args.robot}_scenes.npz"
    robot = load_robot(args.robot)
    print(header(f"obstacle benchmark problems ({args.robot})", args.threads))
    cfg = ProblemConfig(sphere_set=args.sphere_set, hand=args.hand, within=args.within)
    seeds = GRASP_SEEDS if args.hand == "grasp" else WITHIN_SEEDS if args.within == "body" else HELDOUT_SEEDS
    if args.seeds == "tuning":
        if args.hand != "free" or args.within != "robot":
            raise SystemExit("--seeds tuning makes the free-hand sets within the robot's limits only")
        seeds = TUNING_SEEDS
    parts: dict[str, list[ProblemSet]] = {f: [] for f in families}
    spent = {f: 0.0 for f in families}
    t_start = time.perf_counter()
    for i in range(args.per_family):
        if time.perf_counter() - t_start > args.budget:
            print(f"time budget of {args.budget:.0f} s reached after {i} rounds")
            break
        for fam in families:
            t0 = time.perf_counter()
            parts[fam].append(make_problems(fam, 1, seeds[fam], robot=robot, config=cfg, first=i))
            spent[fam] += time.perf_counter() - t0
        if (i + 1) % 10 == 0:
            print(f"  {i + 1} rounds, {time.perf_counter() - t_start:.0f} s", flush=True)
    elapsed = time.perf_counter() - t_start
    rounds = len(parts[families[0]])
    problems = ProblemSet.concat([p for fam in families for p in parts[fam]])
    problems = dataclasses.replace(
        problems,
        config={
            "seeds": {f: seeds[f] for f in families},
            "per_family": rounds,
            "problem_config": dataclasses.asdict(cfg),
            "generated_in_s": round(elapsed, 1),
            "body": problems.body_name,  # the sphere set starts and goals are free for
        },
    )
    path = problems.save(args.out)
    rows = []
    for fam in families:
        sub = problems.of(fam)
        times = sorted(sub.solve_time.tolist())
        rows.append(
            [
                fam,
                len(sub),
                f"{100 * float(sub.hard.double().mean()):.0f}%",
                f"{statistics.median(times):.3f}",
                f"{times[int(0.99 * (len(times) - 1))]:.3f}",
                f"{spent[fam] / max(len(sub), 1):.2f}",
            ]
        )
    rows.append(
        [
            "all",
            len(problems),
            f"{100 * float(problems.hard.double().mean()):.0f}%",
            f"{float(problems.solve_time.median()):.3f}",
            "",
            f"{elapsed / max(len(problems), 1):.2f}",
        ]
    )
    print(
        markdown_table(
            ["family", "problems", "hard", "RRT-Connect verify p50 (s)", "p99 (s)", "generation s/problem"],
            rows,
        )
    )
    print(
        f"\n{len(problems)} problems in {elapsed:.0f} s ({len(problems) / elapsed:.2f} problems/s); "
        f"wrote {path} ({path.stat().st_size / 1e6:.2f} MB)"
    )


if __name__ == "__main__":
    main()
