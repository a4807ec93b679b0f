"""kinlearn: learn robot kinematics and trajectory planning from the robot's own motor babbling."""

from .errors import (
    CheckpointError,
    ConfigError,
    DatasetError,
    JointLimitError,
    KinlearnError,
    NonFiniteError,
    RobotDescriptionError,
    ShapeError,
    UnknownRobotError,
)
from .kinematics import BACKENDS, Kinematics, dls_step, kinematics
from .robot import ROBOTS, Robot, available_robots, load_robot
from .state import StateLayout

__version__ = "0.1.0"

__all__ = [
    "BACKENDS",
    "ROBOTS",
    "CheckpointError",
    "ConfigError",
    "DatasetError",
    "JointLimitError",
    "Kinematics",
    "KinlearnError",
    "NonFiniteError",
    "Robot",
    "RobotDescriptionError",
    "ShapeError",
    "StateLayout",
    "UnknownRobotError",
    "__version__",
    "available_robots",
    "dls_step",
    "kinematics",
    "load_robot",
]
