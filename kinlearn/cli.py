"""The ``kinlearn`` command: babble, train the forward/inverse models, validate them.

Every subcommand writes into a run directory (``--run-dir``, default ``runs/<time>-<command>``)
holding ``config.json`` (the command, its arguments and the resolved configs) beside its outputs.

New subcommands are added with :func:`register_subcommand`::

    @register_subcommand
    def _add_plan(sub):
        p = add_command(sub, "plan", "Plan trajectories.", run=_run_plan)
        ...
"""

from __future__ import annotations

import argparse
import platform
import shutil
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import torch

from . import __version__
from .babbling import BabblingConfig, babble, load_transitions, save_transitions
from .errors import KinlearnError
from .io import read_json, write_json
from .models import FM_PRESETS, AnalyticFM, AnalyticIM, fm_config, im_config, load_fm, load_im
from .robot import available_robots
from .train import (
    TrainResult,
    format_validation_table,
    train_config,
    train_fm,
    train_im,
    train_im_distal,
    validate_models,
)

__all__ = ["add_command", "build_parser", "main", "register_subcommand"]

#: Transitions babbled for training when no ``--data`` is given, per preset.
DEFAULT_TRANSITIONS = {"paper": 500_000, "improved": 500_000, "tiny": 20_000}

SubcommandAdder = Callable[[argparse._SubParsersAction], None]
_SUBCOMMANDS: list[SubcommandAdder] = []


def register_subcommand(add: SubcommandAdder) -> SubcommandAdder:
    """Register a function that adds one subcommand to the parser (usable as a decorator)."""
    _SUBCOMMANDS.append(add)
    return add


def add_command(
    sub: argparse._SubParsersAction, name: str, help: str, run: Callable[[argparse.Namespace], int | None]
) -> argparse.ArgumentParser:
    """Add subcommand ``name`` with the options every subcommand has (robot, seed, run dir, threads)."""
    p = sub.add_parser(name, help=help, description=help)
    p.add_argument("--robot", default="iiwa14", help=f"robot name ({', '.join(available_robots())})")
    p.add_argument("--seed", type=int, default=0, help="seed of everything random (default: 0)")
    p.add_argument(
        "--run-dir", type=Path, default=None, help="output folder (default: runs/<time>-<command>)"
    )
    p.add_argument(
        "--threads",
        type=int,
        default=1,
        help="torch CPU threads (default: 1, fastest for these small models)",
    )
    p.set_defaults(run=run, command=name)
    return p


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every registered subcommand."""
    parser = argparse.ArgumentParser(
        prog="kinlearn", description="Learn robot kinematics and trajectory planning from motor babbling."
    )
    parser.add_argument("--version", action="version", version=f"kinlearn {__version__}")
    sub = parser.add_subparsers(title="commands", metavar="COMMAND", required=True)
    for add in _SUBCOMMANDS:
        add(sub)
    return parser


def _run_dir(args: argparse.Namespace) -> Path:
    if args.run_dir is None:
        args.run_dir = Path("runs") / f"{time.strftime('%Y%m%d-%H%M%S')}-{args.command}"
    args.run_dir.mkdir(parents=True, exist_ok=True)
    return args.run_dir


def _write_config(args: argparse.Namespace, **configs) -> None:
    argv = {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items() if k != "run"}
    write_json(
        args.run_dir / "config.json",
        {
            "command": args.command,
            "args": argv,
            **configs,
            "versions": {
                "kinlearn": __version__,
                "torch": torch.__version__,
                "python": platform.python_version(),
            },
        },
    )


# --------------------------------------------------------------------------------------------------
# babble
# --------------------------------------------------------------------------------------------------


def _add_babbling_options(p: argparse.ArgumentParser, transitions: int | None) -> None:
    p.add_argument(
        "--transitions",
        type=int,
        default=transitions,
        help="transitions to babble (walkers × steps, rounded up to whole steps)",
    )
    p.add_argument("--walkers", type=int, default=1000, help="parallel random walkers (default: 1000)")
    p.add_argument(
        "--max-step", type=float, default=0.083, help="max joint change per step, rad (default: 0.083)"
    )
    p.add_argument(
        "--retarget-prob",
        type=float,
        default=0.0,
        help="per-step chance of a new joint target before the current one is reached (1 = new target every step)",
    )


def _babbling_config(args: argparse.Namespace, n: int) -> BabblingConfig:
    return BabblingConfig.for_transitions(
        n,
        walkers=args.walkers,
        robot=args.robot,
        seed=args.seed,
        max_step=args.max_step,
        retarget_prob=args.retarget_prob,
    )


@register_subcommand
def _add_babble(sub) -> None:
    p = add_command(
        sub, "babble", "Motor babbling: write (s, a, s') transitions to babbling.npz.", _run_babble
    )
    _add_babbling_options(p, 500_000)


def _run_babble(args: argparse.Namespace) -> int:
    run_dir = _run_dir(args)
    cfg = _babbling_config(args, args.transitions)
    _write_config(args, babbling=cfg.to_dict())
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
        help="model + training preset: paper (REFERENCE #5-6), improved, tiny (seconds; for tests)",
    )
    p.add_argument(
        "--data", type=Path, default=None, help="babbling.npz to train on (default: babble afresh)"
    )
    _add_babbling_options(p, None)
    p.add_argument("--epochs", type=int, default=None, help="override the preset's epochs")
    p.add_argument("--lr", type=float, default=None, help="override the preset's learning rate")
    p.add_argument("--batch-size", type=int, default=None, help="override the preset's batch size")
    p.add_argument(
        "--val-fraction", type=float, default=0.1, help="held-out share of the data (default: 0.1)"
    )
    p.add_argument("--resume", action="store_true", help="continue from the run directory's checkpoint")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument(
        "--validate", type=int, default=100_000, help="fresh transitions to validate on afterwards (0: skip)"
    )
    if kind == "im":
        p.add_argument(
            "--through-fm",
            type=Path,
            default=None,
            help="after supervised training, refine the IM through this frozen fm.pt so that its actions "
            "reach their targets (see train_im_distal)",
        )
        p.add_argument("--through-fm-epochs", type=int, default=12, help="epochs of that refinement")
        p.add_argument("--action-weight", type=float, default=0.01, help="pull toward the babbled action")
    p.set_defaults(kind=kind)


register_subcommand(lambda sub: _add_train(sub, "fm"))
register_subcommand(lambda sub: _add_train(sub, "im"))


def _run_train(args: argparse.Namespace) -> int:
    run_dir = _run_dir(args)
    kind = args.kind
    model_cfg = (fm_config if kind == "fm" else im_config)(args.robot, args.preset)
    overrides: dict = {"seed": args.seed, "val_fraction": args.val_fraction, "progress": not args.no_progress}
    if args.epochs is not None:
        overrides["epochs"] = args.epochs
    if args.batch_size is not None:
        overrides["batch_size"] = args.batch_size
    cfg = train_config(kind, args.preset, **overrides)
    if args.lr is not None:
        cfg.optim.lr = args.lr
    if args.data is not None:
        data = load_transitions(args.data, robot=args.robot)
        source = {"data": str(args.data), "babbling": data.config}
    else:
        n = args.transitions or DEFAULT_TRANSITIONS[args.preset]
        bcfg = _babbling_config(args, n)
        data = babble(bcfg)
        source = {"babbling": bcfg.to_dict()}
    _write_config(args, model=model_cfg.to_dict(), train=cfg.to_dict(), **source)
    t0 = time.perf_counter()
    trainer = train_fm if kind == "fm" else train_im
    result = trainer(data, model_cfg, cfg, run_dir=run_dir, resume=args.resume)
    if kind == "im" and args.through_fm is not None:
        # Refine the IM through a frozen learned FM, in its own folder (so each stage resumes alone).
        fm = load_fm(args.through_fm, robot=args.robot)
        dcfg = train_config("im", args.preset, **{**overrides, "epochs": args.through_fm_epochs})
        distal = train_im_distal(
            data,
            result.model,
            fm,
            dcfg,
            run_dir=run_dir / "through-fm",
            resume=args.resume,
            action_weight=args.action_weight,
        )
        shutil.copyfile(distal.checkpoint, run_dir / "im.pt")
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


@register_subcommand
def _add_validate(sub) -> None:
    p = add_command(
        sub,
        "validate",
        "Validate FM/IM checkpoints against the analytic robot on fresh babbling data.",
        _run_validate,
    )
    p.add_argument("--fm", default=None, help="FM checkpoint (.pt), or 'analytic'")
    p.add_argument("--im", default=None, help="IM checkpoint (.pt), or 'analytic'")
    p.add_argument("--n", type=int, default=100_000, help="fresh transitions (default: 100000)")
    p.add_argument("--max-step", type=float, default=0.083, help="babbling step bound, rad (default: 0.083)")
    p.add_argument("--retarget-prob", type=float, default=0.0, help="babbling retarget probability")
    p.add_argument("--im-iterations", type=int, default=1, help="DLS iterations of the analytic IM")
    p.set_defaults(seed=10_000)


def _run_validate(args: argparse.Namespace) -> int:
    if args.fm is None and args.im is None:
        raise KinlearnError("give --fm and/or --im (a checkpoint path or 'analytic')")
    run_dir = _run_dir(args)
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
    _write_config(args)
    res = validate_models(
        fm, im, args.robot, n=args.n, seed=args.seed, max_step=args.max_step, retarget_prob=args.retarget_prob
    )
    for name, path in (("fm", args.fm), ("im", args.im)):
        if path not in (None, "analytic") and Path(path).with_name("config.json").is_file():
            res[f"{name}_run_config"] = read_json(Path(path).with_name("config.json"))
    write_json(run_dir / "validation.json", res)
    table = format_validation_table(res)
    (run_dir / "validation.md").write_text(table + "\n")
    print(table)
    return 0


# --------------------------------------------------------------------------------------------------


# The planning stage's subcommands register themselves on import.
from . import cli_planning  # noqa: E402, F401


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``kinlearn`` command; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.threads < 1:
        parser.error("--threads must be ≥ 1")
    torch.set_num_threads(args.threads)
    try:
        return int(args.run(args) or 0)
    except KinlearnError as exc:
        print(f"kinlearn {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
