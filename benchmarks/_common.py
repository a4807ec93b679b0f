"""Shared helpers of the benchmark scripts: the result writer (:func:`write_result`, every benchmark's
figures as JSON under ``benchmarks/results/``), a header naming hardware and versions, timing, tables."""

from __future__ import annotations

import json
import math
import os
import platform
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Mapping, Sequence
from datetime import datetime, timezone
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import torch


def cpu_name() -> str:
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def header(title: str, threads: int) -> str:
    import numpy

    import kinlearn

    parts = [
        f"# {title}",
        f"CPU: {cpu_name()} ({os.cpu_count()} logical cores), torch threads: {threads}",
        f"Python {platform.python_version()}, torch {torch.__version__}, numpy {numpy.__version__}, "
        f"kinlearn {kinlearn.__version__}",
    ]
    from importlib.metadata import PackageNotFoundError, version

    for dist in ("pytorch-kinematics", "pin"):
        try:
            parts[-1] += f", {dist} {version(dist)}"
        except PackageNotFoundError:
            pass
    return "\n".join(parts)


def time_call(fn: Callable[[], object], repeats: int = 5, min_time: float = 0.0) -> float:
    """Median wall time of ``fn()`` in seconds over ``repeats`` runs (after one warm-up run)."""
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
        if min_time and sum(times) > min_time and len(times) >= 1:
            break
    return statistics.median(times)


def markdown_table(columns: list[str], rows: list[list[object]]) -> str:
    out = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    out += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(out)


def plan_cases(planner, cases, inside: Callable, **kw) -> tuple[int, int, int, list[float]]:
    """Plan every ``(start, goal, scene)`` of ``cases`` with ``planner.plan(..., **kw)``, one after the other:
    how many succeed with every knot ``inside(joints)``, how many succeed but leave it, how many the
    planner refused (:class:`~kinlearn.errors.JointLimitError`), and each call's wall time (s)."""
    from kinlearn.errors import JointLimitError

    ok = beyond = refused = 0
    times = []
    for s, g, sc in cases:
        t0 = time.perf_counter()
        try:
            plan = planner.plan(s, g, obstacles=sc, **kw)
        except JointLimitError:
            refused += 1
            continue
        finally:
            times.append(time.perf_counter() - t0)
        within = bool(inside(plan.joints.detach().cpu().numpy()))
        ok += bool(plan.success) and within
        beyond += bool(plan.success) and not within
    return ok, beyond, refused, times


def limits_row(
    planner: str, mode: str, ok: int, n: int, count: int, times: list[float], digits: int = 1
) -> list:
    """A row of the limit benchmarks' tables: the planner, the mode, the success rate of ``n``, one count
    (the plans beyond the box, or the problems refused) and the p50 / p99 wall times (ms)."""
    t = [1e3 * x for x in times]
    return [
        planner,
        mode,
        f"{100 * ok / n:.1f}%",
        str(count),
        f"{statistics.median(t):.{digits}f}",
        f"{_p99(t):.{digits}f}",
    ]


def _p99(values: list[float]) -> float:
    """The 99th percentile, linear between order statistics (NumPy's default)."""
    v = sorted(values)
    k = 0.99 * (len(v) - 1)
    lo = int(k)
    return v[lo] + (v[min(lo + 1, len(v) - 1)] - v[lo]) * (k - lo)


RESULTS = Path(__file__).resolve().parent / "results"
#: Where benchmarks put what is not a result (per-problem details, figures): not committed.
RUNS = Path(__file__).resolve().parents[1] / "runs" / "benchmarks"
#: The version of the result files' layout (below); :mod:`benchmarks.report` refuses another.
SCHEMA = 1


def table(columns: Sequence[str], rows: Sequence[Sequence[object]], *, caption: str | None = None) -> dict:
    """A table as a result figure: ``{"columns": [...], "rows": [[...], ...]}`` (plus ``"caption"``), every
    row as long as the header."""
    columns = [str(c) for c in columns]
    rows = [list(r) for r in rows]
    for r in rows:
        if len(r) != len(columns):
            raise ValueError(f"a row of {len(r)} cells under {len(columns)} columns: {r}")
    out: dict = {"columns": columns, "rows": rows}
    if caption:
        out["caption"] = caption
    return out


def from_markdown(text: str, *, caption: str | None = None) -> dict:
    """A markdown table (``| a | b |`` lines: a header, a rule, rows) as a result figure (:func:`table`)."""
    lines = [ln.strip() for ln in text.strip().splitlines() if ln.strip().startswith("|")]
    cells = [[c.strip() for c in ln.strip("|").split("|")] for ln in lines]
    if len(cells) < 2 or not all(set(c) <= set(":-") for c in cells[1]):
        raise ValueError(f"not a markdown table: {text[:200]!r}")
    return table(cells[0], cells[2:], caption=caption)


def show(
    figures: dict,
    key: str,
    columns: Sequence[str],
    rows: Sequence[Sequence[object]],
    *,
    caption: str | None = None,
) -> None:
    """Print a table in markdown and keep it in ``figures[key]`` (:func:`table`) for :func:`write_result`."""
    print(markdown_table(list(columns), [list(r) for r in rows]))
    figures[key] = table(columns, rows, caption=caption)


def write_result(
    name: str,
    figures: Mapping[str, object],
    *,
    command: str | None = None,
    title: str | None = None,
    notes: str | None = None,
    threads: int | None = None,
    root: Path | None = None,
) -> Path:
    """Write one benchmark's figures to ``benchmarks/results/<name>.json`` (atomically: a reader never sees a
    half-written file) and return its path. :mod:`benchmarks.report` renders ``docs/results.md`` from these
    files, so a figure reaches the docs only by being measured.

    ``name`` is the file's stem (letters, digits, ``_`` and ``-``); ``figures`` maps a figure's name to its
    value: a number, a string, a bool, ``None``, a list, or a nested mapping of those (NumPy scalars and
    arrays are converted; NaN and infinity are refused, as JSON has none). A table is a mapping made by
    :func:`table`. ``command`` is the command line that regenerates the file (by default the one running,
    ``OMP_NUM_THREADS=<n> python benchmarks/<script>.py <args>``); ``title`` heads its section in the
    docs, ``notes`` is a paragraph under it; ``threads`` is the torch thread count (by default torch's).

    The file holds one JSON object (schema 1)::

        {
          "schema": 1,
          "name": "kinematics_speed",
          "title": "Batched forward kinematics",
          "notes": "..." | null,
          "command": "OMP_NUM_THREADS=1 python benchmarks/kinematics_speed.py --quick",
          "commit": "0123456789ab",          # git HEAD when measured ("unknown" outside git)
          "dirty": false,                    # kinlearn/ or benchmarks/ had uncommitted changes
          "date": "2026-12-07",              # UTC
          "machine": {"cpu": "...", "cores": 2, "threads": 1, "load": 3.2},  # load: 1-min average
          "versions": {"python": "3.12.3", "kinlearn": "0.1.0", "torch": "...", "numpy": "...", ...},
          "figures": {
            "forward kinematics": {"columns": ["batch", "ms"], "rows": [[1, 0.21], [1024, 1.9]]},
            "dof": 7
          }
        }
    """
    if not name or not all(c.isalnum() or c in "_-" for c in name):
        raise ValueError(f"a result name of letters, digits, _ and -: {name!r}")
    root = RESULTS if root is None else Path(root)
    if threads is None:
        threads = torch.get_num_threads()
    record = {
        "schema": SCHEMA,
        "name": name,
        "title": title or name.replace("_", " ").capitalize(),
        "notes": notes,
        "command": command or _command_line(),
        **_commit(),
        "date": datetime.now(timezone.utc).strftime("%Y-%m-%d"),
        "machine": {
            "cpu": cpu_name(),
            "cores": os.cpu_count() or 1,
            "threads": int(threads),
            "load": round(os.getloadavg()[0], 1),  # 1-minute load average as the figures were written
        },
        "versions": versions(),
        "figures": _plain(dict(figures), "figures"),
    }
    text = json.dumps(record, indent=1, allow_nan=False, ensure_ascii=False) + "\n"
    root.mkdir(parents=True, exist_ok=True)
    path = root / f"{name}.json"
    fd, tmp = tempfile.mkstemp(dir=root, prefix=f".{name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    print(f"wrote {path}")
    return path


def versions() -> dict[str, str]:
    """The versions of Python and of the packages the figures depend on (those installed)."""
    from importlib.metadata import PackageNotFoundError, version

    out = {"python": platform.python_version()}
    for dist in ("kinlearn", "torch", "numpy", "numba", "pytorch-kinematics", "pin", "coal"):
        try:
            out[dist] = version(dist)
        except PackageNotFoundError:
            pass
    return out


def _command_line() -> str:
    script = Path(sys.argv[0]).resolve()
    try:
        script = script.relative_to(Path(__file__).resolve().parents[1])
    except ValueError:
        pass
    threads = os.environ.get("OMP_NUM_THREADS")
    prefix = f"OMP_NUM_THREADS={threads} " if threads else ""
    return prefix + shlex.join(["python", str(script), *sys.argv[1:]])


def _commit() -> dict:
    root = Path(__file__).resolve().parents[1]
    try:
        head = subprocess.run(
            ["git", "rev-parse", "--short=12", "HEAD"], cwd=root, capture_output=True, text=True, check=True
        ).stdout.strip()
        changed = subprocess.run(
            ["git", "status", "--porcelain", "--", "kinlearn", "benchmarks/*.py"],
            cwd=root,
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return {"commit": "unknown", "dirty": False}
    return {"commit": head, "dirty": bool(changed)}


def _plain(value: object, where: str) -> object:
    """``value`` as plain JSON values (NumPy scalars and arrays converted), or a ValueError naming where."""
    if value is None or isinstance(value, (bool, str, int)):
        return value
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"{where}: {value} (JSON holds no NaN or infinity; write None or a string)")
        return value
    if hasattr(value, "tolist") and callable(value.tolist):  # NumPy/torch scalars and arrays
        return _plain(value.tolist(), where)
    if isinstance(value, Mapping):
        out = {}
        for k, v in value.items():
            if not isinstance(k, str):
                raise ValueError(f"{where}: a key {k!r} that is not a string")
            out[k] = _plain(v, f"{where}.{k}")
        return out
    if isinstance(value, (list, tuple)):
        return [_plain(v, f"{where}[{i}]") for i, v in enumerate(value)]
    raise ValueError(f"{where}: a {type(value).__name__}, not a number, string, list or mapping")
