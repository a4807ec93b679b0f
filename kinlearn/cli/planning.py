"""``kinlearn`` subcommands of the planning stage: endpoints, TM training, planning, reproduction.

Every command but ``plan`` writes under the run-directory policy of :mod:`kinlearn.runs`.
"""

from __future__ import annotations

import argparse
import dataclasses
import re
from pathlib import Path

import torch

from ..body.robot import load_robot
from ..data.endpoints import EndpointConfig, load_endpoints, make_endpoints, save_endpoints
from ..errors import ConfigError, MissingDependencyError
from ..evaluation.metrics import plan_metrics, summarize
from ..io import atomic_copy, file_sha256, half_weights, load_checkpoint, resolve_dependency, save_checkpoint
from ..models.forward_inverse import load_fm, load_im
from ..models.rollout import LOSS_PRESETS
from ..planning.planner import DEFAULT_CHECKPOINTS, Planner
from ..runs import open_run
from ..training.tm import MODEL_FIELDS, TM_PRESETS, tm_preset, train_tm
from .common import (
    EXISTING_DIR,
    EXISTING_FILE,
    NONNEGATIVE_FLOAT,
    NONNEGATIVE_INT,
    OUTPUT_DIR,
    OUTPUT_FILE,
    POSITIVE_FLOAT,
    POSITIVE_INT,
    add_command,
    add_run_options,
    file_identity,
    number_type,
    open_command_run,
    register_subcommand,
    settle_run_dir,
)

# --------------------------------------------------------------------------------------------------
# make-endpoints
# --------------------------------------------------------------------------------------------------


@register_subcommand
def _add_make_endpoints(sub) -> None:
    p = add_command(
        sub,
        "make-endpoints",
        "Draw [s(0), s(T)] endpoint pairs; writes endpoints_train.npz and endpoints_heldout.npz.",
        _run_make_endpoints,
    )
    p.add_argument("--n", type=POSITIVE_INT, default=12_000, help="training pairs, ≥ 1 (default: 12000)")
    p.add_argument(
        "--heldout",
        type=NONNEGATIVE_INT,
        default=2_000,
        help="held-out pairs (default: 2000; 0: none, and train-tm reports no held-out metrics)",
    )
    p.add_argument(
        "--start-spread", type=NONNEGATIVE_FLOAT, default=0.15, help="start noise around home, rad"
    )
    p.add_argument("--min-distance", type=NONNEGATIVE_FLOAT, default=0.2, help="least start-goal distance, m")
    add_run_options(p, resumable=False)


def _run_make_endpoints(args: argparse.Namespace) -> int:
    cfg = EndpointConfig(
        robot=args.robot,
        n=args.n + args.heldout,
        seed=args.seed,
        start_spread=args.start_spread,
        min_distance=args.min_distance,
    )
    outputs = ("endpoints_train.npz", "endpoints_heldout.npz")
    run = open_command_run(args, outputs, endpoints=dataclasses.asdict(cfg), split={"train": args.n})
    pairs = make_endpoints(cfg)  # may refuse the config: before anything is written
    run_dir = run.begin()
    train, heldout = pairs.split(args.n)
    save_endpoints(train, run_dir / "endpoints_train.npz")
    if len(heldout):
        save_endpoints(heldout, run_dir / "endpoints_heldout.npz")
    print(f"{len(train)} training and {len(heldout)} held-out pairs for {args.robot} in {run_dir}")
    return 0


# --------------------------------------------------------------------------------------------------
# train-tm
# --------------------------------------------------------------------------------------------------


@register_subcommand
def _add_train_tm(sub) -> None:
    p = add_command(
        sub,
        "train-tm",
        "Train the trajectory model through the frozen FM and IM (Algorithm 1); writes tm.pt.",
        _run_train_tm,
    )
    p.add_argument("--preset", choices=sorted(TM_PRESETS), default="default", help="training preset")
    p.add_argument("--endpoints", type=EXISTING_DIR, required=True, help="a make-endpoints run directory")
    p.add_argument(
        "--fm-checkpoint", type=EXISTING_FILE, default=None, help="a learned fm.pt (from train-fm)"
    )
    p.add_argument(
        "--im-checkpoint", type=EXISTING_FILE, default=None, help="a learned im.pt (from train-im)"
    )
    p.add_argument(
        "--models-dir", type=EXISTING_DIR, default=None, help="or: one folder holding fm.pt and im.pt"
    )
    p.add_argument(
        "--fm",
        choices=("learned", "analytic"),
        default="learned",
        help="forward model: learned (a checkpoint) or analytic (the robot's FK) (default: learned)",
    )
    p.add_argument(
        "--im",
        choices=("learned", "analytic"),
        default="learned",
        help="inverse model: learned (a checkpoint) or analytic (a DLS IK step) (default: learned)",
    )
    p.add_argument("--epochs", type=POSITIVE_INT, default=None, help="override the preset's epochs")
    p.add_argument("--batch-size", type=POSITIVE_INT, default=None, help="override the preset's batch size")
    p.add_argument(
        "--optimizer",
        choices=("adam", "adamw", "rmsprop", "sgd"),
        default=None,
        help="override the preset's optimiser",
    )
    p.add_argument(
        "--lr", type=POSITIVE_FLOAT, default=None, help="override the preset's learning rate (> 0)"
    )
    p.add_argument(
        "--alpha",
        type=number_type(float, low=0, high=1, open_high=True),
        default=None,
        help="RMSprop smoothing constant γ, in [0, 1)",
    )
    p.add_argument("--loss", choices=sorted(LOSS_PRESETS), default=None, help="loss preset")
    p.add_argument("--gradient", choices=("stop", "through"), default=None, help="through the FM/IM or not")
    add_run_options(p, resumable=True)
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def _tm_model_sources(args: argparse.Namespace, run_dir: Path) -> dict[str, Path]:
    """The learned FM/IM files to train through, checked (they load, for this robot)."""
    sources = {}
    for kind, loader in (("fm", load_fm), ("im", load_im)):
        given = getattr(args, f"{kind}_checkpoint")
        if given is not None and not given.is_file():
            raise ConfigError(f"--{kind}-checkpoint: no file at {given}")
        if getattr(args, kind) != "learned":
            if given is not None:
                raise ConfigError(f"--{kind}-checkpoint names a learned model, but --{kind} is analytic")
            continue
        src = given or (args.models_dir / f"{kind}.pt" if args.models_dir is not None else None)
        if src is None:
            raise ConfigError(
                f"a learned {kind.upper()} needs --{kind}-checkpoint or --models-dir (or --{kind} analytic)"
            )
        if not src.is_file():
            raise ConfigError(f"--models-dir: no {kind}.pt in {src.parent}")
        if src.resolve().parent == run_dir.resolve():
            raise ConfigError(f"{src} lies in the run directory itself; train the TM into another --run-dir")
        loader(src, robot=args.robot)
        sources[kind] = src
    return sources


def _run_train_tm(args: argparse.Namespace) -> int:
    # Every check first: config, endpoint pairs, the FM/IM files; nothing is written before they pass.
    over: dict = {"robot": args.robot, "fm": args.fm, "im": args.im, "seed": args.seed}
    for key in ("epochs", "batch_size", "loss"):
        if getattr(args, key) is not None:
            over[key] = getattr(args, key)
    cfg = tm_preset(args.preset, **over)
    changes = {k: getattr(args, a) for k, a in (("name", "optimizer"), ("lr", "lr"), ("alpha", "alpha"))}
    changes = {k: v for k, v in changes.items() if v is not None}  # 0 is a value, not "unset"
    if changes:
        cfg = dataclasses.replace(cfg, optim=dataclasses.replace(cfg.optim, **changes))
    if args.gradient is not None:
        cfg = dataclasses.replace(cfg, loss=dataclasses.replace(cfg.loss, gradient=args.gradient))
    train_path = args.endpoints / "endpoints_train.npz"
    train = load_endpoints(train_path, robot=args.robot)
    heldout_path = args.endpoints / "endpoints_heldout.npz"
    heldout = load_endpoints(heldout_path, robot=args.robot) if heldout_path.is_file() else None
    if heldout is not None and len(heldout) == 0:
        heldout = None
    sources = _tm_model_sources(args, settle_run_dir(args))
    endpoints = {"path": str(args.endpoints), "train_sha256": file_sha256(train_path)}
    if heldout is not None:
        endpoints["heldout_sha256"] = file_sha256(heldout_path)
    models = {k: file_identity(sources[k]) if k in sources else "analytic" for k in ("fm", "im")}
    outputs = ("tm.pt", "fm.pt", "im.pt", "metrics.jsonl", "tensorboard")
    run = open_command_run(
        args,
        outputs,
        resumable=True,
        tm={**cfg.to_dict(), "models_dir": None},
        endpoints=endpoints,
        models=models,
    )
    run_dir = run.begin()
    for kind, src in sources.items():  # the run is self-contained: the models beside tm.pt
        dst = run_dir / f"{kind}.pt"
        if not (dst.is_file() and file_sha256(dst) == models[kind]["sha256"]):
            atomic_copy(src, dst)
    if sources:
        cfg = dataclasses.replace(cfg, models_dir=str(run_dir))
    train_tm(
        cfg,
        run_dir,
        train,
        heldout,
        resume=run.resumed,
        progress=not args.no_progress,
        write_config=False,
    )
    if heldout is not None:
        planner = Planner.load(run_dir)
        s = summarize(plan_metrics(planner.plan(heldout.start, heldout.goal), planner.robot))
        print(_summary_line(s))
    print(f"trained TM in {run_dir}")
    return 0


def _summary_line(s: dict) -> str:
    return (
        f"held-out: first waypoint to start {s['init_distance']['mean']:.4f} m, last to goal "
        f"{s['final_distance']['mean']:.4f} m, avg spacing {s['avg_spacing']['mean']:.4f} m, max spacing dev "
        f"{s['max_spacing_deviation']['mean']:.4f} m, mean angle {s['mean_angle']['mean']:.1f}°, executed-goal "
        f"error median {s['goal_error']['median'] * 1e3:.2f} mm, success ≤ 1 cm {s['success']['rate']:.1%}"
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
        default=0,
        help="with --obstacles: gradient steps refining the least colliding proposal when none is free "
        "(bounded time; default 0)",
    )


def plan_from_args(args: argparse.Namespace, strict: bool = False):
    """``(planner, plan, scene or None)`` for the options of :func:`add_plan_inputs`."""
    planner = Planner.load(args.model, robot=args.robot) if args.model else Planner.default(args.robot)
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

        obstacles = Scene.load(args.obstacles)
    elif args.scene is not None:
        from ..collision.scene import Scene

        obstacles = Scene.from_moveit(args.scene, base_pose=args.base_pose)
    options = {"obstacles": obstacles, "refine_steps": args.refine_steps, "strict": strict}
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


@register_subcommand
def _add_train_planner(sub) -> None:
    p = add_command(
        sub,
        "train-planner",
        "Train a joint-path TM (plans anywhere in the joint range, ends at the goal state) through a frozen "
        "FM, self-supervised; the run folder is a planner (tm.pt beside the fm.pt/im.pt it plans with).",
        _run_train_planner,
    )
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--fm-checkpoint", type=EXISTING_FILE, help="the learned FM to train through (fm.pt)")
    src.add_argument(
        "--analytic-fm", action="store_true", help="train through the analytic FK (the ablation)"
    )
    p.add_argument(
        "--im-checkpoint",
        type=EXISTING_FILE,
        default=None,
        help="a learned IM kept beside the TM for position goals (im.pt)",
    )
    p.add_argument(
        "--iterations", type=POSITIVE_INT, default=6000, help="training iterations (default: 6000)"
    )
    p.add_argument(
        "--batch-size", type=POSITIVE_INT, default=512, help="problems per iteration (default: 512)"
    )
    p.add_argument(
        "--lr", type=POSITIVE_FLOAT, default=2e-3, help="Adam learning rate, cosine decay (default: 2e-3)"
    )
    p.add_argument(
        "--hidden",
        type=_int_list(1),
        default=(128, 128, 128),
        help="MLP hidden widths, comma-separated (default: 128,128,128)",
    )
    p.add_argument(
        "--modes", type=NONNEGATIVE_INT, default=6, help="sine modes of the joint correction (0: free)"
    )
    p.add_argument(
        "--heldout",
        type=NONNEGATIVE_INT,
        default=500,
        help="held-out workspace pairs judged at the end (0: none)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_run_options(p, resumable=True)


def _int_list(low: int):
    """An argparse ``type``: integers ≥ ``low`` separated by commas."""

    def parse(text: str) -> tuple[int, ...]:
        try:
            values = tuple(int(v) for v in text.replace(",", " ").split())
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected integers separated by commas, got {text!r}") from None
        if not values or min(values) < low:
            raise argparse.ArgumentTypeError(f"expected integers ≥ {low}, got {text!r}")
        return values

    return parse


def _run_train_planner(args: argparse.Namespace) -> int:
    from ..evaluation.workspace import evaluate_workspace, heldout_pairs, workspace_table
    from ..models.forward_inverse import AnalyticFM, save_model
    from ..training.joint_path import PathTrainConfig, train_path_model

    robot = load_robot(args.robot)
    fm = AnalyticFM(robot) if args.analytic_fm else load_fm(args.fm_checkpoint, robot=robot.name)
    if args.im_checkpoint is not None:
        load_im(args.im_checkpoint, robot=robot.name)  # checked before anything is written
    cfg = PathTrainConfig(
        robot=robot.name,
        fm="analytic" if args.analytic_fm else "learned",
        fm_checkpoint="fm.pt" if not args.analytic_fm else None,
        iterations=args.iterations,
        batch_size=args.batch_size,
        lr=args.lr,
        model={"hidden": list(args.hidden), "modes": args.modes},
        seed=args.seed,
    )
    models = {"fm": "analytic" if args.analytic_fm else file_identity(args.fm_checkpoint)}
    if args.im_checkpoint is not None:
        models["im"] = file_identity(args.im_checkpoint)
    run = open_command_run(
        args,
        ("tm.pt", "fm.pt", "im.pt", "metrics.jsonl", "tensorboard"),
        resumable=True,
        planner=cfg.to_dict(),
        models=models,
    )
    run_dir = run.begin()
    if args.analytic_fm:
        save_model(fm, run_dir / "fm.pt")
    else:
        atomic_copy(args.fm_checkpoint, run_dir / "fm.pt")
    if args.im_checkpoint is not None:
        atomic_copy(args.im_checkpoint, run_dir / "im.pt")
    train_path_model(
        cfg, run_dir, fm=fm, resume=run.resumed, progress=not args.no_progress, write_config=False
    )
    if args.heldout:
        planner = Planner.load(run_dir)
        pairs = heldout_pairs(robot, n=args.heldout)
        res = evaluate_workspace(robot, pairs, {"this planner": planner})
        print(f"held-out workspace pairs ({args.heldout}, uniform within ±90% of the joint range):")
        print(workspace_table(res))
    print(f"trained planner in {run_dir}")
    return 0


@register_subcommand
def _add_train_obstacle_planner(sub) -> None:
    p = add_command(
        sub,
        "train-obstacle-planner",
        "Train the obstacle-aware TM self-supervised through a frozen body model on generated scenes "
        "(tabletop, shelf, barrier; seeds apart from the benchmark's); writes tm_obstacles.pt. Copy it into "
        "a planner folder (or pass --planner) and plan(..., obstacles=...) uses it.",
        _run_train_obstacle_planner,
    )
    p.add_argument(
        "--problems-per-family",
        type=POSITIVE_INT,
        default=1000,
        help="training problems per scene family, generated once into --problems-dir (default: 1000)",
    )
    p.add_argument(
        "--problems-dir",
        type=OUTPUT_DIR,
        default=None,
        help="where training problems are generated or found (default: RUN_DIR/problems)",
    )
    p.add_argument(
        "--body-checkpoint",
        type=EXISTING_FILE,
        default=None,
        help="train through a learned body model (body.pt) instead of the analytic sphere body",
    )
    p.add_argument(
        "--iterations", type=POSITIVE_INT, default=3000, help="training iterations (default: 3000)"
    )
    p.add_argument("--batch-size", type=POSITIVE_INT, default=64, help="problems per iteration (default: 64)")
    p.add_argument(
        "--lr", type=POSITIVE_FLOAT, default=2e-3, help="Adam learning rate, cosine decay (default: 2e-3)"
    )
    p.add_argument(
        "--candidates", type=POSITIVE_INT, default=6, help="paths proposed per problem (default: 6)"
    )
    p.add_argument(
        "--init-checkpoint",
        type=EXISTING_FILE,
        default=None,
        help="fine-tune a trained tm_obstacles.pt (same architecture) instead of starting afresh",
    )
    p.add_argument(
        "--planner",
        type=OUTPUT_DIR,
        default=None,
        help="a planner folder to copy the trained model into (as tm_obstacles.pt), e.g. a train-planner run",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_run_options(p, resumable=True)


def _run_train_obstacle_planner(args: argparse.Namespace) -> int:
    from ..models.obstacle_path import export_obstacle_model
    from ..training.obstacle_path import ObstacleTrainConfig, make_training_problems, train_obstacle_model

    robot = load_robot(args.robot)
    if args.planner is not None and not (args.planner / "tm.pt").is_file():
        raise ConfigError(f"--planner {args.planner} is not a planner folder (it holds no tm.pt)")
    # The models named on the command line are read now: a bad one is refused before anything is written.
    if args.body_checkpoint is not None:
        from ..models.body import load_body_model

        load_body_model(args.body_checkpoint, robot=robot.name)
    if args.init_checkpoint is not None:
        from ..models.obstacle_path import load_obstacle_model

        load_obstacle_model(args.init_checkpoint, robot=robot.name)
    run = open_command_run(
        args,
        ("tm_obstacles.pt", "metrics.jsonl", "tensorboard", "problems"),
        resumable=True,
        obstacle_planner={
            "problems_per_family": args.problems_per_family,
            "iterations": args.iterations,
            "batch_size": args.batch_size,
            "lr": args.lr,
            "candidates": args.candidates,
            "body": file_identity(args.body_checkpoint) if args.body_checkpoint else "analytic",
            "init": file_identity(args.init_checkpoint) if args.init_checkpoint else None,
        },
    )
    run_dir = run.begin()
    problems_dir = args.problems_dir or run_dir / "problems"
    print(f"training problems in {problems_dir} ({args.problems_per_family} per family; generated once)")
    paths = make_training_problems(problems_dir, args.problems_per_family, robot=robot)
    cfg = ObstacleTrainConfig(
        robot=robot.name,
        problems=tuple(sorted(str(p) for p in paths)),
        body="learned" if args.body_checkpoint else "analytic",
        body_checkpoint=str(args.body_checkpoint) if args.body_checkpoint else None,
        iterations=args.iterations,
        batch_size=args.batch_size,
        lr=args.lr,
        model={"candidates": args.candidates},
        init_checkpoint=str(args.init_checkpoint) if args.init_checkpoint else None,
        seed=args.seed,
    )
    train_obstacle_model(cfg, run_dir, resume=run.resumed, progress=not args.no_progress, write_config=False)
    if args.planner is not None:
        export_obstacle_model(run_dir / "tm_obstacles.pt", args.planner / "tm_obstacles.pt")
        print(f"copied the obstacle-aware TM into {args.planner}")
    print(f"trained obstacle-aware TM in {run_dir / 'tm_obstacles.pt'}")
    return 0


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
        "--seeds", type=_int_list(0), default=(0, 1, 2), help="perturbation seeds per level (default: 0,1,2)"
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
        "--quick", action="store_const", const="quick", dest="preset", help="≤ 10 min on 2 cores"
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
    from ..evaluation.reproduce import default_workers, preset_config, reproduce

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


# --------------------------------------------------------------------------------------------------
# export (the shipped default checkpoint)
# --------------------------------------------------------------------------------------------------


@register_subcommand
def _add_export(sub) -> None:
    p = add_command(
        sub,
        "export",
        "Write a train-tm run's tm.pt and the fm.pt/im.pt it was trained through into one folder, without "
        "optimiser state: --out DIR, or --to-package for the planner shipped inside the package "
        f"({DEFAULT_CHECKPOINTS.name}/<robot>).",
        _run_export,
        seed=False,
        run_dir=False,
    )
    p.add_argument("--model", type=EXISTING_DIR, required=True, help="a train-tm run directory")
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--out", type=Path, default=None, help="the folder to write")
    where.add_argument(
        "--to-package",
        action="store_true",
        help=f"write into the package's {DEFAULT_CHECKPOINTS.name}/<robot>, the planner kinlearn.plan uses",
    )
    p.add_argument(
        "--half",
        action="store_true",
        help="store the layers' weights as float16 (half the size; plans change by rounding only: "
        "measure the exported planner)",
    )
    add_run_options(p, resumable=False)


def _export_sources(model_dir: Path, payload: dict) -> dict[str, Path]:
    """The fm.pt/im.pt the TM of ``model_dir`` was trained through (verified by hash where recorded)."""
    tm_path = model_dir / "tm.pt"
    if payload["kind"] != "tm":  # another planner model: its FM/IM, where it has them, lie beside it
        return {k: model_dir / f"{k}.pt" for k in ("fm", "im") if (model_dir / f"{k}.pt").is_file()}
    config = payload["config"]
    models_dir = config.get("models_dir")  # recorded by checkpoints before the model/training split
    sources = {}
    for kind in ("fm", "im"):
        if config.get(kind, "learned") != "learned":
            continue
        if kind in payload["depends"]:
            sources[kind] = resolve_dependency(tm_path, payload, kind)
        elif (model_dir / f"{kind}.pt").is_file():  # a format-1 run: the models beside tm.pt
            sources[kind] = model_dir / f"{kind}.pt"
        elif models_dir and (Path(models_dir) / f"{kind}.pt").is_file():
            sources[kind] = Path(models_dir) / f"{kind}.pt"
        else:
            raise ConfigError(f"cannot find the {kind}.pt that {tm_path} was trained through")
    return sources


def _run_export(args: argparse.Namespace) -> int:
    out = args.out if args.out is not None else DEFAULT_CHECKPOINTS / args.robot
    planner = Planner.load(args.model, robot=args.robot)  # checks the run is complete and consistent
    tm_payload = load_checkpoint(args.model / "tm.pt", kind=None, robot=planner.robot.name)
    sources = _export_sources(args.model, tm_payload)
    if out.resolve() == args.model.resolve():
        raise ConfigError("--out is the run directory itself; export into another folder")
    run = open_run(
        out,
        command="export",
        config={},
        outputs=("tm.pt", "fm.pt", "im.pt", "tm_obstacles.pt"),
        overwrite=args.overwrite,
        resumable=False,
        write_config=False,
        option="--out",
    )
    out = run.begin()
    weights = half_weights if args.half else dict
    for kind, src in sources.items():
        payload = load_checkpoint(src, kind=kind, robot=planner.robot.name)
        save_checkpoint(
            out / f"{kind}.pt",
            kind=kind,
            robot=payload["robot"],
            config=payload["config"],
            state_dict=weights(payload["state_dict"]),
        )
    depends = {kind: out / f"{kind}.pt" for kind in sources}
    if (args.model / "chain.pt").is_file():  # the identified chain goes as it is (float64 geometry)
        load_checkpoint(args.model / "chain.pt", kind="fm", robot=planner.robot.name)
        atomic_copy(args.model / "chain.pt", out / "chain.pt")
    if (args.model / "tm_obstacles.pt").is_file():  # before tm.pt, which records it
        from ..models.obstacle_path import export_obstacle_model

        export_obstacle_model(args.model / "tm_obstacles.pt", out / "tm_obstacles.pt", half=args.half)
        depends["obstacle_tm"] = out / "tm_obstacles.pt"
    config = tm_payload["config"]
    if tm_payload["kind"] == "tm":  # the model's own config (older runs stored the training config)
        config = {k: config[k] for k in MODEL_FIELDS if k in config}
    save_checkpoint(  # last: it records the exported models by hash, so a partial export has no tm.pt
        out / "tm.pt",
        kind=tm_payload["kind"],
        robot=tm_payload["robot"],
        config=config,
        state_dict=weights(tm_payload["state_dict"]),
        depends=depends,
    )
    Planner.load(out, robot=planner.robot.name)  # the exported folder loads on its own
    print(f"exported the planner of {args.model} to {out}")
    return 0
