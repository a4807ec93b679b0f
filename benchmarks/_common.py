"""Shared helpers of the benchmark scripts: a header naming hardware and versions, timing, tables."""

from __future__ import annotations

import os
import platform
import statistics
import time
from collections.abc import Callable

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
