"""What every ``kinlearn`` subcommand module shares: the subcommand registry, argument types, the
options every command has, and opening a run directory. Imported by :mod:`kinlearn.cli.main` and the
subcommand modules alike, so that none of them imports another's helpers (no circle).
"""

from __future__ import annotations

import argparse
import math
import platform
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from .. import __version__

if TYPE_CHECKING:  # imported where used: `kinlearn --help` answers without torch
    from ..data.babbling import Transitions
    from ..runs import Run

#: kinlearn's own arms, named in the help without loading the robot registry (which imports torch);
#: ``tests/test_lazy_imports.py`` holds it to ``kinlearn.body.robot.BUILTIN_ROBOTS``.
OWN_ROBOTS = ("iiwa14", "panda", "ur5", "xarm7", "z1")

__all__ = [
    "EXISTING_DIR",
    "EXISTING_FILE",
    "NONNEGATIVE_FLOAT",
    "NONNEGATIVE_INT",
    "OUTPUT_DIR",
    "OUTPUT_FILE",
    "POSITIVE_FLOAT",
    "POSITIVE_INT",
    "PROBABILITY",
    "SEED",
    "add_command",
    "add_data_options",
    "add_run_options",
    "data_record",
    "file_identity",
    "int_list",
    "number_text",
    "number_type",
    "open_command_run",
    "register_subcommand",
    "settle_run_dir",
]

SubcommandAdder = Callable[[argparse._SubParsersAction], None]
_SUBCOMMANDS: list[SubcommandAdder] = []


def register_subcommand(add: SubcommandAdder) -> SubcommandAdder:
    """Register a function that adds one subcommand to the parser (usable as a decorator)."""
    _SUBCOMMANDS.append(add)
    return add


def number_type(
    kind: type,
    *,
    low: float | None = None,
    high: float | None = None,
    open_low: bool = False,
    open_high: bool = False,
) -> Callable[[str], float]:
    """An argparse ``type``: a finite ``int`` or ``float`` within ``[low, high]`` (ends open when asked),
    rejected with a message that says what is allowed."""
    noun = "an integer" if kind is int else "a finite number"
    parts = []

    def num(v) -> str:  # integers in full (a seed's bound is 4294967295, not 4.29497e+09)
        return str(v) if kind is int else f"{v:g}"

    if low is not None:
        parts.append(f"{'>' if open_low else '≥'} {num(low)}")
    if high is not None:
        parts.append(f"{'<' if open_high else '≤'} {num(high)}")
    allowed = f"{noun} {' and '.join(parts)}".strip()

    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {allowed}, got {text!r}") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"expected {allowed}, got {text!r}")
        too_low = low is not None and (value < low or (open_low and value == low))
        too_high = high is not None and (value > high or (open_high and value == high))
        if too_low or too_high:
            raise argparse.ArgumentTypeError(f"expected {allowed}, got {text!r}")
        return value

    parse.__name__ = allowed
    return parse


def _path_type(check: Callable[[Path], str | None], name: str) -> Callable[[str], Path]:
    def parse(text: str) -> Path:
        path = Path(text)
        problem = check(path)
        if problem:
            raise argparse.ArgumentTypeError(problem)
        return path

    parse.__name__ = name
    return parse


def _output_problem(path: Path) -> str | None:
    from ..io import check_output

    try:
        check_output(path)
    except OSError as exc:  # OutputError
        return str(exc)
    return None


def _folder_problem(path: Path) -> str | None:
    if path.exists() and not path.is_dir():
        return f"{path} is a file, not a folder"
    return _output_problem(path / "x")  # a folder that exists or can be made, to write in


#: argparse ``type``s for paths, checked when the command line is parsed (before anything runs or is
#: written): an input file or folder that must exist, an output file that can be written, a folder
#: that is one (or can be made) and may be written in.
EXISTING_FILE = _path_type(
    lambda p: (
        None if p.is_file() else (f"{p} is a folder, not a file" if p.is_dir() else f"no such file: {p}")
    ),
    "an existing file",
)
EXISTING_DIR = _path_type(
    lambda p: (
        None if p.is_dir() else (f"{p} is a file, not a folder" if p.exists() else f"no such folder: {p}")
    ),
    "an existing folder",
)
OUTPUT_FILE = _path_type(_output_problem, "a file to write")
OUTPUT_DIR = _path_type(_folder_problem, "a folder to write in")


def _robot_name(text: str) -> str:
    if text in OWN_ROBOTS:
        return text
    from ..body.robot import available_robots

    if text in available_robots() or (text.lower().endswith(".urdf") and Path(text).is_file()):
        return text
    raise argparse.ArgumentTypeError(
        f"unknown robot {text!r}; valid names are {', '.join(available_robots())}, or a path to a .urdf file"
    )


#: A robot's name (or a URDF file), checked when the command line is read: a refused command writes nothing.
ROBOT = _robot_name
#: Seeds: integers a NumPy and a torch generator both take.
SEED = number_type(int, low=0, high=2**32 - 1)

POSITIVE_INT = number_type(int, low=1)
NONNEGATIVE_INT = number_type(int, low=0)
POSITIVE_FLOAT = number_type(float, low=0, open_low=True)
NONNEGATIVE_FLOAT = number_type(float, low=0)
PROBABILITY = number_type(float, low=0, high=1)


def number_text(x: float) -> str:
    """A default as a command's help writes it: ``0.083``, ``1000``, ``0``, small ones as ``2e-3``."""
    if x != 0 and abs(x) < 0.01:
        mantissa, exponent = f"{x:e}".split("e")
        return f"{float(mantissa):g}e{int(exponent)}"
    return f"{x:g}"


def int_list(low: int) -> Callable[[str], tuple[int, ...]]:
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


def add_command(
    sub: argparse._SubParsersAction,
    name: str,
    help: str,
    run: Callable[[argparse.Namespace], int | None],
    *,
    seed: bool = True,
    run_dir: bool = True,
    seed_default: int = 0,
) -> argparse.ArgumentParser:
    """Add subcommand ``name`` with the options every subcommand has: robot, threads, and unless
    turned off (a command that draws nothing at random or writes no run directory), seed and run dir."""
    p = sub.add_parser(name, help=help, description=help)
    p.add_argument(
        "--robot",
        type=ROBOT,
        default="iiwa14",
        help=f"robot name ({', '.join(OWN_ROBOTS)}, or one registered) or a .urdf file",
    )
    if seed:
        p.add_argument(
            "--seed",
            type=SEED,
            default=seed_default,
            help=f"seed of everything random (default: {seed_default})",
        )
    if run_dir:
        p.add_argument(
            "--run-dir", type=Path, default=None, help="output folder (default: runs/<time>-<command>)"
        )
    p.add_argument(
        "--threads",
        type=POSITIVE_INT,
        default=1,
        help="torch CPU threads (default: 1, fastest for these small models)",
    )
    p.set_defaults(run=run, command=name)
    return p


def add_run_options(p: argparse.ArgumentParser, resumable: bool) -> None:
    """``--overwrite`` (and ``--resume`` for a command that can continue a run): see :mod:`kinlearn.runs`."""
    if resumable:
        p.add_argument(
            "--resume",
            action="store_true",
            help="continue the run in --run-dir from its last checkpoint; its configuration must be identical",
        )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the run already in the output folder (its outputs are deleted first)",
    )


def add_data_options(p: argparse.ArgumentParser, purpose: str) -> None:
    """``--data`` (a babbling ``.npz`` or a recorded log, see :func:`kinlearn.data.recorded.load_data`)
    and ``--drop-nan``."""
    p.add_argument(
        "--data",
        type=EXISTING_FILE,
        default=None,
        help=f"babbling.npz, or a recorded log (.npz/.csv: joints in rad, ef_x/ef_y/ef_z in m), {purpose}",
    )
    p.add_argument(
        "--drop-nan",
        action="store_true",
        help="drop the rows of a recorded log that hold NaN/inf (default: refuse the file)",
    )


def data_record(data: Transitions) -> dict:
    """What a run records of its loaded ``--data`` beside the file's identity: a babbling file's config
    (``babbling``) or a recorded log's counts (``recorded``)."""
    recorded = data.config.get("source") == "recorded"
    return {"recorded" if recorded else "babbling": data.config}


def settle_run_dir(args: argparse.Namespace) -> Path:
    """``args.run_dir``, set to a new ``runs/<time>-<command>`` when not given."""
    if args.run_dir is None:
        args.run_dir = Path("runs") / f"{time.strftime('%Y%m%d-%H%M%S')}-{args.command}"
    return args.run_dir


def open_command_run(
    args: argparse.Namespace,
    outputs: Sequence[str],
    *,
    resumable: bool = False,
    ignore: Sequence[str] = (),
    **configs,
) -> Run:
    """Check ``args.run_dir`` (default: a new ``runs/<time>-<command>``) for this command under the
    run-directory policy (:func:`kinlearn.runs.open_run`) with ``configs`` as its configuration;
    writes nothing: call ``.begin()`` on the result once every other check has passed."""
    settle_run_dir(args)
    argv = {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items() if k != "run"}
    import torch

    from ..runs import IGNORED_KEYS, open_run

    versions = {"kinlearn": __version__, "torch": torch.__version__, "python": platform.python_version()}
    return open_run(
        args.run_dir,
        command=args.command,
        config=configs,
        outputs=outputs,
        resume=bool(getattr(args, "resume", False)),
        overwrite=bool(getattr(args, "overwrite", False)),
        resumable=resumable,
        meta={"args": argv, "versions": versions},
        ignore=(*IGNORED_KEYS, *ignore),
    )


def file_identity(path: Path) -> dict:
    """An input file as a run records it: its path and its content hash (compared on --resume)."""
    from ..io import file_sha256

    return {"path": str(path), "sha256": file_sha256(path)}
