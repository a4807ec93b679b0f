"""``kinlearn`` subcommands that train the planners of the joint range, self-supervised through frozen
models: ``train-planner`` (the joint-path TM, through an FM) and ``train-obstacle-planner`` (the
obstacle-aware TM, through a body model on generated scenes).

Both write under the run-directory policy of :mod:`kinlearn.runs`.
"""

from __future__ import annotations

import argparse

from ..body.robot import load_robot
from ..data.target_paths import TEACHERS
from ..errors import ConfigError
from ..io import atomic_copy
from ..models.forward_inverse import load_fm, load_im
from ..planning.planner import Planner
from ..planning.teacher import TEACHER_STAGES
from .common import (
    EXISTING_DIR,
    EXISTING_FILE,
    NONNEGATIVE_FLOAT,
    NONNEGATIVE_INT,
    OUTPUT_DIR,
    POSITIVE_FLOAT,
    POSITIVE_INT,
    add_command,
    add_run_options,
    file_identity,
    int_list,
    number_text,
    open_command_run,
    register_subcommand,
)

# --------------------------------------------------------------------------------------------------
# train-planner
# --------------------------------------------------------------------------------------------------


def _add_optimiser_options(p: argparse.ArgumentParser, C) -> None:
    """``--iterations``, ``--batch-size`` and ``--lr``, their defaults read from the training config ``C``."""
    p.add_argument(
        "--iterations",
        type=POSITIVE_INT,
        default=C.iterations,
        help=f"training iterations (default: {C.iterations})",
    )
    p.add_argument(
        "--batch-size",
        type=POSITIVE_INT,
        default=C.batch_size,
        help=f"problems per iteration (default: {C.batch_size})",
    )
    p.add_argument(
        "--lr",
        type=POSITIVE_FLOAT,
        default=C.lr,
        help=f"Adam learning rate, cosine decay (default: {number_text(C.lr)})",
    )


@register_subcommand
def _add_train_planner(sub) -> None:
    from ..training.joint_path import PLANNER_MODEL
    from ..training.joint_path import PathTrainConfig as C

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
    _add_optimiser_options(p, C)
    hidden = PLANNER_MODEL["hidden"]
    p.add_argument(
        "--hidden",
        type=int_list(1),
        default=hidden,
        help=f"MLP hidden widths, comma-separated (default: {','.join(map(str, hidden))})",
    )
    p.add_argument(
        "--modes",
        type=NONNEGATIVE_INT,
        default=PLANNER_MODEL["modes"],
        help="sine modes of the joint correction (0: free)",
    )
    p.add_argument(
        "--heldout",
        type=NONNEGATIVE_INT,
        default=500,
        help="held-out workspace pairs judged at the end (0: none)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_run_options(p, resumable=True)


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
        max_step=fm.max_step,  # the rolled-out path steps as far as the FM's data did
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


# --------------------------------------------------------------------------------------------------
# train-obstacle-planner
# --------------------------------------------------------------------------------------------------


@register_subcommand
def _add_train_obstacle_planner(sub) -> None:
    from ..models.obstacle_path import ObstaclePathConfig
    from ..training.obstacle_path import ObstacleTrainConfig as C

    p = add_command(
        sub,
        "train-obstacle-planner",
        "Train the obstacle-aware TM self-supervised through a frozen body model on generated scenes "
        "(the seven scene families by default; seeds apart from the benchmark's); writes tm_obstacles.pt, "
        "which records the families it saw. Copy it into a planner folder (or pass --planner) and "
        "plan(..., obstacles=...) uses it.",
        _run_train_obstacle_planner,
    )
    p.add_argument(
        "--families",
        nargs="+",
        default=["scenes"],
        metavar="FAMILY",
        help="scene families to train on: names, or 'scenes' (the seven of kinlearn.data.scenes), 'legacy' "
        "(tabletop, shelf, barrier: the shipped iiwa14 network's) or 'all' (default: scenes)",
    )
    p.add_argument(
        "--leave-out",
        nargs="+",
        default=[],
        metavar="FAMILY",
        help="families to hold out of training (a leave-one-family-out run; the benchmark marks them)",
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
    _add_optimiser_options(p, C)
    candidates = ObstaclePathConfig.candidates
    p.add_argument(
        "--candidates",
        type=POSITIVE_INT,
        default=candidates,
        help=f"paths proposed per problem (default: {candidates})",
    )
    p.add_argument(
        "--imitation",
        type=NONNEGATIVE_FLOAT,
        default=0.0,
        metavar="WEIGHT",
        help="distil: each training problem's teacher path (--teacher; made once, cached beside the problems) "
        "pulls the nearest candidate towards it with this weight, besides the self-supervised loss "
        "(default: 0, self-supervised alone; 10 for the sampler's paths, 300 for a planner's own plans)",
    )
    p.add_argument(
        "--teacher",
        choices=tuple(TEACHERS),
        default="sampler",
        help="whose paths --imitation and --solvable-only read: the compiled RRT-Connect's (20,000 iterations "
        "per problem; default) or a kinlearn planner's own plans (plan(..., obstacles=...) by default: its "
        "fixed-time stages, then its default budget of sampler iterations; --teacher-planner), self-distillation",
    )
    p.add_argument(
        "--teacher-planner",
        type=EXISTING_DIR,
        default=None,
        metavar="FOLDER",
        help="the planner folder whose plans teach with --teacher planner (default: the robot's shipped planner)",
    )
    p.add_argument(
        "--teacher-stages",
        choices=TEACHER_STAGES,
        default="default",
        help="what the teacher planner plans with (--teacher planner): plan()'s default stages (the fixed-time "
        "stages, then its default budget of sampler iterations; default) or its fixed-time stages alone "
        "('fixed': the network and the retreat stage, no sampler, so no searched path is shown)",
    )
    p.add_argument(
        "--solvable-only",
        action="store_true",
        help="train only on the problems the teacher solves (--teacher; the sampler within 20,000 iterations; "
        "solved once, cached beside the problems): unverified problems include infeasible ones; a filter, "
        "no path is shown without --imitation",
    )
    p.add_argument(
        "--sphere-set",
        default=None,
        metavar="NAME",
        help="the sphere set training problems are made for and the analytic body trains through "
        "(default: the body the robot's planner checks with, the ur5's carrying its gripper)",
    )
    p.add_argument(
        "--within",
        choices=("robot", "body"),
        default="robot",
        help="whose joint limits training starts and goals keep within: the robot's (default) or the body's "
        "(the ur5's tool model's ±π, as the standard benchmarks' UR5 turns); paths are kept in the same box",
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
    from ..data.problems import select_families
    from ..models.obstacle_path import export_obstacle_model
    from ..training.obstacle_path import (
        ObstacleLossConfig,
        ObstacleTrainConfig,
        make_training_problems,
        train_obstacle_model,
    )

    robot = load_robot(args.robot)
    families = select_families(args.families, args.leave_out)
    if args.planner is not None and not (args.planner / "tm.pt").is_file():
        raise ConfigError(f"--planner {args.planner} is not a planner folder (it holds no tm.pt)")
    # The models named on the command line are read now: a bad one is refused before anything is written.
    if args.body_checkpoint is not None:
        from ..models.body import load_body_model

        load_body_model(args.body_checkpoint, robot=robot.name)
    if args.init_checkpoint is not None:
        from ..models.obstacle_path import load_obstacle_model

        load_obstacle_model(args.init_checkpoint, robot=robot.name)
    from ..collision.body import body_spheres
    from ..data.problems import ProblemConfig

    body_name = ProblemConfig(sphere_set=args.sphere_set).body(robot).name  # an unknown set is refused here
    teacher_record = None
    if args.teacher == "planner":
        from ..planning.planner import DEFAULT_CHECKPOINTS, OBSTACLE_TM

        teacher_dir = args.teacher_planner or DEFAULT_CHECKPOINTS / robot.name
        if not (teacher_dir / "tm.pt").is_file():
            raise ConfigError(f"--teacher-planner {teacher_dir} is not a planner folder (it holds no tm.pt)")
        network = teacher_dir / OBSTACLE_TM
        teacher_record = {
            "planner": str(teacher_dir),
            **({"stages": args.teacher_stages} if args.teacher_stages != "default" else {}),
            **({"network": file_identity(network)} if network.is_file() else {}),
        }
    elif args.teacher_planner is not None or args.teacher_stages != "default":
        raise ConfigError(
            "--teacher-planner and --teacher-stages describe the planner of --teacher planner; add --teacher planner"
        )
    run = open_command_run(
        args,
        ("tm_obstacles.pt", "metrics.jsonl", "tensorboard", "problems"),
        resumable=True,
        obstacle_planner={
            "families": list(families),
            "problems_per_family": args.problems_per_family,
            "iterations": args.iterations,
            "batch_size": args.batch_size,
            "lr": args.lr,
            "candidates": args.candidates,
            **({"imitation": args.imitation} if args.imitation else {}),  # absent: self-supervised, as before
            **({"solvable_only": True} if args.solvable_only else {}),
            **({"teacher": teacher_record} if args.teacher != "sampler" else {}),  # absent: the sampler
            # absent: the robot's default sphere body, as before sets could be chosen
            **({"sphere_set": body_name} if body_name != body_spheres(robot).name else {}),
            **({"within": args.within} if args.within != "robot" else {}),  # absent: the robot's, as before
            "body": file_identity(args.body_checkpoint) if args.body_checkpoint else "analytic",
            "init": file_identity(args.init_checkpoint) if args.init_checkpoint else None,
        },
    )
    run_dir = run.begin()
    problems_dir = args.problems_dir or run_dir / "problems"
    print(
        f"training problems in {problems_dir} ({args.problems_per_family} per family of "
        f"{', '.join(families)}; generated once)"
    )
    paths = make_training_problems(
        problems_dir,
        args.problems_per_family,
        robot=robot,
        families=families,
        sphere_set=args.sphere_set,
        within=args.within,
    )
    if args.teacher == "planner":
        import time

        from ..models.obstacle_path import ObstaclePathConfig
        from ..planning.teacher import planner_paths

        knots = ObstaclePathConfig.for_robot(robot, candidates=args.candidates).steps
        for p in paths:
            t0 = time.perf_counter()
            planner_paths(teacher_dir, p, knots, stages=args.teacher_stages)
            print(f"the teacher planner's plans of {p.name}: {time.perf_counter() - t0:.0f} s", flush=True)
    cfg = ObstacleTrainConfig(
        robot=robot.name,
        problems=tuple(sorted(str(p) for p in paths)),
        body="learned" if args.body_checkpoint else "analytic",
        body_checkpoint=str(args.body_checkpoint) if args.body_checkpoint else None,
        iterations=args.iterations,
        batch_size=args.batch_size,
        lr=args.lr,
        model={"candidates": args.candidates},
        loss=ObstacleLossConfig(imitation=args.imitation),
        solvable_only=args.solvable_only,
        teacher=args.teacher,
        init_checkpoint=str(args.init_checkpoint) if args.init_checkpoint else None,
        seed=args.seed,
    )
    train_obstacle_model(cfg, run_dir, resume=run.resumed, progress=not args.no_progress, write_config=False)
    if args.planner is not None:
        export_obstacle_model(run_dir / "tm_obstacles.pt", args.planner / "tm_obstacles.pt")
        print(f"copied the obstacle-aware TM into {args.planner}")
    print(f"trained obstacle-aware TM in {run_dir / 'tm_obstacles.pt'}")
    return 0
