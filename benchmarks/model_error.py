"""Planning to a position when the robot's model is wrong: goal error against the size of the model error.

    python benchmarks/model_error.py [--n-goals 2000] [--seeds 0 1 2] [--out runs/model_error]
                                     [--figure docs/figures/model_error.png] [--threads 1]

The same held-out end-effector position goals (iiwa14, start and goal joints uniform within ±90% of
the limits) go to kinlearn's shipped planner, learned from babbling on the true robot, and to the
model-based baselines given a *believed* robot: link lengths off by up to 0, 1, 2, 3, 5% and joint
zeros off by up to 0, 0.5, 1, 1.5, 2° (uniform, several seeds per level). Every executed joint path is
judged by the true robot's forward kinematics. Prints the table and the time taken; writes the figure
and ``model_error.json`` into ``--out``. About 1–2 minutes on 2 busy CPU cores at the defaults.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import torch
from _common import header

from kinlearn.io import atomic_write
from kinlearn.model_error import DEFAULT_LEVELS, model_error_sweep, model_error_table, plot_model_error

ROOT = Path(__file__).resolve().parent.parent


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--robot", default="iiwa14")
    ap.add_argument("--n-goals", type=int, default=2000)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2], help="perturbation seeds per level")
    ap.add_argument("--out", type=Path, default=ROOT / "runs" / "model_error", help="folder of the JSON")
    ap.add_argument("--figure", type=Path, default=ROOT / "docs" / "figures" / "model_error.png")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--no-progress", action="store_true")
    args = ap.parse_args(argv)

    torch.set_num_threads(args.threads)
    print(header("Planning with a wrong robot model", args.threads))
    t0 = time.perf_counter()
    results = model_error_sweep(
        args.robot, DEFAULT_LEVELS, args.n_goals, tuple(args.seeds), progress=not args.no_progress
    )
    seconds = time.perf_counter() - t0
    results["seconds"]["total"] = seconds
    json_path = atomic_write(
        args.out / "model_error.json", lambda tmp: tmp.write_text(json.dumps(results, indent=1))
    )
    plot_model_error(results, args.figure)
    print(f"kinlearn's trajectory model: {results['kinlearn_tm']}")
    if results["kinlearn_domain_warnings"]:
        print("domain warnings:", *results["kinlearn_domain_warnings"], sep="\n  ")
    print()
    print(model_error_table(results))
    print()
    print(f"wrote {json_path} and {args.figure}; took {seconds:.1f} s")
    return results


if __name__ == "__main__":
    main()
