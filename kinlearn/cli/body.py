"""``kinlearn train-body``: learn where the arm's collision spheres are from babbling (see
:mod:`kinlearn.models.body`), validate the result against the analytic body, optionally inflate its
radii by a margin.

:func:`register` adds the subcommand to the ``kinlearn`` parser's subcommands.
"""

from __future__ import annotations

import argparse
import time

from ..data.recorded import load_data
from ..errors import ConfigError
from ..io import load_checkpoint, write_json
from ..models.body import BodyModelConfig, save_body_model
from ..models.layers import ACTIVATIONS
from ..training.body import HELDOUT_PROBLEMS, train_body_model, validate_body_model
from .common import (
    EXISTING_FILE,
    NONNEGATIVE_INT,
    POSITIVE_FLOAT,
    POSITIVE_INT,
    add_command,
    add_data_options,
    add_run_options,
    file_identity,
    open_command_run,
)

__all__ = ["register"]


def _widths(text: str) -> tuple[int, ...]:
    try:
        widths = tuple(int(w) for w in text.split(","))
    except ValueError:
        widths = ()
    if not widths or any(w < 1 for w in widths):
        raise argparse.ArgumentTypeError(
            f"expected comma-separated layer widths ≥ 1 (e.g. 160,160,160), got {text!r}"
        )
    return widths


def _margin(text: str) -> str | float:
    if text == "p99":
        return text
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not (value >= 0.0 and value != float("inf")):
        raise argparse.ArgumentTypeError(f"expected 'p99' or a number of metres ≥ 0, got {text!r}")
    return value


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``train-body`` subcommand to ``sub`` (the ``kinlearn`` parser's subcommands)."""
    p = add_command(
        sub,
        "train-body",
        "Learn the arm's collision body (joints -> sphere centres) from babbling; writes body.pt, "
        "metrics.jsonl and validation.json.",
        _run_train_body,
    )
    d = BodyModelConfig()
    add_data_options(p, "whose configurations to learn at (default: --samples uniform configurations)")
    p.add_argument("--dense", action="store_true", help="learn the 46-sphere body (default: 12 + base cover)")
    p.add_argument(
        "--hidden",
        type=_widths,
        default=d.hidden,
        help=f"hidden layer widths (default: {','.join(map(str, d.hidden))})",
    )
    p.add_argument(
        "--activation", choices=sorted(ACTIVATIONS), default=d.activation, help=f"default: {d.activation}"
    )
    p.add_argument("--epochs", type=POSITIVE_INT, default=d.epochs, help=f"default: {d.epochs}")
    p.add_argument("--batch-size", type=POSITIVE_INT, default=d.batch_size, help=f"default: {d.batch_size}")
    p.add_argument("--lr", type=POSITIVE_FLOAT, default=d.lr, help=f"initial learning rate (default: {d.lr})")
    p.add_argument(
        "--samples",
        type=POSITIVE_INT,
        default=d.samples,
        help=f"uniform configurations to learn at without --data (default: {d.samples})",
    )
    p.add_argument(
        "--validate",
        type=NONNEGATIVE_INT,
        default=100_000,
        help="fresh uniform configurations for the centre errors afterwards (0: skip validation)",
    )
    p.add_argument(
        "--problems",
        type=EXISTING_FILE,
        default=HELDOUT_PROBLEMS,
        help="obstacle problems for the collision-verdict check (default: the committed benchmark)",
    )
    p.add_argument(
        "--margin",
        type=_margin,
        default=0.0,
        help="inflate the learned radii by this many metres, or by the validation's p99 centre error ('p99')",
    )
    add_run_options(p, resumable=True)
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def _run_train_body(args: argparse.Namespace) -> int:
    # Every check first: nothing is written before they pass.
    cfg = BodyModelConfig(
        robot=args.robot,
        dense=args.dense,
        hidden=args.hidden,
        activation=args.activation,
        epochs=args.epochs,
        batch_size=args.batch_size,
        lr=args.lr,
        samples=args.samples,
        seed=args.seed,
    )
    if args.margin == "p99" and args.validate == 0:
        raise ConfigError("--margin p99 takes the margin from the validation; give --validate > 0")
    configs: dict = {"body": cfg.to_dict()}
    data = None
    if args.data is not None:
        data = load_data(args.data, robot=args.robot, drop_nan=args.drop_nan)
        configs["data"] = file_identity(args.data)
    problems = None
    if args.validate > 0:
        # Read now, not after the training: a bad file is refused before anything is written.
        from ..data.problems import ProblemSet

        problems = ProblemSet.load(args.problems, robot=args.robot)
        configs["validation"] = {
            "n": args.validate,
            "seed": args.seed + 20_000,
            "problems": file_identity(args.problems),
            "margin": args.margin,
        }
    else:
        configs["margin"] = args.margin
    run = open_command_run(
        args, ("body.pt", "metrics.jsonl", "validation.json", "tensorboard"), resumable=True, **configs
    )
    run_dir = run.begin()

    t0 = time.perf_counter()
    result = train_body_model(cfg, run_dir, data, progress=not args.no_progress, resume=run.resumed)
    dt = time.perf_counter() - t0
    model = result.model.set_margin(0.0)
    last = result.history[-1] if result.history else {}
    print(f"trained the body model in {dt:.1f} s; last epoch: {last}")
    margin = args.margin
    if args.validate > 0:
        seed = args.seed + 20_000
        res = validate_body_model(model, n=args.validate, seed=seed, problems=problems)
        res["train_wall_s"] = dt
        print(_summary(res))
        if margin == "p99":
            margin = res["centre_err_mm_p99"] / 1e3
        if margin > 0:
            model.set_margin(margin)
            res["with_margin"] = validate_body_model(model, n=args.validate, seed=seed, problems=problems)
            print(_summary(res["with_margin"]))
        write_json(run_dir / "validation.json", res)
    if margin > 0:  # the checkpoint keeps its training state beside the margin
        extra = load_checkpoint(result.checkpoint, kind="body", robot=args.robot)["extra"]
        save_body_model(model, result.checkpoint, extra=extra)
    print(f"checkpoint: {result.checkpoint} (radius margin {margin * 1e3:.2f} mm)")
    return 0


def _summary(res: dict) -> str:
    def pct(key: str) -> str:
        value = res.get(key)
        return "–" if value is None else f"{100 * value:.2f}%"

    lines = [
        f"margin {res['margin_mm']:.2f} mm: centre error mean {res['centre_err_mm_mean']:.2f} mm, "
        f"p99 {res['centre_err_mm_p99']:.2f} mm, max {res['centre_err_mm_max']:.2f} mm"
    ]
    for what in ("configs", "lines"):
        if f"{what}_n" in res:
            lines.append(
                f"  {what}: {res[f'{what}_n']} checked, analytic collision rate {pct(f'{what}_collision_rate')}, "
                f"false free {pct(f'{what}_false_free_rate')}, false collision {pct(f'{what}_false_collision_rate')}"
            )
    return "\n".join(lines)
