"""FM and IM checkpoints: :func:`save_model` (weights + config + robot + format version, via
:mod:`kinlearn.io`), :func:`load_fm`, :func:`load_im`, and :func:`frozen_fm_im`, the frozen pair a
trajectory model is trained or planned through. Learned, chain and analytic models alike."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from ..body.robot import Robot
from ..errors import CheckpointError, ConfigError
from ..io import load_checkpoint, save_checkpoint
from .analytic import AnalyticFM, AnalyticIM
from .chain import ChainConfig, ChainFM
from .configs import FMConfig, IMConfig
from .interface import ForwardModel, InverseModel
from .learned import LearnedFM, LearnedIM

__all__ = ["frozen_fm_im", "load_fm", "load_im", "save_model"]


def save_model(model: ForwardModel | InverseModel, path: str | Path, extra: dict | None = None) -> Path:
    """Save a model's weights, config, robot name and format version (atomically).

    Analytic models are saved too (no weights; their config rebuilds them), so a planner's FM/IM
    choice is a file either way. ``extra`` (a dict of tensors and plain values) is stored beside.
    """
    if not isinstance(model, (ForwardModel, InverseModel)):
        raise ConfigError(f"save_model needs a ForwardModel or InverseModel, got {type(model).__name__}")
    config = model.config_dict()
    if isinstance(model, (LearnedFM, LearnedIM)):
        config = {"type": "learned", **config}
    elif isinstance(model, ChainFM):
        config = {"type": "chain", **config}
    elif not isinstance(model, (AnalyticFM, AnalyticIM)):
        raise ConfigError(f"save_model cannot save a {type(model).__name__} (it has no checkpoint form)")
    return save_checkpoint(
        path,
        kind=model.kind,
        robot=model.robot_name,
        config=config,
        state_dict=model.state_dict(),
        extra=extra,
    )


def _build(payload: dict, path, kind: str):
    config = dict(payload.get("config") or {})
    mtype = config.pop("type", None)
    try:
        if mtype == "analytic":
            robot = config.pop("robot")
            model = AnalyticFM(robot) if kind == "fm" else AnalyticIM(robot, **config)
        elif mtype == "chain" and kind == "fm":
            model = ChainFM(ChainConfig.from_dict(config))
        elif mtype == "learned":
            cls, cfg_cls = (LearnedFM, FMConfig) if kind == "fm" else (LearnedIM, IMConfig)
            model = cls(cfg_cls.from_dict(config))
        else:
            raise CheckpointError(
                f"{path}: unknown {kind.upper()} type {mtype!r} (expected 'learned', 'chain' or 'analytic')"
            )
        model.load_state_dict(payload["state_dict"], strict=True)
    except CheckpointError:
        raise
    except Exception as exc:
        raise CheckpointError(
            f"{path}: cannot rebuild the {kind.upper()} from its config and weights ({type(exc).__name__}: {exc})"
        ) from exc
    if model.robot_name != payload.get("robot"):
        raise CheckpointError(
            f"{path}: config robot {model.robot_name!r} != checkpoint robot {payload.get('robot')!r}"
        )
    return model.eval()


def load_fm(path: str | Path, robot: str | None = None) -> ForwardModel:
    """Load a forward model saved by :func:`save_model`; ``robot`` (if given) must match the checkpoint's."""
    return _build(load_checkpoint(path, kind="fm", robot=robot), path, "fm")


def load_im(path: str | Path, robot: str | None = None) -> InverseModel:
    """Load an inverse model saved by :func:`save_model`; ``robot`` (if given) must match the checkpoint's."""
    return _build(load_checkpoint(path, kind="im", robot=robot), path, "im")


def frozen_fm_im(
    robot: Robot,
    fm: Literal["learned", "analytic"],
    im: Literal["learned", "analytic"],
    *,
    fm_path: str | Path | None = None,
    im_path: str | Path | None = None,
    im_iterations: int = 1,
    im_damping: float = 1e-2,
) -> tuple[ForwardModel, InverseModel]:
    """The FM and IM a trajectory model is trained or planned through, frozen (eval mode, no gradient
    to their weights): each learned (loaded from its path) or analytic (FK; ``im_iterations`` damped
    least-squares steps of damping ``im_damping``)."""
    f = AnalyticFM(robot) if fm == "analytic" else load_fm(fm_path, robot=robot.name)
    i = (
        AnalyticIM(robot, iterations=im_iterations, damping=im_damping)
        if im == "analytic"
        else load_im(im_path, robot=robot.name)
    )
    for m in (f, i):
        m.eval()
        m.requires_grad_(False)
    return f, i
