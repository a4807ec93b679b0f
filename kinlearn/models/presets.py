"""Named settings of the learned FM and IM (``paper``, ``improved``, ``tiny``) and the configs they give."""

from __future__ import annotations

from ..body.robot import load_robot
from ..errors import ConfigError
from .configs import FMConfig, IMConfig

__all__ = ["FM_PRESETS", "IM_PRESETS", "fm_config", "im_config"]

#: Named model settings. ``paper`` is the paper's FM and IM exactly (Sect. 4; Cibula et al., ICANN 2024, Sect. 4.1); ``improved`` adds normalisation,
#: delta prediction / ef-displacement input and width; ``tiny`` is ``improved``'s options at the
#: paper's widths (for quick tests).
FM_PRESETS: dict[str, dict] = {
    "paper": {},
    # Normalised, predicting the step; the end-effector step as a difference of a learned function
    # of the joints (see FMConfig.ef_mode); the joints head needs little width (θ' ≈ θ + a).
    "improved": {
        "normalize": True,
        "predict_delta": True,
        "shared": (64,),
        "joints_head": (64,),
        "ef_mode": "difference",
        "fk_hidden": (256, 256, 256),
    },
    "tiny": {"normalize": True, "predict_delta": True},
}
IM_PRESETS: dict[str, dict] = {
    "paper": {},
    "improved": {"normalize": True, "ef_delta_input": True, "hidden": (128, 128, 128)},
    "tiny": {"normalize": True, "ef_delta_input": True},
}


def fm_config(robot: str = "iiwa14", preset: str = "paper", **overrides) -> FMConfig:
    """An :class:`FMConfig` for ``robot`` from a named preset (see :data:`FM_PRESETS`)."""
    if preset not in FM_PRESETS:
        raise ConfigError(f"unknown FM preset {preset!r}; choose one of {', '.join(FM_PRESETS)}")
    return FMConfig(robot=robot, dof=load_robot(robot).dof, **{**FM_PRESETS[preset], **overrides})


def im_config(robot: str = "iiwa14", preset: str = "paper", **overrides) -> IMConfig:
    """An :class:`IMConfig` for ``robot`` from a named preset (see :data:`IM_PRESETS`)."""
    if preset not in IM_PRESETS:
        raise ConfigError(f"unknown IM preset {preset!r}; choose one of {', '.join(IM_PRESETS)}")
    return IMConfig(robot=robot, dof=load_robot(robot).dof, **{**IM_PRESETS[preset], **overrides})
