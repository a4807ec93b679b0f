"""A planner as a teacher: its own plans of training problems, the targets of self-distillation.

The obstacle network proposes smooth bends of the straight joint line; where they clear nothing the
planner's retreat stage leaves the start's cell and enters the goal's, and its sampler clears what the
fixed-time stages leave. :func:`planner_paths` plans every problem of a training set with a planner
(``plan(start, goal, obstacles=scene)``, its default: the fixed-time stages, then a fixed budget of
sampler iterations, so the same paths on every machine; or, ``stages="fixed"``, its fixed-time stages
alone, ``refine_steps=0``: the network and the retreat stage, no sampler, so no searched path is shown)
and writes the plans that succeed, resampled to the network's knots, beside the set
(:mod:`kinlearn.data.target_paths`, teacher ``"planner"``). A training with
``ObstacleTrainConfig(teacher="planner", loss=ObstacleLossConfig(imitation=w))`` then pulls the nearest
candidate of each solved problem towards its plan: the next network learns the paths its planner had to
find by structure or by search. The problems a planner does not solve have no target
(and ``solvable_only`` drops them).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from ..body.robot import load_robot
from ..data.problems import ProblemSet
from ..data.target_paths import load_target_paths, save_target_paths, target_paths_file
from ..errors import ConfigError, NoObstacleModelWarning
from ..io import file_sha256
from ..polyline import resample
from .planner import OBSTACLE_TM, Planner

__all__ = ["TEACHER_STAGES", "planner_paths"]

#: What a teaching planner plans with: ``"default"`` (``plan()``'s default: the fixed-time stages, then
#: a fixed budget of sampler iterations) or ``"fixed"`` (the fixed-time stages alone, ``refine_steps=0``).
TEACHER_STAGES: tuple[str, ...] = ("default", "fixed")


def planner_paths(
    folder: str | Path, problems: str | Path, knots: int = 11, progress=None, stages: str = "default"
) -> Path:
    """Plan every problem of the set ``problems`` (``.npz``) with the planner in ``folder`` (checking with
    the body the problems were made for) and write its successful plans, resampled to ``knots + 1``
    points by joint-space arc length, beside the set; returns the file. ``stages``: the stages it plans
    with (:data:`TEACHER_STAGES`). A file already made by the same planner (its obstacle network's
    content hash) with the same stages for the same set and knots is kept as it is; another is replaced.
    ``progress(done)`` is called after each problem."""
    folder, problems = Path(folder), Path(problems)
    if not isinstance(knots, int) or isinstance(knots, bool) or knots < 1:
        raise ConfigError(f"knots must be a positive integer, got {knots!r}")
    if stages not in TEACHER_STAGES:
        raise ConfigError(f"stages must be one of {', '.join(TEACHER_STAGES)}, got {stages!r}")
    pset = ProblemSet.load(problems)
    robot = load_robot(pset.robot)
    body = pset.body(robot).double()
    network = folder / OBSTACLE_TM
    want = {
        "problems": problems.name,
        "n": len(pset),
        "knots": knots,
        "planner": folder.name,
        "network": file_sha256(network) if network.is_file() else None,
        "body": body.name,
        "plan": stages,
    }
    if load_target_paths(problems, robot.name, "planner", knots, want) is not None:
        return target_paths_file(problems, "planner", knots)
    # The stages' own paths, not shortened: the network proposes smooth bends, and learns those better
    # than the corners a shortcut leaves.
    planner = Planner.load(folder, robot=robot, body=body, shortcut=False)
    options = {"refine_steps": 0} if stages == "fixed" else {}
    paths = np.zeros((len(pset), knots + 1, robot.dof))
    found = np.zeros(len(pset), dtype=bool)
    for i in range(len(pset)):
        start, goal, scene = pset.problem(i)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NoObstacleModelWarning)
            plan = planner.plan(start, goal, obstacles=scene, **options)
        if bool(plan.success):
            paths[i], found[i] = resample(plan.joints.double().numpy(), knots + 1), True
        if progress is not None:
            progress(i + 1)
    return save_target_paths(problems, robot.name, "planner", knots, want, paths, found)
