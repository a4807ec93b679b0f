"""The chain forward model: a serial chain of revolute joints whose axes and end-effector point are
learned from the robot's own babbling (a product of exponentials), and the inverse model that solves
through a forward model's Jacobian.

The end effector of a serial arm of revolute joints is, in the product-of-exponentials form written
about a reference configuration θ̄ (``ChainFM.reference``),

    p(θ) = exp([S₁] φ₁) · exp([S₂] φ₂) ⋯ exp([Sₙ] φₙ) · p₀,        φ = θ − θ̄,

where joint i is a rotation about the line through the point ``qᵢ`` with the unit direction ``ωᵢ``
(both in the base frame, at θ̄) and ``p₀`` is the end effector at θ̄. The parameters are ``axis``
(n × 3, normalised in use), ``point`` (n × 3) and ``tip`` (3): 6n + 3 numbers of which 4n + 3
describe the geometry (a point may slide along its line and a direction has no length). Encoder
offsets need no parameters: a joint zero that is off moves θ̄'s geometry, which the parameters hold.
An optional residual MLP of (sin θ, cos θ) adds what a rigid chain cannot explain (elasticity,
gear eccentricity); it starts at zero.

:class:`ChainFM` is a :class:`~kinlearn.models.interface.ForwardModel` (θ' = θ + a, ef' = p(θ')), so it
goes wherever the paper's MLP FM goes. Its :meth:`ChainFM.position_and_jacobian` gives the geometric
Jacobian ∂p/∂θᵢ = ωᵢ(θ) × (p − qᵢ(θ)) (the axis moved by the joints before it), which
:class:`ThroughFMIM` and :func:`solve_position` use: damped least-squares (Gauss–Newton) steps on the
learned model, kept within the joint limits. Identification from data is
:func:`kinlearn.training.identify.identify`; export to a URDF is :func:`chain_urdf`.
"""

from __future__ import annotations

import functools
import itertools
import math
from dataclasses import dataclass
from typing import Literal
from xml.sax.saxutils import escape

import numpy as np
import torch
from torch import nn

from ..body.robot import Robot
from ..errors import ConfigError
from .interface import ForwardModel, InverseModel, config_from_dict, config_to_dict

__all__ = [
    "ChainConfig",
    "ChainFM",
    "ThroughFMIM",
    "chain_parameter_jacobian",
    "chain_position",
    "chain_urdf",
    "restart_fractions",
    "rotate_about",
    "solve_position",
    "solve_position_arrays",
]


@dataclass(frozen=True)
class ChainConfig:
    """A chain forward model.

    Attributes:
        robot, dof: the robot the model belongs to (revolute joints only).
        residual: hidden widths of the residual MLP on (sin θ, cos θ) (empty: none, a rigid chain).
    """

    robot: str = "iiwa14"
    dof: int = 7
    residual: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        if isinstance(self.dof, bool) or not isinstance(self.dof, int) or self.dof < 1:
            raise ConfigError(f"dof must be an integer ≥ 1, got {self.dof!r}")
        if any(isinstance(w, bool) or not isinstance(w, int) or w < 1 for w in self.residual):
            raise ConfigError(f"residual must be a tuple of positive layer widths, got {self.residual!r}")

    def to_dict(self) -> dict:
        return config_to_dict(self)

    @classmethod
    def from_dict(cls, d: dict) -> ChainConfig:
        return config_from_dict(cls, d)


def rotate_about(p: torch.Tensor, w: torch.Tensor, q: torch.Tensor, c: torch.Tensor, s: torch.Tensor):
    """Points ``p (..., 3)`` rotated about the line through ``q (3,)`` along the unit ``w (3,)`` by the
    angle whose cosine and sine are ``c``, ``s`` ``(..., 1)`` (Rodrigues' formula)."""
    v = p - q
    wxv = torch.stack(
        (
            w[1] * v[..., 2] - w[2] * v[..., 1],
            w[2] * v[..., 0] - w[0] * v[..., 2],
            w[0] * v[..., 1] - w[1] * v[..., 0],
        ),
        dim=-1,
    )
    wdv = (v * w).sum(-1, keepdim=True)
    return q + v * c + wxv * s + w * wdv * (1.0 - c)


def chain_position(w: torch.Tensor, q: torch.Tensor, tip: torch.Tensor, phi: torch.Tensor) -> torch.Tensor:
    """p(φ) = exp([S₁] φ₁) ⋯ exp([Sₙ] φₙ) p₀ for unit axes ``w (n, 3)``, points ``q (n, 3)``, the end
    effector ``tip (3,)`` at φ = 0 and joint displacements ``phi (..., n)``: the end-effector point
    rotated about the last axis, then the one before, and so on (10 operations a joint)."""
    c, s = torch.cos(phi), torch.sin(phi)
    p = tip.expand(*phi.shape[:-1], 3)
    for i in reversed(range(w.shape[0])):
        p = rotate_about(p, w[i], q[i], c[..., i : i + 1], s[..., i : i + 1])
    return p


def _skew(v: torch.Tensor) -> torch.Tensor:
    """``[v]×`` ``(..., 3, 3)`` of vectors ``v (..., 3)``."""
    z = torch.zeros_like(v[..., 0])
    return torch.stack(
        (
            torch.stack((z, -v[..., 2], v[..., 1]), -1),
            torch.stack((v[..., 2], z, -v[..., 0]), -1),
            torch.stack((-v[..., 1], v[..., 0], z), -1),
        ),
        -2,
    )


def chain_parameter_jacobian(
    w_raw: torch.Tensor, q: torch.Tensor, tip: torch.Tensor, phi: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`chain_position` and its Jacobian in the parameters ``(..., 3, 6n + 3)``, ordered as
    (raw axes ``w_raw`` (n × 3, normalised in use), points, tip) — the identification's unknowns.

    With pⁱ the point after the rotations i + 1 … n (pⁿ⁺¹ = p₀), vᵢ = pⁱ⁺¹ − qᵢ and Aᵢ = R₁ ⋯ Rᵢ₋₁:
    ∂p/∂p₀ = Aₙ₊₁, ∂p/∂qᵢ = Aᵢ (I − Rᵢ), and ∂p/∂ωᵢ = Aᵢ (−sin φᵢ [vᵢ]× + (1 − cos φᵢ)((ωᵢ·vᵢ) I
    + ωᵢ vᵢᵀ)), taken through the normalisation ωᵢ = wᵢ / ‖wᵢ‖ (times (I − ωᵢωᵢᵀ) / ‖wᵢ‖)."""
    n = w_raw.shape[0]
    norm = w_raw.norm(dim=-1, keepdim=True)
    w = w_raw / norm
    c, s = torch.cos(phi), torch.sin(phi)
    pts = [tip.expand(*phi.shape[:-1], 3)]
    for i in reversed(range(n)):
        pts.append(rotate_about(pts[-1], w[i], q[i], c[..., i : i + 1], s[..., i : i + 1]))
    pts.reverse()  # pts[i] = pⁱ⁺¹ in the docstring's numbering (pts[0] = p, pts[n] = p₀)
    eye = torch.eye(3, dtype=phi.dtype, device=phi.device)
    A = eye.expand(*phi.shape[:-1], 3, 3)
    d_w, d_q = [], []
    for i in range(n):
        R = _rodrigues(w[i], c[..., i], s[..., i])
        v = pts[i + 1] - q[i]
        wv = (v * w[i]).sum(-1)[..., None, None]
        dR = -s[..., i, None, None] * _skew(v) + (1.0 - c[..., i, None, None]) * (
            wv * eye + w[i][:, None] * v[..., None, :]
        )
        proj = (eye - torch.outer(w[i], w[i])) / norm[i]
        d_w.append(A @ dR @ proj)
        d_q.append(A @ (eye - R))
        A = A @ R
    J = torch.cat((*d_w, *d_q, A), dim=-1)
    return pts[0], J


def moved_axes(
    w: torch.Tensor, q: torch.Tensor, tip: torch.Tensor, phi: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Every joint's axis ``(..., 3, n)`` and axis point ``(..., 3, n)`` moved by the joints before it,
    and the end effector ``(..., 3)``, at displacements ``phi (..., n)`` from the chain's reference: the
    transforms of the joints accumulated from the base (R ← R Rᵢ, t ← R (qᵢ − Rᵢ qᵢ) + t)."""
    c, s = torch.cos(phi), torch.sin(phi)
    batch = phi.shape[:-1]
    R = torch.eye(3, dtype=phi.dtype, device=phi.device).expand(*batch, 3, 3)
    t = torch.zeros(*batch, 3, dtype=phi.dtype, device=phi.device)
    axes, points = [], []
    for i in range(w.shape[0]):
        axes.append(R @ w[i])
        points.append(R @ q[i] + t)
        Ri = _rodrigues(w[i], c[..., i], s[..., i])
        t = _mv(R, q[i] - Ri @ q[i]) + t
        R = R @ Ri
    return torch.stack(axes, -1), torch.stack(points, -1), R @ tip + t


def _rodrigues(w: torch.Tensor, c: torch.Tensor, s: torch.Tensor) -> torch.Tensor:
    """Rotation matrices ``(..., 3, 3)`` about the unit ``w (3,)`` by angles with cosine/sine ``c, s (...)``."""
    K = torch.zeros(3, 3, dtype=w.dtype, device=w.device)
    K[0, 1], K[0, 2], K[1, 2] = -w[2], w[1], -w[0]
    K = K - K.T
    eye = torch.eye(3, dtype=w.dtype, device=w.device)
    return eye + s[..., None, None] * K + (1.0 - c)[..., None, None] * (K @ K)


def _mv(A: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    """Batched matrix–vector product ``(..., 3, 3) @ (..., 3)``."""
    return (A @ x.unsqueeze(-1)).squeeze(-1)


class ChainFM(ForwardModel):
    """A serial chain of revolute joints learned from babbling (see the module docstring)."""

    def __init__(self, config: ChainConfig | None = None):
        config = config or ChainConfig()
        super().__init__(config.robot, config.dof)
        self.config = config
        n = config.dof
        f64 = torch.float64
        self.axis = nn.Parameter(torch.tensor([[0.0, 0.0, 1.0]] * n, dtype=f64))
        self.point = nn.Parameter(torch.zeros(n, 3, dtype=f64))
        self.tip = nn.Parameter(torch.zeros(3, dtype=f64))
        self.register_buffer("reference", torch.zeros(n, dtype=f64))
        # The joint range the chain was identified over (the exported URDF's limits).
        self.register_buffer("lower", torch.full((n,), -math.pi, dtype=f64))
        self.register_buffer("upper", torch.full((n,), math.pi, dtype=f64))
        if config.residual:
            layers: list[nn.Module] = []
            sizes = (2 * n, *config.residual)
            for a, b in itertools.pairwise(sizes):
                layers += [nn.Linear(a, b, dtype=f64), nn.SiLU()]
            out = nn.Linear(sizes[-1], 3, dtype=f64)
            nn.init.zeros_(out.weight)
            nn.init.zeros_(out.bias)
            self.residual = nn.Sequential(*layers, out)
        else:
            self.residual = None

    def config_dict(self) -> dict:
        return self.config.to_dict()

    @classmethod
    def from_robot(cls, robot: Robot, reference=None, residual: tuple[int, ...] = ()) -> ChainFM:
        """The chain a URDF describes (a user's model, perhaps a wrong one: the prior of identification),
        written about ``reference`` (default: θ = 0); limits from the robot."""
        if any(j.kind != "revolute" for j in robot.joints):
            raise ConfigError(f"{robot.name}: the chain model holds revolute joints only")
        ref = np.zeros(robot.dof) if reference is None else np.asarray(reference, dtype=float)
        model = cls(ChainConfig(robot=robot.name, dof=robot.dof, residual=tuple(residual)))
        T = np.eye(4)
        axes, points = [], []
        for j, angle in zip(robot.joints, ref, strict=True):
            T = T @ j.T_prev
            axes.append(T[:3, :3] @ j.axis)
            points.append(T[:3, 3].copy())
            R = torch.from_numpy(j.axis)
            c, s = (torch.tensor(f(angle), dtype=torch.float64) for f in (math.cos, math.sin))
            rot = _rodrigues(R, c, s).numpy()
            step = np.eye(4)
            step[:3, :3] = rot
            T = T @ step
        tip = (T @ robot.T_tip)[:3, 3]
        with torch.no_grad():
            model.axis.copy_(torch.from_numpy(np.array(axes)))
            model.point.copy_(torch.from_numpy(np.array(points)))
            model.tip.copy_(torch.from_numpy(tip))
            model.reference.copy_(torch.from_numpy(ref))
            model.lower.copy_(torch.from_numpy(robot.lower))
            model.upper.copy_(torch.from_numpy(robot.upper))
        return model

    # Parameters in the dtype and device of an input ------------------------------------------------

    def unit_axes(self, dtype: torch.dtype | None = None, device=None) -> torch.Tensor:
        w = self.axis / self.axis.norm(dim=-1, keepdim=True)
        return w.to(dtype=dtype or w.dtype, device=device)

    def _params(self, x: torch.Tensor):
        d, dev = x.dtype, x.device
        return (
            self.unit_axes(d, dev),
            self.point.to(dev, d),
            self.tip.to(dev, d),
            self.reference.to(dev, d),
        )

    def _residual(self, theta: torch.Tensor) -> torch.Tensor:
        x = torch.cat((torch.sin(theta), torch.cos(theta)), dim=-1)
        return self.residual(x.to(self.tip.dtype)).to(theta.dtype)

    # Kinematics ----------------------------------------------------------------------------------

    def position(self, theta: torch.Tensor) -> torch.Tensor:
        """The end effector ``(..., 3)`` (m, base frame) of joint values ``theta (..., dof)``."""
        p = self.rigid_position(theta)
        return p if self.residual is None else p + self._residual(theta)

    def rigid_position(self, theta: torch.Tensor) -> torch.Tensor:
        """The rigid chain's end effector, without the residual MLP (what an exported URDF holds)."""
        w, q, tip, ref = self._params(theta)
        return chain_position(w, q, tip, theta - ref)

    def position_and_jacobian(self, theta: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``p (..., 3)`` and ``∂p/∂θ (..., 3, dof)`` (the residual MLP's part by autograd)."""
        w, q, tip, ref = self._params(theta)
        wa, qa, p = moved_axes(w, q, tip, theta - ref)  # (..., 3, dof) twice, (..., 3)
        J = torch.linalg.cross(wa, p.unsqueeze(-1) - qa, dim=-2)
        if self.residual is not None:
            with torch.enable_grad():
                th = theta.detach().requires_grad_(True)
                r = self._residual(th)
                Jr = torch.stack(
                    [torch.autograd.grad(r[..., k].sum(), th, retain_graph=k < 2)[0] for k in range(3)], -2
                )
            p, J = p + r.detach(), J + Jr
        return p, J

    def _forward(self, s: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        theta = s[..., self.layout.joints] + a
        return self.layout.join(theta, self.position(theta))

    def ef_along(self, theta: torch.Tensor, ef0: torch.Tensor, every: int = 1) -> torch.Tensor:
        """See :meth:`ForwardModel.ef_along`: the chain's end effector of the configurations asked for."""
        return self.position(theta[:, ::every])

    @torch.no_grad()
    def kernel_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Unit axes, points, tip and reference as float64 arrays for the compiled kernel (cached until
        a parameter changes)."""
        key = tuple(t._version for t in (self.axis, self.point, self.tip, self.reference))
        cached = getattr(self, "_kernel_cache", None)
        if cached is None or cached[0] != key:
            arrays = tuple(
                np.ascontiguousarray(t.detach().double().cpu().numpy())
                for t in (self.unit_axes(), self.point, self.tip, self.reference)
            )
            self._kernel_cache = cached = (key, arrays)
        return cached[1]

    @torch.no_grad()
    def canonicalize(self) -> None:
        """Unit axes, and each point the foot of its line's perpendicular from the origin (the same chain)."""
        w = self.unit_axes()
        self.axis.copy_(w)
        self.point.copy_(self.point - (self.point * w).sum(-1, keepdim=True) * w)

    @torch.no_grad()
    def at_zero(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The chain re-expressed about θ = 0: axes ``(n, 3)``, points ``(n, 3)`` and the end effector
        ``(3,)`` at θ = 0 (float64; the residual MLP is not part of it)."""
        axes, points, tip = moved_axes(
            self.unit_axes().double(), self.point.double(), self.tip.double(), -self.reference.double()
        )
        return axes.T.numpy(), points.T.numpy(), tip.numpy()


# --------------------------------------------------------------------------------------------------
# Solving through a forward model
# --------------------------------------------------------------------------------------------------


def _jacobian_of(fm: ForwardModel):
    """``theta -> (p, J)`` for a forward model whose end effector is a function of its joints."""
    if hasattr(fm, "position_and_jacobian"):
        return fm.position_and_jacobian
    raise ConfigError(
        f"solving through the FM needs an end effector that is a function of the joints "
        f"(a ChainFM or an AnalyticFM-like model with position_and_jacobian); got {type(fm).__name__}"
    )


def _dls(J: torch.Tensor, err: torch.Tensor, damping: float) -> torch.Tensor:
    """The damped least-squares step Jᵀ (J Jᵀ + λ² I)⁻¹ err for ``J (..., 3, n)``, ``err (..., 3)``."""
    A = J @ J.transpose(-1, -2)
    A = A + (damping**2) * torch.eye(3, dtype=J.dtype, device=J.device)
    return (J.transpose(-1, -2) @ torch.linalg.solve(A, err.unsqueeze(-1))).squeeze(-1)


def gauss_newton(
    jac, theta: torch.Tensor, target: torch.Tensor, lower, upper, iterations: int, damping: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """``iterations`` damped least-squares steps of ``theta`` toward ``target`` on ``jac``'s model, each
    projected onto the limits; returns the joints and the model's end-effector error (m) there."""
    for _ in range(iterations):
        p, J = jac(theta)
        theta = torch.minimum(torch.maximum(theta + _dls(J, target - p, damping), lower), upper)
    p, _ = jac(theta)
    return theta, (target - p).norm(dim=-1)


#: Fixed restart configurations of :func:`solve_position`, as fractions of each joint's range (a
#: scrambled Halton-like sequence drawn once from a fixed seed): the same for every problem, so a
#: solution never depends on the rest of its batch.
@functools.lru_cache(maxsize=16)
def restart_fractions(count: int, dof: int) -> torch.Tensor:
    gen = torch.Generator().manual_seed(7919)
    return 0.05 + 0.9 * torch.rand((count, dof), generator=gen, dtype=torch.float64)


def solve_position(
    fm: ForwardModel,
    theta0: torch.Tensor,
    target: torch.Tensor,
    lower: torch.Tensor,
    upper: torch.Tensor,
    *,
    iterations: int = 40,
    restarts: int = 16,
    damping: float = 1e-3,
    tolerance: float = 2e-4,
    backend: Literal["auto", "torch", "compiled"] = "auto",
) -> tuple[torch.Tensor, torch.Tensor]:
    """Joint values within ``[lower, upper]`` at which the model ``fm`` puts the end effector on
    ``target``, for each problem of a batch: ``theta0 (N, dof)``, ``target (N, 3)`` → ``(N, dof)`` and
    the model's remaining error ``(N,)`` (m).

    A fixed budget: ``iterations`` projected damped least-squares steps from θ(0) and from ``restarts``
    − 1 fixed configurations spread over the joint range. A start already within ``tolerance`` of the
    target keeps its joints (a move of zero). The solution reached from θ(0) is kept when
    it is within ``tolerance`` of the target, else the restarts' solution within it closest to θ(0)
    (joint-space distance), else the one of least error; each problem is solved on its own (its
    result does not depend on its batch). The compiled kernel stops a descent at its fixed point and
    skips the restarts when θ(0)'s solution is kept: the same answer, sooner.

    ``backend``: ``"compiled"`` (the numba kernel of :mod:`kinlearn.models.chain_kernel`; a rigid
    :class:`ChainFM` on the CPU), ``"torch"`` (any device, any FM with ``position_and_jacobian``), or
    ``"auto"``: compiled where it applies.
    """
    if restarts < 1 or iterations < 1:
        raise ConfigError(f"restarts and iterations must be ≥ 1, got {restarts}, {iterations}")
    if backend not in ("auto", "torch", "compiled"):
        raise ConfigError(f"backend must be 'auto', 'torch' or 'compiled', got {backend!r}")
    rigid_cpu = isinstance(fm, ChainFM) and fm.residual is None and theta0.device.type == "cpu"
    if backend == "compiled" and not rigid_cpu:
        raise ConfigError("the compiled solver takes a ChainFM without a residual MLP, on the CPU")
    n, dof = theta0.shape
    dt = theta0.dtype
    fractions = restart_fractions(restarts - 1, dof)
    if backend != "torch" and rigid_cpu:
        out, err = solve_position_arrays(
            fm,
            theta0.detach().double().numpy(),
            target.detach().double().numpy(),
            lower.double().numpy(),
            upper.double().numpy(),
            iterations=iterations,
            restarts=restarts,
            damping=damping,
            tolerance=tolerance,
        )
        return torch.from_numpy(out).to(dt), torch.from_numpy(err)
    jac = _jacobian_of(fm)
    lo, hi = lower.to(dt), upper.to(dt)
    seeds = lo + (hi - lo) * fractions.to(dt)
    starts = torch.cat((theta0.unsqueeze(1), seeds.expand(n, -1, -1)), dim=1)  # (N, R, dof)
    aim = target.unsqueeze(1).expand(n, restarts, 3)
    theta, err = gauss_newton(jac, starts, aim, lo, hi, iterations, damping)
    p0, _ = jac(theta0)
    at_goal = (target - p0).norm(dim=-1) <= tolerance  # already there: a move of zero
    theta[:, 0] = torch.where(at_goal[:, None], theta0, theta[:, 0])
    err[:, 0] = torch.where(at_goal, (target - p0).norm(dim=-1), err[:, 0])
    dist = (theta - theta0.unsqueeze(1)).norm(dim=-1)
    dist[:, 0] = -1.0  # the solution reached from the start itself, when it reaches the target
    score = torch.where(err <= tolerance, dist, 1e6 + err)
    best = score.argmin(dim=1)
    idx = torch.arange(n, device=theta.device)
    return theta[idx, best], err[idx, best]


def solve_position_arrays(
    chain: ChainFM,
    theta0: np.ndarray,
    target: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    *,
    iterations: int = 40,
    restarts: int = 16,
    damping: float = 1e-3,
    tolerance: float = 2e-4,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`solve_position`'s compiled backend on float64 arrays (a rigid :class:`ChainFM`): the
    planner's batch-1 path, without a tensor on the way."""
    from .chain_kernel import solve_position_numba

    seeds = lower + (upper - lower) * restart_fractions(restarts - 1, chain.dof).numpy()
    return solve_position_numba(
        *chain.kernel_arrays(),
        theta0,
        target,
        lower,
        upper,
        seeds,
        iterations=iterations,
        damping=damping,
        tolerance=tolerance,
    )


class ThroughFMIM(InverseModel):
    """An inverse model that solves through a forward model: ``iterations`` projected damped
    least-squares steps on the FM's Jacobian from θ toward ``ef_target``; the action is θ_new − θ,
    bounded per joint by ``max_step`` (the babbling step) when given.

    The FM must give its end effector as a function of the joints (:class:`ChainFM`). No weights of
    its own: a checkpoint records the FM it solves through.
    """

    def __init__(
        self,
        fm: ForwardModel,
        lower: torch.Tensor,
        upper: torch.Tensor,
        *,
        iterations: int = 3,
        damping: float = 1e-3,
        max_step: float | None = None,
    ):
        _jacobian_of(fm)
        super().__init__(fm.robot_name, fm.dof)
        if int(iterations) < 1:
            raise ConfigError(f"iterations must be ≥ 1, got {iterations}")
        if not damping >= 0.0:
            raise ConfigError(f"damping must be ≥ 0 (metres), got {damping}")
        if max_step is not None and not max_step > 0.0:
            raise ConfigError(f"max_step must be > 0 rad, got {max_step}")
        self.fm = fm
        self.iterations, self.damping = int(iterations), float(damping)
        self.max_step = None if max_step is None else float(max_step)
        self.register_buffer("lower", torch.as_tensor(lower, dtype=torch.float64).clone())
        self.register_buffer("upper", torch.as_tensor(upper, dtype=torch.float64).clone())

    def config_dict(self) -> dict:
        return {"iterations": self.iterations, "damping": self.damping, "max_step": self.max_step}

    def _forward(self, s: torch.Tensor, ef_target: torch.Tensor) -> torch.Tensor:
        theta = s[..., self.layout.joints]
        lo, hi = self.lower.to(theta), self.upper.to(theta)
        if self.max_step is not None:
            lo = torch.maximum(lo, theta - self.max_step)
            hi = torch.minimum(hi, theta + self.max_step)
        new, _ = gauss_newton(
            self.fm.position_and_jacobian, theta, ef_target, lo, hi, self.iterations, self.damping
        )
        return new - theta


# --------------------------------------------------------------------------------------------------
# Export
# --------------------------------------------------------------------------------------------------


def _rpy(R: np.ndarray) -> tuple[float, float, float]:
    """URDF roll-pitch-yaw of a rotation matrix (R = Rz(y) Ry(p) Rx(r))."""
    sp = -R[2, 0]
    if abs(sp) < 1.0 - 1e-12:
        return (
            math.atan2(R[2, 1], R[2, 2]),
            math.asin(max(-1.0, min(1.0, sp))),
            math.atan2(R[1, 0], R[0, 0]),
        )
    # Gimbal lock: pitch ±90°, roll taken as 0.
    return 0.0, math.copysign(math.pi / 2, sp), math.atan2(-R[0, 1], R[1, 1])


def fmt(x) -> str:
    """A float as the shortest text that reads back to the same float64."""
    return repr(float(x))


def _frame(z: np.ndarray, hint: np.ndarray) -> np.ndarray:
    """A rotation whose third column is ``z``, its first as close to ``hint`` as it can be."""
    x = hint - (hint @ z) * z
    if np.linalg.norm(x) < 1e-9:
        e = np.eye(3)[int(np.argmin(np.abs(z)))]
        x = e - (e @ z) * z
    x = x / np.linalg.norm(x)
    return np.column_stack((x, np.cross(z, x), z))


def chain_urdf(
    model: ChainFM,
    *,
    name: str,
    joint_names: tuple[str, ...] | None = None,
    velocity: np.ndarray | None = None,
    effort: float = 100.0,
    base_link: str = "base",
    ee_frame: str = "ee",
) -> str:
    """The chain as a URDF document: ``base_link`` → revolute joints (axis z of their frames, limits from
    ``model.lower``/``model.upper``) → a fixed joint to the link ``ee_frame`` at the end-effector point.

    Its forward kinematics equals the chain's (the residual MLP, if any, is not part of it). Each
    joint frame sits on its axis at the point nearest the previous frame's origin, so the frames are
    as near the arm's links as the chain determines. A joint's rotation about its own axis in the
    exported frames is the one orientation the position data cannot fix; the frames are one choice.
    """
    axes, points, tip = model.at_zero()
    n = model.dof
    joint_names = tuple(joint_names) if joint_names is not None else tuple(f"joint{i + 1}" for i in range(n))
    if len(joint_names) != n:
        raise ConfigError(f"joint_names needs {n} names, got {len(joint_names)}")
    vel = np.full(n, math.pi) if velocity is None else np.asarray(velocity, dtype=float)
    lower, upper = model.lower.double().numpy(), model.upper.double().numpy()
    # The links between the joints are named link1 … unless a given name is one: then link1_ … (never a
    # collision with the prior's base, end-effector or joint names, say an end effector called link2).
    given = {base_link, ee_frame, f"{ee_frame}_joint", *joint_names}
    stem = "link"
    while any(f"{stem}{i + 1}" in given for i in range(n)):
        stem += "_"
    if f"{ee_frame}_joint" in (base_link, ee_frame, *joint_names):
        raise ConfigError(f"the end-effector joint's name {ee_frame}_joint is taken by another name")

    def x(text: str) -> str:  # a name as an XML attribute value
        return escape(str(text), {'"': "&quot;"})

    name, base_link, ee_frame = x(name), x(base_link), x(ee_frame)
    joint_names = tuple(x(j) for j in joint_names)
    lines = [
        '<?xml version="1.0"?>',
        f'<robot name="{name}">',
        "  <!-- A serial chain identified by kinlearn from observed end-effector positions. -->",
        f'  <link name="{base_link}"/>',
    ]
    T_prev = np.eye(4)
    parent = base_link
    for i in range(n):
        z = axes[i] / np.linalg.norm(axes[i])
        o_prev = T_prev[:3, 3]
        origin = points[i] + ((o_prev - points[i]) @ z) * z  # on the axis, nearest the previous origin
        T = np.eye(4)
        T[:3, :3] = _frame(z, T_prev[:3, 0])
        T[:3, 3] = origin
        rel = np.linalg.inv(T_prev) @ T
        r, p, y = _rpy(rel[:3, :3])
        child = f"{stem}{i + 1}"
        lines += [
            f'  <link name="{child}"/>',
            f'  <joint name="{joint_names[i]}" type="revolute">',
            f'    <parent link="{parent}"/>',
            f'    <child link="{child}"/>',
            f'    <origin xyz="{fmt(rel[0, 3])} {fmt(rel[1, 3])} {fmt(rel[2, 3])}" rpy="{fmt(r)} {fmt(p)} {fmt(y)}"/>',
            '    <axis xyz="0 0 1"/>',
            f'    <limit lower="{fmt(float(lower[i]))}" upper="{fmt(float(upper[i]))}" '
            f'effort="{fmt(float(effort))}" velocity="{fmt(float(vel[i]))}"/>',
            "  </joint>",
        ]
        T_prev, parent = T, child
    local = np.linalg.inv(T_prev) @ np.append(tip, 1.0)
    lines += [
        f'  <link name="{ee_frame}"/>',
        f'  <joint name="{ee_frame}_joint" type="fixed">',
        f'    <parent link="{parent}"/>',
        f'    <child link="{ee_frame}"/>',
        f'    <origin xyz="{fmt(local[0])} {fmt(local[1])} {fmt(local[2])}" rpy="0 0 0"/>',
        "  </joint>",
        "</robot>",
        "",
    ]
    return "\n".join(lines)
