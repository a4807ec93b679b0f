"""Identification of a serial chain (:class:`~kinlearn.models.chain.ChainFM`) from observed end-effector
positions: calibration with or without a URDF.

Given N observations (θₖ, yₖ) — joint encoder values and the end effector's measured position in the
base frame (a camera, motion capture, or babbling with simulated sensor noise) — the chain's
parameters x = (ωᵢ, qᵢ, p₀) minimise a robust sum over the samples

    Σₖ ρ(‖p(θₖ; x) − yₖ‖ / δ),      ρ = Huber,

in three rounds: δ = 1 cm; then δ = 3σ̂ with σ̂ the robust (median-absolute-deviation) scale of the
residuals; then again after dropping the samples whose residual exceeds ``outlier_sigma`` σ̂ (gross
outliers, counted in the report). Each round is Levenberg–Marquardt on the reweighted residuals in
float64 (``_fit``).

Initialisation, the hard part (a chain started at random stalls 10–50 cm away):

- **with a prior** (a user's URDF, possibly wrong): the chain the URDF describes
  (:meth:`ChainFM.from_robot`);
- **with nothing but the joint count**: a first MLP g(θ) fitted to the data (``_fit_mlp``), then
  for each joint a virtual sweep through g — joint i moved over its observed range, the others held
  at a reference configuration θ̄ — and a circle fitted to the swept points (``_circle``): its plane's
  normal is the joint's axis (its sign from the sense of rotation), its centre a point on the axis,
  at θ̄, which is exactly the chain's parameterisation about θ̄. Several reference configurations
  drawn from the data are scored by their sweeps' radii (a joint whose sweep barely moves the end
  effector is poorly determined there) and each best-scored one is fitted briefly; the best fit is
  refined.

Parameters the data cannot determine are handled deliberately: a point slides along its axis and a
direction has no length (the fit's gradient is zero along both; :meth:`ChainFM.canonicalize` fixes
them afterwards), and the direction of a trailing joint whose axis passes through the end-effector
point does not move the end effector at all. Such joints are found after the fit (distance of the
end-effector point to the axis below ``unobservable_distance``), keep their initial direction (the
prior's, or the sweep's), and are named in the report: the exported URDF is then right in position
and arbitrary about that joint's orientation.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import time
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch
from torch import nn
from tqdm.auto import tqdm

from ..body.robot import Robot, load_robot
from ..checks import as_int, as_real, check_finite
from ..data.babbling import Transitions
from ..data.recorded import Observations, check_observation_units, load_observations
from ..errors import (
    CheckpointError,
    ConfigError,
    DatasetError,
    PoorExcitationWarning,
    UnidentifiableError,
)
from ..io import load_checkpoint
from ..models.chain import ChainConfig, ChainFM, chain_parameter_jacobian, chain_position, chain_urdf
from ..models.forward_inverse import load_fm, save_model

__all__ = ["Identification", "IdentifyConfig", "fit_residual", "identify"]


@dataclass(frozen=True)
class IdentifyConfig:
    """Settings of :func:`identify`.

    Attributes:
        holdout: fraction of the samples kept out of the fit to report the held-out residual.
        seed: seeds the split, the first MLP and the reference configurations.
        iterations: Levenberg–Marquardt iterations of each robust round (at most; it stops converged).
        outlier_sigma: residuals beyond this many robust standard deviations are dropped in the last round.
        mlp_hidden, mlp_steps: the first MLP of the no-prior initialisation.
        references: reference configurations tried by the no-prior initialisation.
        unobservable_distance: a trailing joint whose axis passes closer than this (m) to the
            end-effector point is reported as undetermined in direction.
        residual, residual_steps: widths and Adam steps of the optional residual MLP (empty: none).
        max_samples: at most this many samples are used (a seeded random subset of more): the fit's
            time grows with them, its accuracy hardly past 10⁵ (the error falls as 1/√N). What remains
            must still be the chain's minimum (20 per parameter), else the fit is refused.
        min_joint_range: a joint whose observed values span less than this (rad) never moved: the data
            cannot identify its axis, and the fit is refused naming it; one that spans less than 10 times
            this is fitted with a :class:`~kinlearn.errors.PoorExcitationWarning` naming it.
    """

    holdout: float = 0.1
    seed: int = 0
    iterations: int = 30
    outlier_sigma: float = 6.0
    mlp_hidden: tuple[int, ...] = (128, 128, 128)
    mlp_steps: int = 1500
    references: int = 3
    unobservable_distance: float = 1e-3
    residual: tuple[int, ...] = ()
    residual_steps: int = 2000
    max_samples: int = 200_000
    min_joint_range: float = 0.01

    def __post_init__(self) -> None:
        def put(name: str, value) -> None:
            object.__setattr__(self, name, value)

        put("holdout", as_real(self.holdout, "holdout", minimum=0.0, maximum=0.5))
        if self.holdout >= 0.5:
            raise ConfigError(f"holdout must lie in [0, 0.5), got {self.holdout}")
        put("seed", as_int(self.seed, "seed", minimum=0))
        for name in ("iterations", "mlp_steps", "references", "residual_steps", "max_samples"):
            put(name, as_int(getattr(self, name), name, minimum=1))
        put("outlier_sigma", as_real(self.outlier_sigma, "outlier_sigma", minimum=1.0, open_minimum=True))
        put(
            "unobservable_distance",
            as_real(self.unobservable_distance, "unobservable_distance (m)", minimum=0.0),
        )
        put("min_joint_range", as_real(self.min_joint_range, "min_joint_range (rad)", minimum=0.0))
        for name in ("mlp_hidden", "residual"):
            widths = getattr(self, name)
            if isinstance(widths, (str, bytes)) or not hasattr(widths, "__iter__"):
                raise ConfigError(f"{name} must be a sequence of layer widths, got {widths!r}")
            put(name, tuple(as_int(w, f"{name} width", minimum=1) for w in widths))

    def to_dict(self) -> dict:
        d = asdict(self)
        return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}


@dataclass
class Identification:
    """What :func:`identify` found: the chain, a report (JSON-able: residuals in metres) and the
    joint names it was identified for (or ``None``)."""

    model: ChainFM
    report: dict = field(default_factory=dict)
    joint_names: tuple[str, ...] | None = None
    base_link: str = "base"
    ee_frame: str = "ee"
    velocity: tuple[float, ...] | None = None  # joint velocity limits for the URDF (rad/s)

    def save(self, path: str | Path, config: IdentifyConfig | None = None) -> Path:
        """Save the chain as an FM checkpoint (read by :meth:`load`, or ``load_fm`` for the model alone)
        with its report and the names its URDF gives."""
        extra = {
            "report": self.report,
            "joint_names": list(self.joint_names or ()),
            "base_link": self.base_link,
            "ee_frame": self.ee_frame,
            "velocity": None if self.velocity is None else list(self.velocity),
        }
        if config is not None:
            extra["identify"] = config.to_dict()
        return save_model(self.model, path, extra=extra)

    @classmethod
    def load(cls, path: str | Path) -> Identification:
        """An identification saved by :meth:`save`; :class:`~kinlearn.errors.CheckpointError` for a file
        that holds no chain."""
        payload = load_checkpoint(path, kind="fm")
        model = load_fm(path)
        if not isinstance(model, ChainFM):
            raise CheckpointError(f"{path} holds a {type(model).__name__}, not an identified chain")
        extra = payload["extra"]
        velocity = extra.get("velocity")
        return cls(
            model,
            extra.get("report", {}),
            tuple(extra.get("joint_names") or ()) or None,
            extra.get("base_link", "base"),
            extra.get("ee_frame", "ee"),
            None if velocity is None else tuple(velocity),
        )

    def urdf(self, name: str | None = None) -> str:
        """The chain as a URDF document (see :func:`~kinlearn.models.chain.chain_urdf`); names are written
        XML-escaped, so any robot name gives a well-formed document."""
        if name is not None and not isinstance(name, str):
            raise ConfigError(f"name must be a string, got {type(name).__name__}")
        return chain_urdf(
            self.model,
            name=name or self.model.robot_name,
            joint_names=self.joint_names,
            base_link=self.base_link,
            ee_frame=self.ee_frame,
            velocity=self.velocity,
        )


# --------------------------------------------------------------------------------------------------
# Fitting
# --------------------------------------------------------------------------------------------------


def _residuals(model: ChainFM, theta: torch.Tensor, ef: torch.Tensor) -> torch.Tensor:
    return (model.position(theta) - ef).norm(dim=-1)


def _robust_scale(r: torch.Tensor) -> float:
    """σ of a 3-D isotropic Gaussian from the median residual norm (median of a χ₃ is 1.5382 σ)."""
    return float(r.median()) / 1.5382


def _unpack(x: torch.Tensor, n: int):
    """The parameter vector (axes, points, tip) as the chain's tensors, axes normalised."""
    w = x[: 3 * n].reshape(n, 3)
    return w / w.norm(dim=-1, keepdim=True), x[3 * n : 6 * n].reshape(n, 3), x[6 * n :]


def _fit(model: ChainFM, theta, ef, delta: float, iterations: int, chunk: int = 16384) -> float:
    """Levenberg–Marquardt on the Huber loss of the residual norms / δ (iteratively reweighted least
    squares: weight min(1, δ / ‖r‖) per sample). The residuals' Jacobian in the 6n + 3 parameters is
    analytic (:func:`~kinlearn.models.chain.chain_parameter_jacobian`); the damping λ·I takes no step along the directions the data cannot
    see (a point sliding along its axis, an axis's length). Returns the final mean Huber loss."""
    n = model.dof
    ref = model.reference.detach()
    phi = theta - ref
    x = torch.cat((model.axis.detach().flatten(), model.point.detach().flatten(), model.tip.detach()))

    def residual(x: torch.Tensor, ph: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        return chain_position(*_unpack(x, n), ph) - y

    def loss_of(r: torch.Tensor) -> torch.Tensor:
        a = r.norm(dim=-1) / delta
        return torch.where(a < 1.0, 0.5 * a.square(), a - 0.5).mean()

    def evaluate(x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        r = torch.cat([residual(x, phi[k : k + chunk], ef[k : k + chunk]) for k in range(0, len(phi), chunk)])
        return r, loss_of(r)

    r, loss = evaluate(x)
    lam = None
    for _ in range(iterations):
        weight = (delta / r.norm(dim=-1).clamp_min(1e-15)).clamp(max=1.0)
        H = torch.zeros(x.numel(), x.numel(), dtype=x.dtype)
        g = torch.zeros(x.numel(), dtype=x.dtype)
        for k in range(0, len(phi), chunk):
            ph, wk = phi[k : k + chunk], weight[k : k + chunk]
            _, J = chain_parameter_jacobian(x[: 3 * n].reshape(n, 3), *_unpack(x, n)[1:], ph)
            J = J.reshape(-1, x.numel())  # (3m, P)
            wr = wk.repeat_interleave(3)
            H += J.T @ (J * wr[:, None])
            g += J.T @ (r[k : k + chunk].reshape(-1) * wr)
        if lam is None:
            lam = 1e-6 * float(H.diagonal().mean())
        improved = False
        for _ in range(10):
            step = torch.linalg.solve(H + lam * torch.eye(x.numel(), dtype=x.dtype), -g)
            x_new = x + step
            r_new, loss_new = evaluate(x_new)
            if loss_new < loss:
                x, r, improved = x_new, r_new, float(loss - loss_new) > 1e-9 * float(loss)
                loss, lam = loss_new, lam / 3.0
                break
            lam *= 8.0
        if not improved:
            break
    w, q, tip = _unpack(x, n)
    with torch.no_grad():
        model.axis.copy_(w)
        model.point.copy_(q)
        model.tip.copy_(tip)
    return float(loss)


def _fit_mlp(theta, ef, hidden, steps: int, gen: torch.Generator, progress: bool = False) -> nn.Module:
    """A first, rough model of the end effector: an MLP of (sin θ, cos θ), standardised output."""
    torch.manual_seed(int(torch.randint(0, 2**31 - 1, (1,), generator=gen)))
    x = torch.cat((theta.sin(), theta.cos()), -1).float()
    mean, std = ef.mean(0).float(), ef.std(0).float().clamp_min(1e-6)
    y = (ef.float() - mean) / std
    sizes = (x.shape[-1], *hidden)
    layers: list[nn.Module] = []
    for a, b in itertools.pairwise(sizes):
        layers += [nn.Linear(a, b), nn.SiLU()]
    net = nn.Sequential(*layers, nn.Linear(sizes[-1], 3))
    opt = torch.optim.Adam(net.parameters(), lr=2e-3)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=2e-3, total_steps=steps, pct_start=0.05)
    n = x.shape[0]
    batch = min(1024, n)
    with torch.enable_grad():
        for _ in tqdm(range(steps), desc="identify: first MLP", disable=not progress, leave=False):
            idx = torch.randint(0, n, (batch,), generator=gen)
            loss = torch.nn.functional.smooth_l1_loss(net(x[idx]), y[idx], beta=0.05)
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
    net.requires_grad_(False)

    def g(th: torch.Tensor) -> torch.Tensor:
        return (net(torch.cat((th.sin(), th.cos()), -1).float()) * std + mean).double()

    return g


def _circle(P: np.ndarray, angles: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """The circle through 3-D points swept by increasing ``angles``: unit axis (right-handed with the
    sweep), centre, radius."""
    c = P.mean(0)
    _, _, Vt = np.linalg.svd(P - c)
    u, v, n = Vt
    x, y = (P - c) @ u, (P - c) @ v
    A = np.column_stack((2 * x, 2 * y, np.ones_like(x)))
    (a, b, k), *_ = np.linalg.lstsq(A, x**2 + y**2, rcond=None)
    centre = c + a * u + b * v
    radius = math.sqrt(max(k + a * a + b * b, 0.0))
    d = P - centre
    sense = np.cross(d[:-1], d[1:]).sum(0) @ n
    return (n if sense >= 0 else -n), centre, radius


def _sweep_init(g, reference: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor, points: int = 48):
    """Axes and points of every joint at ``reference`` from circles swept through ``g``; radii."""
    dof = reference.shape[0]
    axes, centres, radii = np.zeros((dof, 3)), np.zeros((dof, 3)), np.zeros(dof)
    tip = g(reference[None])[0].numpy()
    for i in range(dof):
        angles = torch.linspace(float(lo[i]), float(hi[i]), points, dtype=torch.float64)
        th = reference.repeat(points, 1)
        th[:, i] = angles
        axes[i], centres[i], radii[i] = _circle(g(th).numpy(), angles.numpy())
    return axes, centres, radii, tip


def _chain_from(axes, points, tip, reference, robot_name: str, lo, hi) -> ChainFM:
    model = ChainFM(ChainConfig(robot=robot_name, dof=len(reference)))
    with torch.no_grad():
        model.axis.copy_(torch.as_tensor(axes, dtype=torch.float64))
        model.point.copy_(torch.as_tensor(points, dtype=torch.float64))
        model.tip.copy_(torch.as_tensor(tip, dtype=torch.float64))
        model.reference.copy_(torch.as_tensor(reference, dtype=torch.float64))
        model.lower.copy_(torch.as_tensor(lo, dtype=torch.float64))
        model.upper.copy_(torch.as_tensor(hi, dtype=torch.float64))
    return model


def _check_observations(theta, ef) -> tuple[torch.Tensor, torch.Tensor]:
    out = []
    for what, t in (("theta", theta), ("ef", ef)):
        if not isinstance(t, torch.Tensor):
            try:
                t = torch.as_tensor(np.asarray(t))
            except (TypeError, ValueError, RuntimeError) as exc:
                raise DatasetError(f"{what} must be an array of numbers, got {type(t).__name__}") from exc
        if t.dtype == torch.bool or t.is_complex():
            raise DatasetError(f"{what} must hold real numbers, got a {t.dtype} tensor")
        out.append(t.detach().double().cpu())
    theta, ef = out
    if theta.ndim != 2 or ef.ndim != 2 or ef.shape[-1] != 3 or theta.shape[0] != ef.shape[0]:
        raise DatasetError(
            f"identification needs theta (N, dof) and ef (N, 3) of one length; got {tuple(theta.shape)} "
            f"and {tuple(ef.shape)}"
        )
    check_finite(theta, "theta")
    check_finite(ef, "ef")
    return theta, ef


def identify(
    data,
    *,
    robot: Robot | str | None = None,
    prior: bool | Robot = True,
    dof: int | None = None,
    config: IdentifyConfig | None = None,
    progress: bool = False,
    drop_nan: bool = False,
) -> Identification:
    """Identify a robot's serial chain from observed end-effector positions: calibration.

    ``data``: the path of a babbling ``.npz`` or a recorded log (``.npz``/``.csv``, see
    :mod:`kinlearn.data.recorded`), :class:`~kinlearn.data.recorded.Observations`, babbling
    :class:`~kinlearn.data.babbling.Transitions`, or a pair ``(theta (N, dof) rad, ef (N, 3) m)``.

    ``robot``: the arm the chain is of (a name or a :class:`~kinlearn.Robot`): its joint names and
    limits, and — unless ``prior=False`` — its URDF as the starting guess (it may be wrong).
    ``prior``: ``True`` (the robot's URDF, if a robot is given), ``False`` (no URDF: only the joint
    count), or another :class:`~kinlearn.Robot` whose model starts the fit (a user's rough URDF:
    ``load_robot(path, ee_frame)``).
    ``dof``: the joint count when no robot is given. Data in memory get the checks a file gets (metres,
    radians, the robot's limits). Exact repeats of a row count once (``duplicates_dropped``). Returns the
    chain and a report (held-out residual in metres, the noise's robust σ, outliers dropped, undetermined
    joint directions, ``excitation``: each joint's range and the parameter Jacobian's rank and condition
    number, seconds). Data that cannot identify the chain are refused with
    :class:`~kinlearn.errors.UnidentifiableError` (a joint that never moves, named; fewer distinct samples,
    or fewer left by ``max_samples``, than the chain needs); data that determine it poorly give a
    :class:`~kinlearn.errors.PoorExcitationWarning` naming the joints. Its
    URDF names the joints, the root link and the end-effector link as the robot (or prior) does, else
    ``joint1`` …, ``base`` and ``ee``.
    """
    rob = load_robot(robot) if isinstance(robot, str) else robot
    if rob is not None and not isinstance(rob, Robot):
        raise ConfigError(f"robot must be a robot name or a kinlearn Robot, got {type(rob).__name__}")
    dof = None if dof is None else as_int(dof, "dof (the joint count)", minimum=1)
    if isinstance(prior, bool):
        prior_robot = rob if prior else None
    elif isinstance(prior, Robot):
        prior_robot = prior
    else:
        raise ConfigError(
            f"prior must be True, False or a Robot (load_robot(path, ee_frame) for a URDF file), got {prior!r}"
        )
    cfg = config or IdentifyConfig()
    theta, ef, source = _observations(data, rob, dof, drop_nan, cfg)
    limits = (torch.from_numpy(rob.lower), torch.from_numpy(rob.upper)) if rob is not None else None
    name = rob.name if rob is not None else (prior_robot.name if prior_robot is not None else "chain")
    result = _identify(
        theta,
        ef,
        prior=prior_robot,
        dof=dof,
        robot_name=name,
        limits=limits,
        config=config,
        progress=progress,
    )
    result.report["data"] = source
    named = rob or prior_robot  # the frames and joints the exported URDF names as the user's do
    if named is not None:
        result.joint_names, result.base_link, result.ee_frame = (
            named.joint_names,
            named.root_link,
            named.ee_frame,
        )
        v = named.velocity_limits
        result.velocity = tuple(float(x) if math.isfinite(x) and x > 0 else math.pi for x in v)
    return result


def _observations(data, robot: Robot | None, dof: int | None, drop_nan: bool, cfg: IdentifyConfig):
    """(θ, ef) float64 tensors and a record of where they came from. A recorded log is read as a seeded
    sample of at most ``cfg.max_samples`` rows (memory bounded by them, not by the file)."""
    if isinstance(data, (str, Path)):
        obs = load_observations(
            data, robot=robot, dof=dof, drop_nan=drop_nan, max_rows=cfg.max_samples, seed=cfg.seed
        )
        record = {"path": str(data), "sha256": obs.sha256, "rows": len(obs)}
        if getattr(obs, "sampled_from", len(obs)) > len(obs):
            record["sampled_from"] = obs.sampled_from
        return obs.theta, obs.ef, record
    # In memory: the checks a file gets (shape, finite, metres, radians, the robot's limits) before the fit.
    if isinstance(data, Transitions):
        obs = Observations.from_transitions(data)
        theta, ef, record = obs.theta, obs.ef, {"transitions": len(data)}
    elif isinstance(data, Observations):
        theta, ef, record = data.theta, data.ef, data.record()
    elif isinstance(data, (tuple, list)) and len(data) == 2:
        theta, ef = _check_observations(*data)
        record = {"rows": len(theta)}
    else:
        raise ConfigError(
            "data must be a file path, Observations, Transitions or a pair (theta, ef); "
            f"got {type(data).__name__}"
        )
    theta, ef = _check_observations(theta, ef)
    if robot is not None and theta.shape[1] != robot.dof:
        raise DatasetError(f"the data hold {theta.shape[1]} joints, robot {robot.name} has {robot.dof}")
    check_observation_units(theta.numpy(), ef.numpy(), robot, "the observations (theta, ef)")
    return theta, ef, record


def _identify(
    theta,
    ef,
    *,
    prior: Robot | None,
    dof: int | None,
    robot_name: str,
    limits: tuple | None,
    config: IdentifyConfig | None,
    progress: bool,
) -> Identification:
    """:func:`identify` on (θ, ef) tensors; ``limits`` default to the prior's, else the data's range."""
    cfg = config or IdentifyConfig()
    t_start = time.perf_counter()
    theta, ef = _check_observations(theta, ef)
    n, n_joints = theta.shape
    if dof is not None and dof != n_joints:
        raise DatasetError(f"the data hold {n_joints} joints, dof={dof} was asked for")
    if prior is not None and prior.dof != n_joints:
        raise DatasetError(f"the data hold {n_joints} joints, the prior {prior.name} has {prior.dof}")
    needed = _needed_samples(n_joints)
    if n < needed:
        raise DatasetError(f"identifying a {n_joints}-joint chain needs at least {needed} samples, got {n}")
    theta, ef, duplicates = _distinct_rows(theta, ef)
    n = theta.shape[0]
    if n < needed:
        raise UnidentifiableError(
            f"the data hold {n + duplicates} rows but only {n} distinct samples (θ, ef) — the rest repeat "
            f"them; identifying a {n_joints}-joint chain needs at least {needed} distinct samples"
        )
    joint_range = (theta.max(0).values - theta.min(0).values).tolist()
    still = [i for i, r in enumerate(joint_range) if r < cfg.min_joint_range]
    if still:
        shown = ", ".join(f"{i + 1} ({joint_range[i]:.2g} rad)" for i in still)
        raise UnidentifiableError(
            f"joint(s) {shown} never move in the data (their values span less than min_joint_range = "
            f"{cfg.min_joint_range:g} rad): the data cannot identify their axes, and a chain fitted to them "
            "would be off wherever they move. Record motion of every joint"
        )
    if limits is not None:
        lo, hi = (torch.as_tensor(v, dtype=torch.float64) for v in limits)
    elif prior is not None:
        lo, hi = torch.from_numpy(prior.lower), torch.from_numpy(prior.upper)
    else:
        lo, hi = theta.min(0).values, theta.max(0).values
    gen = torch.Generator().manual_seed(int(cfg.seed))
    report_extra: dict = {"duplicates_dropped": duplicates}
    if n > cfg.max_samples:  # a bounded amount of work: a seeded subset
        keep_rows = torch.randperm(n, generator=gen)[: cfg.max_samples]
        theta, ef = theta[keep_rows], ef[keep_rows]
        report_extra["subsampled_from"] = n
        n = cfg.max_samples
        if n < needed:
            raise UnidentifiableError(
                f"max_samples = {cfg.max_samples} leaves {n} samples; identifying a {n_joints}-joint chain "
                f"needs at least {needed}: raise max_samples"
            )
    perm = torch.randperm(n, generator=gen)
    n_val = round(n * cfg.holdout)
    val, fit = perm[:n_val], perm[n_val:]
    th_fit, ef_fit = theta[fit], ef[fit]
    log = print if progress else (lambda *a, **k: None)

    report: dict = {"samples": n, "fit_samples": int(fit.numel()), "holdout_samples": n_val, **report_extra}
    stages: dict[str, float] = {}
    t_stage = time.perf_counter()
    if prior is not None:
        model = ChainFM.from_robot(prior)
        model.config = dataclasses.replace(model.config, robot=robot_name)  # the arm's, not the prior's
        model.robot_name = robot_name
        with torch.no_grad():
            model.lower.copy_(lo)
            model.upper.copy_(hi)
        report["initialisation"] = f"prior URDF {prior.name}"
        stages["initialisation"] = 0.0
        _fit(model, th_fit, ef_fit, 1e-2, cfg.iterations)
    else:
        t0 = time.perf_counter()
        g = _fit_mlp(th_fit, ef_fit, cfg.mlp_hidden, cfg.mlp_steps, gen, progress)
        mlp_err = float((g(th_fit[:5000]) - ef_fit[:5000]).norm(dim=-1).median())
        log(f"first MLP: median error {mlp_err * 1e3:.2f} mm ({time.perf_counter() - t0:.1f} s)")
        q_lo, q_hi = (torch.quantile(th_fit, v, dim=0) for v in (0.05, 0.95))
        # Candidate references from the data, scored by how well every joint's sweep is determined.
        candidates = th_fit[torch.randperm(th_fit.shape[0], generator=gen)[: 8 * cfg.references]]
        scored = []
        for ref in candidates:
            init = _sweep_init(g, ref, q_lo, q_hi)
            scored.append((float(np.log(np.clip(init[2], 1e-3, 0.2)).sum()), ref, init))
        scored.sort(key=lambda s: -s[0])
        best, best_loss = None, math.inf
        for _, ref, (axes, centres, radii, tip) in scored[: cfg.references]:
            for i in np.flatnonzero(radii < 1e-3):  # a joint that does not move the point here
                centres[i] = tip
            cand = _chain_from(axes, centres, tip, ref, robot_name, lo, hi)
            loss = _fit(cand, th_fit, ef_fit, 1e-2, max(3, cfg.iterations // 6))
            log(f"reference candidate: loss {loss:.4g}")
            if loss < best_loss:
                best, best_loss = cand, loss
        model = best
        stages["initialisation"] = time.perf_counter() - t_stage
        t_stage = time.perf_counter()
        report["initialisation"] = (
            f"no prior: first MLP (median {mlp_err * 1e3:.2f} mm) swept into circles at "
            f"{cfg.references} reference configurations, the best kept"
        )
        _fit(model, th_fit, ef_fit, 1e-2, cfg.iterations)
    # Robust rounds.
    r = _residuals(model, th_fit, ef_fit).detach()
    sigma = _robust_scale(r)
    _fit(model, th_fit, ef_fit, max(3.0 * sigma, 1e-6), cfg.iterations)
    r = _residuals(model, th_fit, ef_fit).detach()
    sigma = _robust_scale(r)
    keep = r <= cfg.outlier_sigma * max(sigma, 1e-7)
    _fit(model, th_fit[keep], ef_fit[keep], max(3.0 * sigma, 1e-6), cfg.iterations)
    model.canonicalize()
    stages["fit"] = time.perf_counter() - t_stage
    log(f"robust fit: {stages['fit']:.1f} s")
    r = _residuals(model, th_fit, ef_fit).detach()
    sigma = _robust_scale(r[keep])
    report["outliers_dropped"] = int((~keep).sum())
    report["noise_sigma"] = sigma
    # Undetermined directions: trailing joints whose axes pass through the end-effector point.
    w, q, tip = model.unit_axes().detach(), model.point.detach(), model.tip.detach()
    dist = torch.linalg.cross(w, (tip - q)).norm(dim=-1)
    unobservable = []
    for i in reversed(range(n_joints)):
        if float(dist[i]) >= cfg.unobservable_distance:
            break
        unobservable.append(i)
    report["undetermined_axis_directions"] = sorted(unobservable)
    report["excitation"] = _excitation(model, th_fit[keep], joint_range, gen)
    ex = report["excitation"]
    poor = [i for i in ex["poorly_determined_joints"] if i not in unobservable]
    weak = [i for i, r in enumerate(joint_range) if r < 10 * cfg.min_joint_range]
    if poor or weak:
        parts = []
        if poor:
            parts.append(
                f"the parameter Jacobian has rank {ex['parameter_rank']} of {ex['expected_rank']}, the directions "
                f"it loses on joint(s) {', '.join(str(i + 1) for i in poor)} (they moved only together with others)"
            )
        if weak:
            parts.append(
                "joint(s) "
                + ", ".join(f"{i + 1} ({joint_range[i]:.2g} rad)" for i in weak)
                + f" moved less than {10 * cfg.min_joint_range:g} rad"
            )
        warnings.warn(
            f"the data determine part of the chain poorly: {'; '.join(parts)}. The chain matches the data "
            "where they were taken and may be far off elsewhere; record wider, independent motion of those joints",
            PoorExcitationWarning,
            stacklevel=3,
        )
    if cfg.residual:
        fit_residual(model, th_fit[keep], ef_fit[keep], cfg, gen)
    with torch.no_grad():
        rv = _residuals(model, theta[val], ef[val]) if n_val else torch.zeros(1)
        rf = _residuals(model, th_fit, ef_fit)
    report["holdout_residual"] = _summary(rv)
    report["fit_residual"] = _summary(rf)
    report["seconds"] = time.perf_counter() - t_start
    report["stage_seconds"] = stages
    model.eval()
    return Identification(model, report)


def _needed_samples(dof: int) -> int:
    """The fewest samples a ``dof``-joint chain is identified from: 20 per parameter (6 per joint, 3 tip)."""
    return 20 * (6 * dof + 3)


def _distinct_rows(theta: torch.Tensor, ef: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, int]:
    """The rows (θ, ef) with exact repeats left out (the first of each kept, in order), and how many went:
    a repeated row adds no information, and left in it would sit on both sides of the held-out split."""
    rows = torch.cat((theta, ef), dim=1)
    _, inverse = torch.unique(rows, dim=0, return_inverse=True)
    first = torch.full((int(inverse.max()) + 1,), rows.shape[0], dtype=torch.int64)
    first.scatter_reduce_(0, inverse, torch.arange(rows.shape[0]), reduce="amin")
    keep = first.sort().values
    return theta[keep], ef[keep], rows.shape[0] - keep.numel()


def _excitation(model: ChainFM, theta: torch.Tensor, joint_range: list[float], gen, rows: int = 4000) -> dict:
    """How well the data determine the chain: each joint's range (rad), and the rank and condition number
    of the residuals' Jacobian in the chain's parameters (at most ``rows`` samples), with the directions
    every chain leaves free (an axis's length, its point's slide along it) taken out: a chain of n joints
    has 4n + 3 parameters the data can fix. Joints that carry the directions the data leave free beyond
    those are ``poorly_determined_joints`` (0-based)."""
    n = model.dof
    pick = torch.randperm(theta.shape[0], generator=gen)[:rows]
    w_raw, q, tip = model.axis.detach(), model.point.detach(), model.tip.detach()
    with torch.no_grad():
        _, J = chain_parameter_jacobian(w_raw, q, tip, theta[pick] - model.reference.detach())
    P = 6 * n + 3
    J = J.reshape(-1, P)
    w = w_raw / w_raw.norm(dim=-1, keepdim=True)
    G = torch.zeros(P, 2 * n, dtype=J.dtype)  # the free directions: axis length, point along the axis
    for i in range(n):
        G[3 * i : 3 * i + 3, 2 * i] = w[i]
        G[3 * n + 3 * i : 3 * n + 3 * i + 3, 2 * i + 1] = w[i]
    Q, _ = torch.linalg.qr(G)
    Jp = J - (J @ Q) @ Q.T
    _, S, Vh = torch.linalg.svd(Jp, full_matrices=False)
    expected = 4 * n + 3
    rank = int((S > S[0] * 1e-8).sum()) if float(S[0]) > 0 else 0
    poor: list[int] = []
    if rank < expected:
        N = Vh[rank:]  # the null space: the free directions and those the data leave free
        N = N - (N @ Q) @ Q.T
        mass = [
            float(
                N[:, 3 * i : 3 * i + 3].square().sum()
                + N[:, 3 * n + 3 * i : 3 * n + 3 * i + 3].square().sum()
            )
            for i in range(n)
        ]
        poor = [i for i in range(n) if mass[i] >= 0.25]
        if not poor:
            poor = [int(np.argmax(mass))]
    return {
        "joint_range": [float(r) for r in joint_range],
        "parameter_rank": rank,
        "expected_rank": expected,
        "condition": float(S[0] / S[expected - 1]) if rank >= expected else None,
        "poorly_determined_joints": poor,
    }


def fit_residual(model: ChainFM, theta, ef, cfg: IdentifyConfig, gen: torch.Generator) -> None:
    """Add to ``model`` a residual MLP of ``cfg.residual`` widths and train it (``cfg.residual_steps``
    Adam steps, Huber loss at 1 mm) on what the rigid chain leaves of ``ef``; the chain is held fixed."""
    torch.manual_seed(int(torch.randint(0, 2**31 - 1, (1,), generator=gen)))
    full = ChainFM(ChainConfig(model.config.robot, model.dof, tuple(cfg.residual)))
    full.load_state_dict(model.state_dict(), strict=False)
    model.config = full.config
    model.residual = full.residual
    opt = torch.optim.Adam(model.residual.parameters(), lr=1e-3)
    n = theta.shape[0]
    with torch.enable_grad():
        for _ in range(cfg.residual_steps):
            idx = torch.randint(0, n, (min(4096, n),), generator=gen)
            r = (model.position(theta[idx]) - ef[idx]).norm(dim=-1) / 1e-3
            loss = torch.where(r < 1.0, 0.5 * r.square(), r - 0.5).mean()
            opt.zero_grad()
            loss.backward()
            opt.step()


def _summary(r: torch.Tensor) -> dict[str, float]:
    r = r.double()
    return {
        "median": float(r.median()),
        "mean": float(r.mean()),
        "p99": float(torch.quantile(r, 0.99)),
        "max": float(r.max()),
    }
