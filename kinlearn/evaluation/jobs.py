"""Running independent jobs: in this process, on local worker processes, or as Ray tasks.

A job is a plain dict (it crosses a process boundary) and a runner a module-level function of one job
returning a list of results; :func:`run_jobs` returns every job's results in the jobs' order, whatever
the order they finish in. :mod:`kinlearn.evaluation.reproduce` runs its training sweep through it.
"""

from __future__ import annotations

import concurrent.futures as cf
import os
from collections.abc import Callable, Sequence

import torch
from tqdm.auto import tqdm

from ..errors import ConfigError, MissingDependencyError
from ..runs import die_with_parent

__all__ = ["default_workers", "run_jobs"]


def run_jobs(
    run: Callable[[dict], list],
    jobs: Sequence[dict],
    workers: int,
    backend: str,
    progress: bool = True,
    desc: str = "training jobs",
) -> list:
    """``run(job)`` for every job, its results concatenated in the jobs' order.

    ``backend="local"``: in this process when ``workers`` ≤ 1, else on ``workers`` spawned processes that
    end with this one (:func:`kinlearn.runs.die_with_parent`: orphans would race a resumed run);
    ``"ray"``: as Ray tasks of one CPU each (:class:`~kinlearn.errors.MissingDependencyError` without
    ray). ``run`` must be importable by name (a module-level function) for either.
    """
    if backend == "ray":
        try:
            import ray
        except ImportError as exc:
            raise MissingDependencyError(
                "backend 'ray' needs the ray extra: pip install 'kinlearn[ray]'"
            ) from exc
        if not ray.is_initialized():
            ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
        remote = ray.remote(num_cpus=1)(run)
        refs = [remote.remote(j) for j in jobs]
        return [r for ref in tqdm(refs, desc=f"{desc} (ray)", disable=not progress) for r in ray.get(ref)]
    if backend != "local":
        raise ConfigError(f"backend must be 'local' or 'ray', got {backend!r}")
    if workers <= 1:
        return [r for j in tqdm(jobs, desc=desc, disable=not progress) for r in run(j)]
    ctx = torch.multiprocessing.get_context("spawn")
    # Workers end with this process, however it ends: orphans would race a resumed run.
    pool_args = dict(
        max_workers=workers, mp_context=ctx, initializer=die_with_parent, initargs=(os.getpid(),)
    )
    with cf.ProcessPoolExecutor(**pool_args) as pool:
        futures = [pool.submit(run, j) for j in jobs]
        for _ in tqdm(cf.as_completed(futures), total=len(futures), desc=desc, disable=not progress):
            pass
        return [r for f in futures for r in f.result()]


def default_workers() -> int:
    """Worker processes by default: the CPU count, at most 2."""
    return max(1, min(2, os.cpu_count() or 1))
