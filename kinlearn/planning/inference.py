"""Fast CPU inference for the joint-path planner: the TM's MLP and the FK check in NumPy, float64.

A plan at batch 1 is a few dozen tiny array operations. Through torch each costs several
microseconds of dispatch; NumPy's cost per operation is a fraction of that, which is what brings a
whole batch-1 plan (checks, inference, joint path, FK of every configuration) to tens of
microseconds. The arithmetic is the same as :class:`~kinlearn.models.joint_path.JointPathModel` and
:class:`~kinlearn.body.kinematics.FastKinematics` (tests hold the two to agree); this module only holds
the weights and constants as float64 arrays, made once when a planner is built.
"""

from __future__ import annotations

import numpy as np
import torch

from ..models.joint_path import JointPathModel

__all__ = ["NumpyFK", "NumpyPathModel"]


def _arr(t: torch.Tensor) -> np.ndarray:
    return t.detach().cpu().double().numpy().copy()


def _folded_mlp(seq: torch.nn.Sequential, mean, std, dtype, rows: int | None = None):
    """The Linear layers of ``seq`` as ``(weights (in, out), biases)`` arrays of ``dtype``, with the
    input standardisation (x − μ)/σ folded into the first layer, x · (W/σ) + (b − (μ/σ) · W), in
    float64 before the cast. ``rows``: only the first ``rows`` inputs are standardised (the rest pass
    as they are)."""
    linears = [m for m in seq if isinstance(m, torch.nn.Linear)]
    weights = [_arr(m.weight.T) for m in linears]
    biases = [_arr(m.bias) for m in linears]
    mean, std = _arr(mean), _arr(std)
    rows = weights[0].shape[0] if rows is None else rows
    W = weights[0]
    biases[0] = biases[0] - (mean / std) @ W[:rows]
    weights[0] = np.concatenate((W[:rows] / std[:, None], W[rows:]))
    return [w.astype(dtype) for w in weights], [b.astype(dtype) for b in biases]


def _run_mlp(h: np.ndarray, weights, biases, silu: bool, last_active: bool = False) -> np.ndarray:
    """The MLP on ``h``: every layer but the last followed by the activation (the last too if
    ``last_active``)."""
    last = len(weights) - 1
    for k, (W, b) in enumerate(zip(weights, biases, strict=True)):
        h = h @ W + b
        if k < last or last_active:
            h = h / (1.0 + np.exp(-h)) if silu else np.tanh(h)
    return h


class NumpyFK:
    """End-effector positions of a serial chain for ``(N, dof)`` float64 arrays.

    Built from a :class:`~kinlearn.body.kinematics.FastKinematics`' canonical fixed transforms (every joint
    a rotation about, or translation along, z): each joint's 4 × 4 transform F_i · Z_i(q_i) is formed
    for all joints at once, and the chain's product is reduced pairwise (log₂ of the joint count
    batched matrix products instead of one product per joint).
    """

    def __init__(self, fast_kinematics):
        F = np.asarray(fast_kinematics.F, dtype=np.float64)
        self.dof = F.shape[0] - 1
        self.F = F
        self.prismatic = np.array(fast_kinematics.prismatic, dtype=bool)
        size = 1 << (self.dof).bit_length()  # dof + 1 transforms, padded with identities to a power of 2
        self._template = np.broadcast_to(np.eye(4), (size, 4, 4)).copy()
        self._template[: self.dof + 1] = F
        self._R0, self._R1 = F[: self.dof, :, 0], F[: self.dof, :, 1]

    def position(self, q: np.ndarray) -> np.ndarray:
        """``q (N, dof)`` → ``(N, 3)``."""
        dof = self.dof
        A = np.repeat(self._template[None], q.shape[0], axis=0)
        if self.prismatic.any():
            qr = np.where(self.prismatic, 0.0, q)
            A[:, :dof, :, 3] += self.F[:dof, :, 2] * np.where(self.prismatic, q, 0.0)[..., None]
        else:
            qr = q
        c, s = np.cos(qr)[..., None], np.sin(qr)[..., None]
        A[:, :dof, :, 0] = c * self._R0 + s * self._R1
        A[:, :dof, :, 1] = c * self._R1 - s * self._R0
        while A.shape[1] > 1:
            A = A[:, 0::2] @ A[:, 1::2]
        return A[:, 0, :3, 3]


class NumpyPathModel:
    """The joint-path TM's forward pass in NumPy: ``(θ(0), ef(0), θ(T), ef(T))`` → joint and
    end-effector waypoints, as :meth:`JointPathModel.forward` computes them."""

    def __init__(self, tm: JointPathModel, dtype=np.float32):
        """``dtype``: of the network's weights and arithmetic (float32 halves a batch-1 pass's time; the
        waypoints are then assembled in float64)."""
        self.dtype = np.dtype(dtype)
        self.weights, self.biases = _folded_mlp(tm.net, tm.in_mean, tm.in_std, self.dtype)
        self.silu = tm.config.activation == "silu"
        self.dof = tm.config.dof
        self.half_range = _arr(tm.half_range)
        self.fractions = _arr(tm.fractions)[:, None]
        self.ef_scale = float(tm.ef_scale)
        self.W = tm.config.steps - 1
        self.modes = tm.config.modes
        self.basis = _arr(tm.basis)
        self.n_joint_out = self.modes * self.dof if self.modes else self.W * self.dof

    def __call__(
        self, theta0: np.ndarray, ef0: np.ndarray, thetaT: np.ndarray, efT: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Each input ``(N, ·)`` float64 → ``(joints (N, T − 1, dof), ef (N, T − 1, 3))``."""
        h = np.concatenate((theta0, ef0, thetaT, efT, thetaT - theta0), axis=1).astype(self.dtype)
        h = _run_mlp(h, self.weights, self.biases, self.silu)
        h = h.astype(np.float64)
        n, nj = h.shape[0], self.n_joint_out
        r = h[:, :nj].reshape(n, nj // self.dof, self.dof)  # explicit sizes: n may be 0
        if self.modes:
            r = self.basis @ r
        f = self.fractions
        joints = theta0[:, None] + f * (thetaT - theta0)[:, None] + self.half_range * r
        ef = ef0[:, None] + f * (efT - ef0)[:, None] + self.ef_scale * h[:, nj:].reshape(n, self.W, 3)
        return joints, ef
