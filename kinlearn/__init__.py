"""kinlearn: learn robot kinematics and trajectory planning from the robot's own motor babbling.

Quick start::

    import kinlearn
    plan = kinlearn.plan(start_joints, goal_joints)   # the shipped iiwa14 planner, anywhere in its range
    plan.joints, plan.ef, plan.success, plan.goal_error
    kinlearn.plan(start_joints, goal_position=[0.5, 0.1, 0.4])   # an end-effector goal
    problem = kinlearn.Problem.make(robot, start, goal, obstacles=spheres)
    planner.plan(problem)                              # any planner: learned or a baseline
    plan.timed()                                       # times, velocities, accelerations within limits
"""

import ast
import importlib
from pathlib import Path
from typing import TYPE_CHECKING

from .errors import (
    CheckpointError,
    ConfigError,
    DatasetError,
    DomainError,
    DomainWarning,
    DTypeError,
    JointLimitError,
    KinlearnError,
    MissingDependencyError,
    NonFiniteError,
    PlanningError,
    RecordedDataError,
    RobotDescriptionError,
    RunDirectoryError,
    ShapeError,
    StateError,
    UnknownRobotError,
)

# Everything else is imported when first used (PEP 562), so that `import kinlearn` and the `kinlearn`
# command start without torch: the imports below are the table of those names, read from this file.
if TYPE_CHECKING:
    from .body.kinematics import BACKENDS, Kinematics, dls_step, kinematics
    from .body.robot import ROBOTS, Robot, available_robots, load_robot, register_robot, unregister_robot
    from .body.state import StateLayout
    from .collision import BodySpheres, Scene, body_spheres, check_path
    from .data.babbling import BabblingConfig, Transitions, babble, load_transitions, save_transitions
    from .data.endpoints import EndpointConfig, EndpointPairs, load_endpoints, make_endpoints, save_endpoints
    from .data.problem import Problem
    from .evaluation.metrics import plan_metrics, summarize, trajectory_metrics
    from .models.body import LearnedBody, load_body_model
    from .models.chain import ChainFM
    from .models.forward_inverse import (
        AnalyticFM,
        AnalyticIM,
        FMConfig,
        ForwardModel,
        IMConfig,
        InverseModel,
        LearnedFM,
        LearnedIM,
        load_fm,
        load_im,
        save_model,
    )
    from .models.joint_path import JointPathConfig, JointPathModel, load_path_model
    from .models.obstacle_path import ObstaclePathConfig, ObstaclePathModel, load_obstacle_model
    from .models.rollout import LossConfig, rectify, tm_loss
    from .models.trajectory import TMConfig, TrajectoryModel
    from .planning.baselines import (
        CartesianDLS,
        JointInterpolation,
        RRTConnect,
        cartesian_dls,
        joint_interpolation,
        rrt_connect,
    )
    from .planning.plan import Plan, PlannerLike, Tolerance, judge
    from .planning.planner import Planner, plan
    from .planning.timing import TimedTrajectory, time_parameterize
    from .training.forward_inverse import train_config, train_fm, train_im, validate_models
    from .training.identify import identify
    from .training.joint_path import PathLossConfig, PathTrainConfig, train_path_model
    from .training.loop import OptimConfig, TrainConfig
    from .training.obstacle_path import ObstacleLossConfig, ObstacleTrainConfig, train_obstacle_model
    from .training.tm import TMTrainConfig, load_tm, tm_preset, train_tm

__version__ = "0.1.0"

__all__ = [
    "BACKENDS",
    "ROBOTS",
    "AnalyticFM",
    "AnalyticIM",
    "BabblingConfig",
    "BodySpheres",
    "CartesianDLS",
    "ChainFM",
    "CheckpointError",
    "ConfigError",
    "DTypeError",
    "DatasetError",
    "DomainError",
    "DomainWarning",
    "EndpointConfig",
    "EndpointPairs",
    "FMConfig",
    "ForwardModel",
    "IMConfig",
    "InverseModel",
    "JointInterpolation",
    "JointLimitError",
    "JointPathConfig",
    "JointPathModel",
    "Kinematics",
    "KinlearnError",
    "LearnedBody",
    "LearnedFM",
    "LearnedIM",
    "LossConfig",
    "MissingDependencyError",
    "NonFiniteError",
    "ObstacleLossConfig",
    "ObstaclePathConfig",
    "ObstaclePathModel",
    "ObstacleTrainConfig",
    "OptimConfig",
    "PathLossConfig",
    "PathTrainConfig",
    "Plan",
    "Planner",
    "PlannerLike",
    "PlanningError",
    "Problem",
    "RRTConnect",
    "RecordedDataError",
    "Robot",
    "RobotDescriptionError",
    "RunDirectoryError",
    "Scene",
    "ShapeError",
    "StateError",
    "StateLayout",
    "TMConfig",
    "TMTrainConfig",
    "TimedTrajectory",
    "Tolerance",
    "TrainConfig",
    "TrajectoryModel",
    "Transitions",
    "UnknownRobotError",
    "__version__",
    "available_robots",
    "babble",
    "body_spheres",
    "cartesian_dls",
    "check_path",
    "dls_step",
    "identify",
    "joint_interpolation",
    "judge",
    "kinematics",
    "load_body_model",
    "load_endpoints",
    "load_fm",
    "load_im",
    "load_obstacle_model",
    "load_path_model",
    "load_robot",
    "load_tm",
    "load_transitions",
    "make_endpoints",
    "plan",
    "plan_metrics",
    "rectify",
    "register_robot",
    "rrt_connect",
    "save_endpoints",
    "save_model",
    "save_transitions",
    "summarize",
    "time_parameterize",
    "tm_loss",
    "tm_preset",
    "train_config",
    "train_fm",
    "train_im",
    "train_obstacle_model",
    "train_path_model",
    "train_tm",
    "trajectory_metrics",
    "unregister_robot",
    "validate_models",
]


def _lazy_table() -> dict[str, str]:
    """Exported name → the module it comes from, as the ``TYPE_CHECKING`` imports above list them."""
    tree = ast.parse(Path(__file__).read_text(encoding="utf-8"))
    table = {}
    for node in tree.body:
        if isinstance(node, ast.If) and getattr(node.test, "id", None) == "TYPE_CHECKING":
            for imp in node.body:
                if isinstance(imp, ast.ImportFrom):
                    for alias in imp.names:
                        table[alias.asname or alias.name] = "." * imp.level + (imp.module or "")
    return table


_LAZY: dict[str, str] | None = None


def __getattr__(name: str):
    global _LAZY
    if _LAZY is None:
        _LAZY = _lazy_table()
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name], __name__), name)
    else:
        try:  # a sub-package or module (kinlearn.collision, kinlearn.io, ...)
            value = importlib.import_module(f".{name}", __name__)
        except ModuleNotFoundError as exc:
            if exc.name != f"{__name__}.{name}":
                raise
            raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
