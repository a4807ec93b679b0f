"""The ``kinlearn`` command: babble, train the forward/inverse models, validate them.

Every subcommand writes into a run directory (``--run-dir``, default ``runs/<time>-<command>``)
holding ``config.json`` (the command, its arguments and the resolved configs) beside its outputs.
A folder that already holds a run is written only with ``--resume`` (same configuration) or
``--overwrite`` (see :mod:`kinlearn.runs`); nothing is written before every check has passed.
Exit status: 0 done, 2 bad input or refused (``kinlearn <command>: error: …``), 130 interrupted
(``kinlearn plan``: 1 when a plan misses its goal).

Shared helpers live in :mod:`kinlearn.cli.common`; new subcommands, in a module of their own listed in
:data:`SUBCOMMAND_MODULES`, are added with :func:`~kinlearn.cli.common.register_subcommand`::

    @register_subcommand
    def _add_plan(sub):
        p = add_command(sub, "plan", "Plan trajectories.", run=_run_plan)
        ...
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from .. import __version__
from ..errors import ConfigError, KinlearnError
from .common import (
    _SUBCOMMANDS,
    EXISTING_FILE,
    NONNEGATIVE_FLOAT,
    NONNEGATIVE_INT,
    POSITIVE_FLOAT,
    POSITIVE_INT,
    PROBABILITY,
    add_command,
    add_data_options,
    add_run_options,
    data_record,
    file_identity,
    number_text,
    number_type,
    open_command_run,
    register_subcommand,
)

# The command's own modules import torch and the models where a command runs (inside its functions), so
# that `kinlearn --help` answers without them (see COMMANDS).

__all__ = ["SUBCOMMAND_MODULES", "build_parser", "main"]

#: Transitions babbled for training when no ``--data`` is given, per preset.
DEFAULT_TRANSITIONS = {"paper": 500_000, "improved": 500_000, "tiny": 20_000}


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every registered subcommand."""
    _load_subcommand_modules()
    parser = argparse.ArgumentParser(
        prog="kinlearn", description="Learn robot kinematics and trajectory planning from motor babbling."
    )
    parser.add_argument("--version", action="version", version=f"kinlearn {__version__}")
    sub = parser.add_subparsers(title="commands", metavar="COMMAND", required=True)
    own = (_add_babble, lambda s: _add_train(s, "fm"), lambda s: _add_train(s, "im"), _add_validate)
    for add in (*own, *sorted(_SUBCOMMANDS, key=_module_rank)):
        add(sub)
    return parser


def _module_rank(add) -> int:
    """A subcommand's place: its module's in :data:`SUBCOMMAND_MODULES` (the order of ``--help``),
    whichever module was imported first; registrations from elsewhere come last, in their order."""
    module = getattr(add, "__module__", "").rpartition(".")[2]
    return SUBCOMMAND_MODULES.index(module) if module in SUBCOMMAND_MODULES else len(SUBCOMMAND_MODULES)


# --------------------------------------------------------------------------------------------------
# babble
# --------------------------------------------------------------------------------------------------


def _add_babbling_options(p: argparse.ArgumentParser, transitions: int | None) -> None:
    from ..data.babbling import BabblingConfig as B

    p.add_argument(
        "--transitions",
        type=POSITIVE_INT,
        default=transitions,
        help="transitions to babble (walkers × steps, rounded up to whole steps)",
    )
    p.add_argument(
        "--walkers",
        type=POSITIVE_INT,
        default=B.walkers,
        help=f"parallel random walkers (default: {B.walkers})",
    )
    p.add_argument(
        "--max-step",
        type=POSITIVE_FLOAT,
        default=B.max_step,
        help=f"max joint change per step, rad (default: {number_text(B.max_step)})",
    )
    p.add_argument(
        "--retarget-prob",
        type=PROBABILITY,
        default=B.retarget_prob,
        help="per-step chance of a new joint target before the current one is reached (1 = new target every step)",
    )


def _babbling_config(args: argparse.Namespace, n: int):
    from ..data.babbling import BabblingConfig

    source = {}
    if getattr(args, "urdf", None) is not None:
        source = {"urdf": str(args.urdf), "ee_frame": args.ee_frame}
    return BabblingConfig.for_transitions(
        n,
        walkers=args.walkers,
        robot=args.robot,
        seed=args.seed,
        max_step=args.max_step,
        retarget_prob=args.retarget_prob,
        **source,
    )


def _add_babble(sub) -> None:
    from ..data.babbling import BabblingConfig as B

    p = add_command(
        sub, "babble", "Motor babbling: write (s, a, s') transitions to babbling.npz.", _run_babble
    )
    _add_babbling_options(p, B.walkers * B.steps)
    p.add_argument(
        "--ef-noise",
        type=NONNEGATIVE_FLOAT,
        default=B.ef_noise,
        metavar="SIGMA",
        help="Gaussian noise on each observed end-effector coordinate, standard deviation in m "
        f"(default: {number_text(B.ef_noise)})",
    )
    p.add_argument(
        "--outliers",
        type=number_type(float, low=0, high=1, open_high=True),
        default=B.outliers,
        metavar="FRACTION",
        help="share of the observed states whose end effector is displaced by --outlier-size "
        f"(default: {number_text(B.outliers)})",
    )
    p.add_argument(
        "--outlier-size",
        type=POSITIVE_FLOAT,
        default=B.outlier_size,
        metavar="METRES",
        help=f"how far an outlier is displaced, in a random direction (default: {number_text(B.outlier_size)})",
    )
    p.add_argument(
        "--urdf",
        type=EXISTING_FILE,
        default=None,
        help="babble with the robot of this URDF file (needs --ee-frame; the data are named after the "
        "file unless --robot is given)",
    )
    p.add_argument("--ee-frame", default=None, help="the end-effector link of --urdf")
    p.set_defaults(robot=None)  # with --urdf: the file's stem; otherwise iiwa14
    add_run_options(p, resumable=False)


def _run_babble(args: argparse.Namespace) -> int:
    from ..data.babbling import babble, save_transitions

    if (args.urdf is None) != (args.ee_frame is None):
        raise ConfigError("--urdf and --ee-frame go together: the URDF file and its end-effector link")
    cfg = dataclasses.replace(
        _babbling_config(args, args.transitions),
        ef_noise=args.ef_noise,
        outliers=args.outliers,
        outlier_size=args.outlier_size,
    )
    run_dir = open_command_run(args, ("babbling.npz",), babbling=cfg.to_dict()).begin()
    t0 = time.perf_counter()
    data = babble(cfg)
    dt = time.perf_counter() - t0
    path = save_transitions(data, run_dir / "babbling.npz")
    print(f"{len(data):,} transitions of {cfg.robot} in {dt:.2f} s → {path}")
    return 0


# --------------------------------------------------------------------------------------------------
# train-fm / train-im
# --------------------------------------------------------------------------------------------------


def _add_train(sub, kind: str) -> None:
    from ..models.presets import FM_PRESETS
    from ..training.forward_inverse import THROUGH_FM_ACTION_WEIGHT
    from ..training.loop import TrainConfig

    what = "forward" if kind == "fm" else "inverse"
    p = add_command(
        sub,
        f"train-{kind}",
        f"Train the learned {what} model on babbling data; writes {kind}.pt and metrics.jsonl.",
        _run_train,
    )
    p.add_argument(
        "--preset",
        choices=sorted(FM_PRESETS),
        default="paper",
        help="model + training preset: paper (the paper's Sect. 4), improved, tiny (seconds; for tests)",
    )
    add_data_options(p, "to train on (default: babble afresh)")
    _add_babbling_options(p, None)
    if kind == "fm":
        p.add_argument(
            "--fk-hidden",
            type=POSITIVE_INT,
            nargs="+",
            default=None,
            metavar="WIDTH",
            help="hidden widths of the FM's g, its learned forward kinematics (presets whose FM is in "
            "difference form: improved; default 256 256 256)",
        )
    else:
        p.add_argument(
            "--hidden",
            type=POSITIVE_INT,
            nargs="+",
            default=None,
            metavar="WIDTH",
            help="hidden widths of the IM (default: the preset's)",
        )
    p.add_argument("--epochs", type=POSITIVE_INT, default=None, help="override the preset's epochs")
    p.add_argument(
        "--lr", type=POSITIVE_FLOAT, default=None, help="override the preset's learning rate (> 0)"
    )
    p.add_argument("--batch-size", type=POSITIVE_INT, default=None, help="override the preset's batch size")
    p.add_argument(
        "--val-fraction",
        type=number_type(float, low=0, high=1, open_high=True),
        default=TrainConfig.val_fraction,
        help=f"held-out share of the data, in [0, 1) (default: {number_text(TrainConfig.val_fraction)})",
    )
    add_run_options(p, resumable=True)
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument(
        "--validate",
        type=NONNEGATIVE_INT,
        default=100_000,
        help="fresh transitions to validate on afterwards (0: skip)",
    )
    if kind == "im":
        p.add_argument(
            "--through-fm",
            type=EXISTING_FILE,
            default=None,
            help="after supervised training (in <run-dir>/supervised), refine the IM through this frozen "
            "fm.pt so that its actions reach their targets (in <run-dir>/through-fm; see train_im_distal)",
        )
        p.add_argument("--through-fm-epochs", type=POSITIVE_INT, default=12, help="epochs of that refinement")
        p.add_argument(
            "--action-weight",
            type=NONNEGATIVE_FLOAT,
            default=THROUGH_FM_ACTION_WEIGHT,
            help="pull toward the babbled action",
        )
    p.set_defaults(kind=kind)


def _run_train(args: argparse.Namespace) -> int:
    from ..data.babbling import babble
    from ..data.recorded import load_data
    from ..io import atomic_copy, write_json
    from ..models.forward_inverse import FM_PRESETS, fm_config, im_config, load_fm
    from ..training.forward_inverse import (
        TrainResult,
        data_max_step,
        format_validation_table,
        train_config,
        train_fm,
        train_im,
        train_im_distal,
        validate_models,
    )

    kind = args.kind
    # Every check first (configs, data, the frozen FM): nothing is written before they pass.
    widths = {}
    if kind == "fm" and args.fk_hidden is not None:
        if FM_PRESETS[args.preset].get("ef_mode") != "difference":
            raise ConfigError(
                f"--fk-hidden sizes the difference-form FM's g; the {args.preset!r} FM has none"
            )
        widths["fk_hidden"] = tuple(args.fk_hidden)
    if kind == "im" and args.hidden is not None:
        widths["hidden"] = tuple(args.hidden)
    model_cfg = (fm_config if kind == "fm" else im_config)(args.robot, args.preset, **widths)
    overrides: dict = {"seed": args.seed, "val_fraction": args.val_fraction, "progress": not args.no_progress}
    if args.epochs is not None:
        overrides["epochs"] = args.epochs
    if args.batch_size is not None:
        overrides["batch_size"] = args.batch_size
    cfg = train_config(kind, args.preset, **overrides)
    if args.lr is not None:  # replace(): the new value is validated like any other
        cfg = dataclasses.replace(cfg, optim=dataclasses.replace(cfg.optim, lr=args.lr))
    configs: dict = {"model": model_cfg.to_dict(), "train": cfg.to_dict()}
    data, bcfg = None, None
    if args.data is not None:
        data = load_data(args.data, robot=args.robot, drop_nan=args.drop_nan)
        configs.update(data=file_identity(args.data), **data_record(data))
    else:
        bcfg = _babbling_config(args, args.transitions or DEFAULT_TRANSITIONS[args.preset])
        configs["babbling"] = bcfg.to_dict()
    if kind == "fm":  # the FM records the step bound of its data, as train_fm does
        step = data_max_step(data) if data is not None else bcfg.max_step
        model_cfg = dataclasses.replace(model_cfg, max_step=step)
        configs["model"] = model_cfg.to_dict()
    through_fm = dcfg = None
    if kind == "im" and args.through_fm is not None:
        through_fm = load_fm(args.through_fm, robot=args.robot)
        dcfg = train_config("im", args.preset, **{**overrides, "epochs": args.through_fm_epochs})
        configs["through_fm"] = {
            **file_identity(args.through_fm),
            "action_weight": args.action_weight,
            "train": dcfg.to_dict(),
        }
    if args.validate > 0:
        configs["validation"] = {"n": args.validate, "seed": args.seed + 10_000}
    outputs = (f"{kind}.pt", "metrics.jsonl", "validation.json", "tensorboard")
    if kind == "im":
        outputs += ("supervised", "through-fm")
    run = open_command_run(args, outputs, resumable=True, **configs)
    run_dir = run.begin()

    t0 = time.perf_counter()
    if data is None:
        data = babble(bcfg)
    trainer = train_fm if kind == "fm" else train_im
    # With a refinement stage, each stage keeps its own checkpoint (so that each resumes alone).
    stage_dir = run_dir / "supervised" if through_fm is not None else run_dir
    result = trainer(data, model_cfg, cfg, run_dir=stage_dir, resume=run.resumed)
    if through_fm is not None:
        distal = train_im_distal(
            data,
            result.model,
            through_fm,
            dcfg,
            run_dir=run_dir / "through-fm",
            resume=run.resumed,
            action_weight=args.action_weight,
        )
        atomic_copy(distal.checkpoint, run_dir / "im.pt")
        result = TrainResult(distal.model, result.history + distal.history, run_dir / "im.pt")
    dt = time.perf_counter() - t0
    last = result.history[-1] if result.history else {}
    print(f"trained {kind.upper()} ({args.preset}) in {dt:.1f} s; last epoch: {last}")
    print(f"checkpoint: {result.checkpoint}")
    if args.validate > 0:
        fm, im = (result.model, None) if kind == "fm" else (None, result.model)
        res = validate_models(fm, im, args.robot, n=args.validate, seed=args.seed + 10_000)
        res["train_wall_s"] = dt
        write_json(run_dir / "validation.json", res)
        print(format_validation_table(res))
    return 0


# --------------------------------------------------------------------------------------------------
# validate
# --------------------------------------------------------------------------------------------------


def _add_validate(sub) -> None:
    from ..data.babbling import BabblingConfig as B

    p = add_command(
        sub,
        "validate",
        "Validate FM/IM checkpoints against the analytic robot on fresh babbling data.",
        _run_validate,
        seed_default=10_000,  # not the training data's seed (0): fresh transitions
    )
    p.add_argument("--fm", default=None, help="FM checkpoint (.pt), or 'analytic'")
    p.add_argument("--im", default=None, help="IM checkpoint (.pt), or 'analytic'")
    p.add_argument("--n", type=POSITIVE_INT, default=100_000, help="fresh transitions (default: 100000)")
    p.add_argument(
        "--max-step",
        type=POSITIVE_FLOAT,
        default=B.max_step,
        help=f"babbling step bound, rad (default: {number_text(B.max_step)})",
    )
    p.add_argument(
        "--retarget-prob", type=PROBABILITY, default=B.retarget_prob, help="babbling retarget probability"
    )
    p.add_argument("--im-iterations", type=POSITIVE_INT, default=1, help="DLS iterations of the analytic IM")
    add_run_options(p, resumable=False)


def _run_validate(args: argparse.Namespace) -> int:
    from ..io import atomic_write, read_json, write_json
    from ..models.forward_inverse import AnalyticFM, AnalyticIM, load_fm, load_im
    from ..training.forward_inverse import format_validation_table, validate_models

    if args.fm is None and args.im is None:
        raise KinlearnError("give --fm and/or --im (a checkpoint path or 'analytic')")
    fm = None
    if args.fm is not None:
        fm = AnalyticFM(args.robot) if args.fm == "analytic" else load_fm(args.fm, robot=args.robot)
    im = None
    if args.im is not None:
        im = (
            AnalyticIM(args.robot, iterations=args.im_iterations)
            if args.im == "analytic"
            else load_im(args.im, robot=args.robot)
        )
    models = {
        name: path if path in (None, "analytic") else file_identity(Path(path))
        for name, path in (("fm", args.fm), ("im", args.im))
    }
    settings = {k: getattr(args, k) for k in ("n", "seed", "max_step", "retarget_prob", "im_iterations")}
    run = open_command_run(args, ("validation.json", "validation.md"), validate={**models, **settings})
    run_dir = run.begin()
    res = validate_models(
        fm, im, args.robot, n=args.n, seed=args.seed, max_step=args.max_step, retarget_prob=args.retarget_prob
    )
    for name, path in (("fm", args.fm), ("im", args.im)):
        if path not in (None, "analytic") and Path(path).with_name("config.json").is_file():
            res[f"{name}_run_config"] = read_json(Path(path).with_name("config.json"))
    write_json(run_dir / "validation.json", res)
    table = format_validation_table(res)
    atomic_write(run_dir / "validation.md", lambda p: p.write_text(table + "\n"))
    print(table)
    return 0


# --------------------------------------------------------------------------------------------------


#: Modules holding further subcommands; each registers its commands with
#: :func:`~kinlearn.cli.common.register_subcommand` (or has a ``register`` function added here). Imported
#: when the full parser is built.
SUBCOMMAND_MODULES = (
    "tm",
    "plan",
    "train_planners",
    "evaluate",
    "export",
    "body",
    "identify",
    "view",
    "onboard",
)

#: Every command with its one-line help, in the parser's order: what ``kinlearn --help`` lists without
#: importing the commands' modules (torch among them). ``tests/test_lazy_imports.py`` holds it to the
#: full parser: a new command is added here too.
COMMANDS = (
    ("babble", "Motor babbling: write (s, a, s') transitions to babbling.npz."),
    ("train-fm", "Train the learned forward model on babbling data; writes fm.pt and metrics.jsonl."),
    ("train-im", "Train the learned inverse model on babbling data; writes im.pt and metrics.jsonl."),
    ("validate", "Validate FM/IM checkpoints against the analytic robot on fresh babbling data."),
    (
        "make-endpoints",
        "Draw [s(0), s(T)] endpoint pairs; writes endpoints_train.npz and endpoints_heldout.npz.",
    ),
    ("train-tm", "Train the trajectory model through the frozen FM and IM (Algorithm 1); writes tm.pt."),
    (
        "plan",
        "Plan from a start to a goal and print how it went. Exit status 0 when every plan reaches its goal, 1 when one misses it (the table says by how much), 2 for bad input.",
    ),
    (
        "train-planner",
        "Train a joint-path TM (plans anywhere in the joint range, ends at the goal state) through a frozen FM, self-supervised; the run folder is a planner (tm.pt beside the fm.pt/im.pt it plans with).",
    ),
    (
        "train-obstacle-planner",
        "Train the obstacle-aware TM self-supervised through a frozen body model on generated scenes (the seven scene families by default; seeds apart from the benchmark's); writes tm_obstacles.pt, which records the families it saw. Copy it into a planner folder (or pass --planner) and plan(..., obstacles=...) uses it.",
    ),
    (
        "model-error",
        "Plan to held-out end-effector positions when the robot's model is wrong: kinlearn's planner (learned from the true robot) against model-based planners given a perturbed URDF, all judged by the true FK; writes model_error.json, model_error.md and model_error.png.",
    ),
    (
        "reproduce",
        "Run the whole pipeline and write results.md/results.json with the paper's tables and figures.",
    ),
    (
        "export",
        "Write a train-tm run's tm.pt and the fm.pt/im.pt it was trained through into one folder, without optimiser state: --out DIR, or --to-package for the planner shipped inside the package (checkpoints/<robot>).",
    ),
    (
        "train-body",
        "Learn the arm's collision body (joints -> sphere centres) from babbling; writes body.pt, metrics.jsonl and validation.json.",
    ),
    (
        "identify",
        "Identify a robot's kinematic chain from observed end-effector positions (calibration); writes chain.pt (a chain FM) and report.json (held-out residual).",
    ),
    (
        "export-urdf",
        "Write an identified chain (a run of `kinlearn identify`, or its chain.pt) as a URDF whose forward "
        "kinematics equal the chain's: written to a temporary file, checked through Pinocchio, then renamed "
        "onto --out (never replaced without --overwrite).",
    ),
    (
        "view",
        "Plan from a start to a goal and show the plan: in the browser (viser, on localhost, until Ctrl-C), or as a GIF with --gif. Exit status 0 when the plan reaches its goal, 1 when it misses it, 2 for bad input.",
    ),
    (
        "onboard",
        "Fit collision spheres to a URDF's own collision geometry, babble, identify the chain, train the free-space planner and the obstacle network on the seven scene families scaled to the arm; writes RUN_DIR/planner (Planner.load) and RUN_DIR/robot (its spheres).",
    ),
)


def _load_subcommand_modules() -> None:
    for name in SUBCOMMAND_MODULES:
        module = importlib.import_module(f".{name}", __package__)
        register = getattr(module, "register", None)
        if register is not None and register not in _SUBCOMMANDS:
            register_subcommand(register)


def _top_level_parser() -> argparse.ArgumentParser:
    """The parser of ``kinlearn`` without its commands' options: answers ``--help`` and ``--version``."""
    parser = argparse.ArgumentParser(
        prog="kinlearn", description="Learn robot kinematics and trajectory planning from motor babbling."
    )
    parser.add_argument("--version", action="version", version=f"kinlearn {__version__}")
    sub = parser.add_subparsers(title="commands", metavar="COMMAND", required=True)
    for name, text in COMMANDS:
        sub.add_parser(name, help=text, description=text)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``kinlearn`` command; returns the exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if not argv or argv[0] in ("-h", "--help", "--version"):
        _top_level_parser().parse_args(argv)  # prints and exits, without importing torch
    parser = build_parser()
    args = parser.parse_args(argv)  # bad options: a usage message and exit status 2
    import torch

    from ..runs import release_locks

    torch.set_num_threads(args.threads)
    try:
        return int(args.run(args) or 0)
    except KinlearnError as exc:
        print(f"kinlearn {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        hint = " (continue it with --resume)" if "resume" in vars(args) else ""
        print(f"kinlearn {args.command}: interrupted{hint}", file=sys.stderr)
        return 130
    finally:
        release_locks()  # the run directory is free for the next command


if __name__ == "__main__":
    sys.exit(main())
