"""Self-supervised training of the trajectory model through a frozen FM and IM (paper Sect. 3).

The FM and IM are each either learned (checkpoints from ``kinlearn train-fm`` / ``train-im``) or
analytic (FK; a damped-least-squares IK step): the four combinations are the ablation. Their
weights never change here: they are frozen and only the TM's parameters reach the optimiser.

``tm.pt`` records the learned FM/IM files it was trained through by identity (path relative to
``tm.pt`` and SHA-256, :func:`kinlearn.io.resolve_dependency`), never by an absolute folder: a run
folder can move, and a swapped model is an error. Resuming checks the configuration, those models
and the training pairs. Divergence (a non-finite loss, waypoints beyond :data:`WAYPOINT_BOUND_REACHES`
arm reaches from the base, or a loss above ``DIVERGENCE_FACTOR`` × the first step's) is an error.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
import torch

from ..body.robot import Robot, load_robot
from ..data.endpoints import EndpointPairs
from ..errors import CheckpointError, ConfigError, DatasetError, TrainingDivergedError
from ..io import (
    content_sha256,
    file_sha256,
    load_checkpoint,
    resolve_dependency,
    save_checkpoint,
    write_json,
)
from ..models.forward_inverse import frozen_fm_im
from ..models.rollout import LossConfig, rectify, tm_loss
from ..models.trajectory import TMConfig, TrajectoryModel
from ..polyline import trajectory_metrics
from .loop import OptimConfig, TrainingLoop, seed_everything

__all__ = [
    "TM_PRESETS",
    "WAYPOINT_BOUND_REACHES",
    "TMTrainConfig",
    "build_fm_im",
    "evaluate_tm",
    "load_tm",
    "tm_preset",
    "train_tm",
]

ModelKind = Literal["learned", "analytic"]

#: Waypoints farther than this many arm reaches from the base mean that training diverged.
WAYPOINT_BOUND_REACHES = 10.0


def arm_reach(robot: Robot) -> float:
    """An upper bound of the end effector's distance from the base (m): the chain's link lengths and
    the prismatic joints' travel, summed."""
    links = sum(float(np.linalg.norm(j.T_prev[:3, 3])) for j in robot.joints)
    travel = sum(max(abs(j.lower), abs(j.upper)) for j in robot.joints if j.kind == "prismatic")
    return links + travel + float(np.linalg.norm(robot.T_tip[:3, 3]))


@dataclass(frozen=True)
class TMTrainConfig:
    """Everything that decides a TM training run; saved as the run's ``config.json``.

    ``fm``/``im``: ``"learned"`` (loaded from ``models_dir``: ``fm.pt``, ``im.pt``) or ``"analytic"``.
    ``trainable``: ``"all"``, or ``"shared"`` (only the shared dense layer, as the authors' code
    effectively did: the authors' code, github.com/Mcibula/traj-planning-icann2025). ``schedule``: constant learning rate or cosine decay to zero.
    """

    robot: str = "iiwa14"
    fm: ModelKind = "learned"
    im: ModelKind = "learned"
    models_dir: str | None = None
    im_iterations: int = 1
    im_damping: float = 1e-2
    epochs: int = 50
    batch_size: int = 64
    optim: OptimConfig = field(default_factory=lambda: OptimConfig(name="rmsprop", lr=1e-3, alpha=0.99))
    schedule: Literal["constant", "cosine"] = "cosine"
    loss: LossConfig = field(default_factory=lambda: LossConfig.preset("smooth"))
    tm: TMConfig = field(default_factory=TMConfig)
    trainable: Literal["all", "shared"] = "all"
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("fm", "im"):
            if getattr(self, name) not in ("learned", "analytic"):
                raise ConfigError(f"{name} must be 'learned' or 'analytic', got {getattr(self, name)!r}")
        if self.schedule not in ("constant", "cosine"):
            raise ConfigError(f"schedule must be 'constant' or 'cosine', got {self.schedule!r}")
        if self.trainable not in ("all", "shared"):
            raise ConfigError(f"trainable must be 'all' or 'shared', got {self.trainable!r}")
        if self.epochs <= 0 or self.batch_size <= 0:
            raise ConfigError("epochs and batch_size must be positive")

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> TMTrainConfig:
        d = dict(d)
        d["optim"] = OptimConfig(**d["optim"])
        d["loss"] = LossConfig(**d["loss"])
        d["tm"] = TMConfig(**d["tm"])
        return cls(**d)


#: Named training configurations: fields of :class:`TMTrainConfig`, with ``loss`` a loss preset name
#: and ``tm`` a dict of :class:`TMConfig` fields.
TM_PRESETS: dict[str, dict] = {
    # kinlearn's default: L_TM plus what the metrics ask for, normalised inputs, cosine decay.
    "default": {},
    # The paper's setting done right: Eq. 4, RMSprop 1e-3 (γ = 0.99), constant lr, no normalisation.
    "paper": {"loss": "paper", "schedule": "constant", "tm": {"normalize": False}},
    # The authors' code, defects included on purpose (the authors' code, github.com/Mcibula/traj-planning-icann2025): only the shared layer trains,
    # random h0 on every call, the released loss (endpoint terms only), batch 1.
    "reference-parity": {
        "loss": "released",
        "schedule": "constant",
        "tm": {"normalize": False, "h0": "random"},
        "trainable": "shared",
        "batch_size": 1,
    },
}


def tm_preset(name: str, **overrides) -> TMTrainConfig:
    """A named training configuration (see :data:`TM_PRESETS`) with fields overridden by keyword.

    ``loss`` may be a :class:`LossConfig` or a loss preset name; ``tm`` a dict of TMConfig fields.
    The TM's robot and joint count follow ``robot``.
    """
    if name not in TM_PRESETS:
        raise ConfigError(f"unknown TM preset {name!r}; choose one of {', '.join(TM_PRESETS)}")
    fields = {**TM_PRESETS[name], **overrides}
    robot = fields.get("robot", "iiwa14")
    tm_fields = {**TM_PRESETS[name].get("tm", {}), **overrides.get("tm", {})}
    fields["tm"] = TMConfig(**{**tm_fields, "robot": robot, "dof": load_robot(robot).dof})
    if isinstance(fields.get("loss"), str):
        fields["loss"] = LossConfig.preset(fields["loss"])
    return TMTrainConfig(**fields)


def build_fm_im(config: TMTrainConfig) -> tuple[torch.nn.Module, torch.nn.Module]:
    """The frozen FM and IM that the configuration names (learned ones from ``models_dir``)."""
    robot = load_robot(config.robot)
    if "learned" in (config.fm, config.im) and config.models_dir is None:
        raise ConfigError("a learned FM or IM needs models_dir, the folder holding fm.pt and im.pt")
    folder = Path(config.models_dir) if config.models_dir else None
    return frozen_fm_im(
        robot,
        config.fm,
        config.im,
        fm_path=folder / "fm.pt" if folder else None,
        im_path=folder / "im.pt" if folder else None,
        im_iterations=config.im_iterations,
        im_damping=config.im_damping,
    )


def _step_loss(tm, fm, im, s0, sT, loss_cfg: LossConfig):
    wp = tm(s0, sT)
    if loss_cfg.gradient == "stop":
        with torch.no_grad():
            rect, _ = rectify(wp.detach(), s0, sT, fm, im, tm.layout)
    else:
        rect, _ = rectify(wp, s0, sT, fm, im, tm.layout)
    return wp, tm_loss(wp, rect, s0, sT, tm.layout, loss_cfg)


@torch.no_grad()
def evaluate_tm(tm, fm, im, pairs: EndpointPairs, loss_cfg: LossConfig, batch_size: int = 4096) -> dict:
    """Mean loss terms and trajectory metrics of ``tm`` on ``pairs``."""
    tm.eval()
    sums: dict[str, float] = {}
    wps = []
    n = len(pairs)
    for i in range(0, n, batch_size):
        s0, sT = pairs.start[i : i + batch_size], pairs.goal[i : i + batch_size]
        wp, (loss, terms) = _step_loss(tm, fm, im, s0, sT, loss_cfg)
        w = s0.shape[0] / n
        for k, v in {"loss": loss, **terms}.items():
            sums[k] = sums.get(k, 0.0) + float(v) * w
        wps.append(wp)
    lay = tm.layout
    per = trajectory_metrics(pairs.start[:, lay.ef], torch.cat(wps), pairs.goal[:, lay.ef])
    return {**sums, **{k: float(v.double().mean()) for k, v in per.items()}}


def train_tm(
    config: TMTrainConfig,
    run_dir: str | Path,
    train: EndpointPairs,
    val: EndpointPairs | None = None,
    *,
    fm: torch.nn.Module | None = None,
    im: torch.nn.Module | None = None,
    resume: bool = True,
    progress: bool = True,
    write_config: bool = True,
) -> TrajectoryModel:
    """Train a TM on ``train`` pairs; checkpoint ``run_dir/tm.pt`` after every epoch; resume from it.

    ``fm``/``im`` override the models that ``config`` names (they are frozen either way); learned
    ones loaded from ``config.models_dir`` are recorded in ``tm.pt`` by identity. Logs per-epoch loss
    terms (and held-out metrics when ``val`` is given) to ``run_dir/metrics.jsonl``; writes the config
    to ``run_dir/config.json`` unless ``write_config=False`` (the CLI keeps its own record there).
    Raises :class:`DatasetError` for empty or non-finite pairs, :class:`CheckpointError` when resuming
    a ``tm.pt`` made with another configuration, FM/IM or pairs, :class:`TrainingDivergedError`.
    """
    run_dir = Path(run_dir)
    robot = _checked_robot(config, train)
    if val is not None and len(val) == 0:
        val = None
    if val is not None:
        _check_pairs(val, "held-out pairs", robot)
    depends: dict[str, tuple[Path, str]] = {}
    if fm is None or im is None:
        built_fm, built_im = build_fm_im(config)
        depends = _learned_dependencies(config, [k for k, given in (("fm", fm), ("im", im)) if given is None])
        fm, im = fm or built_fm, im or built_im
    for m in (fm, im):
        m.eval()
        m.requires_grad_(False)
        m.validate_inputs = False  # a diverging TM is caught by the loss check below
    gen = seed_everything(config.seed)
    tm = TrajectoryModel(config.tm)
    tm.fit_normalization(train.start, train.goal)
    if config.trainable == "shared":
        for name, p in tm.named_parameters():
            p.requires_grad_(name.startswith("shared."))
    n = len(train)
    data_sha256 = content_sha256((train.start, train.goal))
    bound = WAYPOINT_BOUND_REACHES * arm_reach(robot)
    loop = TrainingLoop(
        tm,
        config.optim,
        total=config.epochs,
        generator=gen,
        train_config=_training_record(config),
        schedule=config.schedule,
        steps_per_unit=math.ceil(n / config.batch_size),
        params=[p for p in tm.parameters() if p.requires_grad],
        run_dir=run_dir,
        checkpoint=run_dir / "tm.pt",
        save=lambda path, extra: _save_run_checkpoint(path, config, tm, extra, data_sha256, depends),
        desc="TM training",
        progress=progress,
        postfix=("train/loss", "train/paper_l_tm"),
    )
    if resume:
        loop.resume(lambda path: _load_run(path, robot.name, depends, data_sha256))
    if write_config:
        write_json(run_dir / "config.json", _train_config_dict(config))

    def epoch(e: int) -> dict:
        perm = torch.randperm(n, generator=gen)
        sums: dict[str, float] = {}
        for i in range(0, n, config.batch_size):
            idx = perm[i : i + config.batch_size]
            wp, (loss, terms) = _step_loss(tm, fm, im, train.start[idx], train.goal[idx], config.loss)
            far = wp.detach().abs().amax()
            if not bool(torch.isfinite(loss) & (far <= bound)):  # one check per step
                raise TrainingDivergedError(
                    f"TM training diverged at epoch {e + 1} (loss {loss.item():.4g}, a waypoint "
                    f"{far.item():.4g} m from the base, beyond {bound:.3g} m = {WAYPOINT_BOUND_REACHES:g} "
                    f"× the arm's reach); lower the learning rate"
                )
            loop.step(loss)
            w = idx.numel() / n
            for k, v in {"loss": loss.detach(), **terms}.items():
                sums[k] = sums.get(k, 0.0) + float(v) * w
        loop.check(sums["loss"])
        record = {f"train/{k}": v for k, v in sums.items()}
        if val is not None:
            record.update({f"val/{k}": v for k, v in evaluate_tm(tm, fm, im, val, config.loss).items()})
        return record

    loop.run(epoch)
    return tm


def _checked_robot(config: TMTrainConfig, train: EndpointPairs) -> Robot:
    """The run's robot, once the TM config and the training pairs are checked to be for it."""
    robot = load_robot(config.robot)
    if train.config.robot != robot.name:
        raise ConfigError(f"endpoint pairs are for {train.config.robot!r}, the run is for {robot.name!r}")
    if config.tm.robot != robot.name or config.tm.dof != robot.dof:
        raise ConfigError(
            f"TM config is for {config.tm.robot!r} ({config.tm.dof} joints), not {robot.name!r}"
        )
    _check_pairs(train, "training pairs", robot)
    return robot


def _learned_dependencies(config: TMTrainConfig, kinds=("fm", "im")) -> dict[str, tuple[Path, str]]:
    """The learned FM/IM files (of ``kinds``) the run trains through, with their SHA-256."""
    out = {}
    for kind in kinds:
        if getattr(config, kind) == "learned":
            path = Path(config.models_dir) / f"{kind}.pt"
            out[kind] = (path, file_sha256(path))
    return out


def _save_run_checkpoint(
    path: Path, config: TMTrainConfig, tm: TrajectoryModel, extra: dict, data_sha256: str, depends: dict
) -> None:
    """A training run's ``tm.pt``: the model's config and weights, and the training state ``extra``."""
    save_checkpoint(
        path,
        kind="tm",
        robot=load_robot(config.robot).name,
        config=_checkpoint_config(config),
        state_dict=tm.state_dict(),
        extra={**extra, "data_sha256": data_sha256},
        depends=depends,
    )


def _train_config_dict(config: TMTrainConfig) -> dict:
    return copy.deepcopy(config.to_dict())


#: Fields of the training config that say what a planner needs (the rest is how it was trained).
MODEL_FIELDS = ("tm", "fm", "im", "im_iterations", "im_damping")


def _checkpoint_config(config: TMTrainConfig) -> dict:
    """The config ``tm.pt`` stores: the model's own (its architecture, which FM/IM it plans through),
    no optimiser, loss or folder. The training config travels in the checkpoint's training state."""
    d = _train_config_dict(config)
    return {k: d[k] for k in MODEL_FIELDS}


def _training_record(config: TMTrainConfig) -> dict:
    """The training config as a checkpoint's training state holds it: without ``models_dir`` (the
    FM/IM are recorded by identity)."""
    return {**_train_config_dict(config), "models_dir": None}


def _recorded_training(payload: dict) -> dict | None:
    """The training config a ``tm.pt`` recorded (checkpoints before the split stored it as ``config``)."""
    extra = payload.get("extra") or {}
    if "train_config" in extra:
        return extra["train_config"]
    return payload["config"] if "optim" in payload["config"] else None


def _check_pairs(pairs: EndpointPairs, what: str, robot: Robot) -> None:
    size = robot.dof + 3
    if len(pairs) == 0:
        raise DatasetError(f"the {what} are empty: make endpoints with --n ≥ 1")
    for name, t in (("start", pairs.start), ("goal", pairs.goal)):
        if t.ndim != 2 or t.shape != (len(pairs), size):
            raise DatasetError(f"the {what}' {name} states must have shape (N, {size}), got {tuple(t.shape)}")
        if not bool(torch.isfinite(t).all()):
            raise DatasetError(f"the {what}' {name} states hold NaN or infinity; make the endpoints again")


def _load_run(path: Path, robot: str, depends: dict, data_sha256: str) -> dict:
    """A run's ``tm.pt`` to resume, its training config where every trainer keeps it; it must have been
    trained through the same learned FM/IM (``depends``) on the same pairs (:class:`CheckpointError`)."""
    payload = load_checkpoint(path, kind="tm", robot=robot)
    diffs, recorded = [], payload.get("depends") or {}
    for kind, (dep, sha) in depends.items():
        old = (recorded.get(kind) or {}).get("sha256")
        if old is not None and old != sha:
            diffs.append(f"{kind} {dep}: sha256 {old[:16]}… → {sha[:16]}… (another model)")
    old_data = payload["extra"].get("data_sha256")
    if old_data is not None and old_data != data_sha256:
        diffs.append(f"training pairs: sha256 {old_data[:16]}… → {data_sha256[:16]}…")
    if diffs:
        raise CheckpointError(
            f"{path} was trained with another configuration ({'; '.join(diffs)}); resume with the same "
            "models and pairs, or train into a new run directory"
        )
    training = _recorded_training(payload)
    if training is not None:
        payload["extra"]["train_config"] = {**training, "models_dir": None}
    return payload


def load_tm(
    path: str | Path, robot: str | None = None, *, resolve: bool = True
) -> tuple[TrajectoryModel, TMTrainConfig]:
    """Load a TM checkpoint written by :func:`train_tm`; returns the model (eval mode) and its config.

    With ``resolve`` the learned FM/IM the TM records are found and verified
    (:func:`kinlearn.io.resolve_dependency`) and the config's ``models_dir`` names their folder, so
    that :func:`build_fm_im` loads exactly them. Raises :class:`CheckpointError` when one is missing or
    was replaced.
    """
    payload = load_checkpoint(path, kind="tm", robot=robot)
    try:
        recorded = _recorded_training(payload)
        if recorded is not None:
            config = TMTrainConfig.from_dict(recorded)
        else:  # an exported planner: the model's config alone; training fields at their defaults
            model = payload["config"]
            config = TMTrainConfig(
                robot=model["tm"]["robot"],
                **{k: v for k, v in model.items() if k != "tm"},
                tm=TMConfig(**model["tm"]),
            )
        tm = TrajectoryModel(config.tm)
        tm.load_state_dict(payload["state_dict"])
    except (TypeError, KeyError, RuntimeError, ConfigError) as exc:
        raise CheckpointError(f"{path}: the TM checkpoint does not match this kinlearn ({exc})") from exc
    learned = [k for k in ("fm", "im") if getattr(config, k) == "learned" and k in payload["depends"]]
    if resolve and learned:
        folders = {resolve_dependency(path, payload, k).parent for k in learned}
        if len(folders) > 1:
            raise CheckpointError(
                f"{path}: its FM and IM were found in different folders ({', '.join(map(str, folders))}); "
                "put fm.pt and im.pt in one folder"
            )
        config = dataclasses.replace(config, models_dir=str(folders.pop()))
    tm.eval()
    return tm, config
