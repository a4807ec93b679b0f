"""``kinlearn onboard``: from a URDF to a planner among obstacles (see :mod:`kinlearn.training.onboard`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from .common import EXISTING_FILE, POSITIVE_INT, register_subcommand, settle_run_dir

HELP = (
    "Fit collision spheres to a URDF's own collision geometry, babble, identify the chain, train the free-space "
    "planner and the obstacle network on the seven scene families scaled to the arm; writes RUN_DIR/planner "
    "(Planner.load) and RUN_DIR/robot (its spheres)."
)


@register_subcommand
def _add_onboard(sub) -> None:
    from ..training.onboard import ONBOARD_SIZES

    p = sub.add_parser("onboard", help=HELP, description=HELP)
    p.add_argument("urdf", type=EXISTING_FILE, help="the arm's URDF, with <collision> geometry on its links")
    p.add_argument("--ee-frame", required=True, help="the end-effector link of the URDF")
    p.add_argument("--name", default=None, help="the robot's name (default: the URDF's file name)")
    p.add_argument(
        "--size",
        choices=tuple(ONBOARD_SIZES),
        default="default",
        help="how much babbling and training: tiny (seconds, a check), small (minutes), default",
    )
    p.add_argument(
        "--srdf", type=EXISTING_FILE, default=None, help="an SRDF whose disable_collisions pairs are kept"
    )
    p.add_argument(
        "--package-dir",
        type=Path,
        action="append",
        default=[],
        help="a folder where package:// meshes are found (repeatable)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of everything random (default: 0)")
    p.add_argument("--run-dir", type=Path, default=None, help="output folder (default: runs/<time>-onboard)")
    p.add_argument("--threads", type=POSITIVE_INT, default=1, help="torch CPU threads (default: 1)")
    p.add_argument("--resume", action="store_true", help="continue the run in --run-dir where it stopped")
    p.add_argument("--overwrite", action="store_true", help="replace the run already in --run-dir")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(run=_run_onboard, command="onboard")


def _run_onboard(args: argparse.Namespace) -> int:
    import dataclasses

    from ..training.onboard import ONBOARD_SIZES, onboard

    settle_run_dir(args)
    config = dataclasses.replace(ONBOARD_SIZES[args.size], seed=args.seed)
    result = onboard(
        args.urdf,
        args.ee_frame,
        args.run_dir,
        name=args.name,
        config=config,
        srdf=args.srdf,
        package_dirs=tuple(args.package_dir),
        resume=args.resume,
        overwrite=args.overwrite,
        progress=not args.no_progress,
    )
    took = ", ".join(f"{k} {v:.0f} s" for k, v in result.seconds.items())
    print(f"onboarded {result.robot.name} into {result.run_dir} ({took or 'every step done before'})")
    print(f"planner: {result.planner}  spheres: {result.spheres}")
    print(
        "plan with it: `from kinlearn.training.onboard import load_onboarded; "
        f"load_onboarded({str(result.run_dir)!r})`, then kinlearn.plan(..., robot={result.robot.name!r})"
    )
    return 0
