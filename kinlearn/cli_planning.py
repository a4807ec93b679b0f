"""``kinlearn`` subcommands of the planning stage: endpoints, TM training, planning, reproduction."""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

import torch

from .cli import _run_dir, _write_config, add_command, register_subcommand
from .endpoints import EndpointConfig, load_endpoints, make_endpoints, save_endpoints
from .errors import ConfigError
from .io import load_checkpoint, save_checkpoint
from .metrics import plan_metrics, summarize
from .planner import DEFAULT_CHECKPOINTS, Planner
from .rectify import LOSS_PRESETS
from .train import OptimConfig
from .train_tm import TM_PRESETS, tm_preset, train_tm

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
    p.add_argument("--n", type=int, default=12_000, help="training pairs (default: 12000)")
    p.add_argument("--heldout", type=int, default=2_000, help="held-out pairs (default: 2000)")
    p.add_argument("--start-spread", type=float, default=0.15, help="start noise around home, rad")
    p.add_argument("--min-distance", type=float, default=0.2, help="least start-goal distance, m")


def _run_make_endpoints(args: argparse.Namespace) -> int:
    run_dir = _run_dir(args)
    cfg = EndpointConfig(
        robot=args.robot,
        n=args.n + args.heldout,
        seed=args.seed,
        start_spread=args.start_spread,
        min_distance=args.min_distance,
    )
    train, heldout = make_endpoints(cfg).split(args.n)
    save_endpoints(train, run_dir / "endpoints_train.npz")
    save_endpoints(heldout, run_dir / "endpoints_heldout.npz")
    _write_config(args, endpoints=cfg.__dict__)
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
    p.add_argument("--endpoints", type=Path, required=True, help="a make-endpoints run directory")
    p.add_argument("--fm-checkpoint", type=Path, default=None, help="a learned fm.pt (from train-fm)")
    p.add_argument("--im-checkpoint", type=Path, default=None, help="a learned im.pt (from train-im)")
    p.add_argument("--models-dir", type=Path, default=None, help="or: one folder holding fm.pt and im.pt")
    p.add_argument("--fm", choices=("learned", "analytic"), default="learned")
    p.add_argument("--im", choices=("learned", "analytic"), default="learned")
    p.add_argument("--epochs", type=int, default=None)
    p.add_argument("--batch-size", type=int, default=None)
    p.add_argument("--optimizer", choices=("adam", "adamw", "rmsprop", "sgd"), default=None)
    p.add_argument("--lr", type=float, default=None)
    p.add_argument("--alpha", type=float, default=None, help="RMSprop smoothing constant γ")
    p.add_argument("--loss", choices=sorted(LOSS_PRESETS), default=None, help="loss preset")
    p.add_argument("--gradient", choices=("stop", "through"), default=None, help="through the FM/IM or not")
    p.add_argument("--no-progress", action="store_true")


def _run_train_tm(args: argparse.Namespace) -> int:
    run_dir = _run_dir(args)
    over: dict = {"robot": args.robot, "fm": args.fm, "im": args.im, "seed": args.seed}
    if args.models_dir is not None:
        over["models_dir"] = str(args.models_dir.resolve())
    for kind, path in (("fm", args.fm_checkpoint), ("im", args.im_checkpoint)):
        if path is not None:  # the run directory becomes the models' folder
            if not path.is_file():
                raise ConfigError(f"--{kind}-checkpoint: no file at {path}")
            shutil.copyfile(path, run_dir / f"{kind}.pt")
            over["models_dir"] = str(run_dir.resolve())
    for key in ("epochs", "batch_size", "loss"):
        if getattr(args, key) is not None:
            over[key] = getattr(args, key)
    cfg = tm_preset(args.preset, **over)
    if args.optimizer or args.lr or args.alpha:
        o = cfg.optim
        cfg.optim = OptimConfig(
            name=args.optimizer or o.name, lr=args.lr or o.lr, alpha=args.alpha or o.alpha
        )
    if args.gradient:
        cfg.loss.gradient = args.gradient
    train = load_endpoints(args.endpoints / "endpoints_train.npz", robot=args.robot)
    heldout_path = args.endpoints / "endpoints_heldout.npz"
    heldout = load_endpoints(heldout_path, robot=args.robot) if heldout_path.is_file() else None
    for kind in ("fm", "im"):  # keep the run self-contained: copy the learned models beside tm.pt
        if getattr(cfg, kind) == "learned" and cfg.models_dir:
            src = Path(cfg.models_dir) / f"{kind}.pt"
            if src.is_file() and src.resolve() != (run_dir / f"{kind}.pt").resolve():
                shutil.copyfile(src, run_dir / f"{kind}.pt")
    train_tm(cfg, run_dir, train, heldout, progress=not args.no_progress)
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
    return [float(v) for v in text.replace(",", " ").split()]


@register_subcommand
def _add_plan(sub) -> None:
    p = add_command(sub, "plan", "Plan one trajectory and print it.", _run_plan)
    p.add_argument(
        "--start", type=_floats, required=True, help="start joints (or full state), comma-separated"
    )
    p.add_argument("--goal", type=_floats, required=True, help="goal joints (or full state), comma-separated")
    p.add_argument("--model", type=Path, default=None, help="a train-tm run directory (default: shipped)")


def _run_plan(args: argparse.Namespace) -> int:
    planner = Planner.load(args.model, robot=args.robot) if args.model else Planner.default(args.robot)
    plan = planner.plan(
        torch.tensor(args.start, dtype=torch.float64), torch.tensor(args.goal, dtype=torch.float64)
    )
    torch.set_printoptions(precision=4, sci_mode=False)
    print("waypoints (end effector, m):")
    print(plan.waypoints)
    print("joint path (rad):")
    print(plan.joints)
    err = float((plan.ef[-1] - plan.goal[planner.layout.ef]).norm())
    print(f"executed end effector at the end: {plan.ef[-1].tolist()}; goal error {err * 1e3:.2f} mm")
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
    p.add_argument("--workers", type=int, default=None, help="worker processes of the TM sweep")
    p.add_argument("--backend", choices=("local", "ray"), default="local", help="where the sweep runs")
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(preset="quick")


def _run_reproduce(args: argparse.Namespace) -> int:
    from .reproduce import default_workers, preset_config, reproduce

    run_dir = _run_dir(args)
    cfg = preset_config(
        args.preset,
        robot=args.robot,
        seed=args.seed,
        workers=args.workers or default_workers(),
        backend=args.backend,
    )
    reproduce(cfg, run_dir, progress=not args.no_progress)
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
        "Copy a train-tm run's tm.pt, fm.pt and im.pt into a folder, without optimiser state "
        f"(default folder: the package's shipped planner, {DEFAULT_CHECKPOINTS.name}/<robot>).",
        _run_export,
    )
    p.add_argument("--model", type=Path, required=True, help="a train-tm run directory")
    p.add_argument("--out", type=Path, default=None)


def _run_export(args: argparse.Namespace) -> int:
    out = args.out or DEFAULT_CHECKPOINTS / args.robot
    planner = Planner.load(args.model, robot=args.robot)  # checks the run is complete and consistent
    for kind in ("tm", "fm", "im"):
        src = args.model / f"{kind}.pt"
        if not src.is_file():
            if kind == "tm":
                raise ConfigError(f"{args.model} has no tm.pt")
            continue
        payload = load_checkpoint(src, kind=kind, robot=planner.robot.name)
        save_checkpoint(
            out / f"{kind}.pt",
            kind=kind,
            robot=payload["robot"],
            config=payload["config"],
            state_dict=payload["state_dict"],
        )
    print(f"exported the planner of {args.model} to {out}")
    return 0
