"""Training: optimisers, run logging, seeding, a generic resumable loop, FM/IM training and validation.

The generic pieces (:class:`OptimConfig`, :func:`make_optimizer`, :class:`RunLogger`,
:func:`seed_everything`, :class:`TrainConfig`, :func:`fit`) know nothing about forward or inverse
models; :func:`train_fm` and :func:`train_im` put them together for the supervised models and
:func:`validate_models` checks the result against the analytic robot.

A training run directory holds ``metrics.jsonl`` (one JSON record per epoch) and a checkpoint written
atomically after every epoch with the weights, the optimiser's state, the epoch, the shuffling
generator's state and the history so far. ``resume=True`` continues from it: the learning rate is a
pure function of the step and the shuffling generator is restored, so a resumed run ends with the
same weights as an uninterrupted one. Resuming checks that the checkpoint was made with the same
training configuration, model configuration and data (:class:`~kinlearn.CheckpointError` naming
what differs); a constant-rate run may be extended to more epochs.

Divergence is an error (:class:`~kinlearn.errors.TrainingDivergedError`): a non-finite loss, or an
epoch's mean loss above :data:`DIVERGENCE_FACTOR` times the loss of the run's first step.
"""

from __future__ import annotations

import dataclasses
import json
import math
import random
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import torch
from torch import nn
from tqdm.auto import tqdm

from ..body.kinematics import kinematics
from ..body.robot import Robot, load_robot
from ..body.state import StateLayout
from ..data.babbling import BabblingConfig, Transitions, babble
from ..errors import CheckpointError, ConfigError, DatasetError, TrainingDivergedError
from ..io import atomic_write, content_sha256, load_checkpoint, remove_stale_tmp
from ..models.forward_inverse import (
    FMConfig,
    ForwardModel,
    IMConfig,
    InverseModel,
    LearnedFM,
    LearnedIM,
    save_model,
)
from ..runs import diff_configs

__all__ = [
    "DIVERGENCE_FACTOR",
    "GOALS",
    "PAPER_FIGURES",
    "TRAIN_PRESETS",
    "OptimConfig",
    "RunLogger",
    "TrainConfig",
    "TrainResult",
    "fit",
    "fit_iterations",
    "format_validation_table",
    "make_optimizer",
    "seed_everything",
    "train_config",
    "train_fm",
    "train_im",
    "train_im_distal",
    "validate_models",
]


# --------------------------------------------------------------------------------------------------
# Generic pieces
# --------------------------------------------------------------------------------------------------

#: An epoch's mean loss above this multiple of the first step's loss means training diverged.
DIVERGENCE_FACTOR = 1e6


@dataclass
class OptimConfig:
    """An optimiser. ``alpha`` is RMSprop's smoothing constant γ; ``momentum`` applies to RMSprop and SGD."""

    name: Literal["adam", "adamw", "rmsprop", "sgd"] = "adam"
    lr: float = 1e-3
    weight_decay: float = 0.0
    alpha: float = 0.99
    momentum: float = 0.0

    def __post_init__(self) -> None:
        if self.name not in _OPTIMIZERS:
            raise ConfigError(f"unknown optimiser {self.name!r}; choose one of {', '.join(_OPTIMIZERS)}")
        if not (self.lr > 0.0 and math.isfinite(self.lr)):
            raise ConfigError(f"lr must be a positive number, got {self.lr}")
        if self.weight_decay < 0.0 or self.momentum < 0.0 or not 0.0 <= self.alpha < 1.0:
            raise ConfigError(
                f"need weight_decay ≥ 0, momentum ≥ 0 and 0 ≤ alpha < 1; got {self.weight_decay}, "
                f"{self.momentum}, {self.alpha}"
            )


_OPTIMIZERS: dict[str, Callable[[OptimConfig, Any], torch.optim.Optimizer]] = {
    "adam": lambda c, p: torch.optim.Adam(p, lr=c.lr, weight_decay=c.weight_decay),
    "adamw": lambda c, p: torch.optim.AdamW(p, lr=c.lr, weight_decay=c.weight_decay),
    "rmsprop": lambda c, p: torch.optim.RMSprop(
        p, lr=c.lr, alpha=c.alpha, weight_decay=c.weight_decay, momentum=c.momentum
    ),
    "sgd": lambda c, p: torch.optim.SGD(p, lr=c.lr, weight_decay=c.weight_decay, momentum=c.momentum),
}


def make_schedule(
    opt: torch.optim.Optimizer, kind: str, total_steps: int
) -> torch.optim.lr_scheduler.LambdaLR:
    """The learning-rate schedule per optimiser step: ``"constant"``, or ``"cosine"`` decay from the
    optimiser's rate to zero over ``total_steps`` (then zero)."""
    if kind == "constant":
        return torch.optim.lr_scheduler.LambdaLR(opt, lambda k: 1.0)
    if kind != "cosine":
        raise ConfigError(f"schedule must be 'constant' or 'cosine', got {kind!r}")
    total = max(1, int(total_steps))
    return torch.optim.lr_scheduler.LambdaLR(
        opt, lambda k: 0.5 * (1 + math.cos(math.pi * min(k, total) / total))
    )


def make_optimizer(cfg: OptimConfig, params) -> torch.optim.Optimizer:
    """The optimiser named by ``cfg`` over ``params``."""
    return _OPTIMIZERS[cfg.name](cfg, params)


def seed_everything(seed: int) -> torch.Generator:
    """Seed torch, numpy and ``random`` with ``seed``; returns a CPU ``torch.Generator`` seeded with it."""
    seed = int(seed)
    torch.manual_seed(seed)
    np.random.seed(seed % 2**32)  # noqa: NPY002 (the legacy global RNG, for code that uses it)
    random.seed(seed)
    return torch.Generator().manual_seed(seed)


class RunLogger:
    """Append one JSON line per record to ``run_dir/metrics.jsonl``; TensorBoard scalars when installed.

    Numeric values of a record become TensorBoard scalars at step ``record["epoch"]`` (or a running
    count). Usable as a context manager.
    """

    def __init__(self, run_dir: str | Path, tensorboard: bool = True):
        self.run_dir = Path(run_dir)
        self.run_dir.mkdir(parents=True, exist_ok=True)
        self.path = self.run_dir / "metrics.jsonl"
        self._fh = open(self.path, "a")
        self._count = 0
        self._tb = None
        if tensorboard:
            try:
                from torch.utils.tensorboard import SummaryWriter

                self._tb = SummaryWriter(log_dir=str(self.run_dir / "tensorboard"))
            except Exception:  # tensorboard not installed: JSONL only
                self._tb = None

    def log(self, record: dict) -> None:
        self._fh.write(json.dumps(record, sort_keys=True) + "\n")
        self._fh.flush()
        self._count += 1
        if self._tb is not None:
            step = int(record.get("epoch", self._count))
            for key, value in record.items():
                if isinstance(value, (int, float)) and not isinstance(value, bool) and key != "epoch":
                    self._tb.add_scalar(key, value, step)
            self._tb.flush()

    def close(self) -> None:
        if not self._fh.closed:
            self._fh.close()
        if self._tb is not None:
            self._tb.close()
            self._tb = None

    def __enter__(self) -> RunLogger:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _truncate_log(path: Path, epoch: int) -> None:
    """Drop records of epochs after ``epoch`` (written after the last checkpoint) from a JSONL log."""
    if not path.is_file():
        return
    keep = []
    for line in path.read_text().splitlines():
        try:
            rec = json.loads(line)
        except json.JSONDecodeError:
            continue
        if int(rec.get("epoch", 0)) <= epoch:
            keep.append(line)
    atomic_write(path, lambda p: p.write_text("".join(k + "\n" for k in keep)))


@dataclass
class TrainConfig:
    """A supervised training run.

    Attributes:
        optim: the optimiser.
        epochs, batch_size: passes over the training split and samples per step.
        val_fraction: share of the data held out (random split seeded by ``seed``).
        seed: seeds weight initialisation, the split and the shuffling.
        schedule: ``constant`` learning rate or ``cosine`` decay per step to ``lr × min_lr_ratio``.
        min_lr_ratio: final learning rate of the cosine schedule, relative to ``optim.lr``.
        progress: show a tqdm progress bar.
        eval_batch_size: batch size of evaluation (no gradients).
    """

    optim: OptimConfig = field(default_factory=OptimConfig)
    epochs: int = 60
    batch_size: int = 256
    val_fraction: float = 0.1
    seed: int = 0
    schedule: Literal["constant", "cosine"] = "constant"
    min_lr_ratio: float = 0.0
    progress: bool = True
    eval_batch_size: int = 65536

    def __post_init__(self) -> None:
        if isinstance(self.optim, dict):
            self.optim = OptimConfig(**self.optim)
        if int(self.epochs) < 1 or int(self.batch_size) < 1 or int(self.eval_batch_size) < 1:
            raise ConfigError(
                f"epochs, batch_size and eval_batch_size must be ≥ 1, got {self.epochs}, "
                f"{self.batch_size}, {self.eval_batch_size}"
            )
        if not 0.0 <= self.val_fraction < 1.0:
            raise ConfigError(f"val_fraction must lie in [0, 1), got {self.val_fraction}")
        if self.schedule not in ("constant", "cosine"):
            raise ConfigError(f"schedule must be 'constant' or 'cosine', got {self.schedule!r}")
        if not 0.0 <= self.min_lr_ratio <= 1.0:
            raise ConfigError(f"min_lr_ratio must lie in [0, 1], got {self.min_lr_ratio}")

    def lr_at(self, step: int, total_steps: int) -> float:
        """Learning rate at optimiser step ``step`` (0-based) of ``total_steps``."""
        lr = self.optim.lr
        if self.schedule == "constant" or total_steps <= 1:
            return lr
        frac = min(step / (total_steps - 1), 1.0)
        return lr * (self.min_lr_ratio + (1.0 - self.min_lr_ratio) * 0.5 * (1.0 + math.cos(math.pi * frac)))

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    def resume_differences(self, stored: dict) -> list[str]:
        """What differs between this config and ``stored`` (a checkpoint's) in a way that forbids
        resuming: all but the progress bar and the evaluation batch size; a constant-rate run may
        change its number of epochs (its learning rate does not depend on it)."""
        diffs = diff_configs(stored, self.to_dict(), ignore=("progress", "eval_batch_size"))
        if self.schedule == "constant" and stored.get("schedule") == "constant":
            diffs = [d for d in diffs if not d.startswith("epochs:")]
        return diffs

    @classmethod
    def from_dict(cls, d: dict) -> TrainConfig:
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = set(d) - names
        if unknown:
            raise ConfigError(f"unknown TrainConfig field(s): {', '.join(sorted(unknown))}")
        return cls(**d)


def _loss_by_method(model: nn.Module, *batch: torch.Tensor) -> torch.Tensor:
    return model.training_loss(*batch)


def fit(
    model: nn.Module,
    train: Sequence[torch.Tensor],
    val: Sequence[torch.Tensor] | None,
    cfg: TrainConfig,
    *,
    loss_fn: Callable[..., torch.Tensor] = _loss_by_method,
    metrics_fn: Callable[..., dict[str, float]] | None = None,
    run_dir: str | Path | None = None,
    checkpoint: str | Path | None = None,
    save_fn: Callable[[Path, nn.Module, dict], object] | None = None,
    load_fn: Callable[[Path], dict] | None = None,
    resume: bool = False,
    desc: str = "train",
) -> list[dict]:
    """Minibatch training of ``model`` on in-memory tensors; returns the per-epoch history.

    ``train`` (and ``val``) are tensors sharing their first dimension; each step calls
    ``loss_fn(model, *batch)`` (default: ``model.training_loss(*batch)``). After each epoch the held-out
    loss and ``metrics_fn(model, *val)`` (a dict of floats, computed without gradients in chunks of
    ``cfg.eval_batch_size``, averaged over chunks by size) are recorded. With ``run_dir`` the records go
    to ``run_dir/metrics.jsonl``; with ``checkpoint`` and ``save_fn(path, model, extra)`` a checkpoint
    is written after every epoch, and ``resume=True`` restores the latest one through
    ``load_fn(path) -> {"state_dict": ..., "extra": ...}``, after checking that it was trained with the
    same ``cfg`` (:meth:`TrainConfig.resume_differences`; :class:`CheckpointError` otherwise).
    Raises :class:`TrainingDivergedError` when the loss diverges (see the module docstring).
    """
    train = tuple(train)
    n = train[0].shape[0]
    if n == 0 or any(t.shape[0] != n for t in train):
        raise DatasetError(
            f"training tensors must share a non-empty first dimension, got {[tuple(t.shape) for t in train]}"
        )
    opt = make_optimizer(cfg.optim, model.parameters())
    gen = torch.Generator().manual_seed(int(cfg.seed) + 1)
    steps_per_epoch = -(-n // cfg.batch_size)
    total_steps = steps_per_epoch * cfg.epochs
    start_epoch, history = 0, []
    loss_ref: float | None = None  # the loss of the run's first step: the scale divergence is judged on
    ckpt = Path(checkpoint) if checkpoint is not None else None
    if ckpt is not None:
        remove_stale_tmp(ckpt.parent, ckpt.name)  # left by a write that was killed
    if resume and ckpt is not None and ckpt.is_file():
        if load_fn is None:
            raise ConfigError("resume=True needs load_fn to read the checkpoint")
        payload = load_fn(ckpt)
        extra = payload.get("extra") or {}
        if "optimizer" not in extra or "epoch" not in extra:
            raise CheckpointError(f"{ckpt} holds no training state (optimizer, epoch); cannot resume from it")
        if isinstance(extra.get("train_config"), dict):
            diffs = cfg.resume_differences(extra["train_config"])
            if diffs:
                raise CheckpointError(
                    f"{ckpt} was trained with another training configuration ({'; '.join(diffs)}); resume "
                    "with the same settings or train into a new run directory"
                )
        try:
            model.load_state_dict(payload["state_dict"])
            opt.load_state_dict(extra["optimizer"])
        except (RuntimeError, ValueError, KeyError) as exc:
            raise CheckpointError(f"{ckpt} does not fit the model being trained ({exc})") from exc
        gen.set_state(extra["generator"])
        start_epoch, history = int(extra["epoch"]), list(extra.get("history", []))
        loss_ref = extra.get("loss_ref")
    logger = None
    if run_dir is not None:
        if start_epoch > 0:
            _truncate_log(Path(run_dir) / "metrics.jsonl", start_epoch)
        elif not resume:
            (Path(run_dir) / "metrics.jsonl").unlink(missing_ok=True)
        logger = RunLogger(run_dir)
    bar = tqdm(
        total=cfg.epochs, initial=start_epoch, desc=desc, disable=not cfg.progress, unit="epoch", leave=False
    )
    try:
        for epoch in range(start_epoch, cfg.epochs):
            t0 = time.perf_counter()
            model.train()
            perm = torch.randperm(n, generator=gen)
            shuffled = [t[perm] for t in train]
            total = torch.zeros((), dtype=torch.float64)
            step0 = epoch * steps_per_epoch
            for k in range(steps_per_epoch):
                lo = k * cfg.batch_size
                batch = [t[lo : lo + cfg.batch_size] for t in shuffled]
                if cfg.schedule != "constant":
                    lr = cfg.lr_at(step0 + k, total_steps)
                    for group in opt.param_groups:
                        group["lr"] = lr
                loss = loss_fn(model, *batch)
                if loss_ref is None:
                    loss_ref = float(loss.detach())
                opt.zero_grad(set_to_none=True)
                loss.backward()
                opt.step()
                total += loss.detach()
            record: dict[str, Any] = {
                "epoch": epoch + 1,
                "train_loss": float(total) / steps_per_epoch,
                "lr": opt.param_groups[0]["lr"],
            }
            _check_divergence(record["train_loss"], loss_ref, epoch)
            if val is not None and val[0].shape[0] > 0:
                record.update(_evaluate(model, tuple(val), cfg.eval_batch_size, loss_fn, metrics_fn))
            record["epoch_time_s"] = time.perf_counter() - t0
            history.append(record)
            if logger is not None:  # before the checkpoint: a resume drops records beyond it
                logger.log(record)
            if ckpt is not None and save_fn is not None:
                extra = {
                    "epoch": epoch + 1,
                    "optimizer": opt.state_dict(),
                    "generator": gen.get_state(),
                    "history": history,
                    "train_config": cfg.to_dict(),
                    "loss_ref": loss_ref,
                }
                save_fn(ckpt, model, extra)
            bar.update(1)
            bar.set_postfix({k: f"{v:.3g}" for k, v in record.items() if k in ("train_loss", "val_loss")})
    finally:
        bar.close()
        if logger is not None:
            logger.close()
    model.eval()
    return history


def fit_iterations(
    model: nn.Module,
    step: Callable[[int], tuple[torch.Tensor, dict[str, float]]],
    save: Callable[[Path, dict], object],
    *,
    run_dir: str | Path,
    checkpoint: str,
    kind: str,
    robot: str,
    train_config: dict,
    iterations: int,
    lr: float,
    checkpoint_every: int,
    generator: torch.Generator,
    resume: bool = True,
    progress: bool = True,
    desc: str = "train",
    postfix: Sequence[str] = ("loss",),
) -> nn.Module:
    """The resumable loop of the self-supervised trainers, which draw fresh problems every iteration.

    ``step(iteration)`` draws its batch with ``generator``, returns the loss (a tensor to minimise) and
    the terms to log (floats). Adam with cosine decay to zero over ``iterations``. Every
    ``checkpoint_every`` iterations and at the end, the mean of each term since the last record goes to
    ``run_dir/metrics.jsonl`` and ``save(path, extra)`` writes ``run_dir/checkpoint`` atomically with
    ``extra`` = the iteration, ``train_config``, the optimiser's, schedule's and generator's states.
    ``resume``: continue from that checkpoint (``kind``, ``robot``), which must record the same
    ``train_config`` (:class:`~kinlearn.CheckpointError` otherwise); the resumed run ends with the same
    weights as an uninterrupted one. A non-finite or huge loss raises
    :class:`~kinlearn.errors.TrainingDivergedError`.
    """
    run_dir = Path(run_dir)
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    sched = make_schedule(opt, "cosine", iterations)
    path = run_dir / checkpoint
    start = 0
    if resume and path.exists():
        payload = load_checkpoint(path, kind=kind, robot=robot)
        if payload["extra"].get("train_config") != train_config:
            raise CheckpointError(f"{path} was trained with another configuration; use a new run directory")
        model.load_state_dict(payload["state_dict"])
        extra = payload["extra"]
        opt.load_state_dict(extra["optimizer"])
        sched.load_state_dict(extra["scheduler"])
        generator.set_state(extra["generator"])
        start = extra["iteration"]
    run_dir.mkdir(parents=True, exist_ok=True)

    def write(iteration: int) -> None:
        save(
            path,
            {
                "iteration": iteration,
                "train_config": train_config,
                "optimizer": opt.state_dict(),
                "scheduler": sched.state_dict(),
                "generator": generator.get_state(),
            },
        )

    t0 = time.perf_counter()
    with RunLogger(run_dir) as logger:
        bar = tqdm(range(start, iterations), desc=desc, disable=not progress, initial=start, total=iterations)
        sums: dict[str, float] = {}
        for it in bar:
            model.train()
            loss, terms = step(it)
            value = float(loss.detach())
            if not math.isfinite(value) or value > 1e6:
                raise TrainingDivergedError(
                    f"{desc}: diverged at iteration {it + 1} (loss {value:.3g}); lower the learning rate"
                )
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            sched.step()
            for k, v in {"loss": value, **terms}.items():
                sums[k] = sums.get(k, 0.0) + float(v)
            done = it + 1
            if done % checkpoint_every == 0 or done == iterations:
                n = done - (done - 1) // checkpoint_every * checkpoint_every
                record = {
                    "iteration": done,
                    "lr": sched.get_last_lr()[0],
                    "seconds": time.perf_counter() - t0,
                }
                record.update({f"train/{k}": v / max(n, 1) for k, v in sums.items()})
                logger.log(record)
                bar.set_postfix({k: f"{record[f'train/{k}']:.3g}" for k in postfix if f"train/{k}" in record})
                sums = {}
                write(done)
    model.eval()
    return model


def _check_divergence(loss: float, loss_ref: float | None, epoch: int, what: str = "training") -> None:
    """Raise :class:`TrainingDivergedError` for a non-finite ``loss`` or one that exploded."""
    if not math.isfinite(loss):
        raise TrainingDivergedError(
            f"{what} diverged at epoch {epoch + 1} (loss {loss}); lower the learning rate"
        )
    if (
        loss_ref is not None
        and math.isfinite(loss_ref)
        and loss_ref > 0
        and loss > DIVERGENCE_FACTOR * loss_ref
    ):
        raise TrainingDivergedError(
            f"{what} diverged at epoch {epoch + 1}: the loss grew to {loss:.4g}, more than "
            f"{DIVERGENCE_FACTOR:g} times its first value {loss_ref:.4g}; lower the learning rate"
        )


@torch.no_grad()
def _evaluate(model, val, chunk, loss_fn, metrics_fn) -> dict[str, float]:
    model.eval()
    n = val[0].shape[0]
    sums: dict[str, float] = {}
    for lo in range(0, n, chunk):
        batch = [t[lo : lo + chunk] for t in val]
        w = batch[0].shape[0] / n
        metrics = {"val_loss": float(loss_fn(model, *batch))}
        if metrics_fn is not None:
            metrics.update(metrics_fn(model, *batch))
        for k, v in metrics.items():
            sums[k] = sums.get(k, 0.0) + w * float(v)
    return sums


# --------------------------------------------------------------------------------------------------
# Forward and inverse model training
# --------------------------------------------------------------------------------------------------

#: Named training settings per model kind. ``paper``: REFERENCE #5–6. ``tiny``: seconds, for tests.
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
    ckpt = Path(run_dir) / f"{kind}.pt" if run_dir is not None else None
    identity = {"data_sha256": content_sha256(data.tensors())} if ckpt is not None else {}

    def load(path: Path) -> dict:
        return _load_to_resume(path, kind, model, identity)

    def save(path: Path, m: nn.Module, extra: dict) -> None:
        save_model(m, path, extra={**extra, **identity})

    history = fit(
        model,
        train.tensors(),
        val.tensors() if len(val) else None,
        cfg,
        metrics_fn=_fm_metrics if kind == "fm" else _im_metrics,
        run_dir=run_dir,
        checkpoint=ckpt,
        save_fn=save,
        load_fn=load,
        resume=resume,
        desc=f"train {kind.upper()}",
    )
    return TrainResult(model, history, ckpt)


def _load_to_resume(path: Path, kind: str, model: nn.Module, identity: dict) -> dict:
    """Load checkpoint ``path`` to continue training ``model``: it must hold the same architecture and
    (where it records them) the same data and frozen models (``identity``)."""
    payload = load_checkpoint(path, kind=kind, robot=model.robot_name)
    diffs = diff_configs(payload.get("config") or {}, {"type": "learned", **model.config_dict()})
    diffs = [f"model {d}" for d in diffs]
    extra = payload.get("extra") or {}
    for key, value in identity.items():
        if key in extra and extra[key] != value:
            diffs.append(f"{key}: {extra[key][:16]}… → {value[:16]}…")
    if diffs:
        raise CheckpointError(
            f"{path} was trained with another model or data ({'; '.join(diffs)}); resume with the same "
            "preset and data, or train into a new run directory"
        )
    return payload


def train_fm(
    data: Transitions,
    model: FMConfig | LearnedFM | None = None,
    cfg: TrainConfig | None = None,
    run_dir: str | Path | None = None,
    resume: bool = False,
) -> TrainResult:
    """Train a :class:`LearnedFM` on babbling transitions (paper settings by default).

    ``model`` is a config (the model is built after seeding with ``cfg.seed``) or a model to train
    further. With ``run_dir`` the checkpoint ``run_dir/fm.pt`` (loadable by :func:`kinlearn.models.forward_inverse.load_fm`)
    and ``metrics.jsonl`` are written every epoch; ``resume=True`` continues from that checkpoint.
    """
    cfg = cfg or train_config("fm", "paper")
    seed_everything(cfg.seed)
    if model is None:
        model = LearnedFM(FMConfig(robot=data.robot, dof=data.layout.dof))
    elif isinstance(model, FMConfig):
        model = LearnedFM(model)
    if not isinstance(model, LearnedFM):
        raise ConfigError(f"train_fm trains a LearnedFM, got {type(model).__name__}")
    return _train_supervised("fm", model, data, cfg, run_dir, resume)


def train_im(
    data: Transitions,
    model: IMConfig | LearnedIM | None = None,
    cfg: TrainConfig | None = None,
    run_dir: str | Path | None = None,
    resume: bool = False,
) -> TrainResult:
    """Train a :class:`LearnedIM` on babbling transitions (paper settings by default); see :func:`train_fm`."""
    cfg = cfg or train_config("im", "paper")
    seed_everything(cfg.seed)
    if model is None:
        model = LearnedIM(IMConfig(robot=data.robot, dof=data.layout.dof))
    elif isinstance(model, IMConfig):
        model = LearnedIM(model)
    if not isinstance(model, LearnedIM):
        raise ConfigError(f"train_im trains a LearnedIM, got {type(model).__name__}")
    return _train_supervised("im", model, data, cfg, run_dir, resume)


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

    ckpt = Path(run_dir) / "im.pt" if run_dir is not None else None
    identity = {}
    if ckpt is not None:
        fm_id = {"config": fm.config_dict(), "state_dict": fm.state_dict(), "action_weight": action_weight}
        identity = {"data_sha256": content_sha256(data.tensors()), "through_fm_sha256": content_sha256(fm_id)}
    history = fit(
        im,
        train.tensors(),
        val.tensors() if len(val) else None,
        cfg,
        loss_fn=loss_fn,
        metrics_fn=metrics_fn,
        run_dir=run_dir,
        checkpoint=ckpt,
        save_fn=lambda path, m, extra: save_model(m, path, extra={**extra, **identity}),
        load_fn=lambda path: _load_to_resume(path, "im", im, identity),
        resume=resume,
        desc="train IM through FM",
    )
    return TrainResult(im, history, ckpt)


# --------------------------------------------------------------------------------------------------
# Validation against the analytic robot
# --------------------------------------------------------------------------------------------------

#: The paper's reported mean absolute errors (REFERENCE #7) and this project's goals.
PAPER_FIGURES = {"fm_ef_mae_mm": 1.1, "fm_joints_mae_rad": 6.3e-4, "im_action_mae_rad": 1.7e-3}
GOALS = {"fm_ef_mae_mm": 0.5, "fm_joints_mae_rad": 3e-4, "im_action_mae_rad": 1e-3}


@torch.no_grad()
def validate_models(
    fm: ForwardModel | None,
    im: InverseModel | None,
    robot: Robot | str = "iiwa14",
    n: int = 100_000,
    seed: int = 10_000,
    max_step: float = 0.083,
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
