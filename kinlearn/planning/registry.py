"""The baseline registry: every planner kinlearn compares with, by name, for whoever runs them all.

Reproduction (:mod:`kinlearn.evaluation.reproduce`), the model-error sweep
(:mod:`kinlearn.evaluation.model_error`), the benchmarks and the tests iterate :func:`names` and build each
with :func:`make`, instead of keeping lists of their own. A baseline is a class of the planner protocol
(:class:`~kinlearn.planning.plan.PlannerLike`: ``robot`` and ``plan(problem) -> Plan``) whose first
argument is the robot and which says what it does in class attributes (see
:class:`~kinlearn.planning.baselines.Baseline`, the base every built-in one derives from): ``label``,
``avoids_obstacles``, ``goals``, ``requires`` and ``one_at_a_time``.

A new baseline is one file (its class) and one line in :data:`BUILTIN`; or, from outside kinlearn,
``register("name", MyPlanner)`` (and :func:`unregister` to take it out again).
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import re

from ..data.problem import GOAL_KINDS
from ..errors import ConfigError

__all__ = [
    "BUILTIN",
    "available",
    "get",
    "make",
    "names",
    "planners",
    "register",
    "subset_label",
    "unregister",
]

#: The built-in baselines, in table order: name → ``"module:Class"`` (imported when first asked for, so
#: that listing them imports no optional dependency). A new baseline adds one line here.
BUILTIN: dict[str, str] = {
    "joint-line": "kinlearn.planning.baselines:JointLine",
    "cartesian-line": "kinlearn.planning.baselines:CartesianLine",
    "rrt-connect": "kinlearn.planning.baselines:RRTConnect",
    "scene-rrt-connect": "kinlearn.planning.obstacle_baselines:SceneRRTConnect",
    "compiled-rrt-connect": "kinlearn.planning.obstacle_baselines:CompiledRRTConnect",
    "trajectory-optimiser": "kinlearn.planning.obstacle_baselines:TrajectoryOptimiser",
}

_NAME = re.compile(r"[a-z][a-z0-9]*(-[a-z0-9]+)*")
#: name → its class, or the ``"module:Class"`` not yet imported.
_REGISTRY: dict[str, type | str] = dict(BUILTIN)


def _checked(name: str, cls) -> type:
    """``cls`` if it can be a baseline (a class with ``plan`` and the attributes the registry reads)."""
    if isinstance(cls, str):
        module, _, attr = cls.partition(":")
        try:
            cls = getattr(importlib.import_module(module), attr)
        except (ImportError, AttributeError) as exc:
            raise ConfigError(f"baseline {name!r}: cannot import {module}:{attr} ({exc})") from exc
    if not isinstance(cls, type) or not callable(getattr(cls, "plan", None)):
        raise ConfigError(
            f"baseline {name!r} must be a planner class with a plan(problem) method, got {cls!r}"
        )
    problems = []
    if not isinstance(getattr(cls, "label", None), str):
        problems.append("label (a str)")
    for attr in ("avoids_obstacles", "one_at_a_time"):
        if not isinstance(getattr(cls, attr, None), bool):
            problems.append(f"{attr} (a bool)")
    goals = getattr(cls, "goals", None)
    if not (isinstance(goals, tuple) and goals and set(goals) <= set(GOAL_KINDS)):
        problems.append(f"goals (a non-empty tuple of {GOAL_KINDS})")
    requires = getattr(cls, "requires", None)
    if not (isinstance(requires, tuple) and all(isinstance(r, str) for r in requires)):
        problems.append("requires (a tuple of module names)")
    if problems:
        raise ConfigError(
            f"baseline {name!r} ({cls.__name__}) needs the class attributes {', '.join(problems)}: derive "
            "it from kinlearn.baselines.Baseline, which gives the defaults"
        )
    return cls


def register(name: str, cls: type | str, *, replace: bool = False) -> None:
    """Add baseline ``cls`` (a class, or ``"module:Class"`` imported when first asked for) under ``name``
    (lower case words joined by hyphens). :class:`ConfigError` for a name taken (unless ``replace``) or
    a class that cannot be a baseline."""
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise ConfigError(
            f"a baseline's name is lower-case words joined by hyphens ('my-planner'), got {name!r}"
        )
    if name in _REGISTRY and not replace:
        raise ConfigError(f"a baseline named {name!r} is registered already; pass replace=True to replace it")
    _REGISTRY[name] = cls if isinstance(cls, str) else _checked(name, cls)


def unregister(name: str) -> None:
    """Take baseline ``name`` out of the registry (a built-in one too, until the process ends)."""
    if name not in _REGISTRY:
        raise ConfigError(f"no baseline named {name!r}; registered: {', '.join(_REGISTRY)}")
    del _REGISTRY[name]


def get(name: str) -> type:
    """The class of baseline ``name``; :class:`ConfigError` naming the registered ones for another."""
    if name not in _REGISTRY:
        raise ConfigError(f"no baseline named {name!r}; registered: {', '.join(_REGISTRY)}")
    cls = _REGISTRY[name]
    if isinstance(cls, str):
        cls = _REGISTRY[name] = _checked(name, cls)
    return cls


def available(name: str) -> bool:
    """Whether baseline ``name`` can run here: the optional modules it ``requires`` are installed."""
    return all(importlib.util.find_spec(module) is not None for module in get(name).requires)


def names(
    *,
    avoids_obstacles: bool | None = None,
    goal_kind: str | None = None,
    only_available: bool = False,
) -> list[str]:
    """The registered baselines' names in table order (built-in ones first, then those registered),
    those that avoid obstacles or not (``None``: both), that plan ``goal_kind`` goals (``None``: any),
    and with ``only_available`` those whose optional dependencies are installed."""
    if goal_kind is not None and goal_kind not in GOAL_KINDS:
        raise ConfigError(f"goal_kind must be one of {GOAL_KINDS} or None, got {goal_kind!r}")
    out = []
    for name in list(_REGISTRY):
        cls = get(name)
        if avoids_obstacles is not None and cls.avoids_obstacles != avoids_obstacles:
            continue
        if goal_kind is not None and goal_kind not in cls.goals:
            continue
        if only_available and not available(name):
            continue
        out.append(name)
    return out


def make(name: str, robot, *, seed: int | None = None, **options):
    """Baseline ``name`` for ``robot`` (a :class:`~kinlearn.body.robot.Robot` or its name), with
    ``options`` its constructor's keyword arguments. ``seed`` goes to a baseline that takes one (a
    ``seed`` argument: the searches) and is ignored by the deterministic ones, so that a caller seeds
    every baseline alike."""
    cls = get(name)
    if seed is not None and "seed" in inspect.signature(cls).parameters:
        options["seed"] = seed
    return cls(robot, **options)


def planners(
    robot,
    *,
    avoids_obstacles: bool | None = None,
    goal_kind: str | None = None,
    options: dict[str, dict] | None = None,
) -> dict:
    """Every available baseline that passes the filters of :func:`names`, built for ``robot``: name →
    planner. ``options``: name → that baseline's keyword arguments."""
    options = options or {}
    return {
        name: make(name, robot, **options.get(name, {}))
        for name in names(avoids_obstacles=avoids_obstacles, goal_kind=goal_kind, only_available=True)
    }


def subset_label(label: str, n: int) -> str:
    """A baseline's table label for a run on the first ``n`` problems only: ``"RRT-Connect (OMPL)"`` →
    ``"RRT-Connect (OMPL, 500 pairs)"``."""
    return f"{label[:-1]}, {n} pairs)" if label.endswith(")") else f"{label} ({n} pairs)"
