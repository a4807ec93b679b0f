"""Forward kinematics and the position Jacobian behind one interface, with three backends.

=============  =================================================================================
``"fast"``     Vectorised torch product of the chain's joint transforms, derived from the exact
               float64 chain of :class:`~kinlearn.body.robot.Robot`. Batched, differentiable, the
               fastest: used for babbling, training and planning.
``"pk"``       pytorch-kinematics, with its float32-parsed constants replaced by the exact ones.
``"pinocchio"``  Pinocchio, float64, one configuration at a time in C++: the ground truth for
               checks. Not differentiable.
=============  =================================================================================

Every backend takes joint values of shape ``(..., dof)`` and returns ``(..., 3)`` positions,
``(..., 4, 4)`` poses or ``(..., 3, dof)`` Jacobians in the robot's base (root link) frame, with the
dtype and device of the input.
"""

from __future__ import annotations

import contextlib
import io
import math
from abc import ABC, abstractmethod
from pathlib import Path
from typing import Any, Literal

import numpy as np
import torch

from ..checks import check_finite, check_last_dim, check_real_dtype
from ..errors import ConfigError
from .robot import Robot, load_robot

__all__ = [
    "BACKENDS",
    "FastKinematics",
    "Kinematics",
    "PinocchioKinematics",
    "PkKinematics",
    "approach_axis",
    "dls_step",
    "kinematics",
    "pointing_dls_step",
]

Backend = Literal["fast", "pk", "pinocchio"]
BACKENDS: tuple[str, ...] = ("fast", "pk", "pinocchio")


class Kinematics(ABC):
    """Forward kinematics of one robot. Subclasses implement the ``_flat`` methods on ``(N, dof)``."""

    backend: str = ""

    def __init__(self, robot: Robot):
        self.robot = robot
        self.dof = robot.dof

    def _prepare(self, q: torch.Tensor, validate: bool) -> tuple[torch.Tensor, tuple[int, ...]]:
        if isinstance(q, np.ndarray):  # numpy arrays are taken as plan() takes them; dtype follows
            q = torch.from_numpy(q)
        if validate:
            check_real_dtype(q, "joint values q")
            check_last_dim(q, self.dof, "joint values q")
            check_finite(q, "joint values q")
        batch = tuple(q.shape[:-1])
        return q.reshape(-1, self.dof), batch

    def position(self, q: torch.Tensor, validate: bool = True) -> torch.Tensor:
        """End-effector position ``(..., 3)`` in the base frame. ``validate=False`` skips input checks."""
        flat, batch = self._prepare(q, validate)
        return self._position_flat(flat).reshape(*batch, 3)

    def pose(self, q: torch.Tensor, validate: bool = True) -> torch.Tensor:
        """End-effector pose ``(..., 4, 4)``, a homogeneous transform base ← end effector."""
        flat, batch = self._prepare(q, validate)
        return self._pose_flat(flat).reshape(*batch, 4, 4)

    def jacobian(self, q: torch.Tensor, validate: bool = True) -> torch.Tensor:
        """Position Jacobian ``(..., 3, dof)``: d(end-effector position)/dq, in the base frame."""
        flat, batch = self._prepare(q, validate)
        return self._jacobian_flat(flat).reshape(*batch, 3, self.dof)

    def position_and_jacobian(
        self, q: torch.Tensor, validate: bool = True
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """``(position (..., 3), jacobian (..., 3, dof))``, in one pass where the backend allows."""
        flat, batch = self._prepare(q, validate)
        p, J = self._position_and_jacobian_flat(flat)
        return p.reshape(*batch, 3), J.reshape(*batch, 3, self.dof)

    def _position_and_jacobian_flat(self, q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self._position_flat(q), self._jacobian_flat(q)

    @abstractmethod
    def _position_flat(self, q: torch.Tensor) -> torch.Tensor: ...

    @abstractmethod
    def _pose_flat(self, q: torch.Tensor) -> torch.Tensor: ...

    @abstractmethod
    def _jacobian_flat(self, q: torch.Tensor) -> torch.Tensor: ...

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.robot.name!r})"


# --------------------------------------------------------------------------------------------------
# Fast path
# --------------------------------------------------------------------------------------------------


def _z_to_axis(k: np.ndarray) -> np.ndarray:
    """A rotation A with A @ e_z = k, exact for the signed coordinate axes."""
    exact: dict[tuple[int, ...], np.ndarray] = {
        (0, 0, 1): np.eye(3),
        (0, 0, -1): np.diag([1.0, -1.0, -1.0]),
        (1, 0, 0): np.array([[0.0, 0, 1], [0, 1, 0], [-1, 0, 0]]),
        (-1, 0, 0): np.array([[0.0, 0, -1], [0, 1, 0], [1, 0, 0]]),
        (0, 1, 0): np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]),
        (0, -1, 0): np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]),
    }
    key = tuple(int(v) for v in k) if np.all(k == np.round(k)) else None
    if key in exact:
        return exact[key]
    v = np.cross([0.0, 0.0, 1.0], k)
    s2, c = float(v @ v), float(k[2])
    if s2 < 1e-30:  # k is (anti)parallel to z but not exactly a unit axis
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx * ((1.0 - c) / s2)


def _snap(x: float) -> float:
    """Round values within 1e-14 of 0 or ±1 to them, so that the fast path can skip the product."""
    for target in (0.0, 1.0, -1.0):
        if abs(x - target) < 1e-14:
            return target
    return x


class FastKinematics(Kinematics):
    """Vectorised forward kinematics built from the exact float64 chain.

    Each joint's axis is rotated onto z by folding a constant rotation into the fixed transforms
    around it, so every joint becomes a rotation about (or translation along) z. The end-effector
    position is then computed from the tip backwards as a short sequence of elementwise products on
    ``(N,)`` tensors, skipping products by constant 0 and ±1: no 4×4 matrix is formed.
    """

    backend = "fast"

    def __init__(self, robot: Robot):
        super().__init__(robot)
        F = []  # canonical fixed transforms F_0 … F_dof (float64, 4×4)
        A_prev = np.eye(4)
        for j in robot.joints:
            A = np.eye(4)
            A[:3, :3] = _z_to_axis(j.axis)
            F.append(A_prev.T @ j.T_prev @ A)
            A_prev = A
        F.append(A_prev.T @ robot.T_tip)
        self.F = np.stack(F)
        self.prismatic = tuple(j.kind == "prismatic" for j in robot.joints)
        # Sparse rows (coefficient, source column) of every fixed rotation, and translations.
        self._rows = [
            [[(_snap(float(f[r, c])), c) for c in range(3) if _snap(float(f[r, c])) != 0.0] for r in range(3)]
            for f in self.F
        ]
        self._trans = [[_snap(float(v)) for v in f[:3, 3]] for f in self.F]
        self._const: dict[tuple[torch.dtype, torch.device], torch.Tensor] = {}

    def _F(self, dtype: torch.dtype, device: torch.device) -> torch.Tensor:
        key = (dtype, device)
        if key not in self._const:
            self._const[key] = torch.as_tensor(self.F, dtype=dtype, device=device)
        return self._const[key]

    @staticmethod
    def _row(terms, comps, t: float):
        out = None
        for coef, c in terms:
            x = comps[c]
            term = x if coef == 1.0 else (-x if coef == -1.0 else x * coef)
            out = term if out is None else out + term
        if out is None:
            return t  # a constant
        return out + t if t != 0.0 else out

    #: Batches are processed in chunks of this many configurations: the ≈80 elementwise products
    #: then work on cache-resident tensors, faster at large batches than one pass on the whole batch
    #: (benchmarks/kinematics_speed.py).
    chunk: int = 65536

    def _position_flat(self, q: torch.Tensor) -> torch.Tensor:
        if q.shape[0] > self.chunk:
            return torch.cat([self._position_chunk(c) for c in q.split(self.chunk)])
        return self._position_chunk(q)

    def _position_chunk(self, q: torch.Tensor) -> torch.Tensor:
        n = q.shape[0]
        qt = q.t()
        cq, sq = torch.cos(qt), torch.sin(qt)
        # v = F_dof's translation, then for each joint from the tip: v = F_i (Z_i(q_i) v).
        v = list(self._trans[-1])
        for i in range(self.dof - 1, -1, -1):
            x, y, z = v
            if self.prismatic[i]:
                z = z + qt[i]
            else:
                c, s = cq[i], sq[i]
                x, y = c * x - s * y, s * x + c * y
            comps = (x, y, z)
            v = [self._row(self._rows[i][r], comps, self._trans[i][r]) for r in range(3)]
        cols = [c if isinstance(c, torch.Tensor) else q.new_full((n,), c) for c in v]
        return torch.stack(cols, dim=-1)

    def _frames(self, q: torch.Tensor) -> tuple[list[torch.Tensor], list[torch.Tensor], torch.Tensor]:
        """World rotation and origin of each joint frame (before its motion), and the end-effector pose."""
        F = self._F(q.dtype, q.device)
        n = q.shape[0]
        R = F[0, :3, :3].expand(n, 3, 3)
        p = F[0, :3, 3].expand(n, 3)
        Rs, ps = [], []
        c, s = torch.cos(q), torch.sin(q)
        for i in range(self.dof):
            Rs.append(R)
            ps.append(p)
            if self.prismatic[i]:
                p = p + R[..., 2] * q[:, i : i + 1]
            else:
                ci, si = c[:, i : i + 1], s[:, i : i + 1]
                R = torch.stack(
                    (ci * R[..., 0] + si * R[..., 1], ci * R[..., 1] - si * R[..., 0], R[..., 2]), dim=-1
                )
            p = p + R @ F[i + 1, :3, 3]
            R = R @ F[i + 1, :3, :3]
        T = torch.cat((torch.cat((R, p.unsqueeze(-1)), dim=-1), F[0, 3:4, :].expand(n, 1, 4).clone()), dim=-2)
        return Rs, ps, T

    def _pose_flat(self, q: torch.Tensor) -> torch.Tensor:
        return self._frames(q)[2]

    def link_positions(self, q: torch.Tensor) -> torch.Tensor:
        """Origins of the base, of every joint frame and of the end effector: ``(..., dof + 2, 3)``.

        For drawing the arm as a polyline.
        """
        flat, batch = self._prepare(q, True)
        _, ps, T = self._frames(flat)
        base = torch.zeros_like(T[:, :3, 3])
        pts = torch.stack([base, *ps, T[:, :3, 3]], dim=1)
        return pts.reshape(*batch, self.dof + 2, 3)

    def link_poses(self, q: torch.Tensor, validate: bool = True) -> torch.Tensor:
        """Poses base ← link of the root link and of each joint's child link: ``(..., dof + 1, 4, 4)``.

        Index 0 is the root link (the identity); index k is the URDF frame of the link that joint k
        moves, i.e. joint k's frame after its motion (where collision geometry of that link lives).
        """
        flat, batch = self._prepare(q, validate)
        Rs, ps, _ = self._frames(flat)
        if not hasattr(self, "_link_axes"):  # A_kᵀ: undo the fold of each joint's axis onto z
            self._link_axes = np.stack([_z_to_axis(j.axis).T for j in self.robot.joints])
        R, p = torch.stack(Rs, dim=1), torch.stack(ps, dim=1)  # (N, dof, 3, 3), (N, dof, 3)
        prism = torch.tensor(self.prismatic, device=flat.device)
        c = torch.where(prism, torch.ones_like(flat), torch.cos(flat)).unsqueeze(-1)
        s = torch.where(prism, torch.zeros_like(flat), torch.sin(flat)).unsqueeze(-1)
        p = p + R[..., 2] * torch.where(prism, flat, torch.zeros_like(flat)).unsqueeze(-1)
        R = torch.stack((c * R[..., 0] + s * R[..., 1], c * R[..., 1] - s * R[..., 0], R[..., 2]), dim=-1)
        R = R @ torch.as_tensor(self._link_axes, dtype=flat.dtype, device=flat.device)
        bottom = flat.new_tensor([0.0, 0.0, 0.0, 1.0]).expand(*R.shape[:2], 1, 4)
        T = torch.cat((torch.cat((R, p.unsqueeze(-1)), dim=-1), bottom), dim=-2)
        root = torch.eye(4, dtype=flat.dtype, device=flat.device).expand(flat.shape[0], 1, 4, 4)
        return torch.cat((root, T), dim=1).reshape(*batch, self.dof + 1, 4, 4)

    def _jacobian_flat(self, q: torch.Tensor) -> torch.Tensor:
        return self._position_and_jacobian_flat(q)[1]

    def _position_and_jacobian_flat(self, q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        Rs, ps, T = self._frames(q)
        return T[:, :3, 3], self._position_jacobian(Rs, ps, T[:, :3, 3])

    def _position_jacobian(self, Rs, ps, p_ee: torch.Tensor) -> torch.Tensor:
        """``(N, 3, dof)`` from the joint frames of :meth:`_frames` and the end effector's position."""
        cols = []
        for i in range(self.dof):
            z = Rs[i][..., 2]
            cols.append(z if self.prismatic[i] else torch.linalg.cross(z, p_ee - ps[i], dim=-1))
        return torch.stack(cols, dim=-1)

    def pose_and_axes(self, q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """For ``q (N, dof)``: the end-effector pose ``(N, 4, 4)``, its position Jacobian ``(N, 3, dof)``
        and every joint's axis in the base frame ``(N, 3, dof)`` (a revolute joint's column of the
        angular Jacobian; a prismatic joint turns nothing: its column is zero). Not validated."""
        Rs, ps, T = self._frames(q)
        axes = [
            torch.zeros_like(R[..., 2]) if prism else R[..., 2]
            for R, prism in zip(Rs, self.prismatic, strict=True)
        ]
        return T, self._position_jacobian(Rs, ps, T[:, :3, 3]), torch.stack(axes, dim=-1)


# --------------------------------------------------------------------------------------------------
# pytorch-kinematics
# --------------------------------------------------------------------------------------------------


class PkKinematics(Kinematics):
    """pytorch-kinematics' serial chain, with every fixed transform and axis set to the exact values.

    pytorch-kinematics parses URDF origins in float32; casting its chain to float64 would keep the
    rounded values (≈1e-7 m error), so the chain's constants are overwritten from the float64 parse.
    """

    backend = "pk"

    def __init__(self, robot: Robot):
        super().__init__(robot)
        # pytorch-kinematics' chains, untyped (it ships no annotations pyright reads)
        self._chains: dict[tuple[torch.dtype, torch.device], Any] = {}
        self._chain(torch.float64, torch.device("cpu"))  # fail early on a URDF pk cannot read

    def _chain(self, dtype: torch.dtype, device: torch.device):
        key = (dtype, device)
        if key in self._chains:
            return self._chains[key]
        import pytorch_kinematics as pk

        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            chain = pk.build_serial_chain_from_urdf(self.robot.urdf, self.robot.ee_frame)
        chain = chain.to(dtype=torch.float64, device=device)
        names = list(chain.get_joint_parameter_names())
        if names != list(self.robot.joint_names):
            raise ConfigError(
                f"pytorch-kinematics orders the joints {names}, kinlearn {self.robot.joint_names}"
            )
        static = chain._static_offsets.clone()
        for idx in range(static.shape[0]):
            frame = chain.find_frame(chain.idx_to_frame[idx])
            exact = self.robot.path_origins.get(frame.joint.name) if idx > 0 else np.eye(4)
            if exact is None:
                raise ConfigError(f"pytorch-kinematics frame {frame.name!r} is not on kinlearn's chain")
            exact_t = torch.as_tensor(exact, dtype=torch.float64, device=device)
            if not torch.allclose(static[idx], exact_t, atol=1e-5):
                raise ConfigError(f"pytorch-kinematics frame {frame.name!r} disagrees with the URDF parse")
            static[idx] = exact_t
        axes = torch.as_tensor(
            np.stack([j.axis for j in self.robot.joints]), dtype=torch.float64, device=device
        )
        chain._static_offsets = static
        chain.axes = axes.clone()
        chain._serial_dof_axes = axes.clone()
        chain._dof_ancestor_mask = chain._dof_ancestor_mask.to(torch.float64)
        if dtype != torch.float64:
            chain = chain.to(dtype=dtype)
        self._chains[key] = chain
        return chain

    def _position_flat(self, q: torch.Tensor) -> torch.Tensor:
        return self._pose_flat(q)[:, :3, 3]

    def _pose_flat(self, q: torch.Tensor) -> torch.Tensor:
        chain = self._chain(q.dtype, q.device)
        return chain.forward_kinematics(q).get_matrix()

    def _jacobian_flat(self, q: torch.Tensor) -> torch.Tensor:
        chain = self._chain(q.dtype, q.device)
        return chain.jacobian(q)[:, :3, :]


# --------------------------------------------------------------------------------------------------
# Pinocchio
# --------------------------------------------------------------------------------------------------


class PinocchioKinematics(Kinematics):
    """Pinocchio's model of the same URDF (parsed by Pinocchio itself), evaluated per configuration.

    Joints that are not on the root → end-effector chain (grippers, say) are locked at their neutral
    value. Results are float64 and carry no gradient; they are cast to the input's dtype.
    """

    backend = "pinocchio"

    def __init__(self, robot: Robot):
        super().__init__(robot)
        import pinocchio as pin

        self._pin = pin
        full = pin.buildModelFromXML(robot.urdf.decode("utf-8"))
        lock = [full.getJointId(n) for n in list(full.names)[1:] if n not in robot.joint_names]
        model = pin.buildReducedModel(full, lock, pin.neutral(full)) if lock else full
        if not model.existFrame(robot.ee_frame, pin.FrameType.BODY):
            raise ConfigError(f"Pinocchio finds no link frame {robot.ee_frame!r} in {robot.name}")
        self.model, self.data = model, model.createData()
        self.frame_id = model.getFrameId(robot.ee_frame, pin.FrameType.BODY)
        jids = [model.getJointId(n) for n in robot.joint_names]
        self._idx_q = [model.joints[j].idx_q for j in jids]
        self._nq = [model.joints[j].nq for j in jids]  # 2 for continuous joints (cos, sin)
        self._idx_v = [model.joints[j].idx_v for j in jids]

    def _q(self, qi: np.ndarray) -> np.ndarray:
        out = self._pin.neutral(self.model)
        for k, (iq, nq) in enumerate(zip(self._idx_q, self._nq, strict=True)):
            if nq == 2:
                out[iq], out[iq + 1] = math.cos(qi[k]), math.sin(qi[k])
            else:
                out[iq] = qi[k]
        return out

    def _loop(self, q: torch.Tensor, fn, shape: tuple[int, ...]) -> torch.Tensor:
        qn = q.detach().cpu().double().numpy()
        out = np.empty((qn.shape[0], *shape))
        for i in range(qn.shape[0]):
            out[i] = fn(self._q(qn[i]))
        return torch.as_tensor(out, dtype=q.dtype, device=q.device)

    def _placement(self, qp: np.ndarray):
        pin = self._pin
        pin.forwardKinematics(self.model, self.data, qp)
        return pin.updateFramePlacement(self.model, self.data, self.frame_id)

    def _position_flat(self, q: torch.Tensor) -> torch.Tensor:
        return self._loop(q, lambda qp: self._placement(qp).translation, (3,))

    def _pose_flat(self, q: torch.Tensor) -> torch.Tensor:
        return self._loop(q, lambda qp: self._placement(qp).homogeneous, (4, 4))

    def _jacobian_flat(self, q: torch.Tensor) -> torch.Tensor:
        pin = self._pin

        def jac(qp):
            J = pin.computeFrameJacobian(self.model, self.data, qp, self.frame_id, pin.LOCAL_WORLD_ALIGNED)
            return J[:3, self._idx_v]

        return self._loop(q, jac, (3, self.dof))


def dls_step(
    kin: Kinematics,
    q: torch.Tensor,
    target: torch.Tensor,
    iterations: int = 1,
    damping: float = 1e-2,
    clamp: bool = True,
) -> torch.Tensor:
    """Damped-least-squares steps moving ``q (..., dof)`` so its end effector approaches ``target (..., 3)``.

    Each iteration: dq = Jᵀ (J Jᵀ + λ² I)⁻¹ (target − FK(q)), with λ = ``damping`` (metres). With
    ``clamp`` the result is kept within the joint limits. Differentiable in ``q`` and ``target``.
    """
    lo, hi = kin.robot.limits(q.dtype, q.device)
    eye = torch.eye(3, dtype=q.dtype, device=q.device)
    for _ in range(iterations):
        p, J = kin.position_and_jacobian(q, validate=False)
        err = target - p
        JJt = J @ J.transpose(-1, -2) + (damping**2) * eye
        dq = (J.transpose(-1, -2) @ torch.linalg.solve(JJt, err.unsqueeze(-1))).squeeze(-1)
        q = q + dq
        if clamp:
            q = torch.clamp(q, lo, hi)
    return q


def approach_axis(robot: Robot) -> np.ndarray:
    """The hand's approach axis in the end-effector frame ``(3,)`` (unit, float64): the last joint's
    axis, the flange's normal on every arm kinlearn ships, pointing from that joint toward the end
    effector (the way a gripper on the flange points)."""
    joint = robot.joints[-1]
    R, t = robot.T_tip[:3, :3], robot.T_tip[:3, 3]
    axis = np.asarray(joint.axis, dtype=np.float64) / np.linalg.norm(joint.axis)
    if float(t @ axis) < 0.0:
        axis = -axis
    return R.T @ axis


def pointing_dls_step(
    kin: FastKinematics,
    q: torch.Tensor,
    target: torch.Tensor,
    direction: torch.Tensor,
    iterations: int = 1,
    damping: float = 1e-2,
    weight: float = 0.2,
) -> torch.Tensor:
    """Damped-least-squares steps moving ``q (N, dof)`` so that its end effector approaches ``target
    (N, 3)`` and its :func:`approach_axis` turns toward the unit ``direction (N, 3)`` (base frame), the
    turn about the axis itself left free: dq = Jᵀ (J Jᵀ + λ² I)⁻¹ e with the position error and
    ``weight`` (m/rad) × a × d, the rotation that takes the axis ``a`` onto ``d`` (its sine for the angle),
    over the rows of the position Jacobian and of the angular one with its part about ``a`` taken out.
    Kept within the joint limits."""
    lo, hi = kin.robot.limits(q.dtype, q.device)
    local = torch.as_tensor(approach_axis(kin.robot), dtype=q.dtype, device=q.device)
    eye = torch.eye(6, dtype=q.dtype, device=q.device)
    for _ in range(iterations):
        T, Jp, W = kin.pose_and_axes(q)
        a = T[:, :3, :3] @ local
        Wp = W - a.unsqueeze(-1) * (a.unsqueeze(-2) @ W)  # no turn about the axis itself is asked for
        J = torch.cat((Jp, weight * Wp), dim=-2)
        err = torch.cat((target - T[:, :3, 3], weight * torch.linalg.cross(a, direction, dim=-1)), dim=-1)
        dq = J.transpose(-1, -2) @ torch.linalg.solve(
            J @ J.transpose(-1, -2) + damping**2 * eye, err.unsqueeze(-1)
        )
        q = torch.clamp(q + dq.squeeze(-1), lo, hi)
    return q


_KINDS: dict[str, type[Kinematics]] = {
    "fast": FastKinematics,
    "pk": PkKinematics,
    "pinocchio": PinocchioKinematics,
}
_KIN_CACHE: dict[tuple[int, str], tuple[Robot, Kinematics]] = {}


def kinematics(robot: Robot | str, backend: Backend = "fast") -> Kinematics:
    """The kinematics of ``robot`` (a :class:`Robot`, or a name or URDF path for :func:`load_robot`)
    through ``backend`` (one of :data:`BACKENDS`), cached per robot."""
    if backend not in _KINDS:
        raise ConfigError(f"unknown kinematics backend {backend!r}; choose one of {', '.join(BACKENDS)}")
    if isinstance(robot, (str, Path)):
        robot = load_robot(robot)
    elif not isinstance(robot, Robot):
        raise ConfigError(f"robot must be a kinlearn Robot or a robot name, got {type(robot).__name__}")
    # The cache holds the robot itself beside its kinematics: while an entry lives its robot does too,
    # so no other Robot can take over its id and be handed this robot's kinematics.
    key = (id(robot), backend)
    cached = _KIN_CACHE.get(key)
    if cached is None or cached[0] is not robot:
        cached = _KIN_CACHE[key] = (robot, _KINDS[backend](robot))
    return cached[1]
