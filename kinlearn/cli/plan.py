"""``kinlearn plan``: plan from a start to a goal with a planner folder (or the shipped planner) and print
how it went; :func:`add_plan_inputs` and :func:`plan_from_args` read what to plan, for ``plan`` and
``view`` alike.
"""

from __future__ import annotations

import argparse
import re

import numpy as np
import torch

from ..errors import ConfigError
from ..planning.planner import Planner
from .common import (
    EXISTING_DIR,
    EXISTING_FILE,
    NONNEGATIVE_INT,
    OUTPUT_FILE,
    add_command,
    number_type,
    register_subcommand,
)

# --------------------------------------------------------------------------------------------------
# plan
# --------------------------------------------------------------------------------------------------


def _floats(text: str) -> list[float]:
    try:
        values = [float(v) for v in text.replace(",", " ").split()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected numbers separated by commas, got {text!r}") from None
    if not values:
        raise argparse.ArgumentTypeError("expected at least one number")
    return values


#: Lets ``--start -0.3,0.45,…`` through: argparse otherwise takes a value starting with "-" for an option.
_NEGATIVE_VALUES = re.compile(r"^-\.?\d[\d.,eE+\- ]*$")


def add_plan_inputs(p: argparse.ArgumentParser) -> None:
    """The options that say what to plan (start, goal, planner, obstacles), shared by ``plan`` and ``view``."""
    p._negative_number_matcher = _NEGATIVE_VALUES
    p.add_argument(
        "--start",
        type=_floats,
        default=None,
        help="start joints (rad) or a full state [θ, ef], comma-separated (or --request)",
    )
    goal = p.add_mutually_exclusive_group()
    goal.add_argument("--goal", type=_floats, help="goal joints (rad) or a full state, comma-separated")
    goal.add_argument(
        "--goal-position",
        type=_floats,
        help="goal end-effector position x,y,z (m, base frame), any configuration",
    )
    p.add_argument(
        "--model", type=EXISTING_DIR, default=None, help="a planner folder (default: the shipped planner)"
    )
    p.add_argument(
        "--obstacles",
        type=EXISTING_FILE,
        default=None,
        metavar="SCENE",
        help="plan around the obstacles of a scene file (.npz, kinlearn.collision.Scene.save)",
    )
    p.add_argument(
        "--scene",
        type=EXISTING_FILE,
        default=None,
        metavar="YAML",
        help="plan around the obstacles of a MoveIt planning scene (.yaml: world.collision_objects)",
    )
    p.add_argument(
        "--base-pose",
        type=_floats,
        default=None,
        metavar="X,Y,Z,QX,QY,QZ,QW",
        help="with --scene: the robot base's pose in the scene's frame (default: the scene's frame)",
    )
    p.add_argument(
        "--points",
        type=EXISTING_FILE,
        action="append",
        default=None,
        metavar="FILE",
        help="plan among a point cloud (.npy, .ply or .pcd; metres, the robot's base frame unless "
        "--camera-pose), each point an obstacle ball of --point-radius; with --obstacles or --scene, beside them; "
        "repeated: several cameras' clouds, fused",
    )
    p.add_argument(
        "--camera-pose",
        type=_floats,
        action="append",
        default=None,
        metavar="X,Y,Z,QX,QY,QZ,QW",
        help="with --points: the camera's pose in the robot's base frame (the points are in its frame); "
        "with several --points, one per cloud, in their order",
    )
    p.add_argument(
        "--point-radius",
        type=number_type(float, low=0),
        default=None,
        metavar="M",
        help="with --points: the radius of each point's obstacle ball (default 0.01)",
    )
    p.add_argument(
        "--contact",
        type=number_type(float, low=0),
        default=None,
        metavar="M",
        help="with --points: how deep points may lie inside the arm at the start or goal and be taken as the "
        "surface it touches (default 0.006; 0 refuses an end the points' balls touch)",
    )
    p.add_argument(
        "--self-filter",
        action="store_true",
        help="with --points: drop the points on the robot's own body at the start (and those beyond its reach)",
    )
    p.add_argument(
        "--vouch-goal",
        action="store_true",
        help="with --points and a joint --goal: the goal is vouched for, the points its body touches dropped "
        "(within 4 mm), as --self-filter drops the robot's own at the start; docs/clouds.md says what it risks",
    )
    p.add_argument(
        "--drop-nan",
        action="store_true",
        help="with --points: drop points holding NaN (a depth camera's missing pixels) instead of refusing them",
    )
    p.add_argument(
        "--request",
        type=EXISTING_FILE,
        default=None,
        metavar="YAML",
        help="take start and goal joints from a MoveIt motion plan request (.yaml: start_state, "
        "goal_constraints' joint_constraints), matched to the robot's joints by name",
    )
    p.add_argument(
        "--refine-steps",
        type=NONNEGATIVE_INT,
        default=None,
        help="with obstacles: plan in fixed time, with this many gradient steps refining the least colliding "
        "proposal when none is free (0: the proposals and the retreat stage alone); default: not given, so "
        "a plan they leave colliding is sampled for (a fixed budget of RRT-Connect iterations, deterministic)",
    )
    p.add_argument(
        "--no-retreat",
        action="store_true",
        help="with obstacles: leave out the retreat stage (out of the start's cell and into the goal's along "
        "fixed end-effector retreats), so the network's proposals alone make the fixed-time plan",
    )
    p.add_argument(
        "--sphere-set",
        default=None,
        metavar="NAME",
        help="with obstacles: check plans with this sphere set of the robot's (robots/<robot>/"
        "collision_spheres.json; the ur5's 'spherized' is its arm alone, a bare flange); default: the "
        "robot's planning body (the ur5's carries the standard benchmarks' gripper)",
    )
    p.add_argument(
        "--deadline",
        type=number_type(float, low=0, open_low=True),
        default=None,
        metavar="SECONDS",
        help="with obstacles: where the fixed-time stages (and refinement) clear nothing, RRT-Connect on the "
        "compiled checker gets what is left of SECONDS; the plan comes back by then (default: none: "
        "a budget of iterations instead, deterministic)",
    )


def plan_from_args(args: argparse.Namespace, strict: bool = False):
    """``(planner, plan, scene or None)`` for the options of :func:`add_plan_inputs`."""
    options = {"retreat": False} if args.no_retreat else {}
    if args.sphere_set is not None:
        from ..body.robot import load_robot
        from ..collision.body import body_spheres

        options["body"] = body_spheres(load_robot(args.robot), sphere_set=args.sphere_set)
    if args.model:
        planner = Planner.load(args.model, robot=args.robot, **options)
    else:
        planner = Planner.default(args.robot, **options)
    if args.request is not None:
        if args.start is not None or args.goal is not None or args.goal_position is not None:
            raise ConfigError(
                "--request gives the start and the goal: leave out --start, --goal, --goal-position"
            )
        from ..collision.moveit import request_joints

        start, goal = request_joints(args.request, planner.robot)
        args.goal = goal.tolist()
    elif args.start is None or (args.goal is None and args.goal_position is None):
        raise ConfigError("give --start and one of --goal, --goal-position (or a MoveIt --request)")
    else:
        start = torch.tensor(args.start, dtype=torch.float64)
    if args.obstacles is not None and args.scene is not None:
        raise ConfigError("give the obstacles as --obstacles (.npz) or --scene (MoveIt .yaml), not both")
    if args.base_pose is not None and args.scene is None:
        raise ConfigError("--base-pose places the robot in a --scene; give --scene too")
    obstacles = None
    if args.obstacles is not None:
        from ..collision.scene import Scene

        with open(args.obstacles, "rb") as fh:  # an .npz is a zip archive; a MoveIt scene is YAML text
            if fh.read(4) != b"PK\x03\x04":
                raise ConfigError(
                    f"--obstacles takes a kinlearn scene (.npz, written by Scene.save); {args.obstacles} is "
                    "not one: give a MoveIt planning scene (.yaml) as --scene"
                )
        obstacles = Scene.load(args.obstacles)
    elif args.scene is not None:
        from ..collision.scene import Scene

        obstacles = Scene.from_moveit(args.scene, base_pose=args.base_pose)
    if args.points is None and (
        args.camera_pose is not None
        or args.point_radius is not None
        or args.contact is not None
        or args.self_filter
        or args.vouch_goal
        or args.drop_nan
    ):
        raise ConfigError(
            "--camera-pose, --point-radius, --contact, --self-filter, --vouch-goal and --drop-nan describe --points: "
            "give it too"
        )
    if args.vouch_goal and args.goal_position is not None:
        raise ConfigError("--vouch-goal vouches for a goal given as joints (--goal), not --goal-position")
    if args.points is not None:
        from ..collision.scene import Scene

        dof = planner.robot.dof
        at = [start[:dof].numpy()] if args.self_filter or args.vouch_goal else []
        if args.vouch_goal:  # where the robot stands first (its own points), then the goal vouched for
            at.append(np.asarray(args.goal, dtype=np.float64)[:dof])
        views, poses = args.points, args.camera_pose
        if poses is not None and len(poses) != len(views):
            raise ConfigError(
                f"--camera-pose is given {len(poses)} time(s) for {len(views)} --points: give one per cloud, "
                "in their order, or none (clouds in the base frame)"
            )
        obstacles = Scene.from_points(
            views[0] if len(views) == 1 else views,
            radius=args.point_radius,
            contact=args.contact,
            frame=(poses[0] if len(views) == 1 else poses) if poses is not None else None,
            self_filter=(planner.body, np.stack(at)) if at else None,
            drop_nonfinite=args.drop_nan,
            primitives=obstacles,
        )
    if args.deadline is not None and obstacles is None:
        raise ConfigError(
            "--deadline bounds planning around obstacles: give --obstacles, --scene or --points too"
        )
    if args.no_retreat and obstacles is None:
        raise ConfigError(
            "--no-retreat leaves out a stage of planning around obstacles: give --obstacles, --scene or --points too"
        )
    if args.sphere_set is not None and obstacles is None:
        raise ConfigError(
            "--sphere-set is the body plans around obstacles are checked with: give --obstacles, --scene or --points too"
        )
    options = {
        "obstacles": obstacles,
        "refine_steps": args.refine_steps,
        "deadline": args.deadline,
        "strict": strict,
    }
    if args.goal_position is not None:
        goal = torch.tensor(args.goal_position, dtype=torch.float64)
        plan = planner.plan(start, goal_position=goal, **options)
    else:
        plan = planner.plan(start, torch.tensor(args.goal, dtype=torch.float64), **options)
    return planner, plan, obstacles


@register_subcommand
def _add_plan(sub) -> None:
    p = add_command(
        sub,
        "plan",
        "Plan from a start to a goal and print how it went. Exit status 0 when every plan reaches its "
        "goal, 1 when one misses it (the table says by how much), 2 for bad input.",
        _run_plan,
        seed=False,
        run_dir=False,
    )
    add_plan_inputs(p)
    p.add_argument("--strict", action="store_true", help="refuse a start or goal outside the training domain")
    p.add_argument("--joints", action="store_true", help="also print the joint path")
    p.add_argument(
        "--timed",
        type=OUTPUT_FILE,
        default=None,
        metavar="FILE",
        help="write a time-parameterised trajectory within the robot's limits (.csv or .json) for a controller",
    )
    p.add_argument(
        "--velocity-scale",
        type=number_type(float, low=0, high=1, open_low=True),
        default=1.0,
        help="fraction of the velocity limits the timed trajectory may use (default: 1)",
    )


def _run_plan(args: argparse.Namespace) -> int:
    planner, plan, _ = plan_from_args(args, strict=args.strict)
    print(plan.summary())
    if args.joints:
        print("\njoint path (rad), one configuration per line:")
        for q in plan.joints.tolist():
            print("  " + ", ".join(f"{v:+.4f}" for v in q))
    if args.timed is not None:
        suffix = args.timed.suffix.lower()
        if suffix not in (".csv", ".json"):
            raise ConfigError(f"--timed must name a .csv or .json file, got {args.timed}")
        traj = plan.timed(planner.robot, velocity_scale=args.velocity_scale)
        (traj.to_csv if suffix == ".csv" else traj.to_json)(args.timed)
        print(f"timed trajectory: {len(traj.t)} samples over {traj.duration:.3f} s → {args.timed}")
    return 0 if bool(plan.success.all()) else 1
