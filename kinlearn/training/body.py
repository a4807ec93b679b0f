"""Training and validating the learned body model (:mod:`kinlearn.models.body`).

:func:`train_body_model` reuses the generic resumable loop of :mod:`kinlearn.training.loop`
(``metrics.jsonl`` and a checkpoint ``body.pt`` after every epoch, ``resume=True`` continues it);
:func:`validate_body_model` measures the centre errors on fresh uniform joints and how often the
learned body's collision verdicts differ from the analytic body's on the committed obstacle benchmark.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import torch

from ..body.robot import Robot, load_robot
from ..body.state import StateLayout
from ..checks import check_last_dim
from ..collision import BodySpheres, Scene, check_path, clearances
from ..data.babbling import Transitions
from ..data.problems import ProblemSet
from ..data.recorded import load_data
from ..errors import ConfigError, DatasetError, ShapeError
from ..io import content_sha256
from ..models.body import (
    BODY_KIND,
    BodyModelConfig,
    LearnedBody,
    _analytic_body,
    _config_record,
    save_body_model,
)
from .loop import OptimConfig, TrainConfig, _load_to_resume, fit, seed_everything

__all__ = ["HELDOUT_PROBLEMS", "BodyTrainResult", "train_body_model", "validate_body_model"]

#: The committed obstacle benchmark problems (present in a source checkout of kinlearn).
HELDOUT_PROBLEMS = (
    Path(__file__).resolve().parents[2] / "benchmarks" / "data" / "obstacle_problems_heldout.npz"
)


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
        trans = load_data(data, robot=config.robot)
        source: dict = {"source": trans.config.get("source", "babbling"), "path": str(data)}
    elif isinstance(data, Transitions):
        trans, source = data, {"source": data.config.get("source", "babbling")}
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

    ``data``: a babbling ``.npz`` (``kinlearn babble``) or a recorded log (:func:`kinlearn.data.recorded.load_data`;
    the joints of its transitions' states are used), loaded
    :class:`~kinlearn.data.Transitions`, a joint tensor ``(N, dof)``, or ``None``: ``config.samples``
    configurations drawn uniformly in the joint box with ``config.seed``. A share
    ``config.val_fraction`` is held out for the per-epoch record. Uses :func:`kinlearn.training.loop.fit`:
    with ``run_dir``, ``metrics.jsonl`` and the checkpoint ``run_dir/body.pt`` (weights + training
    state, loadable by :func:`load_body_model`) are written after every epoch, and ``resume=True``
    continues from that checkpoint (:class:`~kinlearn.CheckpointError` if it was made with another
    configuration or other data). Deterministic for a given config and data.
    """
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
    history = fit(
        model,
        train,
        val,
        cfg,
        metrics_fn=_centre_metrics,
        run_dir=run_dir,
        checkpoint=ckpt,
        save_fn=lambda path, m, extra: save_body_model(m, path, extra={**extra, **identity, "data": source}),
        load_fn=lambda path: _load_to_resume(path, BODY_KIND, config.robot, _config_record(config), identity),
        resume=resume,
        desc="body training",
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
