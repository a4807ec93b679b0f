"""The learned and analytic models: FM/IM, the trajectory models, the body model, Algorithm 1's rollout.

==========================  ===================================================================
forward and inverse models  :class:`ForwardModel`, :class:`InverseModel` (the interfaces),
                            :class:`LearnedFM`, :class:`LearnedIM`, :class:`AnalyticFM`,
                            :class:`AnalyticIM`, :class:`ChainFM` (an identified chain),
                            :class:`FMConfig`, :class:`IMConfig`, :class:`ChainConfig`,
                            :func:`fm_config`, :func:`im_config` (presets)
trajectory models           :class:`TrajectoryModel` (the paper's waypoint TM), :class:`TMConfig`,
                            :class:`JointPathModel`, :class:`JointPathConfig`,
                            :class:`ObstaclePathModel`, :class:`ObstaclePathConfig`
body model                  :class:`LearnedBody`, :class:`BodyModelConfig`
Algorithm 1's rollout       :func:`rectify`, :func:`tm_loss`, :class:`LossConfig`
files                       :func:`save_model`, :func:`load_fm`, :func:`load_im`,
                            :func:`load_trajectory_model`, :func:`load_path_model`,
                            :func:`load_obstacle_model`, :func:`load_body_model`
                            (or :func:`kinlearn.load` for any of them)
==========================  ===================================================================

Each name is imported when first used.
"""

from typing import TYPE_CHECKING

from ..lazy import lazy_package

if TYPE_CHECKING:
    from .analytic import AnalyticFM, AnalyticIM
    from .body import BodyModelConfig, LearnedBody, load_body_model
    from .chain import ChainConfig, ChainFM
    from .checkpoint import load_fm, load_im, save_model
    from .configs import FMConfig, IMConfig
    from .interface import ForwardModel, InverseModel
    from .joint_path import JointPathConfig, JointPathModel, load_path_model
    from .learned import LearnedFM, LearnedIM
    from .obstacle_path import ObstaclePathConfig, ObstaclePathModel, load_obstacle_model
    from .presets import fm_config, im_config
    from .rollout import LossConfig, rectify, tm_loss
    from .trajectory import TMConfig, TrajectoryModel, load_trajectory_model

__all__ = [
    "AnalyticFM",
    "AnalyticIM",
    "BodyModelConfig",
    "ChainConfig",
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
    "fm_config",
    "im_config",
    "load_body_model",
    "load_fm",
    "load_im",
    "load_obstacle_model",
    "load_path_model",
    "load_trajectory_model",
    "rectify",
    "save_model",
    "tm_loss",
]

__getattr__, __dir__ = lazy_package(__name__, __file__, __all__)
