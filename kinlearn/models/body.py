"""A body model the robot learns: joints → the centres of its collision spheres.

In the spirit of the learned forward model, the robot learns where its body is from babbling: the
configurations it visited (or joints drawn uniformly in its joint box) and, as its vision, the
sphere centres of the analytic collision body (:func:`~kinlearn.collision.body_spheres`) at them.

:class:`LearnedBody` answers like :class:`~kinlearn.collision.BodySpheres` wherever the planner and
the collision functions use a body (``forward(q, validate)``, ``radii_like``, ``radii``, ``link``,
``pairs``, ``floor_mask``, ``lever``, ``robot``, ``num_spheres``), so
:func:`~kinlearn.collision.check_path`, :func:`~kinlearn.collision.clearances` and
:func:`~kinlearn.collision.body_obstacle_distance` take either body. What it learns is the centres
of the moving spheres: an MLP of (sin θ, cos θ) predicts them all at once, its outputs centred per
coordinate and divided by one common scale, so that the loss weighs a millimetre of every sphere
alike (per-coordinate scales gave a lower mean but a higher p99 error: 10.8 vs 9.5 mm after 20k steps).
The base spheres never move and are kept as constants; the geometry that is not learned (radii,
self-collision pairs, the floor mask, the per-joint travel bounds ``lever`` of the dense path check)
is copied from the analytic body it is trained against. The radii can be inflated by a ``margin``
(:meth:`LearnedBody.set_margin`, e.g. the validation p99 centre error) so that a body–obstacle
distance errs on the safe side; it is saved with the weights.

Predicting each link's frame (a 3×4 transform, the centres then fixed linear combinations of it)
instead of the centres was measured to be no more accurate for the same steps and width (p99 10.1
vs 9.5 mm after 20k steps of a 160-160-160 SiLU MLP on the 12-sphere body), with more outputs; the
centres are predicted directly.

Training (:func:`train_body_model`) reuses the generic resumable loop of :mod:`kinlearn.training.loop`
(``metrics.jsonl`` and a checkpoint ``body.pt`` after every epoch, ``resume=True`` continues it);
:func:`validate_body_model` measures the centre errors on fresh uniform joints and how often the
learned body's collision verdicts differ from the analytic body's on the committed obstacle
benchmark. Loading and running a body model needs none of the training code: :func:`train_body_model`
imports :mod:`kinlearn.training.loop` when it is called.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import torch
from torch import nn

from ..body.robot import Robot, check_finite, check_last_dim, check_real_dtype, load_robot
from ..body.state import StateLayout
from ..collision import BodySpheres, Scene, body_spheres, check_path, clearances
from ..collision.problems import ProblemSet
from ..data.babbling import Transitions, load_transitions
from ..errors import CheckpointError, ConfigError, DatasetError, ShapeError
from ..io import content_sha256, load_checkpoint, save_checkpoint
from ..runs import diff_configs
from .forward_inverse import ACTIVATIONS

__all__ = [
    "BODY_KIND",
    "BODY_MODEL_FORMAT",
    "HELDOUT_PROBLEMS",
    "BodyModelConfig",
    "BodyTrainResult",
    "LearnedBody",
    "load_body_model",
    "save_body_model",
    "train_body_model",
    "validate_body_model",
]

#: The ``kind`` of a body model's checkpoint.
BODY_KIND = "body"
#: Version of the body model's checkpoint contents (its config and state dict layout).
BODY_MODEL_FORMAT = 1
#: The committed obstacle benchmark problems (present in a source checkout of kinlearn).
HELDOUT_PROBLEMS = (
    Path(__file__).resolve().parents[2] / "benchmarks" / "data" / "obstacle_problems_heldout.npz"
)

Activation = Literal["tanh", "relu", "gelu", "silu", "elu"]


@dataclass(frozen=True)
class BodyModelConfig:
    """A learned body model and how it is trained.

    Attributes:
        robot: the robot (a name with a bundled sphere model).
        dense: learn the 46-sphere body instead of the 12-sphere one (+ the base cover).
        hidden: widths of the MLP's hidden layers.
        activation: of every hidden layer.
        epochs, batch_size: passes over the training configurations and configurations per step.
        lr: Adam's initial learning rate, decayed per step on a cosine to ``lr × min_lr_ratio``.
        samples: configurations drawn uniformly in the joint box when no babbling data are given.
        val_fraction: share of the configurations held out for the per-epoch validation record.
        seed: seeds the uniform sample, the weights, the split and the shuffling.
    """

    robot: str = "iiwa14"
    dense: bool = False
    hidden: tuple[int, ...] = (160, 160, 160)
    activation: Activation = "silu"
    epochs: int = 80
    batch_size: int = 512
    lr: float = 3e-3
    min_lr_ratio: float = 0.003
    samples: int = 400_000
    val_fraction: float = 0.02
    seed: int = 0

    def __post_init__(self) -> None:
        hidden = tuple(self.hidden)
        object.__setattr__(self, "hidden", hidden)
        if not hidden or any(isinstance(w, bool) or not isinstance(w, int) or w < 1 for w in hidden):
            raise ConfigError(f"hidden must be a non-empty tuple of positive layer widths, got {hidden}")
        if self.activation not in ACTIVATIONS:
            raise ConfigError(f"activation must be one of {', '.join(ACTIVATIONS)}, got {self.activation!r}")
        for name in ("epochs", "batch_size", "samples"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ConfigError(f"BodyModelConfig.{name} must be an integer ≥ 1, got {value!r}")
        if not (isinstance(self.lr, (int, float)) and math.isfinite(self.lr) and self.lr > 0):
            raise ConfigError(f"lr must be a finite number > 0, got {self.lr!r}")
        if not 0.0 <= self.min_lr_ratio <= 1.0:
            raise ConfigError(f"min_lr_ratio must lie in [0, 1], got {self.min_lr_ratio!r}")
        if not 0.0 <= self.val_fraction < 1.0:
            raise ConfigError(f"val_fraction must lie in [0, 1), got {self.val_fraction!r}")
        if not isinstance(self.robot, str) or not self.robot:
            raise ConfigError(f"robot must be a robot name, got {self.robot!r}")

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["hidden"] = list(self.hidden)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> BodyModelConfig:
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = set(d) - names
        if unknown:
            raise ConfigError(f"unknown BodyModelConfig field(s): {', '.join(sorted(unknown))}")
        return cls(**{k: tuple(v) if k == "hidden" else v for k, v in d.items()})


def _analytic_body(config: BodyModelConfig) -> BodySpheres:
    return body_spheres(load_robot(config.robot), dense=config.dense)


class LearnedBody(nn.Module):
    """A learned collision body: joints ``(..., dof)`` → sphere centres ``(..., M, 3)``.

    The same spheres, in the same order, as the analytic body of ``config`` (base first); the base
    spheres' centres are constants, the others come from the MLP. Buffers: ``radii`` ``(M,)`` (the
    analytic radii + ``margin``), ``margin`` (metres, 0-d), ``link``, ``pairs``, ``floor_mask`` and
    ``lever`` as in :class:`~kinlearn.collision.BodySpheres` (copied from the analytic body),
    ``base_centres`` ``(M_base, 3)``, and the output statistics ``out_mean`` ``(3 M_moving,)`` and
    ``out_scale`` (0-d). The network's weights are float32 unless converted; the input is cast to
    them and the output follows the input's dtype and device. Differentiable in the joints.
    """

    def __init__(self, config: BodyModelConfig | None = None):
        super().__init__()
        config = config or BodyModelConfig()
        analytic = _analytic_body(config)
        self.config = config
        self.robot: Robot = analytic.robot
        self.name = analytic.name
        link = analytic.link
        self._num_base = int((link == 0).sum())
        n_moving = int(link.shape[0]) - self._num_base
        if n_moving == 0:
            raise ConfigError(f"the {analytic.name!r} body of {config.robot!r} has no moving sphere to learn")
        dof = self.robot.dof
        layers: list[nn.Module] = []
        width = 2 * dof
        for h in config.hidden:
            layers += [nn.Linear(width, h), ACTIVATIONS[config.activation]()]
            width = h
        layers.append(nn.Linear(width, 3 * n_moving))
        self.net = nn.Sequential(*layers)
        geometry = analytic.state_dict()
        self.register_buffer("base_centres", geometry["local"][: self._num_base].clone())
        self.register_buffer("sphere_radii", geometry["radii"].clone(), persistent=False)
        self.register_buffer("margin", torch.zeros((), dtype=geometry["radii"].dtype))
        self.register_buffer("radii", geometry["radii"].clone())
        for key in ("link", "pairs", "floor_mask", "lever"):
            self.register_buffer(key, geometry[key].clone())
        self.register_buffer("out_mean", torch.zeros(3 * n_moving))
        self.register_buffer("out_scale", torch.ones(()))

    @property
    def num_spheres(self) -> int:
        return int(self.radii.shape[0])

    @property
    def num_moving(self) -> int:
        """The number of spheres the network places (all but the base's)."""
        return self.num_spheres - self._num_base

    def extra_repr(self) -> str:
        return (
            f"robot={self.robot.name!r}, set={self.name!r}, spheres={self.num_spheres}, "
            f"learned={self.num_moving}, margin={float(self.margin):.4g} m"
        )

    def _weights_dtype(self) -> torch.dtype:
        return self.net[0].weight.dtype

    def _raw(self, q: torch.Tensor) -> torch.Tensor:
        """The network's output ``(N, 3 M_moving)`` in standardised units for joints ``(N, dof)``."""
        q = q.to(self._weights_dtype())
        return self.net(torch.cat((torch.sin(q), torch.cos(q)), dim=-1))

    def forward(self, q: torch.Tensor, validate: bool = True) -> torch.Tensor:
        """Sphere centres ``(..., M, 3)`` for joints ``q (..., dof)``.

        ``validate=False`` skips the dtype, shape and finiteness checks of ``q``.
        """
        if isinstance(q, np.ndarray):
            q = torch.from_numpy(q)
        if validate:
            check_real_dtype(q, "joint values q")
            check_last_dim(q, self.robot.dof, "joint values q")
            check_finite(q, "joint values q")
        batch = q.shape[:-1]
        flat = q.reshape(-1, self.robot.dof)
        y = self._raw(flat)
        y = y * self.out_scale.to(y.dtype) + self.out_mean.to(y.dtype)
        moving = y.reshape(flat.shape[0], self.num_moving, 3).to(q.dtype)
        base = self.base_centres.to(q.dtype).expand(flat.shape[0], self._num_base, 3)
        return torch.cat((base, moving), dim=1).reshape(*batch, self.num_spheres, 3)

    centres = forward

    def radii_like(self, x: torch.Tensor) -> torch.Tensor:
        """The radii ``(M,)`` (margin included) in ``x``'s dtype and device."""
        return self.radii.to(dtype=x.dtype, device=x.device)

    @torch.no_grad()
    def set_margin(self, margin: float) -> LearnedBody:
        """Inflate every sphere's radius by ``margin`` metres (≥ 0) over the analytic radius; returns self.

        A body–obstacle distance then shrinks by ``margin`` and a self-collision pair's by twice it.
        """
        m = float(margin)
        if not (math.isfinite(m) and m >= 0.0):
            raise ConfigError(f"margin must be a finite number of metres ≥ 0, got {margin!r}")
        self.margin.fill_(m)
        self.radii.copy_(self.sphere_radii.to(self.radii) + m)
        return self

    # ----------------------------------------------------------------------------------------------
    # Training
    # ----------------------------------------------------------------------------------------------

    @torch.no_grad()
    def fit_normalization(self, target: torch.Tensor) -> None:
        """Output statistics from training targets ``(N, 3 M_moving)`` (metres): the mean of each
        coordinate and one scale for all, the root-mean-square deviation from those means."""
        target = target.double()
        mean = target.mean(0)
        self.out_mean.copy_(mean)
        self.out_scale.fill_(float((target - mean).square().mean().sqrt().clamp_min(1e-6)))

    def training_loss(self, q: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        """Mean squared error of the moving centres ``target (N, 3 M_moving)``, in output-scale units."""
        y = (target.to(self._weights_dtype()) - self.out_mean.to(self._weights_dtype())) / self.out_scale
        return (self._raw(q) - y).square().mean()

    def moving_centres(self, centres: torch.Tensor) -> torch.Tensor:
        """``(..., M, 3)`` centres → ``(..., 3 M_moving)``: the training target layout."""
        return centres[..., self._num_base :, :].reshape(*centres.shape[:-2], 3 * self.num_moving)


# --------------------------------------------------------------------------------------------------
# Checkpoints
# --------------------------------------------------------------------------------------------------


def _config_record(config: BodyModelConfig) -> dict:
    return {"body_format": BODY_MODEL_FORMAT, **config.to_dict()}


def save_body_model(model: LearnedBody, path: str | Path, extra: dict | None = None) -> Path:
    """Save a learned body (weights, margin, geometry, config, robot and format version) atomically.

    ``extra`` (tensors and plain values, e.g. training state) is stored beside; leave it out for a
    small weights-only file.
    """
    if not isinstance(model, LearnedBody):
        raise ConfigError(f"save_body_model needs a LearnedBody, got {type(model).__name__}")
    return save_checkpoint(
        path,
        kind=BODY_KIND,
        robot=model.robot.name,
        config=_config_record(model.config),
        state_dict=model.state_dict(),
        extra=extra,
    )


def load_body_model(path: str | Path, robot: Robot | str | None = None) -> LearnedBody:
    """Load a body model saved by :func:`save_body_model`.

    ``robot`` (a :class:`Robot` or its name; ``None``: any) must be the one it was trained for.
    Raises :class:`~kinlearn.CheckpointError` for a missing or corrupt file, another kind of model,
    another robot, another body model format, or a robot whose sphere model changed since training.
    """
    name = robot.name if isinstance(robot, Robot) else robot
    payload = load_checkpoint(path, kind=BODY_KIND, robot=name)
    config = dict(payload.get("config") or {})
    version = config.pop("body_format", None)
    if version != BODY_MODEL_FORMAT:
        raise CheckpointError(
            f"{path} holds body model format {version!r}; this kinlearn reads format {BODY_MODEL_FORMAT}"
        )
    try:
        cfg = BodyModelConfig.from_dict(config)
        model = LearnedBody(cfg)
        model.load_state_dict(payload["state_dict"], strict=True)
    except Exception as exc:
        raise CheckpointError(
            f"{path}: cannot rebuild the body model from its config and weights ({type(exc).__name__}: {exc})"
        ) from exc
    if model.robot.name != payload.get("robot"):
        raise CheckpointError(
            f"{path}: config robot {model.robot.name!r} != checkpoint robot {payload.get('robot')!r}"
        )
    _check_geometry(model, path)
    return model.eval()


def _check_geometry(model: LearnedBody, path) -> None:
    """The loaded geometry must be the robot's current analytic sphere model (+ the saved margin)."""
    ref = _analytic_body(model.config).state_dict()
    same = (
        torch.equal(model.link, ref["link"])
        and torch.equal(model.pairs, ref["pairs"])
        and torch.equal(model.floor_mask, ref["floor_mask"])
        and torch.allclose(model.lever, ref["lever"], rtol=0, atol=1e-9)
        and torch.allclose(model.base_centres, ref["local"][: model._num_base], rtol=0, atol=1e-9)
        and torch.allclose(model.radii, ref["radii"] + model.margin, rtol=0, atol=1e-9)
    )
    if not same:
        raise CheckpointError(
            f"{path} was trained against another sphere model of {model.robot.name!r} than the one this "
            "kinlearn bundles (radii, links, pairs or base spheres differ); train the body model again"
        )


# --------------------------------------------------------------------------------------------------
# Training
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class BodyTrainResult:
    """What :func:`train_body_model` returns: the trained model, its per-epoch history, its checkpoint
    (``None`` without a run directory) and where its training configurations came from."""

    model: LearnedBody
    history: list[dict]
    checkpoint: Path | None
    data: dict


def _training_joints(
    config: BodyModelConfig, robot: Robot, data: str | Path | Transitions | torch.Tensor | None
) -> tuple[torch.Tensor, dict]:
    """Joint configurations ``(N, dof)`` (float64) to learn the body at, and a record of their source."""
    if data is None:
        gen = torch.Generator().manual_seed(int(config.seed))
        q = robot.sample(config.samples, gen, dtype=torch.float64)
        return q, {"source": "uniform", "samples": config.samples, "seed": config.seed}
    if isinstance(data, (str, Path)):
        trans = load_transitions(data, robot=config.robot)
        source: dict = {"source": "babbling", "path": str(data)}
    elif isinstance(data, Transitions):
        trans, source = data, {"source": "babbling"}
    elif isinstance(data, torch.Tensor):
        if data.ndim != 2:
            raise ShapeError(
                f"joint configurations must have shape (N, {robot.dof}), got {tuple(data.shape)}"
            )
        trans, source = None, {"source": "joints"}
    else:
        raise DatasetError(
            f"data must be a babbling .npz path, Transitions, a (N, dof) joint tensor or None; got {type(data).__name__}"
        )
    if trans is not None:
        if trans.robot != config.robot:
            raise DatasetError(
                f"the data were babbled with {trans.robot!r}, the body model is for {config.robot!r}"
            )
        q = trans.s[:, StateLayout(robot.dof).joints]
    else:
        q = data
    check_last_dim(q, robot.dof, "joint configurations")
    q = q.detach().to(dtype=torch.float64, device="cpu")
    robot.check_joints(q, tol=1e-6, what="training joint configurations")
    if q.shape[0] < 2:
        raise DatasetError(f"need at least 2 joint configurations to train on, got {q.shape[0]}")
    return q.contiguous(), {**source, "configurations": int(q.shape[0])}


@torch.no_grad()
def _targets(analytic: BodySpheres, model: LearnedBody, q: torch.Tensor, chunk: int = 65536) -> torch.Tensor:
    """The analytic moving centres ``(N, 3 M_moving)`` at ``q`` (float64), in the model's dtype."""
    parts = [model.moving_centres(analytic(c, validate=False)) for c in q.split(chunk)]
    return torch.cat(parts).to(model._weights_dtype())


def _centre_metrics(model: LearnedBody, q: torch.Tensor, target: torch.Tensor) -> dict[str, float]:
    pred = model.moving_centres(model(q, validate=False))
    err = (pred.to(target.dtype) - target).reshape(q.shape[0], -1, 3).norm(dim=-1)
    return {"val_centre_err_mm": float(err.mean()) * 1e3}


def train_body_model(
    config: BodyModelConfig,
    run_dir: str | Path | None = None,
    data: str | Path | Transitions | torch.Tensor | None = None,
    *,
    progress: bool = True,
    resume: bool = False,
) -> BodyTrainResult:
    """Train a :class:`LearnedBody` on the analytic sphere centres at babbled or sampled joints.

    ``data``: a babbling ``.npz`` (``kinlearn babble``; its states' joints are used), loaded
    :class:`~kinlearn.Transitions`, a joint tensor ``(N, dof)``, or ``None``: ``config.samples``
    configurations drawn uniformly in the joint box with ``config.seed``. A share
    ``config.val_fraction`` is held out for the per-epoch record. Uses :func:`kinlearn.training.loop.fit`:
    with ``run_dir``, ``metrics.jsonl`` and the checkpoint ``run_dir/body.pt`` (weights + training
    state, loadable by :func:`load_body_model`) are written after every epoch, and ``resume=True``
    continues from that checkpoint (:class:`~kinlearn.CheckpointError` if it was made with another
    configuration or other data). Deterministic for a given config and data.
    """
    # Imported here: the model and its checkpoints do not depend on the training code.
    from ..training.loop import OptimConfig, TrainConfig, fit, seed_everything

    if not isinstance(config, BodyModelConfig):
        raise ConfigError(f"train_body_model needs a BodyModelConfig, got {type(config).__name__}")
    robot = load_robot(config.robot)
    q, source = _training_joints(config, robot, data)
    seed_everything(config.seed)
    model = LearnedBody(config)
    analytic = _analytic_body(config)
    target = _targets(analytic, model, q)
    n_val = round(q.shape[0] * config.val_fraction)
    perm = torch.randperm(q.shape[0], generator=torch.Generator().manual_seed(int(config.seed) + 2))
    tr, va = perm[n_val:], perm[:n_val]
    wdt = model._weights_dtype()
    train = (q[tr].to(wdt), target[tr])
    val = (q[va].to(wdt), target[va]) if n_val else None
    model.fit_normalization(target[tr])
    cfg = TrainConfig(
        optim=OptimConfig(name="adam", lr=config.lr),
        epochs=config.epochs,
        batch_size=config.batch_size,
        val_fraction=config.val_fraction,
        seed=config.seed,
        schedule="cosine",
        min_lr_ratio=config.min_lr_ratio,
        progress=progress,
    )
    ckpt = Path(run_dir) / "body.pt" if run_dir is not None else None
    identity = {"data_sha256": content_sha256(q)}

    def load(path: Path) -> dict:
        payload = load_checkpoint(path, kind=BODY_KIND, robot=config.robot)
        diffs = [f"model {d}" for d in diff_configs(payload.get("config") or {}, _config_record(config))]
        stored = (payload.get("extra") or {}).get("data_sha256")
        if stored is not None and stored != identity["data_sha256"]:
            diffs.append(f"data_sha256: {stored[:16]}… → {identity['data_sha256'][:16]}…")
        if diffs:
            raise CheckpointError(
                f"{path} was trained with another configuration or data ({'; '.join(diffs)}); resume with "
                "the same settings and data, or train into a new run directory"
            )
        return payload

    history = fit(
        model,
        train,
        val,
        cfg,
        metrics_fn=_centre_metrics,
        run_dir=run_dir,
        checkpoint=ckpt,
        save_fn=lambda path, m, extra: save_body_model(m, path, extra={**extra, **identity, "data": source}),
        load_fn=load,
        resume=resume,
        desc="train body",
    )
    return BodyTrainResult(model.eval(), history, ckpt, source)


# --------------------------------------------------------------------------------------------------
# Validation against the analytic body
# --------------------------------------------------------------------------------------------------


def _rates(learned_hit: torch.Tensor, true_hit: torch.Tensor, prefix: str) -> dict:
    """Verdict agreement counts and rates; a rate is ``None`` when its denominator is 0."""
    n_hit = int(true_hit.sum())
    n_free = int((~true_hit).sum())
    false_free = int((~learned_hit & true_hit).sum())
    false_hit = int((learned_hit & ~true_hit).sum())
    n = n_hit + n_free
    return {
        f"{prefix}_n": n,
        f"{prefix}_collision_rate": n_hit / n if n else None,
        f"{prefix}_false_free": false_free,
        f"{prefix}_false_collision": false_hit,
        f"{prefix}_false_free_rate": false_free / n_hit if n_hit else None,
        f"{prefix}_false_collision_rate": false_hit / n_free if n_free else None,
        f"{prefix}_agreement": (n - false_free - false_hit) / n if n else None,
    }


@torch.no_grad()
def validate_body_model(
    model: LearnedBody,
    analytic_body: BodySpheres | None = None,
    n: int = 100_000,
    seed: int = 20_000,
    *,
    problems: ProblemSet | str | Path | None = HELDOUT_PROBLEMS,
    configs_per_scene: int = 32,
    max_travel: float = 0.01,
) -> dict:
    """How closely ``model`` matches the analytic body (``None``: the one it was trained against).

    Returns a dict (JSON-able) with:

    - ``centre_err_mm_mean``, ``_p99``, ``_max``: Euclidean error of the moving spheres' centres over
      ``n`` configurations drawn uniformly in the joint box with ``seed`` (the base spheres are
      exact and left out); ``centre_err_mm_p99_by_link``: the p99 per link 1…dof (``None`` for a
      link without a sphere); ``margin_mm``: the model's radius margin.
    - On the obstacle problems (``problems``: a :class:`ProblemSet` or its file, by default the
      committed benchmark; ``None`` skips this part), the collision verdicts (scene or self-collision)
      of the learned body against the analytic body's, for ``configs_per_scene`` uniform random
      configurations in every scene (keys ``configs_*``) and for every problem's straight joint-space
      line from start to goal, checked densely by :func:`~kinlearn.collision.check_path` with
      ``max_travel`` (keys ``lines_*``). For each: ``_n``, ``_collision_rate`` (analytic),
      ``_false_free`` (learned says free, analytic says collision) and ``_false_free_rate`` (of the
      analytic collisions), ``_false_collision`` and ``_false_collision_rate`` (of the analytic free
      ones), ``_agreement``; ``configs_clearance_err_mm_mean``/``_p99``: the error of the learned
      body–scene clearance where both are finite.
    """
    if not isinstance(model, LearnedBody):
        raise ConfigError(f"validate_body_model needs a LearnedBody, got {type(model).__name__}")
    analytic = analytic_body if analytic_body is not None else _analytic_body(model.config)
    if analytic.robot.name != model.robot.name or not torch.equal(analytic.link.cpu(), model.link.cpu()):
        raise ConfigError(
            f"the analytic body ({analytic.robot.name!r}, {analytic.num_spheres} spheres) is not the one the "
            f"model learned ({model.robot.name!r}, {model.num_spheres} spheres)"
        )
    if isinstance(n, bool) or not isinstance(n, int) or n < 1 or configs_per_scene < 1:
        raise ConfigError(f"n and configs_per_scene must be integers ≥ 1, got {n!r}, {configs_per_scene!r}")
    was_training = model.training
    model.eval()
    robot = model.robot
    dev = model.radii.device
    out: dict = {"robot": robot.name, "set": model.name, "n": n, "seed": seed}
    out["margin_mm"] = float(model.margin) * 1e3
    gen = torch.Generator().manual_seed(int(seed))
    q = robot.sample(n, gen, dtype=torch.float64).to(dev)
    nb = model._num_base
    errs = torch.cat(
        [
            (model(c, validate=False) - analytic(c, validate=False))[:, nb:].norm(dim=-1)
            for c in q.split(65536)
        ]
    ).cpu()  # (n, M_moving)
    mm = errs * 1e3
    out["centre_err_mm_mean"] = float(mm.mean())
    out["centre_err_mm_p99"] = _quantile(mm.reshape(-1), 0.99)
    out["centre_err_mm_max"] = float(mm.max())
    link = model.link[nb:].cpu()
    out["centre_err_mm_p99_by_link"] = [
        _quantile(mm[:, link == k].reshape(-1), 0.99) if bool((link == k).any()) else None
        for k in range(1, robot.dof + 1)
    ]
    if problems is not None:
        ps = problems if isinstance(problems, ProblemSet) else ProblemSet.load(problems, robot=robot.name)
        if ps.robot != robot.name:
            raise DatasetError(f"the problems are for {ps.robot!r}, the body model for {robot.name!r}")
        out.update(_verdicts(model, analytic, ps, gen, configs_per_scene, max_travel))
    model.train(was_training)
    return out


def _quantile(x: torch.Tensor, p: float) -> float:
    """The ``p`` quantile of a 1-d tensor (exact; torch.quantile limits its input size)."""
    x = x.double().sort().values
    pos = p * (x.shape[0] - 1)
    lo = math.floor(pos)
    hi = min(lo + 1, x.shape[0] - 1)
    return float(x[lo] + (x[hi] - x[lo]) * (pos - lo))


def _verdicts(
    model: LearnedBody,
    analytic: BodySpheres,
    ps: ProblemSet,
    gen: torch.Generator,
    per_scene: int,
    max_travel: float,
) -> dict:
    dev = model.radii.device
    scene: Scene = ps.scene.to(dtype=torch.float64, device=dev)
    q = model.robot.sample((len(ps), per_scene), gen, dtype=torch.float64).to(dev)
    per_config = scene.unsqueeze(1)  # (P, 1): one scene for each problem's configurations
    d_true, s_true = clearances(analytic, q, per_config, validate=False)
    d_learn, s_learn = clearances(model, q, per_config, validate=False)
    true_hit = ((d_true <= 0.0) | (s_true <= 0.0)).reshape(-1).cpu()
    learn_hit = ((d_learn <= 0.0) | (s_learn <= 0.0)).reshape(-1).cpu()
    out = {"problems": len(ps), "configs_per_scene": per_scene, "max_travel_m": max_travel}
    out.update(_rates(learn_hit, true_hit, "configs"))
    finite = torch.isfinite(d_true) & torch.isfinite(d_learn)
    gap = ((d_learn - d_true)[finite].abs() * 1e3).cpu()
    out["configs_clearance_err_mm_mean"] = float(gap.mean()) if gap.numel() else None
    out["configs_clearance_err_mm_p99"] = _quantile(gap, 0.99) if gap.numel() else None
    lines = torch.stack((ps.start, ps.goal), dim=1).to(device=dev, dtype=torch.float64)  # (P, 2, dof)
    free_true = check_path(analytic, lines, scene, max_travel=max_travel).collision_free.cpu()
    free_learn = check_path(model, lines, scene, max_travel=max_travel).collision_free.cpu()
    out.update(_rates(~free_learn, ~free_true, "lines"))
    return out
