"""Target paths of a training problem set: a teacher's path for each problem, cached beside the set.

The obstacle-aware TM can be distilled (:mod:`kinlearn.training.obstacle_path`): the candidate nearest
to a problem's target path is pulled towards it. A target comes from one of two teachers, each written
once beside the problem set ``NAME.npz`` and read by every training that names it:

=============  ====================================================================================
``sampler``    the compiled RRT-Connect, a fixed iteration budget per problem
               (``NAME.experts{K}.npz``; made by :func:`kinlearn.training.obstacle_path.expert_paths`)
``planner``    a kinlearn planner's own plans (``NAME.planner{K}.npz``; made by
               :func:`kinlearn.planning.teacher.planner_paths`): its fixed-time stages, then its
               sampler for what they leave (self-distillation)
=============  ====================================================================================

Each file holds ``paths (N, K + 1, dof)``, every path resampled to K + 1 points by joint-space arc
length (:func:`kinlearn.polyline.resample`), and ``found (N,)``, whether the teacher solved the problem
(its row is zeros where not), with a record of what made it; a file made for another problem set, robot,
number of knots or teacher setting is not read (:func:`load_target_paths` returns None).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import ConfigError, DatasetError
from ..io import load_npz, save_npz

__all__ = ["TEACHERS", "load_target_paths", "read_target_paths", "save_target_paths", "target_paths_file"]

#: The teachers a target path can come from, and the kind of file each writes.
TEACHERS: dict[str, str] = {"sampler": "expert_paths", "planner": "planner_paths"}
#: Each teacher's file name beside ``NAME.npz``: ``NAME.{suffix}{knots}.npz``.
_SUFFIX = {"sampler": "experts", "planner": "planner"}


def _teacher(teacher: str) -> str:
    if teacher not in TEACHERS:
        raise ConfigError(f"unknown teacher {teacher!r}; choose from {', '.join(TEACHERS)}")
    return teacher


def target_paths_file(problems: str | Path, teacher: str, knots: int) -> Path:
    """Where ``teacher``'s paths of the problem set ``problems`` (``.npz``) at ``knots`` knots are kept."""
    problems = Path(problems)
    return problems.with_name(f"{problems.stem}.{_SUFFIX[_teacher(teacher)]}{knots}.npz")


def read_target_paths(
    problems: str | Path, robot: str, teacher: str, knots: int, n: int
) -> tuple[dict, np.ndarray, np.ndarray]:
    """``(config, paths (n, knots + 1, dof), found (n,))`` from ``teacher``'s file for the set
    ``problems`` of ``n`` problems. A :class:`~kinlearn.errors.DatasetError` where there is none, it is
    unreadable, of another robot, or made for another set, size or number of knots."""
    path = target_paths_file(problems, teacher, knots)
    meta, arrays = load_npz(path, kind=TEACHERS[teacher], robot=robot)
    config = meta.get("config") or {}
    if (config.get("problems"), config.get("n"), config.get("knots")) != (Path(problems).name, n, knots):
        raise DatasetError(f"{path} holds paths of another problem set, size or number of knots")
    if arrays["paths"].shape[:2] != (n, knots + 1) or arrays["found"].shape != (n,):
        raise DatasetError(f"{path} holds arrays of the wrong shape for {n} problems at {knots} knots")
    return config, arrays["paths"], arrays["found"]


def load_target_paths(
    problems: str | Path, robot: str, teacher: str, knots: int, want: dict
) -> tuple[np.ndarray, np.ndarray] | None:
    """``(paths, found)`` of ``teacher`` for the set ``problems`` if its file is there, readable and made
    exactly as ``want`` records (its config, which names the set, its size ``n`` and the knots); else
    None (a cache to make again)."""
    try:
        config, paths, found = read_target_paths(problems, robot, teacher, knots, want.get("n", -1))
    except DatasetError:
        return None
    return (paths, found) if config == want else None


def save_target_paths(
    problems: str | Path,
    robot: str,
    teacher: str,
    knots: int,
    want: dict,
    paths: np.ndarray,
    found: np.ndarray,
) -> Path:
    """Write ``teacher``'s paths ``(N, knots + 1, dof)`` and ``found (N,)`` beside ``problems``
    (atomically), recording ``want``; returns the file."""
    paths, found = np.asarray(paths, dtype=np.float64), np.asarray(found, dtype=bool)
    if paths.ndim != 3 or paths.shape[1] != knots + 1 or found.shape != paths.shape[:1]:
        raise ConfigError(
            f"target paths must be (N, {knots + 1}, dof) with found (N,), got {paths.shape} and {found.shape}"
        )
    path = target_paths_file(problems, teacher, knots)
    return save_npz(
        path, kind=TEACHERS[teacher], robot=robot, config=want, arrays={"paths": paths, "found": found}
    )
