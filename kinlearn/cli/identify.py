"""``kinlearn identify`` and ``kinlearn export-urdf``: calibration — a robot's serial chain identified from
its observed end-effector positions (see :mod:`kinlearn.training.identify`), and the chain written as
a URDF that other tools load.

:func:`register` adds both subcommands to the ``kinlearn`` parser's subcommands.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

from ..body.kinematics import kinematics
from ..body.robot import Robot, load_robot
from ..errors import CheckpointError, ConfigError, KinlearnError, RobotDescriptionError, RunDirectoryError
from ..io import atomic_write, check_output, write_json
from ..runs import acquire_lock
from ..training.identify import Identification, IdentifyConfig, identify
from .common import (
    POSITIVE_INT,
    add_command,
    add_run_options,
    file_identity,
    number_type,
    open_command_run,
)

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``identify`` and ``export-urdf`` to ``sub`` (the ``kinlearn`` parser's subcommands)."""
    p = add_command(
        sub,
        "identify",
        "Identify a robot's kinematic chain from observed end-effector positions (calibration); writes "
        "chain.pt (a chain FM) and report.json (held-out residual).",
        _run_identify,
    )
    p.set_defaults(robot=None)
    p.add_argument(
        "--data",
        type=Path,
        required=True,
        help="babbling.npz or a recorded log (.npz/.csv: joints in rad, ef_x/ef_y/ef_z in m, base frame)",
    )
    p.add_argument(
        "--no-prior",
        action="store_true",
        help="with --robot: use only its joint count, names and limits, not its URDF's geometry",
    )
    p.add_argument("--urdf", type=Path, default=None, help="a prior URDF (perhaps wrong) to start from")
    p.add_argument("--ee-frame", default=None, help="the end-effector link of --urdf")
    p.add_argument(
        "--dof", type=POSITIVE_INT, default=None, help="no robot and no URDF: only the joint count"
    )
    p.add_argument(
        "--holdout",
        type=number_type(float, low=0, high=0.5, open_high=True),
        default=IdentifyConfig.holdout,
        help=f"share of the samples held out to report the residual (default: {IdentifyConfig.holdout})",
    )
    p.add_argument(
        "--residual",
        type=POSITIVE_INT,
        nargs="+",
        default=None,
        metavar="WIDTH",
        help="add a residual MLP of these hidden widths for what a rigid chain cannot explain",
    )
    p.add_argument(
        "--drop-nan", action="store_true", help="drop a recorded log's NaN/inf rows (default: refuse)"
    )
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    add_run_options(p, resumable=False)

    e = add_command(
        sub,
        "export-urdf",
        "Write an identified chain (a run of `kinlearn identify`, or its chain.pt) as a URDF whose forward "
        "kinematics equal the chain's: written to a temporary file, checked through Pinocchio, then renamed "
        "onto --out (never replaced without --overwrite).",
        _run_export_urdf,
        seed=False,
        run_dir=False,
    )
    e.add_argument("source", type=Path, help="an identify run directory or a chain.pt")
    e.add_argument("--out", type=Path, required=True, help="the URDF file to write")
    e.add_argument("--name", default=None, help="the robot name in the URDF (default: the chain's)")
    e.add_argument("--overwrite", action="store_true", help="replace --out if it exists")


def _run_identify(args: argparse.Namespace) -> int:
    # Every check before anything is written.
    chosen = sum(x is not None for x in (args.robot, args.urdf, args.dof))
    if chosen != 1:
        raise ConfigError("give exactly one of --robot NAME, --urdf PRIOR --ee-frame F, or --dof N")
    if (args.urdf is None) != (args.ee_frame is None):
        raise ConfigError("--urdf and --ee-frame go together (the prior URDF and its end-effector link)")
    if args.no_prior and args.robot is None:
        raise ConfigError("--no-prior applies to --robot (with --dof there is no prior anyway)")
    if not args.data.is_file():
        raise ConfigError(f"no data file at {args.data}")
    if args.robot is not None:
        robot, prior = load_robot(args.robot), not args.no_prior
    elif args.urdf is not None:
        if not args.urdf.is_file():
            raise ConfigError(f"no URDF file at {args.urdf}")
        robot = load_robot(args.urdf, args.ee_frame)
        prior = True
    else:
        robot, prior = None, False
    cfg = IdentifyConfig(holdout=args.holdout, seed=args.seed, residual=tuple(args.residual or ()))
    configs = {
        "identify": cfg.to_dict(),
        "data": file_identity(args.data),
        "robot": None if robot is None else robot.name,
        "prior": None if not prior else (file_identity(args.urdf) if args.urdf else robot.name),
        "dof": args.dof,
    }
    run = open_command_run(args, ["chain.pt", "report.json"], **configs)
    result = identify(
        args.data,
        robot=robot,
        prior=prior,
        dof=args.dof,
        config=cfg,
        progress=not args.quiet,
        drop_nan=args.drop_nan,
    )
    run_dir = run.begin()
    path = result.save(run_dir / "chain.pt", cfg)
    write_json(run_dir / "report.json", result.report)
    r, h = result.report, result.report["holdout_residual"]
    undetermined = r["undetermined_axis_directions"]
    print(
        f"identified a {result.model.dof}-joint chain from {r['samples']:,} samples in {r['seconds']:.1f} s "
        f"({r['initialisation']})\n"
        f"held-out residual: median {h['median'] * 1e3:.3f} mm, p99 {h['p99'] * 1e3:.3f} mm "
        f"(it includes the observations' noise, robust σ ≈ {r['noise_sigma'] * 1e3:.3f} mm per axis); "
        f"{r['outliers_dropped']} outliers dropped"
    )
    ex = r["excitation"]
    least = min(range(len(ex["joint_range"])), key=ex["joint_range"].__getitem__)
    condition = "—" if ex["condition"] is None else f"{ex['condition']:.3g}"
    print(
        f"excitation: joints moved {min(ex['joint_range']):.2f}–{max(ex['joint_range']):.2f} rad (least: joint "
        f"{least + 1}); parameter Jacobian rank {ex['parameter_rank']} of {ex['expected_rank']}, condition "
        f"{condition}"
    )
    if undetermined:
        print(
            "axis direction not determined by position data (the end-effector point lies on it): joint(s) "
            + ", ".join(str(i + 1) for i in undetermined)
        )
    print(f"→ {path}")
    return 0


def _chain_path(source: Path) -> Path:
    path = source / "chain.pt" if source.is_dir() else source
    if not path.is_file():
        raise CheckpointError(f"no chain checkpoint at {path} (run `kinlearn identify --run-dir {source}`)")
    return path


def _run_export_urdf(args: argparse.Namespace) -> int:
    if args.out.suffix.lower() != ".urdf":
        raise ConfigError(f"--out must name a .urdf file, got {args.out}")
    source = _chain_path(args.source)
    out = check_output(args.out)
    # held to the end: a second export to the same file is refused naming this one
    acquire_lock(out.parent, "export-urdf", lock=out.parent / f".{out.name}.kinlearn.lock")
    if out.exists() and not args.overwrite:
        raise RunDirectoryError(f"{out} exists; pass --overwrite to replace it, or choose another --out")
    result = Identification.load(source)
    model = result.model
    text = result.urdf(args.name)
    if model.residual is not None:
        print("note: the chain's residual MLP is not part of a URDF; the file holds the rigid chain")
    checked: list[float] = []

    def write_checked(tmp: Path) -> None:
        """Write the URDF to ``tmp`` and check it through Pinocchio: its forward kinematics against the
        chain's. Only a file that passes is renamed onto --out."""
        tmp.write_text(text)
        try:
            robot = Robot(model.robot_name, tmp.read_bytes(), result.ee_frame, tmp)
        except KinlearnError as exc:
            raise RobotDescriptionError(
                f"the URDF made from {source} does not load, so nothing was written: {exc}"
            ) from exc
        gen = np.random.default_rng(0)
        q = torch.from_numpy(gen.uniform(robot.lower, robot.upper, size=(1000, robot.dof)))
        with torch.no_grad():
            diff = float(
                (kinematics(robot, "pinocchio").position(q) - model.rigid_position(q)).norm(dim=-1).max()
            )
        if not diff <= 1e-6:
            raise RobotDescriptionError(
                f"the URDF made from {source} does not reproduce the chain (Pinocchio FK off by up to {diff:.3g} m), "
                "so nothing was written"
            )
        checked.append(diff)

    atomic_write(out, write_checked)
    print(
        f"wrote {out}: {model.dof} revolute joints from {result.base_link!r} to the end-effector link "
        f"{result.ee_frame!r}; Pinocchio FK against the chain: max {checked[0]:.2e} m over 1,000 configurations"
    )
    return 0
