"""Training the forward and inverse models on babbling data, and validating them against the analytic robot.

:func:`train_fm`, :func:`train_im` and :func:`train_im_distal` run :func:`~kinlearn.training.loop.fit`
(the one training loop) with the presets of :data:`TRAIN_PRESETS`; :func:`validate_models` measures
the result on held-out motion against the paper's figures (:data:`PAPER_FIGURES`) and kinlearn's
goals (:data:`GOALS`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import torch
from torch import nn

from ..body.kinematics import kinematics
from ..body.robot import Robot, load_robot
from ..body.state import StateLayout
from ..data.babbling import MAX_STEP, BabblingConfig, Transitions, babble
from ..errors import ConfigError, DatasetError
from ..io import content_sha256
from ..models.forward_inverse import (
    FMConfig,
    ForwardModel,
    IMConfig,
    InverseModel,
    LearnedFM,
    LearnedIM,
    save_model,
)
from .loop import OptimConfig, TrainConfig, _load_to_resume, fit, seed_everything

__all__ = [
    "GOALS",
    "PAPER_FIGURES",
    "THROUGH_FM_ACTION_WEIGHT",
    "TRAIN_PRESETS",
    "TrainResult",
    "data_max_step",
    "format_validation_table",
    "train_config",
    "train_fm",
    "train_im",
    "train_im_distal",
    "validate_models",
]


# --------------------------------------------------------------------------------------------------
# Forward and inverse model training
# --------------------------------------------------------------------------------------------------

#: Named training settings per model kind. ``paper``: the paper's Sect. 4 (Cibula et al., ICANN 2024, Sect. 4.1, for the architectures). ``tiny``: seconds, for tests.
TRAIN_PRESETS: dict[str, dict[str, dict]] = {
    "fm": {
        "paper": {"optim": {"name": "adam", "lr": 1e-3}, "epochs": 60, "batch_size": 256},
        "improved": {
            "optim": {"name": "adam", "lr": 3e-3},
            "epochs": 30,
            "batch_size": 512,
            "schedule": "cosine",
            "min_lr_ratio": 0.01,
        },
        "tiny": {"optim": {"name": "adam", "lr": 3e-3}, "epochs": 4, "batch_size": 128},
    },
    "im": {
        "paper": {
            "optim": {"name": "adamw", "lr": 1e-3, "weight_decay": 4e-3},
            "epochs": 100,
            "batch_size": 256,
        },
        "improved": {
            "optim": {"name": "adam", "lr": 3e-3},
            "epochs": 100,
            "batch_size": 256,
            "schedule": "cosine",
            "min_lr_ratio": 0.01,
        },
        "tiny": {"optim": {"name": "adam", "lr": 3e-3}, "epochs": 4, "batch_size": 128},
    },
}


def train_config(kind: Literal["fm", "im"], preset: str = "paper", **overrides) -> TrainConfig:
    """The :class:`TrainConfig` of a preset (see :data:`TRAIN_PRESETS`) with ``overrides`` applied."""
    if kind not in TRAIN_PRESETS:
        raise ConfigError(f"kind must be 'fm' or 'im', got {kind!r}")
    if preset not in TRAIN_PRESETS[kind]:
        raise ConfigError(
            f"unknown training preset {preset!r}; choose one of {', '.join(TRAIN_PRESETS[kind])}"
        )
    d = {**TRAIN_PRESETS[kind][preset], **overrides}
    d["optim"] = OptimConfig(**d["optim"]) if isinstance(d["optim"], dict) else d["optim"]
    return TrainConfig(**d)


@dataclass
class TrainResult:
    """What :func:`train_fm` / :func:`train_im` return: the trained model, its history and checkpoint."""

    model: nn.Module
    history: list[dict]
    checkpoint: Path | None


def _fm_metrics(model: LearnedFM, s, a, s_next) -> dict[str, float]:
    pred = model(s, a)
    L = model.layout
    return {
        "val_ef_mae_mm": float((pred[..., L.ef] - s_next[..., L.ef]).abs().mean()) * 1e3,
        "val_joints_mae_rad": float((pred[..., L.joints] - s_next[..., L.joints]).abs().mean()),
    }


def _im_metrics(model: LearnedIM, s, a, s_next) -> dict[str, float]:
    pred = model(s, s_next[..., model.layout.ef])
    return {"val_action_mae_rad": float((pred - a).abs().mean())}


def _train_supervised(
    kind: str,
    model: LearnedFM | LearnedIM,
    data: Transitions,
    cfg: TrainConfig,
    run_dir: str | Path | None,
    resume: bool,
) -> TrainResult:
    if not isinstance(data, Transitions):
        raise DatasetError(f"training data must be kinlearn Transitions, got {type(data).__name__}")
    if data.robot != model.robot_name:
        raise DatasetError(
            f"the data were babbled with {data.robot!r}, the model is for {model.robot_name!r}"
        )
    if data.layout.dof != model.dof:
        raise DatasetError(f"the data have {data.layout.dof} joints, the model expects {model.dof}")
    dtype = next(model.parameters()).dtype
    train, val = data.to(dtype).split(cfg.val_fraction, seed=cfg.seed)
    model.fit_normalization(*train.tensors())
    metrics_fn = _fm_metrics if kind == "fm" else _im_metrics
    desc = f"{kind.upper()} training"
    return _fit_run(kind, model, data, (train, val), cfg, run_dir, resume, metrics_fn=metrics_fn, desc=desc)


def _fit_run(kind, model, data, split, cfg, run_dir, resume, through_fm=None, **fit_kwargs) -> TrainResult:
    """:func:`fit` ``model`` on ``split`` (train and held-out parts of ``data``), with the checkpoint
    ``run_dir/<kind>.pt`` recording the data and the frozen FM (``through_fm``) it was trained with."""
    ckpt = Path(run_dir) / f"{kind}.pt" if run_dir is not None else None
    identity = {}
    if ckpt is not None:
        identity["data_sha256"] = content_sha256(data.tensors())
        if through_fm is not None:
            identity["through_fm_sha256"] = content_sha256(through_fm)
    model_config = {"type": "learned", **model.config_dict()}
    train, val = split
    history = fit(
        model,
        train.tensors(),
        val.tensors() if len(val) else None,
        cfg,
        run_dir=run_dir,
        checkpoint=ckpt,
        save_fn=lambda path, m, extra: save_model(m, path, extra={**extra, **identity}),
        load_fn=lambda path: _load_to_resume(path, kind, model.robot_name, model_config, identity),
        resume=resume,
        **fit_kwargs,
    )
    return TrainResult(model, history, ckpt)


#: Per learned model kind: its config class and model class.
_KINDS = {"fm": (FMConfig, LearnedFM), "im": (IMConfig, LearnedIM)}


def _train_kind(kind: str, data, model, cfg: TrainConfig | None, run_dir, resume: bool) -> TrainResult:
    """:func:`train_fm` / :func:`train_im`: the preset's config by default, seeding, then the model built
    from ``model`` (None: the data's robot; a config; or a model to train further) and trained."""
    config_cls, model_cls = _KINDS[kind]
    cfg = cfg or train_config(kind, "paper")
    seed_everything(cfg.seed)
    if model is None:
        model = config_cls(robot=data.robot, dof=data.layout.dof)
    if isinstance(model, FMConfig):  # an FM is valid for the steps of the data it learns from
        model = dataclasses.replace(model, max_step=data_max_step(data))
    if isinstance(model, config_cls):
        model = model_cls(model)
    if not isinstance(model, model_cls):
        raise ConfigError(f"train_{kind} trains a {model_cls.__name__}, got {type(model).__name__}")
    return _train_supervised(kind, model, data, cfg, run_dir, resume)


def data_max_step(data: Transitions) -> float:
    """The babbling step bound ``data`` were made with (their babbling config's ``max_step``, rad), or
    :data:`~kinlearn.data.babbling.MAX_STEP` where they record none (recorded observations)."""
    return float((data.config or {}).get("max_step", MAX_STEP))


def train_fm(
    data: Transitions,
    model: FMConfig | LearnedFM | None = None,
    cfg: TrainConfig | None = None,
    run_dir: str | Path | None = None,
    resume: bool = False,
) -> TrainResult:
    """Train a :class:`LearnedFM` on babbling transitions (paper settings by default).

    ``model`` is a config (the model is built after seeding with ``cfg.seed``; its ``max_step`` becomes
    the data's babbling step bound, :func:`data_max_step`) or a model to train further. With ``run_dir`` the checkpoint ``run_dir/fm.pt`` (loadable by :func:`kinlearn.models.forward_inverse.load_fm`)
    and ``metrics.jsonl`` are written every epoch; ``resume=True`` continues from that checkpoint.
    """
    return _train_kind("fm", data, model, cfg, run_dir, resume)


def train_im(
    data: Transitions,
    model: IMConfig | LearnedIM | None = None,
    cfg: TrainConfig | None = None,
    run_dir: str | Path | None = None,
    resume: bool = False,
) -> TrainResult:
    """Train a :class:`LearnedIM` on babbling transitions (paper settings by default); see :func:`train_fm`."""
    return _train_kind("im", data, model, cfg, run_dir, resume)


#: ``kinlearn train-im --through-fm``'s pull toward the babbled action (``--action-weight``): the shipped
#: IMs were refined with it. :func:`train_im_distal`'s own default (0.1) is what ``reproduce`` uses.
THROUGH_FM_ACTION_WEIGHT = 0.01


def train_im_distal(
    data: Transitions,
    im: LearnedIM,
    fm: ForwardModel,
    cfg: TrainConfig | None = None,
    run_dir: str | Path | None = None,
    resume: bool = False,
    action_weight: float = 0.1,
) -> TrainResult:
    """Train ``im`` through the frozen forward model ``fm``: the action must *reach* the target.

    Regression onto babbled actions learns, for a redundant arm, the mean of the many actions that
    reach a displacement, which need not reach it. Here the loss is the distance between the target
    ef(t+1) and where ``fm`` says the IM's action leads, ‖FM(s, IM(s, ef′))_ef − ef′‖², plus
    ``action_weight`` times the squared error to the babbled action, which picks one solution among
    the redundant ones. Both terms are divided by the data's variance (of the ef step and of the
    action) so that the weight is unit-free. Only the IM's parameters change; ``fm`` is frozen.
    ``im`` is usually a model already trained by :func:`train_im`, refined here.
    """
    cfg = cfg or train_config("im", "improved", epochs=10)
    if not isinstance(im, LearnedIM):
        raise ConfigError(f"train_im_distal refines a LearnedIM, got {type(im).__name__}")
    if fm.robot_name != im.robot_name:
        raise ConfigError(f"the FM is for {fm.robot_name!r}, the IM for {im.robot_name!r}")
    if action_weight < 0:
        raise ConfigError(f"action_weight must be ≥ 0, got {action_weight}")
    fm.eval()
    fm.requires_grad_(False)
    seed_everything(cfg.seed)
    L = im.layout
    dtype = next(im.parameters()).dtype
    train, val = data.to(dtype).split(cfg.val_fraction, seed=cfg.seed)
    s, a, s_next = train.tensors()
    var_ef = float((s_next[:, L.ef] - s[:, L.ef]).square().mean())
    var_a = float(a.square().mean())

    def loss_fn(model, s, a, s_next):
        target = s_next[..., L.ef]
        action = model(s, target)
        reached = fm(s, action)[..., L.ef]
        return (reached - target).square().sum(-1).mean() / var_ef + action_weight * (
            (action - a).square().sum(-1).mean() / var_a
        )

    def metrics_fn(model, s, a, s_next):
        target = s_next[..., L.ef]
        reached = fm(s, model(s, target))[..., L.ef]
        return {"val_fm_reach_err_mm": float((reached - target).norm(dim=-1).mean()) * 1e3}

    fm_id = {"config": fm.config_dict(), "state_dict": fm.state_dict(), "action_weight": action_weight}
    kwargs = {"loss_fn": loss_fn, "metrics_fn": metrics_fn, "desc": "IM training through the FM"}
    return _fit_run("im", im, data, (train, val), cfg, run_dir, resume, through_fm=fm_id, **kwargs)


# --------------------------------------------------------------------------------------------------
# Validation against the analytic robot
# --------------------------------------------------------------------------------------------------

#: The paper's reported mean absolute errors (its Sect. 4) and this project's goals.
PAPER_FIGURES = {"fm_ef_mae_mm": 1.1, "fm_joints_mae_rad": 6.3e-4, "im_action_mae_rad": 1.7e-3}
GOALS = {"fm_ef_mae_mm": 0.5, "fm_joints_mae_rad": 3e-4, "im_action_mae_rad": 1e-3}


@torch.no_grad()
def validate_models(
    fm: ForwardModel | None,
    im: InverseModel | None,
    robot: Robot | str = "iiwa14",
    n: int = 100_000,
    seed: int = 10_000,
    max_step: float = MAX_STEP,
    retarget_prob: float = 0.0,
    walkers: int = 1000,
) -> dict:
    """Errors of ``fm`` and/or ``im`` on ``n`` fresh babbling transitions (babbled with ``seed``).

    Returns a dict with, where the model is given:

    - ``fm_ef_mae_mm``, ``fm_joints_mae_rad``: mean absolute error per coordinate of the FM's next
      state against analytic FK (ef in mm, joints in rad);
    - ``im_action_mae_rad``: mean absolute error per joint of the IM's action against the babbled one;
    - ``im_exec_err_mm`` (mean), ``im_exec_err_mm_median``, ``im_exec_err_mm_p95``: Euclidean distance
      between FK(θ + â), the IM's action executed on the robot (clamped to the limits), and the
      requested target ef(t+1);
    - the trivial predictors' errors for scale: ``fm_ef_mae_mm_identity`` (s' = s),
      ``im_action_mae_rad_zero`` and ``im_exec_err_mm_zero`` (a = 0, the mean distance to the target).
    """
    robot = robot if isinstance(robot, Robot) else load_robot(robot)
    for m, what in ((fm, "fm"), (im, "im")):
        if m is not None and m.robot_name != robot.name:
            raise ConfigError(
                f"the {what.upper()} belongs to {m.robot_name!r}, validation robot is {robot.name!r}"
            )
    cfg = BabblingConfig.for_transitions(
        n, walkers=walkers, robot=robot.name, seed=seed, max_step=max_step, retarget_prob=retarget_prob
    )
    data = babble(cfg, robot)
    L = StateLayout(robot.dof)
    s, a, s_next = (t[:n] for t in data.tensors())
    out: dict = {"robot": robot.name, "n": int(s.shape[0]), "seed": seed}
    out["fm_ef_mae_mm_identity"] = float((s[:, L.ef] - s_next[:, L.ef]).abs().mean()) * 1e3
    out["im_action_mae_rad_zero"] = float(a.abs().mean())
    out["im_exec_err_mm_zero"] = float((s[:, L.ef] - s_next[:, L.ef]).norm(dim=-1).mean()) * 1e3
    if fm is not None:
        dtype = _model_dtype(fm, s.dtype)
        pred = _batched(lambda s_, a_: fm(s_, a_), s.to(dtype), a.to(dtype)).to(s.dtype)
        out["fm_ef_mae_mm"] = float((pred[:, L.ef] - s_next[:, L.ef]).abs().mean()) * 1e3
        out["fm_joints_mae_rad"] = float((pred[:, L.joints] - s_next[:, L.joints]).abs().mean())
    if im is not None:
        dtype = _model_dtype(im, s.dtype)
        ef_t = s_next[:, L.ef]
        a_hat = _batched(lambda s_, e_: im(s_, e_), s.to(dtype), ef_t.to(dtype)).to(s.dtype)
        out["im_action_mae_rad"] = float((a_hat - a).abs().mean())
        lo, hi = robot.limits(s.dtype)
        theta = torch.clamp(s[:, L.joints] + a_hat, lo, hi)
        dist = (kinematics(robot, "fast").position(theta, validate=False) - ef_t).norm(dim=-1) * 1e3
        out["im_exec_err_mm"] = float(dist.mean())
        out["im_exec_err_mm_median"] = float(dist.median())
        out["im_exec_err_mm_p95"] = float(torch.quantile(dist[:100_000].double(), 0.95))
    return out


def _model_dtype(model: nn.Module, default: torch.dtype) -> torch.dtype:
    p = next(iter(model.parameters()), None)
    return p.dtype if p is not None else default


def _batched(fn, x: torch.Tensor, y: torch.Tensor, chunk: int = 65536) -> torch.Tensor:
    return torch.cat([fn(xc, yc) for xc, yc in zip(x.split(chunk), y.split(chunk), strict=True)])


def format_validation_table(results: dict | Sequence[tuple[str, dict]]) -> str:
    """A markdown table of :func:`validate_models` results beside the paper's figures and the goals.

    ``results`` is one result dict or a sequence of ``(label, result)`` pairs (one column each).
    """
    cols = [("ours", results)] if isinstance(results, dict) else list(results)
    rows = [
        ("FM ef MAE (mm)", "fm_ef_mae_mm", "{:.3f}"),
        ("FM joints MAE (rad)", "fm_joints_mae_rad", "{:.2e}"),
        ("IM action MAE (rad)", "im_action_mae_rad", "{:.2e}"),
        ("IM executed ef error, mean (mm)", "im_exec_err_mm", "{:.2f}"),
        ("IM executed ef error, median (mm)", "im_exec_err_mm_median", "{:.2f}"),
        ("IM executed ef error, p95 (mm)", "im_exec_err_mm_p95", "{:.2f}"),
        ("trivial s' = s: ef MAE (mm)", "fm_ef_mae_mm_identity", "{:.3f}"),
        ("trivial a = 0: action MAE (rad)", "im_action_mae_rad_zero", "{:.2e}"),
        ("trivial a = 0: executed ef error, mean (mm)", "im_exec_err_mm_zero", "{:.2f}"),
    ]
    head = ["metric", *[label for label, _ in cols], "paper", "goal"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, key, fmt in rows:
        if not any(key in r for _, r in cols):
            continue
        vals = [fmt.format(r[key]) if key in r else "–" for _, r in cols]
        paper = fmt.format(PAPER_FIGURES[key]) if key in PAPER_FIGURES else "–"
        goal = ("≤ " + fmt.format(GOALS[key])) if key in GOALS else "–"
        lines.append("| " + " | ".join([name, *vals, paper, goal]) + " |")
    return "\n".join(lines)
