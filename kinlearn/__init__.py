"""kinlearn: learn robot kinematics and trajectory planning from the robot's own motor babbling.

Quick start::

    import kinlearn
    plan = kinlearn.plan(start_joints, goal_joints)   # the shipped iiwa14 planner, anywhere in its range
    plan.joints, plan.ef, plan.success, plan.goal_error
    kinlearn.plan(start_joints, goal_position=[0.5, 0.1, 0.4])   # an end-effector goal
    problem = kinlearn.Problem.make(robot, start, goal, obstacles=spheres)
    planner.plan(problem)                              # any planner: learned or a baseline
    plan.timed()                                       # times, velocities, accelerations within limits
    kinlearn.load("runs/planner")                      # any checkpoint or run directory kinlearn wrote

The front door holds what a user plans with and the errors they catch; everything else lives in a
module named for its purpose: :mod:`kinlearn.train` (every trainer and its configuration, the
identification), :mod:`kinlearn.baselines` (the baselines and their registry), :mod:`kinlearn.models`,
:mod:`kinlearn.data` (babbling, endpoints, recorded logs), :mod:`kinlearn.collision` (bodies, scenes,
checks), :mod:`kinlearn.body` (robots and kinematics), :mod:`kinlearn.errors` (every error and warning).
"""

from typing import TYPE_CHECKING

from .errors import (
    CheckpointError,
    ConfigError,
    DomainError,
    DomainWarning,
    JointLimitError,
    KinlearnError,
    KinlearnWarning,
    NonFiniteError,
    ObstacleError,
    PlanningError,
    ShapeError,
    TimingError,
    TrainingDivergedError,
    UnknownRobotError,
)
from .lazy import lazy_package

# Everything else is imported when first used (PEP 562), so that `import kinlearn` and the `kinlearn`
# command start without torch: the imports below are the table of those names, read from this file.
if TYPE_CHECKING:
    from .body.kinematics import kinematics
    from .body.robot import Robot, available_robots, load_robot, register_robot
    from .collision import Scene
    from .data.problem import Problem
    from .loading import load
    from .planning.judge import judge
    from .planning.plan import Plan, PlannerLike, Tolerance
    from .planning.planner import Planner, plan

__version__ = "0.1.0"

__all__ = [
    "CheckpointError",
    "ConfigError",
    "DomainError",
    "DomainWarning",
    "JointLimitError",
    "KinlearnError",
    "KinlearnWarning",
    "NonFiniteError",
    "ObstacleError",
    "Plan",
    "Planner",
    "PlannerLike",
    "PlanningError",
    "Problem",
    "Robot",
    "Scene",
    "ShapeError",
    "TimingError",
    "Tolerance",
    "TrainingDivergedError",
    "UnknownRobotError",
    "__version__",
    "available_robots",
    "judge",
    "kinematics",
    "load",
    "load_robot",
    "plan",
    "register_robot",
]


def _moved(home: str, *names: str) -> dict[str, str]:
    return {name: f"{home}.{name}" for name in names}


#: Names that left the front door → where they are now; they resolve, with a DeprecationWarning, for
#: one release.
MOVED: dict[str, str] = {
    **_moved(
        "kinlearn.body", "BACKENDS", "ROBOTS", "Kinematics", "StateLayout", "dls_step", "unregister_robot"
    ),
    **_moved("kinlearn.collision", "BodySpheres", "body_spheres", "check_path"),
    **_moved(
        "kinlearn.data",
        "BabblingConfig",
        "EndpointConfig",
        "EndpointPairs",
        "Transitions",
        "babble",
        "load_endpoints",
        "load_transitions",
        "make_endpoints",
        "save_endpoints",
        "save_transitions",
    ),
    **_moved(
        "kinlearn.models",
        "AnalyticFM",
        "AnalyticIM",
        "ChainFM",
        "FMConfig",
        "ForwardModel",
        "IMConfig",
        "InverseModel",
        "JointPathConfig",
        "JointPathModel",
        "LearnedBody",
        "LearnedFM",
        "LearnedIM",
        "LossConfig",
        "ObstaclePathConfig",
        "ObstaclePathModel",
        "TMConfig",
        "TrajectoryModel",
        "load_body_model",
        "load_fm",
        "load_im",
        "load_obstacle_model",
        "load_path_model",
        "rectify",
        "save_model",
        "tm_loss",
    ),
    **_moved(
        "kinlearn.train",
        "ObstacleLossConfig",
        "ObstacleTrainConfig",
        "OptimConfig",
        "PathLossConfig",
        "PathTrainConfig",
        "TMTrainConfig",
        "TrainConfig",
        "identify",
        "load_tm",
        "tm_preset",
        "train_config",
        "train_fm",
        "train_im",
        "train_obstacle_model",
        "train_path_model",
        "train_tm",
        "validate_models",
    ),
    **_moved("kinlearn.baselines", "RRTConnect", "rrt_connect"),
    "JointInterpolation": "kinlearn.baselines.JointLine",
    "CartesianDLS": "kinlearn.baselines.CartesianLine",
    "joint_interpolation": "kinlearn.baselines.joint_line",
    "cartesian_dls": "kinlearn.baselines.cartesian_line",
    **_moved("kinlearn.evaluation.metrics", "plan_metrics", "summarize", "trajectory_metrics"),
    **_moved("kinlearn.planning.timing", "TimedTrajectory", "time_parameterize"),
    **_moved(
        "kinlearn.errors",
        "DTypeError",
        "DatasetError",
        "MissingDependencyError",
        "RecordedDataError",
        "RobotDescriptionError",
        "RunDirectoryError",
        "StateError",
    ),
}

__getattr__, __dir__ = lazy_package(__name__, __file__, __all__, MOVED)
