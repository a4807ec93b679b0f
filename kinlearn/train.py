"""Training, by what is trained: the forward and inverse models, the trajectory models, the obstacle-aware
model, the body model, and the identification of a kinematic chain from observations.

=====================================  =============================================================
FM / IM                                :func:`train_fm`, :func:`train_im`, :func:`train_config`,
                                       :func:`validate_models` (against the analytic robot)
waypoint trajectory model (the paper)  :func:`train_tm`, :class:`TMTrainConfig`, :func:`tm_preset`,
                                       :func:`load_tm` (a TM with its training configuration)
joint-path trajectory model            :func:`train_path_model`, :class:`PathTrainConfig`,
                                       :class:`PathLossConfig`
obstacle-aware trajectory model        :func:`train_obstacle_model`, :class:`ObstacleTrainConfig`,
                                       :class:`ObstacleLossConfig`
body model                             :func:`train_body_model`
identification (calibration)           :func:`identify`, :class:`IdentifyConfig`, :class:`Identification`
a new arm, URDF to planner             :func:`onboard`, :class:`OnboardConfig`, :func:`load_onboarded`
the generic loop's settings            :class:`TrainConfig`, :class:`OptimConfig`
=====================================  =============================================================

The models' own configurations (:class:`~kinlearn.models.configs.FMConfig`, ``TMConfig``, ...) are in
:mod:`kinlearn.models`; the data they are trained on in :mod:`kinlearn.data`. Each name is imported when
first used.
"""

from typing import TYPE_CHECKING

from .lazy import lazy_package

if TYPE_CHECKING:
    from .training.body import train_body_model
    from .training.forward_inverse import train_config, train_fm, train_im, validate_models
    from .training.identify import Identification, IdentifyConfig, identify
    from .training.joint_path import PathLossConfig, PathTrainConfig, train_path_model
    from .training.loop import OptimConfig, TrainConfig
    from .training.obstacle_path import ObstacleLossConfig, ObstacleTrainConfig, train_obstacle_model
    from .training.onboard import OnboardConfig, load_onboarded, onboard
    from .training.tm import TMTrainConfig, load_tm, tm_preset, train_tm

__all__ = [
    "Identification",
    "IdentifyConfig",
    "ObstacleLossConfig",
    "ObstacleTrainConfig",
    "OnboardConfig",
    "OptimConfig",
    "PathLossConfig",
    "PathTrainConfig",
    "TMTrainConfig",
    "TrainConfig",
    "identify",
    "load_onboarded",
    "load_tm",
    "onboard",
    "tm_preset",
    "train_body_model",
    "train_config",
    "train_fm",
    "train_im",
    "train_obstacle_model",
    "train_path_model",
    "train_tm",
    "validate_models",
]

__getattr__, __dir__ = lazy_package(__name__, __file__, __all__)
