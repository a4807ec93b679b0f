"""``kinlearn view``: plan from a start to a goal and look at the plan.

By default the plan opens in the browser viewer (:meth:`kinlearn.Plan.show`, viser) on localhost; the
command prints the address and serves until Ctrl-C. With ``--gif PATH`` it writes an animation of the
arm moving along the plan (:meth:`kinlearn.Plan.animate`, matplotlib) and returns. Start and goal are
read as ``kinlearn plan`` reads them. Exit status: 0 when the plan reaches its goal, 1 when it misses it
(it is shown all the same), 2 for bad input.

The subcommand is added to a parser by :func:`register`.
"""

from __future__ import annotations

import argparse

from ..errors import ConfigError
from .common import OUTPUT_FILE, add_command, number_type
from .plan import add_plan_inputs, plan_from_args

__all__ = ["register"]

PORT = number_type(int, low=1, high=65535)
FPS = number_type(float, low=0.5, high=100)


def register(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add the ``view`` subcommand to ``subparsers`` (the object ``add_subparsers()`` returns)."""
    p = add_command(
        subparsers,
        "view",
        "Plan from a start to a goal and show the plan: in the browser (viser, on localhost, until Ctrl-C), "
        "or as a GIF with --gif. Exit status 0 when the plan reaches its goal, 1 when it misses it, 2 for "
        "bad input.",
        _run_view,
        seed=False,
        run_dir=False,
    )
    add_plan_inputs(p)
    p.add_argument(
        "--gif",
        type=OUTPUT_FILE,
        default=None,
        metavar="PATH",
        help="write an animation of the plan to this .gif file instead of opening the viewer",
    )
    p.add_argument(
        "--port",
        type=PORT,
        default=8080,
        help="viewer port on localhost (default: 8080; the next free one if it is taken)",
    )
    p.add_argument(
        "--fps", type=FPS, default=10.0, help="configurations per second when playing (default: 10)"
    )
    return p


def _run_view(args: argparse.Namespace) -> int:
    if args.gif is not None and args.gif.suffix.lower() != ".gif":
        raise ConfigError(f"--gif must name a .gif file, got {args.gif}")
    planner, plan, scene = plan_from_args(args)
    print(plan.summary())
    if args.gif is not None:
        path = plan.animate(args.gif, planner.robot, fps=args.fps, **_obstacles(scene))
        print(f"animation: {plan.joints.shape[0]} frames → {path}")
    else:
        plan.show(
            planner.robot, host="127.0.0.1", port=args.port, fps=args.fps, block=True, **_obstacles(scene)
        )
    return 0 if bool(plan.success) else 1


def _obstacles(scene) -> dict:
    """A scene as the ``scene=`` of :meth:`Plan.show` and :meth:`Plan.animate`."""
    return {} if scene is None else {"scene": scene}
