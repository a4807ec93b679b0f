"""Forward and inverse models of a robot, learned (MLPs) or analytic, behind one interface.

=================  ================================================================================
``ForwardModel``   ``forward(s (..., S), a (..., dof)) -> s_next (..., S)``
``InverseModel``   ``forward(s (..., S), ef_target (..., 3)) -> a (..., dof)``
=================  ================================================================================

S = dof + 3 and s = [θ, ef] (:class:`~kinlearn.body.state.StateLayout`). Every model has ``layout`` and
``robot_name``, accepts leading batch dimensions, is differentiable in its inputs and follows the
inputs' dtype (learned models hold float32 weights unless converted with ``.to()``).

Learned models (the paper's Sect. 4; Cibula et al., ICANN 2024, Sect. 4.1):

- :class:`LearnedFM`: input [s, a] → shared dense layer(s) → a joints head (→ θ') and an ef head
  (→ ef'). Paper: shared 30 tanh; heads 20 tanh → 7 linear and 20 tanh → 3 linear.
- :class:`LearnedIM`: input [s, ef_target] → dense 40-60-60-40 tanh → dof linear (the action).

Options beyond the paper (off in the ``paper`` preset): ``normalize`` (inputs and outputs
standardised by buffers fitted on the training data with :meth:`fit_normalization`),
``predict_delta`` (the FM predicts s' − s and adds s) and, for the IM, ``ef_delta_input`` (the IM
sees ef_target − ef instead of ef_target).

Analytic models (for the ablation): :class:`AnalyticFM` (θ' = θ + a, ef' = FK(θ')) and
:class:`AnalyticIM` (damped-least-squares steps toward the target, kept within the joint limits).

Checkpoints: :func:`save_model`, :func:`load_fm`, :func:`load_im` (weights + config + robot + format
version, via :mod:`kinlearn.io`). :func:`kinlearn.training.forward_inverse.validate_models` measures
models against the analytic robot on fresh babbling data.

This module gathers the names; each is defined in a module of its own concept: :mod:`.configs`
(:class:`FMConfig`, :class:`IMConfig`), :mod:`.presets` (``FM_PRESETS``, :func:`fm_config`, …),
:mod:`.layers` (the dense layers and the normaliser), :mod:`.learned`, :mod:`.analytic` and
:mod:`.checkpoint` (saving, loading, :func:`frozen_fm_im`).
"""

from __future__ import annotations

from .analytic import AnalyticFM, AnalyticIM
from .checkpoint import frozen_fm_im, load_fm, load_im, save_model
from .configs import FMConfig, IMConfig
from .interface import ForwardModel, InverseModel
from .layers import ACTIVATIONS
from .learned import LearnedFM, LearnedIM
from .presets import FM_PRESETS, IM_PRESETS, fm_config, im_config

__all__ = [
    "ACTIVATIONS",
    "FM_PRESETS",
    "IM_PRESETS",
    "AnalyticFM",
    "AnalyticIM",
    "FMConfig",
    "ForwardModel",
    "IMConfig",
    "InverseModel",
    "LearnedFM",
    "LearnedIM",
    "fm_config",
    "frozen_fm_im",
    "im_config",
    "load_fm",
    "load_im",
    "save_model",
]
