"""Generate the committed held-out obstacle benchmark set for the iiwa14.

    python benchmarks/make_obstacle_problems.py [--per-family 340] [--budget 900] \\
        [--out benchmarks/data/obstacle_problems_heldout.npz]

Three families (tabletop, shelf, barrier; see ``kinlearn/data/problems.py``), each from a fixed
seed (held-out seeds below; training sets use other seeds). Problems are made round-robin, one of
each family in turn, so that a time budget cuts every family at the same count; problem i of a
family is the same whatever the budget (its sub-seed depends on (seed, i) only). Every problem is
verified solvable by OMPL RRT-Connect within 5 s on kinlearn's checker. Prints the generation time,
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

from kinlearn.data.problems import FAMILIES, ProblemConfig, ProblemSet, make_problems

#: Held-out seeds, one per family. Training scenes must use other seeds.
HELDOUT_SEEDS = {"tabletop": 1001, "shelf": 1002, "barrier": 1003}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--per-family", type=int, default=340)
    ap.add_argument("--budget", type=float, default=900.0, help="stop after this many seconds (whole rounds)")
    ap.add_argument(
        "--out", type=Path, default=Path(__file__).parent / "data" / "obstacle_problems_heldout.npz"
    )
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    print(header("obstacle benchmark problems (iiwa14)", args.threads))
    cfg = ProblemConfig()
    parts: dict[str, list[ProblemSet]] = {f: [] for f in FAMILIES}
    spent = {f: 0.0 for f in FAMILIES}
    t_start = time.perf_counter()
    for i in range(args.per_family):
        if time.perf_counter() - t_start > args.budget:
            print(f"time budget of {args.budget:.0f} s reached after {i} rounds")
            break
        for fam in FAMILIES:
            t0 = time.perf_counter()
            parts[fam].append(make_problems(fam, 1, HELDOUT_SEEDS[fam], config=cfg, first=i))
            spent[fam] += time.perf_counter() - t0
        if (i + 1) % 10 == 0:
            print(f"  {i + 1} rounds, {time.perf_counter() - t_start:.0f} s", flush=True)
    elapsed = time.perf_counter() - t_start
    rounds = len(parts[FAMILIES[0]])
    problems = ProblemSet.concat([p for fam in FAMILIES for p in parts[fam]])
    problems = dataclasses.replace(
        problems,
        config={
            "seeds": HELDOUT_SEEDS,
            "per_family": rounds,
            "problem_config": dataclasses.asdict(cfg),
            "generated_in_s": round(elapsed, 1),
        },
    )
    path = problems.save(args.out)
    rows = []
    for fam in FAMILIES:
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
