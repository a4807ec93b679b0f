"""``kinlearn export``: a trained planner folder written as one self-contained folder without optimiser
state (``--out DIR``), or as the planner shipped inside the package (``--to-package``).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import ConfigError
from ..io import atomic_copy, half_weights, load_checkpoint, resolve_dependency, save_checkpoint
from ..planning.planner import DEFAULT_CHECKPOINTS, Planner
from ..runs import open_run
from ..training.tm import MODEL_FIELDS
from .common import (
    EXISTING_DIR,
    add_command,
    add_run_options,
    register_subcommand,
)

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
