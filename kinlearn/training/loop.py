"""The one resumable training loop, and what it is made of: optimisers, schedules, run logging, seeding.

Nothing here knows about a particular model: :class:`OptimConfig`, :func:`make_optimizer`,
:func:`make_schedule`, :class:`RunLogger`, :func:`seed_everything`, :class:`TrainingLoop`,
:class:`TrainConfig` with :func:`fit` (minibatch epochs over in-memory tensors) and
:func:`iteration_loop` (fresh problems every iteration). The trainers of the models use them:
:mod:`kinlearn.training.forward_inverse` (FM, IM), :mod:`~kinlearn.training.tm`,
:mod:`~kinlearn.training.imitation`, :mod:`~kinlearn.training.joint_path`,
:mod:`~kinlearn.training.obstacle_path`, :mod:`~kinlearn.training.body`.

Every trainer of kinlearn runs in a :class:`TrainingLoop`: it owns the optimiser, the learning-rate
schedule, the caller's shuffling or sampling generator, the run's ``metrics.jsonl`` (one JSON record
per epoch, or per checkpoint of an iteration-based trainer), the progress bar, the divergence check and
a checkpoint written atomically with the weights and the training state. A resumed run ends with the
same weights as an uninterrupted one: the schedule, both generators and the optimiser are restored.
Resuming checks that the checkpoint was made with the same training configuration (and, through the
caller, the same model and data; :class:`~kinlearn.CheckpointError` naming what differs); a
constant-rate run may be extended to more epochs.

Divergence is an error (:class:`~kinlearn.errors.TrainingDivergedError`): a non-finite loss, or an
epoch's mean loss above :data:`DIVERGENCE_FACTOR` times the loss of the run's first step.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import math
import random
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import torch
from torch import nn
from tqdm.auto import tqdm

from ..errors import CheckpointError, ConfigError, DatasetError, TrainingDivergedError
from ..io import atomic_write, load_checkpoint, remove_stale_tmp, write_json
from ..runs import diff_configs

__all__ = [
    "DIVERGENCE_FACTOR",
    "OptimConfig",
    "RunLogger",
    "TrainConfig",
    "TrainingLoop",
    "fit",
    "iteration_loop",
    "make_optimizer",
    "make_schedule",
    "seed_everything",
]


# --------------------------------------------------------------------------------------------------
# Generic pieces
# --------------------------------------------------------------------------------------------------

#: An epoch's mean loss above this multiple of the first step's loss means training diverged.
DIVERGENCE_FACTOR = 1e6


@dataclass(frozen=True)
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


def _schedule_factor(kind: str, total_steps: int) -> Callable[[int], float]:
    if kind == "constant":
        return lambda k: 1.0
    if kind != "cosine":
        raise ConfigError(f"schedule must be 'constant' or 'cosine', got {kind!r}")
    total = max(1, int(total_steps))
    return lambda k: 0.5 * (1 + math.cos(math.pi * min(k, total) / total))


def make_schedule(
    opt: torch.optim.Optimizer, kind: str, total_steps: int
) -> torch.optim.lr_scheduler.LambdaLR:
    """The learning-rate schedule per optimiser step: ``"constant"``, or ``"cosine"`` decay from the
    optimiser's rate to zero over ``total_steps`` (then zero)."""
    return torch.optim.lr_scheduler.LambdaLR(opt, _schedule_factor(kind, total_steps))


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


def _truncate_log(path: Path, done: int, key: str = "epoch") -> None:
    """Drop records beyond ``record[key] == done`` (written after the last checkpoint) from a JSONL log."""
    if not path.is_file():
        return
    keep = []
    for line in path.read_text().splitlines():
        try:
            rec = json.loads(line)
        except json.JSONDecodeError:
            continue
        if int(rec.get(key, 0)) <= done:
            keep.append(line)
    atomic_write(path, lambda p: p.write_text("".join(k + "\n" for k in keep)))


def _check_divergence(loss: float, loss_ref: float | None, where: str) -> None:
    """Raise :class:`TrainingDivergedError` (``where``: e.g. "TM training diverged at epoch 3") for a
    non-finite ``loss`` or one above :data:`DIVERGENCE_FACTOR` times the first step's ``loss_ref``."""
    if not math.isfinite(loss):
        raise TrainingDivergedError(f"{where} (loss {loss}); lower the learning rate")
    if loss_ref is not None and loss_ref > 0 and loss > DIVERGENCE_FACTOR * loss_ref:
        raise TrainingDivergedError(
            f"{where}: the loss grew to {loss:.4g}, more than {DIVERGENCE_FACTOR:g} times its first value "
            f"{loss_ref:.4g}; lower the learning rate"
        )


def _config_differences(stored: dict, current: dict) -> list[str]:
    """What differs between a checkpoint's training configuration and the run about to resume from it,
    in a way that forbids resuming: all but the progress bar and the evaluation batch size; a run of
    constant learning rate may change its number of epochs (its rate does not depend on it)."""
    diffs = diff_configs(stored, current, ignore=("progress", "eval_batch_size"))
    if stored.get("schedule") == current.get("schedule") == "constant":
        diffs = [d for d in diffs if not d.startswith("epochs:")]
    return diffs


def _stored_step(path: Path, extra: dict) -> int:
    """The epochs or iterations a checkpoint's training state says are done (``step``; checkpoints of
    earlier versions named it ``epoch`` or ``iteration``); :class:`CheckpointError` if it has none."""
    done = next((extra[k] for k in ("step", "epoch", "iteration") if k in extra), None)
    if done is None or "optimizer" not in extra:
        raise CheckpointError(f"{path} holds no training state (optimizer, step); cannot resume from it")
    return int(done)


def _training_state(step, unit, optimizer, scheduler, generator, loss_ref, train_config, history) -> dict:
    """A checkpoint's training state, the same for every trainer (see :class:`TrainingLoop`):
    ``optimizer`` is the optimiser's state dict, ``scheduler`` and ``generator`` the objects."""
    return {
        "step": step,
        "unit": unit,
        "optimizer": optimizer,
        "scheduler": scheduler.state_dict(),
        "generator": generator.get_state(),
        "torch_rng": torch.get_rng_state(),
        "loss_ref": loss_ref,
        "train_config": train_config,
        "history": list(history),
    }


class TrainingLoop:
    """One resumable training run, driven by the caller one epoch or iteration at a time.

    It builds the optimiser (``optim``) over ``params`` (default: the model's) and its per-step
    learning-rate schedule (``"constant"``, ``"cosine"`` decay to zero over ``total × steps_per_unit``
    optimiser steps, see :func:`make_schedule`, or a function of the step giving the factor of the
    rate). The caller's ``step(i)`` (:meth:`run`) trains unit ``i`` (an epoch or an iteration), drawing
    its batches with ``generator`` and taking optimiser steps through :meth:`step`, and returns a dict
    of floats. Every ``record_every`` units and at the end, their mean becomes a record, stamped with
    ``unit`` (the count done), ``lr`` (the rate of the next step) and ``seconds`` (since :meth:`run`
    began); it is appended to :attr:`history` and ``run_dir/metrics.jsonl``, and then ``save(path,
    extra)`` writes ``checkpoint`` atomically with the training state ``extra`` of
    :func:`_training_state`: ``step`` (units done) and ``unit``, ``optimizer``, ``scheduler``,
    ``generator``, ``torch_rng`` (torch's global generator), ``loss_ref`` (the first step's loss, the
    scale of the divergence check), ``train_config`` and ``history``.

    :meth:`resume` continues from that checkpoint. Checkpoints of earlier versions resume too: a
    counter named ``epoch`` or ``iteration``, no schedule (rebuilt from the counter), no torch state.
    """

    def __init__(
        self,
        model: nn.Module,
        optim: OptimConfig,
        *,
        total: int,
        generator: torch.Generator,
        train_config: dict,
        schedule: str | Callable[[int], float] = "constant",
        steps_per_unit: int = 1,
        unit: Literal["epoch", "iteration"] = "epoch",
        record_every: int = 1,
        params: Iterable[nn.Parameter] | None = None,
        run_dir: str | Path | None = None,
        checkpoint: str | Path | None = None,
        save: Callable[[Path, dict], object] | None = None,
        desc: str = "training",
        progress: bool = True,
        postfix: Sequence[str] = (),
    ):
        self.model, self.total, self.unit = model, int(total), unit
        self.generator, self.train_config = generator, train_config
        self.optimizer = make_optimizer(optim, model.parameters() if params is None else params)
        self._factor = schedule if callable(schedule) else _schedule_factor(schedule, total * steps_per_unit)
        self.scheduler = torch.optim.lr_scheduler.LambdaLR(self.optimizer, self._factor)
        self.steps_per_unit, self.record_every = steps_per_unit, record_every
        self.run_dir = Path(run_dir) if run_dir is not None else None
        self.checkpoint = Path(checkpoint) if checkpoint is not None else None
        self.save, self.desc, self.progress, self.postfix = save, desc, progress, tuple(postfix)
        self.done, self.history, self.loss_ref = 0, [], None
        if self.checkpoint is not None:
            remove_stale_tmp(self.checkpoint.parent, self.checkpoint.name)  # left by a killed write

    def resume(self, load: Callable[[Path], dict] | None) -> bool:
        """Continue from the checkpoint if there is one (``False`` if not). ``load(path)`` reads it,
        refusing (:class:`CheckpointError`) one made with another model or data; the training
        configuration it records must match (:func:`_config_differences`), its weights and optimiser
        state fit, or :class:`CheckpointError` is raised before anything is written."""
        path = self.checkpoint
        if path is None or not path.is_file():
            return False
        if load is None:
            raise ConfigError("resuming needs a function that reads the checkpoint")
        payload = load(path)
        extra = payload.get("extra") or {}
        done = _stored_step(path, extra)
        stored = extra.get("train_config")
        diffs = _config_differences(stored, self.train_config) if isinstance(stored, dict) else []
        if diffs:
            raise CheckpointError(
                f"{path} was trained with another configuration ({'; '.join(diffs)}); resume with the "
                "same settings or train into a new run directory"
            )
        try:
            self.model.load_state_dict(payload["state_dict"])
            self.optimizer.load_state_dict(extra["optimizer"])
            if "scheduler" in extra:
                self.scheduler.load_state_dict(extra["scheduler"])
            else:  # a checkpoint of an earlier version: the schedule at the step it stopped
                for group, base in zip(self.optimizer.param_groups, self.scheduler.base_lrs, strict=True):
                    group.setdefault("initial_lr", base)
                steps = done * self.steps_per_unit
                self.scheduler = torch.optim.lr_scheduler.LambdaLR(self.optimizer, self._factor, steps - 1)
            self.generator.set_state(extra["generator"])
        except (RuntimeError, ValueError, KeyError, TypeError) as exc:
            raise CheckpointError(f"{path} does not fit the model being trained ({exc})") from exc
        if "torch_rng" in extra:
            torch.set_rng_state(extra["torch_rng"])
        self.done, self.history, self.loss_ref = done, list(extra.get("history", [])), extra.get("loss_ref")
        return True

    def step(self, loss: torch.Tensor, check: bool = False) -> torch.Tensor:
        """One optimiser step on ``loss`` (and one of the schedule); returns the loss, detached. With
        ``check``, :meth:`check` the loss first (no step is taken on a diverged one)."""
        if check:
            self.check(float(loss.detach()))
        if self.loss_ref is None:
            self.loss_ref = float(loss.detach())
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        self.optimizer.step()
        self.scheduler.step()
        return loss.detach()

    def check(self, loss: float) -> None:
        """Raise :class:`TrainingDivergedError` if ``loss`` (of the current unit) says training diverged."""
        _check_divergence(loss, self.loss_ref, f"{self.desc} diverged at {self.unit} {self.done + 1}")

    def state(self) -> dict:
        """The training state a checkpoint holds now (:func:`_training_state`)."""
        opt, sched, gen, ref = self.optimizer.state_dict(), self.scheduler, self.generator, self.loss_ref
        return _training_state(self.done, self.unit, opt, sched, gen, ref, self.train_config, self.history)

    def run(self, step: Callable[[int], dict[str, float]]) -> list[dict]:
        """Call ``step(i)`` for every unit ``i`` not done yet (model in training mode), recording and
        checkpointing as described above; returns the history of records (a resumed run's included)
        and leaves the model in eval mode."""
        logger = None
        if self.run_dir is not None:
            _truncate_log(self.run_dir / "metrics.jsonl", self.done, self.unit)  # beyond the checkpoint
            logger = RunLogger(self.run_dir)
        bar = tqdm(
            total=self.total, initial=self.done, desc=self.desc, disable=not self.progress, unit=self.unit
        )
        t0, sums, count = time.perf_counter(), {}, 0
        try:
            for i in range(self.done, self.total):
                self.model.train()
                for k, v in step(i).items():
                    sums[k] = sums.get(k, 0.0) + float(v)
                self.done, count = i + 1, count + 1
                bar.update(1)
                if self.done % self.record_every and self.done != self.total:
                    continue
                record = {self.unit: self.done, "lr": self.scheduler.get_last_lr()[0]}
                record.update(seconds=time.perf_counter() - t0, **{k: v / count for k, v in sums.items()})
                sums, count = {}, 0
                self.history.append(record)
                if logger is not None:  # before the checkpoint: a resume drops records beyond it
                    logger.log(record)
                if self.checkpoint is not None and self.save is not None:
                    self.save(self.checkpoint, self.state())
                bar.set_postfix({k.split("/")[-1]: f"{record[k]:.3g}" for k in self.postfix if k in record})
        finally:
            bar.close()
            if logger is not None:
                logger.close()
        self.model.eval()
        return self.history


@dataclass(frozen=True)
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
            object.__setattr__(self, "optim", OptimConfig(**self.optim))  # frozen: set once, here
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

    def lr_factor(self, step: int, total_steps: int) -> float:
        """Learning rate at optimiser step ``step`` (0-based) of ``total_steps``, relative to ``optim.lr``."""
        if self.schedule == "constant" or total_steps <= 1:
            return 1.0
        frac = min(step / (total_steps - 1), 1.0)
        return self.min_lr_ratio + (1.0 - self.min_lr_ratio) * 0.5 * (1.0 + math.cos(math.pi * frac))

    def lr_at(self, step: int, total_steps: int) -> float:
        """Learning rate at optimiser step ``step`` (0-based) of ``total_steps``."""
        return self.optim.lr * self.lr_factor(step, total_steps)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> TrainConfig:
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = set(d) - names
        if unknown:
            raise ConfigError(f"unknown TrainConfig field(s): {', '.join(sorted(unknown))}")
        return cls(**d)


def _loss_by_method(model: nn.Module, *batch: torch.Tensor) -> torch.Tensor:
    return model.training_loss(*batch)


def iteration_loop(
    model: nn.Module,
    config,
    run_dir: Path,
    checkpoint: str,
    save: Callable[[Path, dict], object],
    *,
    kind: str,
    robot: str,
    generator: torch.Generator,
    resume: bool,
    write_config: bool,
    desc: str,
    progress: bool,
    postfix: Sequence[str],
) -> TrainingLoop:
    """The :class:`TrainingLoop` of a self-supervised trainer that draws fresh problems every iteration
    (``config``: ``lr``, ``iterations``, ``checkpoint_every``, ``to_dict()``): Adam at ``config.lr`` with
    cosine decay over ``config.iterations``, a record and a checkpoint ``run_dir/checkpoint`` every
    ``config.checkpoint_every`` iterations. Writes ``run_dir/config.json`` (unless ``write_config`` is
    False or a run is resumed) and, with ``resume``, continues from the checkpoint (``kind``, ``robot``)."""
    run_dir.mkdir(parents=True, exist_ok=True)
    cfg_dict = copy.deepcopy(config.to_dict())
    if write_config and not (resume and (run_dir / checkpoint).exists()):
        write_json(run_dir / "config.json", cfg_dict)
    loop = TrainingLoop(
        model,
        OptimConfig("adam", config.lr),
        total=config.iterations,
        generator=generator,
        train_config=cfg_dict,
        schedule="cosine",
        unit="iteration",
        record_every=config.checkpoint_every,
        run_dir=run_dir,
        checkpoint=run_dir / checkpoint,
        save=save,
        desc=desc,
        progress=progress,
        postfix=postfix,
    )
    if resume:
        loop.resume(lambda path: load_checkpoint(path, kind=kind, robot=robot))
    return loop


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
    desc: str = "training",
) -> list[dict]:
    """Minibatch training of ``model`` on in-memory tensors in a :class:`TrainingLoop`; returns the
    per-epoch history.

    ``train`` (and ``val``) are tensors sharing their first dimension; each step calls
    ``loss_fn(model, *batch)`` (default: ``model.training_loss(*batch)``). After each epoch the held-out
    loss and ``metrics_fn(model, *val)`` (a dict of floats, computed without gradients in chunks of
    ``cfg.eval_batch_size``, averaged over chunks by size) are recorded. With ``run_dir`` the records go
    to ``run_dir/metrics.jsonl``; with ``checkpoint`` and ``save_fn(path, model, extra)`` a checkpoint
    is written after every epoch, and ``resume=True`` restores the latest one through
    ``load_fn(path) -> {"state_dict": ..., "extra": ...}``, after checking that it was trained with the
    same ``cfg`` (:meth:`TrainingLoop.resume`; :class:`CheckpointError` otherwise).
    Raises :class:`TrainingDivergedError` when the loss diverges (see the module docstring).
    """
    train = tuple(train)
    n = train[0].shape[0]
    if n == 0 or any(t.shape[0] != n for t in train):
        raise DatasetError(
            f"training tensors must share a non-empty first dimension, got {[tuple(t.shape) for t in train]}"
        )
    steps_per_epoch = -(-n // cfg.batch_size)
    total_steps = steps_per_epoch * cfg.epochs
    loop = TrainingLoop(
        model,
        cfg.optim,
        total=cfg.epochs,
        generator=torch.Generator().manual_seed(int(cfg.seed) + 1),
        train_config=cfg.to_dict(),
        schedule=lambda k: cfg.lr_factor(k, total_steps),
        steps_per_unit=steps_per_epoch,
        run_dir=run_dir,
        checkpoint=checkpoint,
        save=None if save_fn is None else lambda path, extra: save_fn(path, model, extra),
        desc=desc,
        progress=cfg.progress,
        postfix=("train_loss", "val_loss"),
    )
    if resume:
        loop.resume(load_fn)

    def epoch(_: int) -> dict:
        t0 = time.perf_counter()
        perm = torch.randperm(n, generator=loop.generator)
        shuffled = [t[perm] for t in train]
        total = torch.zeros((), dtype=torch.float64)
        for lo in range(0, n, cfg.batch_size):
            total += loop.step(loss_fn(model, *(t[lo : lo + cfg.batch_size] for t in shuffled)))
        record: dict[str, Any] = {"train_loss": float(total) / steps_per_epoch}
        loop.check(record["train_loss"])
        if val is not None and val[0].shape[0] > 0:
            record.update(_evaluate(model, tuple(val), cfg.eval_batch_size, loss_fn, metrics_fn))
        record["epoch_time_s"] = time.perf_counter() - t0
        return record

    return loop.run(epoch)


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


def _load_to_resume(path: Path, kind: str, robot: str, model_config: dict, identity: dict) -> dict:
    """Load checkpoint ``path`` to continue training a model: it must hold the same architecture
    (``model_config``) and, where it records them, the same data and frozen models (``identity``)."""
    payload = load_checkpoint(path, kind=kind, robot=robot)
    diffs = [f"model {d}" for d in diff_configs(payload.get("config") or {}, model_config)]
    extra = payload.get("extra") or {}
    for key, value in identity.items():
        if key in extra and extra[key] != value:
            diffs.append(f"{key}: {extra[key][:16]}… → {value[:16]}…")
    if diffs:
        raise CheckpointError(
            f"{path} was trained with another model or data ({'; '.join(diffs)}); resume with the same "
            "settings and data, or train into a new run directory"
        )
    return payload
