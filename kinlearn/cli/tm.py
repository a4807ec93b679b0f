"""``kinlearn`` subcommands of the paper's waypoint TM: its endpoint pairs (``make-endpoints``) and its
training through the frozen FM and IM (``train-tm``, Algorithm 1).

Both write under the run-directory policy of :mod:`kinlearn.runs`.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from ..data.endpoints import EndpointConfig, load_endpoints, make_endpoints, save_endpoints
from ..errors import ConfigError
from ..evaluation.metrics import plan_metrics, summarize
from ..io import atomic_copy, file_sha256
from ..models.forward_inverse import load_fm, load_im
from ..models.rollout import LOSS_PRESETS
from ..planning.planner import Planner
from ..training.tm import TM_PRESETS, tm_preset, train_tm
from .common import (
    EXISTING_DIR,
    EXISTING_FILE,
    NONNEGATIVE_FLOAT,
    NONNEGATIVE_INT,
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
        "--start-spread",
        type=NONNEGATIVE_FLOAT,
        default=EndpointConfig.start_spread,
        help="start noise around home, rad",
    )
    p.add_argument(
        "--min-distance",
        type=NONNEGATIVE_FLOAT,
        default=EndpointConfig.min_distance,
        help="least start-goal distance, m",
    )
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
