"""The joint-path planner's batch-1 inference, compiled (numba): the TM's MLP, its knots and a whole
free-space plan in one call.

torch (:class:`~kinlearn.models.joint_path.JointPathModel`) is the implementation for training and large
batches. A plan of a few problems is a few dozen tiny array operations, each costing microseconds of
dispatch through torch or NumPy; here they are one compiled call. :class:`CompiledPathModel` holds the
network's weights (the input standardisation folded into the first layer) and its constants as arrays,
made once per planner, and is held to torch by a contract test (``tests/test_joint_path_planner.py``).
:meth:`CompiledPathModel.free_plan` is the planner's batch-1 free-space entry: the start and goal
checked and their FK, the network, the knots clipped to the limits, and the verdict of
:func:`~kinlearn.planning.judge.judge`'s rule (:func:`~kinlearn.planning.judge._judged`, the same
arithmetic every small plan is judged by), from two joint vectors to the plan's arrays.
"""

from __future__ import annotations

import numpy as np
import torch

from ..body.fk import checked_tips
from ..body.jit import jit
from ..models.joint_path import JointPathModel
from .judge import _judged

__all__ = ["CompiledPathModel"]

_jit = jit()  # stamped with the kernels it calls: their edits recompile it (kinlearn.body.jit)


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


def packed_mlp(seq: torch.nn.Sequential, mean, std, dtype=np.float32, rows: int | None = None):
    """The Linear layers of ``seq`` (the standardisation folded in: :func:`_folded_mlp`) as tuples for
    :func:`mlp`: weights ``(in, out)`` and biases ``(1, out)`` of ``dtype``, contiguous."""
    weights, biases = _folded_mlp(seq, mean, std, dtype, rows=rows)
    return tuple(np.ascontiguousarray(w) for w in weights), tuple(
        np.ascontiguousarray(b[None]) for b in biases
    )


@_jit
def mlp(h, weights, biases, silu, last_active):
    """(Compiled.) The MLP on ``h (N, in)`` (the weights' dtype): every layer but the last followed by the
    activation (SiLU, else tanh), the last too if ``last_active``. Products through BLAS (``np.dot``)."""
    last = len(weights) - 1
    one = np.ones(1, dtype=h.dtype)[0]  # 1 in the network's dtype (SiLU in float32 as torch's)
    for k in range(len(weights)):
        h = np.dot(h, weights[k]) + biases[k]
        if k < last or last_active:
            for i in range(h.shape[0]):
                for j in range(h.shape[1]):
                    v = h[i, j]
                    h[i, j] = v / (one + np.exp(-v)) if silu else np.tanh(v)
    return h


@_jit
def _path_tm(
    theta0, ef0, thetaT, efT, weights, biases, silu, basis, fractions, half_range, ef_scale, joints, ef
):
    """The joint-path TM's forward pass on ``N`` problems (float64 ``(N, dof)`` joints and ``(N, 3)`` end
    effectors): its knots into ``joints (N, T − 1, dof)`` and its end-effector waypoints into
    ``ef (N, T − 1, 3)``, as :meth:`JointPathModel.forward` computes them (the network in the weights'
    dtype, the rest float64). ``basis (T − 1, modes)``, or ``(0, 0)`` where the network gives knots."""
    n, dof = theta0.shape
    W = fractions.shape[0]
    h = np.empty((n, 3 * dof + 6), dtype=weights[0].dtype)
    for i in range(n):
        for j in range(dof):
            h[i, j] = theta0[i, j]
            h[i, dof + 3 + j] = thetaT[i, j]
            h[i, 2 * dof + 6 + j] = thetaT[i, j] - theta0[i, j]
        for c in range(3):
            h[i, dof + c] = ef0[i, c]
            h[i, 2 * dof + 3 + c] = efT[i, c]
    out = mlp(h, weights, biases, silu, False)
    modes = basis.shape[1]
    nj = modes * dof if modes else W * dof
    for i in range(n):
        for k in range(W):
            f = fractions[k]
            for j in range(dof):
                if modes:
                    r = 0.0
                    for m in range(modes):
                        r += basis[k, m] * np.float64(out[i, m * dof + j])
                else:
                    r = np.float64(out[i, k * dof + j])
                joints[i, k, j] = theta0[i, j] + f * (thetaT[i, j] - theta0[i, j]) + half_range[j] * r
            for c in range(3):
                e = np.float64(out[i, nj + 3 * k + c])
                ef[i, k, c] = ef0[i, c] + f * (efT[i, c] - ef0[i, c]) + ef_scale * e


@_jit
def _free_plan(
    q, F, prismatic, lower, upper, zero_move, limit_tol, start_tol, position_tol, joint_tol, weights, biases, silu, basis,
    fractions, half_range, ef_scale, joints, waypoints, states, scores, ok,
):  # fmt: skip
    """A batch-1 free-space plan from ``q (2, dof)`` (start, goal): False where either lies outside the
    limits or is not finite, or the two are within ``zero_move`` of each other (the general path explains
    or plans those); else True, with the plan's knots in ``joints (T + 1, dof)`` (the TM's inner knots
    clipped to the limits), its end-effector waypoints in ``waypoints (T − 1, 3)``, the start and goal
    states in ``states (2, dof + 3)``, and the verdict's ``scores (2, 1)`` and ``ok (1,)``; returns the
    end effectors of every knot too."""
    dof = q.shape[1]
    K = joints.shape[0]
    inside = np.empty(2, dtype=np.bool_)
    tips = checked_tips(q, F, prismatic, lower, upper, 0.0, inside)
    moved = False
    for j in range(dof):
        if abs(q[1, j] - q[0, j]) > zero_move:
            moved = True
    if not (inside[0] and inside[1] and moved):
        return False, tips
    for r in range(2):
        for j in range(dof):
            states[r, j] = q[r, j]
        for c in range(3):
            states[r, dof + c] = tips[r, c]
    mid = np.empty((1, K - 2, dof))
    _path_tm(
        q[:1], tips[:1], q[1:], tips[1:], weights, biases, silu, basis, fractions, half_range, ef_scale, mid,
        waypoints.reshape(1, K - 2, 3),
    )  # fmt: skip
    for j in range(dof):
        joints[0, j] = q[0, j]
        joints[K - 1, j] = q[1, j]
    for k in range(K - 2):
        for j in range(dof):
            joints[k + 1, j] = min(max(mid[0, k, j], lower[j]), upper[j])
    every = np.ones(1, dtype=np.bool_)
    ef, _ = _judged(
        joints, K, states[:1], states[1:], True, F, prismatic, lower, upper, limit_tol, start_tol, position_tol,
        joint_tol, every, every, scores, ok,
    )  # fmt: skip
    return True, ef


class CompiledPathModel:
    """The joint-path TM's forward pass compiled: ``(θ(0), ef(0), θ(T), ef(T))`` → joint and end-effector
    waypoints, as :meth:`JointPathModel.forward` computes them, and :meth:`free_plan`, a whole batch-1
    free-space plan."""

    def __init__(self, tm: JointPathModel, dtype=np.float32):
        """``dtype``: of the network's weights and arithmetic (float32 halves a batch-1 pass's time; the
        waypoints are then assembled in float64)."""
        self.dtype = np.dtype(dtype)
        self.weights, self.biases = packed_mlp(tm.net, tm.in_mean, tm.in_std, self.dtype)
        self.silu = tm.config.activation == "silu"
        self.dof = tm.config.dof
        self.half_range = np.ascontiguousarray(_arr(tm.half_range))
        self.fractions = np.ascontiguousarray(_arr(tm.fractions))
        self.ef_scale = float(tm.ef_scale)
        self.W = tm.config.steps - 1
        self.basis = np.ascontiguousarray(_arr(tm.basis)) if tm.config.modes else np.zeros((0, 0))

    def _args(self) -> tuple:
        return (
            self.weights,
            self.biases,
            self.silu,
            self.basis,
            self.fractions,
            self.half_range,
            self.ef_scale,
        )

    def __call__(
        self, theta0: np.ndarray, ef0: np.ndarray, thetaT: np.ndarray, efT: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Each input ``(N, ·)`` float64 → ``(joints (N, T − 1, dof), ef (N, T − 1, 3))``."""
        n = theta0.shape[0]
        joints, ef = np.empty((n, self.W, self.dof)), np.empty((n, self.W, 3))
        c = np.ascontiguousarray
        _path_tm(c(theta0), c(ef0), c(thetaT), c(efT), *self._args(), joints, ef)
        return joints, ef

    def free_plan(self, q: np.ndarray, chain, zero_move: float, tols: tuple) -> tuple | None:
        """A batch-1 free-space plan from ``q (2, dof)`` float64 (start, goal) for a robot packed as
        ``chain`` (:class:`~kinlearn.body.fk.KernelChain`), ``tols`` (the verdict's limit, start, position and
        joint tolerances):
        ``(joints (T + 1, dof), end effectors (T + 1, 3), waypoints (T − 1, 3), states (2, dof + 3),
        scores (2, 1), ok (1,))``; None where either end lies outside the limits or is not finite, or they
        are within ``zero_move`` of each other (for the general path to explain or plan)."""
        dof = self.dof
        joints, waypoints = np.empty((self.W + 2, dof)), np.empty((self.W, 3))
        states, scores, ok = np.empty((2, dof + 3)), np.empty((2, 1)), np.empty(1, dtype=bool)
        done, ef = _free_plan(
            q, chain.F, chain.prismatic, chain.lower, chain.upper, zero_move, *tols, *self._args(), joints,
            waypoints, states, scores, ok,
        )  # fmt: skip
        return (joints, ef, waypoints, states, scores, ok) if done else None
