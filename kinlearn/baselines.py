"""The planners kinlearn compares with, and the registry that lists them (one home for all of them).

Every baseline is a planner of the protocol (:class:`PlannerLike`): ``make(name, robot).plan(problem)``
returns a judged :class:`~kinlearn.planning.plan.Plan`. The built-in ones, by registry name:

========================  ============================  ==================================================
``joint-line``            :class:`JointLine`            the straight joint-space line (joint interpolation)
``cartesian-line``        :class:`CartesianLine`        the end effector on a straight line by DLS IK
``rrt-connect``           :class:`RRTConnect`           OMPL RRT-Connect in free space
``scene-rrt-connect``     :class:`SceneRRTConnect`      OMPL RRT-Connect around the obstacles (dense check)
``compiled-rrt-connect``  :class:`CompiledRRTConnect`   RRT-Connect compiled with the dense check
``trajectory-optimiser``  :class:`TrajectoryOptimiser`  Adam on a knot path around the obstacles
========================  ============================  ==================================================

The first three plan as in free space (``avoids_obstacles`` False: given obstacles they warn with
:class:`~kinlearn.errors.ObstaclesIgnoredWarning`, and their plans are checked among them). The
functions :func:`joint_line`, :func:`cartesian_line` and :func:`rrt_connect` plan batches of states
directly; :func:`joint_line_path`, :func:`cartesian_line_path`, :func:`scene_rrt_connect` and
:func:`trajectory_optimiser` plan one problem among a scene and return ``(path, seconds)``.

Iterate the registry with :func:`names` (filters: ``avoids_obstacles``, ``goal_kind``,
``only_available``) and build with :func:`make`; add a baseline with :func:`register` (a
:class:`Baseline` subclass gives the class attributes the registry reads), or in kinlearn itself
with one line in :data:`kinlearn.planning.registry.BUILTIN`.
"""

from .planning.baselines import (
    Baseline,
    CartesianLine,
    JointLine,
    RRTConnect,
    cartesian_line,
    joint_line,
    rrt_connect,
    rrt_connect_timed,
)
from .planning.obstacle_baselines import (
    OptimiserConfig,
    SceneRRTConnect,
    TrajectoryOptimiser,
    cartesian_line_path,
    joint_line_path,
    scene_rrt_connect,
    trajectory_optimiser,
)
from .planning.plan import PlannerLike
from .planning.registry import available, get, make, names, planners, register, subset_label, unregister

__all__ = [
    "Baseline",
    "CartesianLine",
    "JointLine",
    "OptimiserConfig",
    "PlannerLike",
    "RRTConnect",
    "SceneRRTConnect",
    "TrajectoryOptimiser",
    "available",
    "cartesian_line",
    "cartesian_line_path",
    "get",
    "joint_line",
    "joint_line_path",
    "make",
    "names",
    "planners",
    "register",
    "rrt_connect",
    "rrt_connect_timed",
    "scene_rrt_connect",
    "subset_label",
    "trajectory_optimiser",
    "unregister",
]
