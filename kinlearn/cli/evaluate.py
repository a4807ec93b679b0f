"""``kinlearn`` subcommands that evaluate: ``model-error`` (planning when the robot's model is wrong) and
``reproduce`` (the whole pipeline against the paper).

Both write under the run-directory policy of :mod:`kinlearn.runs`.
"""

from __future__ import annotations

import argparse
import dataclasses

from ..errors import MissingDependencyError
from ..planning.planner import Planner
from .common import (
    EXISTING_DIR,
    POSITIVE_INT,
    add_command,
    add_run_options,
    int_list,
    open_command_run,
    register_subcommand,
)

# --------------------------------------------------------------------------------------------------
# model-error
# --------------------------------------------------------------------------------------------------


@register_subcommand
def _add_model_error(sub) -> None:
    p = add_command(
        sub,
        "model-error",
        "Plan to held-out end-effector positions when the robot's model is wrong: kinlearn's planner (learned "
        "from the true robot) against model-based planners given a perturbed URDF, all judged by the true FK; "
        "writes model_error.json, model_error.md and model_error.png.",
        _run_model_error,
    )
    p.add_argument(
        "--model", type=EXISTING_DIR, default=None, help="a planner folder (default: the shipped planner)"
    )
    p.add_argument(
        "--n-goals", type=POSITIVE_INT, default=2000, help="held-out position goals (default: 2000)"
    )
    p.add_argument(
        "--seeds", type=int_list(0), default=(0, 1, 2), help="perturbation seeds per level (default: 0,1,2)"
    )
    p.add_argument("--no-rrt", action="store_true", help="leave out RRT-Connect")
    p.add_argument(
        "--no-calibrate",
        action="store_true",
        help="leave out the believed URDFs calibrated from the true robot's babbling (kinlearn identify)",
    )
    p.add_argument(
        "--calibration-samples",
        type=POSITIVE_INT,
        default=20_000,
        help="babbled states (1 mm noise) each believed URDF is calibrated from (default: 20000)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_run_options(p, resumable=False)


def _run_model_error(args: argparse.Namespace) -> int:
    import json

    from ..evaluation.model_error import (
        DEFAULT_LEVELS,
        model_error_sweep,
        model_error_table,
        plot_model_error,
    )
    from ..io import atomic_write

    planner = Planner.load(args.model, robot=args.robot) if args.model else Planner.default(args.robot)
    run = open_command_run(
        args,
        ("model_error.json", "model_error.md", "model_error.png"),
        sweep={
            "n_goals": args.n_goals,
            "seeds": list(args.seeds),
            "rrt": not args.no_rrt,
            "calibrate": not args.no_calibrate,
            "calibration_samples": args.calibration_samples,
            "model": str(args.model),
        },
    )
    out = run.begin()
    results = model_error_sweep(
        args.robot,
        DEFAULT_LEVELS,
        args.n_goals,
        tuple(args.seeds),
        planner=planner,
        rrt=not args.no_rrt,
        calibrate=not args.no_calibrate,
        calibration_samples=args.calibration_samples,
        progress=not args.no_progress,
    )
    atomic_write(out / "model_error.json", lambda tmp: tmp.write_text(json.dumps(results, indent=1)))
    table = model_error_table(results)
    atomic_write(out / "model_error.md", lambda tmp: tmp.write_text(table + "\n"))
    try:
        plot_model_error(results, out / "model_error.png")
    except MissingDependencyError as exc:
        print(f"figure skipped: {exc}")
    print(table)
    print(f"results in {out}")
    return 0


# --------------------------------------------------------------------------------------------------
# reproduce
# --------------------------------------------------------------------------------------------------


@register_subcommand
def _add_reproduce(sub) -> None:
    p = add_command(
        sub,
        "reproduce",
        "Run the whole pipeline and write results.md/results.json with the paper's tables and figures.",
        _run_reproduce,
    )
    mode = p.add_mutually_exclusive_group()
    mode.add_argument(
        "--quick",
        action="store_const",
        const="quick",
        dest="preset",
        help="the quick preset: fewer seeds, smaller runs",
    )
    mode.add_argument(
        "--smoke", action="store_const", const="smoke", dest="preset", help="seconds; for tests"
    )
    mode.add_argument(
        "--full", action="store_const", const="full", dest="preset", help="paper sizes, 10 seeds"
    )
    p.add_argument(
        "--workers", type=POSITIVE_INT, default=None, help="worker processes of the TM sweep (≥ 1)"
    )
    p.add_argument("--backend", choices=("local", "ray"), default="local", help="where the sweep runs")
    add_run_options(p, resumable=True)
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(preset="quick")


#: Everything ``reproduce`` writes into its run directory beside config.json (``--overwrite`` removes it all).
REPRODUCE_OUTPUTS = (
    "results.json",
    "results.md",
    "metrics.jsonl",
    "models",
    "tm",
    "workspace",
    "endpoints_train.npz",
    "endpoints_heldout.npz",
    "fig3_trajectories.png",
    "fig4_histograms.png",
)


def _run_reproduce(args: argparse.Namespace) -> int:
    from ..evaluation.jobs import default_workers
    from ..evaluation.reproduce import preset_config, reproduce

    cfg = preset_config(
        args.preset,
        robot=args.robot,
        seed=args.seed,
        workers=args.workers or default_workers(),
        backend=args.backend,
    )
    # where and how wide the sweep runs does not change its results: a resume may change them
    run = open_command_run(
        args,
        REPRODUCE_OUTPUTS,
        resumable=True,
        ignore=("workers", "backend"),
        reproduce=dataclasses.asdict(cfg),
    )
    run_dir = run.begin()
    reproduce(cfg, run_dir, progress=not args.no_progress, write_config=False)
    print((run_dir / "results.md").read_text())
    print(f"results in {run_dir}")
    return 0
