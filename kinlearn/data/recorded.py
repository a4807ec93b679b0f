"""Recorded data: a robot's own log of joint values and observed end-effector positions.

A log is a sequence of observations, one per row: the joint values θ (rad, as the encoders read them)
and the end-effector position ef (m, in the robot's base frame, as a camera or motion capture sees
it). Consecutive rows of one *episode* are transitions (s, a = θ' − θ, s'), so the FM/IM trainers
learn from a log as they do from babbling (:meth:`Observations.transitions`). Two file formats:

``.npz``
    ``theta (N, dof)`` radians; ``ef (N, 3)`` metres; optional ``episode (N,)`` integer labels
    (each episode's rows consecutive); optional ``time (N,)`` seconds, increasing within an episode;
    optional ``joint_names (dof,)`` strings. No other keys.
``.csv``
    A header row naming the columns, then one row per observation, comma-separated: one column per
    joint (named as the robot's joints when a robot is given, in any order), ``ef_x, ef_y, ef_z``,
    optional ``episode`` and ``time``. Empty cells and ``nan`` are NaN.

Without an ``episode`` the whole file is one episode. :func:`load_recorded` checks a file before
anything learns from it and raises :class:`~kinlearn.errors.RecordedDataError` saying what to fix:
a missing, empty or unreadable file, an unknown suffix, missing or unknown columns or keys, the wrong
number of joints, cells that are no numbers (row and column named), NaN/inf rows (refused with their
count and first rows, or dropped with ``drop_nan=True``), values that look like millimetres or degrees,
joints outside the robot's limits, episodes whose rows are not consecutive, time that does not
increase within an episode. :func:`load_data` loads either a kinlearn babbling ``.npz`` or a recorded
log as :class:`~kinlearn.data.babbling.Transitions`: the one loader of every learning command's
``--data``.
"""

from __future__ import annotations

import csv
import math
import warnings
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from ..body.robot import Robot, load_robot
from ..body.state import StateLayout
from ..checks import as_int
from ..errors import ConfigError, DroppedRowsWarning, RecordedDataError, ShapeError
from ..io import atomic_write, file_sha256
from .babbling import Transitions, load_transitions

__all__ = [
    "ANGLE_BOUND",
    "EF_BOUND",
    "REACH_FACTOR",
    "Observations",
    "check_observation_units",
    "load_data",
    "load_observations",
    "load_recorded",
    "save_recorded",
]

#: The end-effector columns of a CSV log, in order.
EF_COLUMNS = ("ef_x", "ef_y", "ef_z")
#: Every column of a CSV log that is not a joint.
RESERVED_COLUMNS = (*EF_COLUMNS, "episode", "time")
#: The keys of an ``.npz`` log.
NPZ_KEYS = ("theta", "ef", "episode", "time", "joint_names")
#: Without a robot: an end effector farther than this from the base (m) is taken for millimetres.
EF_BOUND = 10.0
#: With a robot: an end effector farther than this many of its reaches from the base is taken for millimetres.
REACH_FACTOR = 3.0
#: Without a robot: a joint value beyond this magnitude (rad; a turn and a margin) is taken for degrees.
ANGLE_BOUND = 2 * math.pi + 0.1
#: Joint values may leave the robot's limits by this much (rad) before they are refused.
LIMIT_TOL = 1e-6
#: Rows named in an error message.
SHOWN_ROWS = 5


@dataclass
class Observations:
    """Observations of one robot, one per row: ``theta (N, dof)`` rad and ``ef (N, 3)`` m (float64),
    ``episode (N,)`` int64 labels 0, 1, … in order (each episode's rows consecutive), ``time (N,)`` s
    or ``None``; ``joint_names`` (the columns' names, in the robot's order when loaded for one),
    ``path`` and ``sha256`` of the file they came from, and ``dropped``, the NaN/inf rows left out.

    Arrays and tensors are taken as float64 tensors (episode: int64; all zeros when ``None``).
    """

    theta: torch.Tensor
    ef: torch.Tensor
    episode: torch.Tensor | None = None
    time: torch.Tensor | None = None
    joint_names: tuple[str, ...] | None = None
    path: Path | None = None
    sha256: str | None = None
    dropped: int = 0

    def __post_init__(self) -> None:
        self.theta = torch.as_tensor(self.theta, dtype=torch.float64)
        self.ef = torch.as_tensor(self.ef, dtype=torch.float64)
        n = self.theta.shape[0] if self.theta.ndim else 0
        if self.theta.ndim != 2 or self.theta.shape[1] < 1 or tuple(self.ef.shape) != (n, 3):
            raise ShapeError(
                f"observations need theta (N, dof) and ef (N, 3) with one N, got {tuple(self.theta.shape)} "
                f"and {tuple(self.ef.shape)}"
            )
        self.episode = (
            torch.zeros(n, dtype=torch.int64)
            if self.episode is None
            else torch.as_tensor(self.episode, dtype=torch.int64)
        )
        if self.time is not None:
            self.time = torch.as_tensor(self.time, dtype=torch.float64)
        for what, t in (("episode", self.episode), ("time", self.time)):
            if t is not None and tuple(t.shape) != (n,):
                raise ShapeError(f"observations' {what} must have shape ({n},), got {tuple(t.shape)}")
        if self.joint_names is not None:
            self.joint_names = tuple(str(name) for name in self.joint_names)
            if len(self.joint_names) != self.dof:
                raise ShapeError(f"{len(self.joint_names)} joint names for {self.dof} joints")
        if self.path is not None:
            self.path = Path(self.path)

    def __len__(self) -> int:
        return self.theta.shape[0]

    @property
    def dof(self) -> int:
        return self.theta.shape[1]

    @property
    def episodes(self) -> int:
        """How many episodes (runs of one label)."""
        return 0 if not len(self) else 1 + int((self.episode[1:] != self.episode[:-1]).sum())

    def transitions(self, robot: str | Robot) -> Transitions:
        """The transitions of consecutive rows within each episode: s = [θ, ef], a = θ' − θ, s' (float64),
        labelled with ``robot`` (its name), ready for :func:`~kinlearn.train.train_fm` / :func:`~kinlearn.train.train_im`.

        Raises :class:`~kinlearn.errors.RecordedDataError` when no episode has two rows.
        """
        name = robot.name if isinstance(robot, Robot) else str(robot)
        same = self.episode[1:] == self.episode[:-1]
        if not bool(same.any()):
            raise RecordedDataError(
                f"{self._what()} holds no transition: each of its {self.episodes} episode(s) has one row; "
                "label consecutive rows of one motion with the same episode"
            )
        idx = torch.nonzero(same).squeeze(1)
        layout = StateLayout(self.dof)
        s = layout.join(self.theta, self.ef)
        a = self.theta[idx + 1] - self.theta[idx]
        return Transitions(s[idx], a, s[idx + 1], name, self.record(transitions=len(idx)))

    def record(self, **more) -> dict:
        """What a run records of these observations: their source file, its hash and their counts."""
        return {
            "source": "recorded",
            "path": None if self.path is None else str(self.path),
            "sha256": self.sha256,
            "rows": len(self),
            "episodes": self.episodes,
            "dropped": self.dropped,
            "joint_names": None if self.joint_names is None else list(self.joint_names),
            **more,
        }

    @classmethod
    def from_transitions(cls, data: Transitions, joint_names: Sequence[str] | None = None) -> Observations:
        """The states of transitions as observations: each chain of transitions (s' of one is s of the
        next) is an episode of its states, the last s' included, so :meth:`transitions` gives the same
        transitions back. Babbling is ordered (step, walker): its walkers' chains are found from its
        config's ``walkers``. ``joint_names``: the names to give the joints (e.g. the robot's)."""
        n = len(data)
        if n == 0:
            raise RecordedDataError("no transitions to take observations from")
        s, s_next = data.s.detach().cpu(), data.s_next.detach().cpu()
        walkers, steps = int(data.config.get("walkers", 0) or 0), int(data.config.get("steps", 0) or 0)
        if walkers > 1 and walkers * steps == n:  # (step, walker) → (walker, step)
            order = torch.arange(n).reshape(steps, walkers).T.reshape(-1)
            s, s_next = s[order], s_next[order]
        breaks = torch.ones(n, dtype=torch.bool)  # a chain ends after row i
        breaks[:-1] = (s_next[:-1] != s[1:]).any(dim=1)
        ends = torch.nonzero(breaks).squeeze(1)
        starts = torch.cat((torch.zeros(1, dtype=torch.int64), ends[:-1] + 1))
        # Row i of the states is s[i]; after each chain's last transition comes its final s'.
        chain = torch.repeat_interleave(torch.arange(len(ends)), ends - starts + 1)
        rows = torch.cat((s, s_next[ends]))
        episode = torch.cat((chain, torch.arange(len(ends))))
        position = torch.cat((torch.arange(n), ends + 0.5))  # the final s' right after its chain
        order = torch.argsort(position, stable=True)
        theta, ef = data.layout.split(rows[order])
        return cls(theta, ef, episode[order], joint_names=joint_names)

    def _what(self) -> str:
        return str(self.path) if self.path is not None else "the observations"


# --------------------------------------------------------------------------------------------------
# Loading
# --------------------------------------------------------------------------------------------------


class _Rows:
    """How a file's data rows are named in messages: CSV lines (the header is line 1), ``.npz`` rows."""

    def __init__(self, path: Path, lines: np.ndarray | None, n: int):
        self.path = path
        self.lines = lines  # CSV: the file line of each data row
        self.index = np.arange(n)  # the file row of each row still held (rows may be dropped)

    def keep(self, mask: np.ndarray) -> None:
        self.index = self.index[mask]

    def name(self, rows: np.ndarray) -> str:
        rows = self.index[np.asarray(rows)]
        shown = rows[:SHOWN_ROWS]
        if self.lines is not None:
            text = ", ".join(str(int(self.lines[r])) for r in shown)
            head = "line" if len(rows) == 1 else "lines"
        else:
            text = ", ".join(str(int(r)) for r in shown)
            head = "row" if len(rows) == 1 else "rows (from 0)"
        return f"{head} {text}{', …' if len(rows) > SHOWN_ROWS else ''}"


def _error(path: Path, message: str) -> RecordedDataError:
    return RecordedDataError(f"{path}: {message}")


#: Data rows of a CSV log parsed at a time: a log is read in chunks of this many, never whole.
CSV_CHUNK_ROWS = 65_536


def _parse_rows(path: Path, header: list[str], body: list[str], lines: list[int]) -> np.ndarray:
    """The cells of CSV data rows ``body`` (non-blank, at file ``lines``) as float64 ``(m, columns)``, empty
    cells NaN; a row of the wrong length or a cell that is no number is refused naming its line."""
    try:  # the fast path: plain numbers, one row per line
        values = np.loadtxt(body, delimiter=",", dtype=np.float64, ndmin=2, comments=None)
    except ValueError:
        values = None
    if values is not None and values.shape == (len(body), len(header)):
        return values
    numbers = []
    for row, line in zip(csv.reader(body), lines, strict=False):
        if len(row) != len(header):
            raise _error(path, f"line {line} has {len(row)} cells; the header names {len(header)} columns")
        values_row = []
        for name, cell in zip(header, row, strict=True):
            cell = cell.strip()
            if not cell:
                values_row.append(math.nan)
                continue
            try:
                values_row.append(float(cell))
            except ValueError:
                raise _error(
                    path,
                    f"line {line}, column {name!r}: {cell!r} is not a number; every cell must be a number",
                ) from None
        numbers.append(values_row)
    return np.asarray(numbers, dtype=np.float64).reshape(len(numbers), len(header))


def _csv_chunks(path: Path, chunk_rows: int | None = None):
    """The header of a CSV log, then its data rows in chunks: ``(cells (m, columns) float64, file lines
    (m,))``, blank lines skipped. Reads the file line by line: memory is one chunk, not the file."""
    try:
        fh = open(path, encoding="utf-8-sig", newline="")
    except OSError as exc:
        raise _error(path, f"cannot be read ({type(exc).__name__}: {exc})") from exc
    chunk_rows = CSV_CHUNK_ROWS if chunk_rows is None else chunk_rows
    with fh:
        try:
            first = fh.readline()
            if not first.strip():
                raise _error(
                    path, "the first line must be the header naming the columns, " + _csv_columns_hint()
                )
            header = [name.strip() for name in next(csv.reader([first]))]
            if all(_is_number(name) for name in header):
                raise _error(
                    path,
                    "the first line holds numbers; it must be the header naming the columns, "
                    + _csv_columns_hint(),
                )
            yield header
            body: list[str] = []
            lines: list[int] = []
            for number, text in enumerate(fh, start=2):
                if not text.strip():
                    continue
                body.append(text)
                lines.append(number)
                if len(body) == chunk_rows:
                    yield _parse_rows(path, header, body, lines), np.asarray(lines)
                    body, lines = [], []
            if body:
                yield _parse_rows(path, header, body, lines), np.asarray(lines)
        except UnicodeDecodeError as exc:
            raise _error(path, f"cannot be read as UTF-8 text ({type(exc).__name__}: {exc})") from exc


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _csv_columns_hint() -> str:
    return "e.g. 'joint_1,...,joint_n,ef_x,ef_y,ef_z[,episode][,time]'"


def _split_csv(
    path: Path, header: list[str], values: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None, list[str]]:
    """theta, ef, episode, time and the joint columns' names of a CSV log's cells."""
    twice = sorted(name for name, count in Counter(header).items() if count > 1)
    if twice:
        raise _error(path, f"the header names column(s) {', '.join(map(repr, twice))} more than once")
    missing = [c for c in EF_COLUMNS if c not in header]
    if missing:
        raise _error(
            path,
            f"lacks the column(s) {', '.join(missing)}; a log needs the end effector's position in metres "
            f"as ef_x, ef_y, ef_z beside one column per joint ({_csv_columns_hint()})",
        )
    near = [
        n
        for n in header
        if n not in RESERVED_COLUMNS and (n.lower() in RESERVED_COLUMNS or n.lower().startswith("ef_"))
    ]
    if near:
        raise _error(
            path,
            f"column(s) {', '.join(map(repr, near))} look like end-effector, episode or time columns; "
            f"those must be named exactly {', '.join(RESERVED_COLUMNS)} (lower case)",
        )
    col = {name: i for i, name in enumerate(header)}
    joints = [n for n in header if n not in RESERVED_COLUMNS]
    if not joints:
        raise _error(
            path, f"has no joint columns; besides {', '.join(RESERVED_COLUMNS)} each column is a joint"
        )
    theta = values[:, [col[n] for n in joints]]
    ef = values[:, [col[n] for n in EF_COLUMNS]]
    episode = values[:, col["episode"]] if "episode" in col else None
    time = values[:, col["time"]] if "time" in col else None
    return theta, ef, episode, time, joints


def _read_npz(
    path: Path,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None, list[str] | None]:
    """theta, ef, episode, time and joint names (or None) of an ``.npz`` log."""
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except Exception as exc:  # zipfile, pickle and value errors alike
        raise _error(path, f"is not a readable .npz file ({type(exc).__name__}: {exc})") from exc
    unknown = sorted(set(arrays) - set(NPZ_KEYS))
    if unknown:
        raise _error(
            path,
            f"holds the unknown key(s) {', '.join(unknown)}; a recorded .npz holds theta, ef and optionally "
            "episode, time, joint_names (rename or remove the others)",
        )
    missing = [k for k in ("theta", "ef") if k not in arrays]
    if missing:
        raise _error(
            path,
            f"lacks the key(s) {', '.join(missing)}; a recorded .npz needs theta (N, dof) in radians and "
            "ef (N, 3) in metres",
        )
    out = {}
    for key in ("theta", "ef", "episode", "time"):
        if key not in arrays:
            out[key] = None
            continue
        a = arrays[key]
        if a.dtype.kind not in "fiu":
            raise _error(path, f"{key} holds {a.dtype} values; it must hold real numbers")
        out[key] = a.astype(np.float64)
    theta, ef = out["theta"], out["ef"]
    if theta.ndim != 2 or theta.shape[1] < 1:
        raise _error(path, f"theta must have shape (N, dof), got {theta.shape}")
    n = theta.shape[0]
    if ef.shape != (n, 3):
        raise _error(path, f"ef must have shape ({n}, 3) beside theta {theta.shape}, got {ef.shape}")
    for key in ("episode", "time"):
        if out[key] is not None and out[key].shape != (n,):
            raise _error(
                path, f"{key} must have shape ({n},) beside theta {theta.shape}, got {out[key].shape}"
            )
    names = None
    if "joint_names" in arrays:
        raw = arrays["joint_names"]
        if raw.dtype.kind not in "US" or raw.shape != (theta.shape[1],):
            raise _error(path, f"joint_names must be {theta.shape[1]} strings, got {raw.dtype} {raw.shape}")
        names = [str(v) for v in raw.tolist()]
    return theta, ef, out["episode"], out["time"], names


def _match_joints(
    path: Path, theta: np.ndarray, names: list[str] | None, robot: Robot | None, dof: int | None
) -> tuple[np.ndarray, tuple[str, ...] | None]:
    """theta in the robot's joint order (when a robot is given and the file names its joints)."""
    if robot is not None and dof is not None and dof != robot.dof:
        raise _error(path, f"dof={dof} was asked for, but robot {robot.name!r} has {robot.dof} joints")
    if robot is not None and names is not None:
        expected = list(robot.joint_names)
        extra = [n for n in names if n not in expected]
        lacking = [n for n in expected if n not in names]
        if extra or lacking:
            parts = []
            if extra:
                parts.append(f"column(s) {', '.join(map(repr, extra))} name no joint of {robot.name}")
            if lacking:
                parts.append(f"joint(s) {', '.join(lacking)} have no column")
            raise _error(
                path,
                f"{'; '.join(parts)}. The joint columns must be named as {robot.name}'s joints: "
                f"{', '.join(expected)} (any order)",
            )
        theta = theta[:, [names.index(n) for n in expected]]
        names = expected
    want = robot.dof if robot is not None else dof
    if want is not None and theta.shape[1] != want:
        whose = f"robot {robot.name!r} has" if robot is not None else "dof asks for"
        raise _error(path, f"has {theta.shape[1]} joint column(s), {whose} {want}")
    return theta, None if names is None else tuple(names)


def _reach(robot: Robot) -> float:
    """An upper bound of the end effector's distance from the base (m): the link lengths and prismatic travel."""
    links = sum(float(np.linalg.norm(j.T_prev[:3, 3])) for j in robot.joints)
    travel = sum(max(abs(j.lower), abs(j.upper)) for j in robot.joints if j.kind == "prismatic")
    return links + travel + float(np.linalg.norm(robot.T_tip[:3, 3]))


def _check_units(path: Path, rows: _Rows, theta: np.ndarray, ef: np.ndarray, robot: Robot | None) -> None:
    """Refuse end effectors that look like millimetres, joints that look like degrees, joints outside the limits."""
    dist = np.linalg.norm(ef, axis=1)
    if robot is not None:
        bound = REACH_FACTOR * _reach(robot)
        why = f"{REACH_FACTOR:g} × the reach of {robot.name}, {_reach(robot):.3g} m"
    else:
        bound, why = EF_BOUND, "a bound for any arm"
    far = np.nonzero(dist > bound)[0]
    if len(far):
        raise _error(
            path,
            f"{len(far)} end-effector position(s) lie farther than {bound:.3g} m from the base ({why}), up to "
            f"{dist.max():.4g} m ({rows.name(far)}). ef must be in metres: if these are millimetres, divide by 1000",
        )
    names = robot.joint_names if robot is not None else None
    if robot is None:
        big = np.nonzero((np.abs(theta) > ANGLE_BOUND).any(axis=1))[0]
        if len(big):
            raise _error(
                path,
                f"{len(big)} row(s) hold joint values beyond ±{ANGLE_BOUND:.3g} rad, up to "
                f"{np.abs(theta).max():.4g} ({rows.name(big)}). theta must be in radians: if these are degrees, "
                "convert them (numpy.deg2rad)",
            )
        return
    lo, hi = robot.lower, robot.upper
    outside = (theta < lo - LIMIT_TOL) | (theta > hi + LIMIT_TOL)
    bad = np.nonzero(outside.any(axis=1))[0]
    if not len(bad):
        return
    rad = np.deg2rad(theta)
    if np.abs(theta).max() > ANGLE_BOUND and ((rad >= lo - LIMIT_TOL) & (rad <= hi + LIMIT_TOL)).all():
        raise _error(
            path,
            f"{len(bad)} row(s) leave {robot.name}'s joint limits ({rows.name(bad)}) with values up to "
            f"{np.abs(theta).max():.4g}, and every value would lie within them in degrees: theta must be in "
            "radians; convert it (numpy.deg2rad)",
        )
    j = int(np.nonzero(outside[bad[0]])[0][0])
    raise _error(
        path,
        f"{len(bad)} row(s) hold joints outside {robot.name}'s limits ({rows.name(bad)}; the first: "
        f"{names[j]} = {theta[bad[0], j]:.6g} rad, allowed [{lo[j]:.6g}, {hi[j]:.6g}]). Check that the log is "
        f"of this robot and its joint columns are named right, or remove those rows",
    )


def check_observation_units(theta: np.ndarray, ef: np.ndarray, robot: Robot | None, what: str) -> None:
    """The unit and limit checks a log file gets, for observations in memory (``what`` names them):
    :class:`~kinlearn.errors.RecordedDataError` for end effectors that look like millimetres, joints that
    look like degrees, or joints outside ``robot``'s limits (rows named from 0)."""
    _check_units(what, _Rows(Path(what), None, theta.shape[0]), theta, ef, robot)


def _episodes(path: Path, rows: _Rows, episode: np.ndarray | None, n: int) -> np.ndarray:
    """The file's episode labels checked (integers, each episode's rows consecutive), as given (int64)."""
    if episode is None:
        return np.zeros(n, dtype=np.int64)
    fractional = np.nonzero(episode != np.round(episode))[0]
    if len(fractional):
        raise _error(
            path,
            f"episode holds {len(fractional)} value(s) that are not whole numbers ({rows.name(fractional)})",
        )
    labels = episode.astype(np.int64)
    starts = np.concatenate(([0], np.nonzero(labels[1:] != labels[:-1])[0] + 1))
    run_labels = labels[starts]
    unique, counts = np.unique(run_labels, return_counts=True)
    if (counts > 1).any():
        label = unique[counts > 1][0]
        runs = starts[np.nonzero(run_labels == label)[0]]
        raise _error(
            path,
            f"the rows of episode {int(label)} are not consecutive (it starts again at {rows.name(runs[1:2])} "
            f"after other episodes); {int((counts > 1).sum())} episode(s) are split. Sort the rows by episode "
            "(and time), or give each run of rows its own label",
        )
    return labels


def _check_time(path: Path, rows: _Rows, time: np.ndarray, labels: np.ndarray) -> None:
    back = np.nonzero((labels[1:] == labels[:-1]) & (np.diff(time) <= 0))[0] + 1
    if len(back):
        raise _error(
            path,
            f"time does not increase within an episode at {len(back)} row(s) ({rows.name(back)}); sort each "
            "episode's rows by time, and remove repeated samples",
        )


def load_recorded(
    path: str | Path,
    *,
    robot: str | Robot | None = None,
    dof: int | None = None,
    drop_nan: bool = False,
    max_rows: int | None = None,
    seed: int = 0,
) -> Observations:
    """Load and check a recorded log (``.npz`` or ``.csv``, see the module docstring).

    ``robot`` (a name or a :class:`~kinlearn.Robot`): the CSV's joint columns (or the ``.npz``'s
    ``joint_names``) are matched to its joint names in any order and reordered to its order; end
    effectors must lie within :data:`REACH_FACTOR` of its reaches and joints within its limits. Without
    one, the columns other than ``ef_x, ef_y, ef_z, episode, time`` are the joints in file order, end
    effectors must lie within :data:`EF_BOUND` m and joints within ±:data:`ANGLE_BOUND` rad. ``dof``,
    if given, must be the joint count. Rows holding NaN/inf are refused, or with ``drop_nan=True``
    dropped with a warning (``Observations.dropped`` counts them; a dropped row ends its episode's
    run, so no transition spans it). Episodes are renumbered 0, 1, … in file order.

    A CSV log is read in chunks of :data:`CSV_CHUNK_ROWS` rows, every row checked, never the whole file
    in memory. ``max_rows``: keep a seeded (``seed``) uniform sample of at most this many of the rows
    (reservoir sampling in one pass) instead of all of them: memory is then bounded by ``max_rows`` rows
    (``max_rows × (dof + 3) × 8`` bytes) plus one chunk, whatever the file's size, which is how
    :func:`~kinlearn.training.identify.identify` reads a log (its ``max_samples``). Such a sample has no
    time and each row is its own episode (it holds no transitions); ``sampled_from`` counts the rows it
    was drawn from.

    Raises :class:`~kinlearn.errors.RecordedDataError` naming what to fix.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".npz", ".csv"):
        raise _error(path, f"unknown suffix {path.suffix!r}: a recorded log is a .npz or a .csv file")
    if not path.exists():
        raise _error(path, "no such file")
    if not path.is_file():
        raise _error(path, "is not a file")
    if path.stat().st_size == 0:
        raise _error(path, "is empty")
    if dof is not None:
        try:
            dof = as_int(dof, "dof (the joint count)", minimum=1)
        except ConfigError as exc:
            raise RecordedDataError(str(exc)) from None
    robot = load_robot(robot) if isinstance(robot, str) else robot
    if robot is not None and not isinstance(robot, Robot):
        raise RecordedDataError(f"robot must be a robot name or a kinlearn Robot, got {type(robot).__name__}")
    if max_rows is not None:
        max_rows = as_int(max_rows, "max_rows", minimum=1)
    reader = _Reader(path, robot, drop_nan, max_rows, as_int(seed, "seed", minimum=0))
    if suffix == ".csv":
        chunks = _csv_chunks(path)
        header = next(chunks)
        names = _split_csv(path, header, np.empty((0, len(header))))[4]
        order, joint_names = _match_joints(
            path, np.arange(len(names), dtype=np.float64)[None], names, robot, dof
        )
        order = order[0].astype(np.int64)
        for values, lines in chunks:
            theta, ef, episode, time, _ = _split_csv(path, header, values)
            reader.add(theta[:, order], ef, episode, time, lines)
        if reader.rows == 0:
            raise _error(path, "holds a header but no data rows")
    else:
        theta, ef, episode, time, names = _read_npz(path)
        if theta.shape[0] == 0:
            raise _error(path, "holds no data rows")
        theta, joint_names = _match_joints(path, theta, names, robot, dof)
        reader.add(theta, ef, episode, time, None)
    return reader.observations(joint_names)


class _Reader:
    """The checks of a log's rows, block by block (a CSV log's chunks, or an ``.npz`` log whole), with what
    carries from one block to the next (a dropped row's gap, the episodes seen, the last time), and the
    rows kept: all of them, or a seeded reservoir sample of ``max_rows`` (memory: that many rows)."""

    def __init__(self, path: Path, robot: Robot | None, drop_nan: bool, max_rows: int | None, seed: int):
        self.path, self.robot, self.drop_nan, self.max_rows = path, robot, drop_nan, max_rows
        self.rng = np.random.default_rng(seed)
        self.rows = 0  # rows read
        self.kept = 0  # rows that passed (NaN rows dropped)
        self.dropped = 0
        self.dropped_lines: list[str] = []
        self.prev_dropped = False
        self.seen: set[int] = set()  # the episode labels whose runs have begun
        self.last_label: int | None = None
        self.last_time: float | None = None
        self.next_id = 0
        self.parts: list[tuple] = []  # all rows: (theta, ef, episode ids, time)
        self.sample: tuple[np.ndarray, np.ndarray] | None = None  # the reservoir: (theta, ef)

    def add(self, theta, ef, episode, time, lines) -> None:
        path, n = self.path, theta.shape[0]
        rows = _Rows(path, lines, n)
        if lines is None:
            rows.index = rows.index + self.rows
        self.rows += n
        finite = np.isfinite(theta).all(axis=1) & np.isfinite(ef).all(axis=1)
        for column in (episode, time):
            if column is not None:
                finite &= np.isfinite(column)
        dropped = int((~finite).sum())
        gap = np.zeros(n, dtype=bool)  # a row kept after dropped ones starts a new run
        gap[0] = self.prev_dropped
        if dropped:
            bad = np.nonzero(~finite)[0]
            if not self.drop_nan:
                raise _error(
                    path,
                    f"{dropped} row(s) hold NaN or infinity ({rows.name(bad)}); fix them, or drop them with "
                    "drop_nan=True (--drop-nan)",
                )
            self.dropped += dropped
            if len(self.dropped_lines) < SHOWN_ROWS:
                shown = rows.index[bad[:SHOWN_ROWS]] if lines is None else lines[bad[:SHOWN_ROWS]]
                self.dropped_lines += [str(int(v)) for v in shown][: SHOWN_ROWS - len(self.dropped_lines)]
            gap[1:] |= ~finite[:-1]
            theta, ef, gap = theta[finite], ef[finite], gap[finite]
            episode = None if episode is None else episode[finite]
            time = None if time is None else time[finite]
            rows.keep(finite)
        self.prev_dropped = not bool(finite[-1])
        m = theta.shape[0]
        if m == 0:
            return
        labels = _episodes(path, rows, episode, m)
        if episode is not None:
            starts = np.concatenate(([0], np.nonzero(labels[1:] != labels[:-1])[0] + 1))
            for k, start in enumerate(starts):
                label = int(labels[start])
                if k == 0 and label == self.last_label:
                    continue  # the episode of the last block goes on
                if label in self.seen:
                    raise _error(
                        path,
                        f"the rows of episode {label} are not consecutive (it starts again at "
                        f"{rows.name(np.array([start]))} after other episodes). Sort the rows by episode (and "
                        "time), or give each run of rows its own label",
                    )
                self.seen.add(label)
        _check_units(path, rows, theta, ef, self.robot)
        if time is not None:
            _check_time(path, rows, time, labels)
            if self.last_time is not None and labels[0] == self.last_label and time[0] <= self.last_time:
                raise _error(
                    path,
                    f"time does not increase within an episode at 1 row(s) ({rows.name(np.array([0]))}); sort "
                    "each episode's rows by time, and remove repeated samples",
                )
            self.last_time = float(time[-1])
        new_run = np.ones(m, dtype=bool)
        new_run[1:] = (labels[1:] != labels[:-1]) | gap[1:]
        new_run[0] = self.kept == 0 or int(labels[0]) != self.last_label or bool(gap[0])
        ids = self.next_id + np.cumsum(new_run) - 1
        self.next_id = int(ids[-1]) + 1
        self.last_label = int(labels[-1])
        if self.max_rows is None:
            self.parts.append((theta, ef, ids, time))
        else:
            self._reservoir(theta, ef)
        self.kept += m

    def _reservoir(self, theta: np.ndarray, ef: np.ndarray) -> None:
        """Algorithm R over the rows in file order: after ``i`` rows each is in the sample with
        probability ``max_rows / i``; seeded, so the same file gives the same sample."""
        k, seen, m = self.max_rows, self.kept, theta.shape[0]
        fill = min(max(k - seen, 0), m)
        if self.sample is None:
            self.sample = (np.empty((k, theta.shape[1])), np.empty((k, 3)))
        self.sample[0][seen : seen + fill] = theta[:fill]
        self.sample[1][seen : seen + fill] = ef[:fill]
        if fill == m:
            return
        position = np.arange(seen + fill, seen + m)  # 0-based index of each remaining row in the file
        slot = self.rng.integers(0, position + 1)
        take = np.nonzero(slot < k)[0]
        if len(take):
            slots, last = np.unique(
                slot[take][::-1], return_index=True
            )  # the last row to land in a slot wins
            src = fill + take[::-1][last]
            self.sample[0][slots] = theta[src]
            self.sample[1][slots] = ef[src]

    def observations(self, joint_names) -> Observations:
        path = self.path
        if self.dropped:
            if self.kept == 0:
                raise _error(path, f"every one of its {self.dropped} rows holds NaN or infinity")
            if path.suffix.lower() == ".csv":
                head = "line" if self.dropped == 1 else "lines"
            else:
                head = "row" if self.dropped == 1 else "rows (from 0)"
            more = ", …" if self.dropped > SHOWN_ROWS else ""
            warnings.warn(
                f"{path}: dropped {self.dropped} row(s) holding NaN or infinity ({head} "
                f"{', '.join(self.dropped_lines)}{more})",
                DroppedRowsWarning,
                stacklevel=3,
            )
        if self.max_rows is not None:
            k = min(self.kept, self.max_rows)
            theta, ef = self.sample[0][:k], self.sample[1][:k]
            obs = Observations(
                torch.from_numpy(np.ascontiguousarray(theta)),
                torch.from_numpy(np.ascontiguousarray(ef)),
                torch.arange(k),  # a sample of rows: each its own episode (no transitions between them)
                None,
                joint_names,
                path,
                file_sha256(path),
                self.dropped,
            )
            obs.sampled_from = self.kept
            return obs
        theta, ef, ids, time = (
            np.concatenate(x) if x[0] is not None else None for x in zip(*self.parts, strict=True)
        )
        return Observations(
            torch.from_numpy(np.ascontiguousarray(theta)),
            torch.from_numpy(np.ascontiguousarray(ef)),
            torch.from_numpy(ids),
            None if time is None else torch.from_numpy(np.ascontiguousarray(time)),
            joint_names,
            path,
            file_sha256(path),
            self.dropped,
        )


def load_data(path: str | Path, robot: str | Robot | None = None, *, drop_nan: bool = False) -> Transitions:
    """Transitions from a kinlearn babbling ``.npz`` (:func:`~kinlearn.data.load_transitions`, checked to be of
    ``robot``) or from a recorded log (:func:`load_recorded`, then :meth:`Observations.transitions`,
    labelled with ``robot``'s name; without a robot, unlabelled: ``""``). The loader of every learning
    command's ``--data``. Raises :class:`~kinlearn.errors.DatasetError` (or its
    :class:`~kinlearn.errors.RecordedDataError`) for a bad file.
    """
    path = Path(path)
    if path.suffix.lower() == ".npz" and path.is_file() and _is_kinlearn_npz(path):
        return load_transitions(path, robot=robot)
    name = robot.name if isinstance(robot, Robot) else robot
    return load_recorded(path, robot=robot, drop_nan=drop_nan).transitions(name or "")


def load_observations(
    path: str | Path,
    robot: str | Robot | None = None,
    *,
    dof: int | None = None,
    drop_nan: bool = False,
    max_rows: int | None = None,
    seed: int = 0,
) -> Observations:
    """Observations (θ, ef) from a kinlearn babbling ``.npz`` (its states,
    :meth:`Observations.from_transitions`) or a recorded log (:func:`load_recorded`): what
    identification learns from. Raises :class:`~kinlearn.errors.DatasetError` for a bad file."""
    path = Path(path)
    if path.suffix.lower() == ".npz" and path.is_file() and _is_kinlearn_npz(path):
        data = load_transitions(path, robot=robot)
        if dof is not None and data.layout.dof != dof:
            raise RecordedDataError(f"{path} holds {data.layout.dof} joints, not {dof}")
        obs = Observations.from_transitions(
            data, joint_names=robot.joint_names if isinstance(robot, Robot) else None
        )
        obs.path, obs.sha256 = path, file_sha256(path)
        return obs
    return load_recorded(path, robot=robot, dof=dof, drop_nan=drop_nan, max_rows=max_rows, seed=seed)


def _is_kinlearn_npz(path: Path) -> bool:
    """Whether ``path`` is an ``.npz`` written by kinlearn (it holds kinlearn's metadata)."""
    try:
        with np.load(path, allow_pickle=False) as data:
            return "__meta__" in data.files
    except Exception:  # not readable: load_recorded says why
        return False


def save_recorded(path: str | Path, obs: Observations) -> Path:
    """Write ``obs`` as a recorded log, ``.npz`` or ``.csv`` by the suffix, atomically.

    Every field is written (``episode``; ``time`` and ``joint_names`` when set; a CSV's joint columns are
    the joint names, or ``joint_1`` … ``joint_n`` without them); values round-trip exactly.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".npz", ".csv"):
        raise RecordedDataError(f"{path}: unknown suffix {path.suffix!r}: write a .npz or a .csv file")
    if not isinstance(obs, Observations):
        raise RecordedDataError(f"save_recorded writes Observations, got {type(obs).__name__}")
    arrays = {k: getattr(obs, k).detach().cpu().numpy() for k in ("theta", "ef", "episode")}
    if obs.time is not None:
        arrays["time"] = obs.time.detach().cpu().numpy()
    if suffix == ".npz":
        if obs.joint_names is not None:
            arrays["joint_names"] = np.array(obs.joint_names)

        def write(p: Path) -> None:
            with open(p, "wb") as fh:
                np.savez(fh, **arrays)

        return atomic_write(path, write)
    names = obs.joint_names or tuple(f"joint_{i + 1}" for i in range(obs.dof))
    clash = [n for n in names if n in RESERVED_COLUMNS]
    if clash:
        raise RecordedDataError(
            f"joint name(s) {', '.join(clash)} clash with the columns {', '.join(RESERVED_COLUMNS)}"
        )
    columns: list[tuple[str, np.ndarray, str]] = [
        (n, arrays["theta"][:, i], "%.17g") for i, n in enumerate(names)
    ]
    columns += [(c, arrays["ef"][:, i], "%.17g") for i, c in enumerate(EF_COLUMNS)]
    columns.append(("episode", arrays["episode"], "%d"))
    if obs.time is not None:
        columns.append(("time", arrays["time"], "%.17g"))
    table = np.column_stack([c[1].astype(np.float64) for c in columns])

    def write_csv(p: Path) -> None:
        np.savetxt(
            p,
            table,
            fmt=[c[2] for c in columns],
            delimiter=",",
            header=",".join(c[0] for c in columns),
            comments="",
        )

    return atomic_write(path, write_csv)
