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
    """The Linear layers of ``seq`` (the standardisation folded in: :func:`_folded_mlp`) packed for
    :func:`mlp`: ``(flat, widths)``, every layer's weights ``(in, out)`` then its biases ``(out,)`` in one
    contiguous buffer of ``dtype``, in order, and the layers' widths (input first, int64)."""
    weights, biases = _folded_mlp(seq, mean, std, dtype, rows=rows)
    flat = np.concatenate([a.ravel() for w, b in zip(weights, biases, strict=True) for a in (w, b)])
    widths = np.array([weights[0].shape[0], *(w.shape[1] for w in weights)], dtype=np.int64)
    return np.ascontiguousarray(flat.astype(dtype)), widths


@_jit
def _activate(h, silu):
    """The activation in place on ``h (N, width)``: SiLU (in the network's dtype, as torch's), else tanh."""
    one = np.ones(1, dtype=h.dtype)[0]
    for i in range(h.shape[0]):
        for j in range(h.shape[1]):
            v = h[i, j]
            h[i, j] = v / (one + np.exp(-v)) if silu else np.tanh(v)


@_jit
def mlp(h, flat, widths, silu, last_active):
    """(Compiled.) The MLP packed by :func:`packed_mlp` (``flat``, ``widths``) on ``h (N, in)`` (the
    weights' dtype): every layer but the last followed by the activation (SiLU, else tanh), the last too if
    ``last_active``. Products through BLAS (``np.dot``)."""
    o = 0
    last = widths.shape[0] - 2
    for k in range(last + 1):
        n_in, n_out = widths[k], widths[k + 1]
        W = flat[o : o + n_in * n_out].reshape(n_in, n_out)
        o += n_in * n_out
        h = np.dot(h, W) + flat[o : o + n_out].reshape(1, n_out)
        o += n_out
        if k < last or last_active:
            _activate(h, silu)
    return h


@_jit
def _path_input(theta0, ef0, thetaT, efT, dtype_of):
    """The joint-path TM's input rows ``(N, 3 · dof + 6)`` (θ0, ef0, θT, efT, θT − θ0), in the dtype of the
    array ``dtype_of`` (the network's)."""
    n, dof = theta0.shape
    h = np.empty((n, 3 * dof + 6), dtype=dtype_of.dtype)
    for i in range(n):
        for j in range(dof):
            h[i, j] = theta0[i, j]
            h[i, dof + 3 + j] = thetaT[i, j]
            h[i, 2 * dof + 6 + j] = thetaT[i, j] - theta0[i, j]
        for c in range(3):
            h[i, dof + c] = ef0[i, c]
            h[i, 2 * dof + 3 + c] = efT[i, c]
    return h


@_jit
def _path_knots(out, theta0, ef0, thetaT, efT, basis, fractions, half_range, ef_scale, joints, ef):
    """The network's output ``out (N, ·)`` into the knots ``joints (N, T − 1, dof)`` and end-effector waypoints
    ``ef (N, T − 1, 3)``, as :meth:`JointPathModel.forward` assembles them (float64)."""
    n, dof = theta0.shape
    W = fractions.shape[0]
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
def _path_tm(theta0, ef0, thetaT, efT, net, widths, silu, basis, fractions, half_range, ef_scale, joints, ef):
    """The joint-path TM's forward pass on ``N`` problems (float64 ``(N, dof)`` joints and ``(N, 3)`` end
    effectors): its knots into ``joints (N, T − 1, dof)`` and its end-effector waypoints into
    ``ef (N, T − 1, 3)``, as :meth:`JointPathModel.forward` computes them (the network, ``net`` and
    ``widths`` as :func:`packed_mlp` packs it, in its dtype; the rest float64). ``basis (T − 1, modes)``, or
    ``(0, 0)`` where the network gives knots."""
    out = mlp(_path_input(theta0, ef0, thetaT, efT, net), net, widths, silu, False)
    _path_knots(out, theta0, ef0, thetaT, efT, basis, fractions, half_range, ef_scale, joints, ef)


#: The packed free-space kernel's scalars, in order at the head of its float64 buffer.
_SCALARS = 6  # zero move, the verdict's limit, start, position and joint tolerances, ef scale


@_jit
def _layout(dof, W):
    """Where a free-space plan's parts start in :func:`_free_plan`'s output buffer: the knots ``(W + 2, dof)``
    at 0, then the waypoints ``(W, 3)``, the start and goal states ``(2, dof + 3)``, the two scores and the
    verdict; returns (waypoints, states, scores, the buffer's size)."""
    waypoints = (W + 2) * dof
    states = waypoints + 3 * W
    scores = states + 2 * (dof + 3)
    return waypoints, states, scores, scores + 3


@_jit
def _free_plan(a, b, f64, net, ints, out):
    """A batch-1 free-space plan from the start ``a`` and goal ``b (dof,)``, everything else packed
    (:meth:`CompiledPathModel._packed`: few arguments, each of which costs a call time): ``f64`` the
    scalars (:data:`_SCALARS`), the chain's fixed transforms ``F (dof + 1, 4, 4)`` (the last to the tip),
    limits, knot basis, fractions and half ranges; ``net`` the network's layers in its dtype
    (:func:`mlp`); ``ints`` dof, T − 1, modes, SiLU, the joints' prismatic flags, the layers'
    widths. False where either end lies
    outside the limits or is not finite, or the two are within the zero move of each other (the general
    path explains or plans those); else True, with ``out`` filled (:meth:`CompiledPathModel.views`: the
    plan's knots ``(T + 1, dof)``, the TM's inner knots clipped to the limits, its end-effector waypoints
    ``(T − 1, 3)``, the start and goal states ``(2, dof + 3)``, the verdict's scores ``(2,)`` and whether
    it succeeds, 1 or 0); returns the end effectors of every knot too."""
    dof, W, modes, silu = ints[0], ints[1], ints[2], ints[3] != 0
    prismatic = ints[4 : 4 + dof] != 0
    widths = ints[4 + dof :]
    zero_move, limit_tol, start_tol, position_tol, joint_tol, ef_scale = f64[:_SCALARS]
    o = _SCALARS
    F = f64[o : o + 16 * (dof + 1)].reshape(dof + 1, 4, 4)
    o += 16 * (dof + 1)
    lower, upper = f64[o : o + dof], f64[o + dof : o + 2 * dof]
    o += 2 * dof
    basis = f64[o : o + W * modes].reshape(W, modes)
    o += W * modes
    fractions, half_range = f64[o : o + W], f64[o + W : o + W + dof]
    K = W + 2
    wp, st, o, _ = _layout(dof, W)
    joints = out[:wp].reshape(K, dof)
    waypoints = out[wp:st].reshape(W, 3)
    states = out[st:o].reshape(2, dof + 3)
    scores, ok = out[o : o + 2].reshape(2, 1), np.empty(1, dtype=np.bool_)
    q = np.empty((2, dof))
    for j in range(dof):
        q[0, j], q[1, j] = a[j], b[j]
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
    y = mlp(_path_input(q[:1], tips[:1], q[1:], tips[1:], net), net, widths, silu, False)
    _path_knots(y, q[:1], tips[:1], q[1:], tips[1:], basis, fractions, half_range, ef_scale, mid,
                waypoints.reshape(1, K - 2, 3))  # fmt: skip
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
    out[o + 2] = 1.0 if ok[0] else 0.0
    return True, ef


class CompiledPathModel:
    """The joint-path TM's forward pass compiled: ``(θ(0), ef(0), θ(T), ef(T))`` → joint and end-effector
    waypoints, as :meth:`JointPathModel.forward` computes them, and :meth:`free_plan`, a whole batch-1
    free-space plan."""

    def __init__(self, tm: JointPathModel, dtype=np.float32):
        """``dtype``: of the network's weights and arithmetic (float32 halves a batch-1 pass's time; the
        waypoints are then assembled in float64)."""
        self.dtype = np.dtype(dtype)
        self.net, self.widths = packed_mlp(tm.net, tm.in_mean, tm.in_std, self.dtype)
        self.silu = tm.config.activation == "silu"
        self.dof = tm.config.dof
        self.half_range = np.ascontiguousarray(_arr(tm.half_range))
        self.fractions = np.ascontiguousarray(_arr(tm.fractions))
        self.ef_scale = float(tm.ef_scale)
        self.W = tm.config.steps - 1
        self.basis = np.ascontiguousarray(_arr(tm.basis)) if tm.config.modes else np.zeros((0, 0))
        self._free_key: tuple | None = None  # what _free_packed was packed for
        self._size = _layout(self.dof, self.W)[3]  # free_plan's output buffer
        self._free_packed: tuple = ()

    def _args(self) -> tuple:
        return (
            self.net,
            self.widths,
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

    def _packed(self, chain, zero_move: float, tols: tuple) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:func:`_free_plan`'s packed constants for ``chain``, ``zero_move`` and ``tols`` (made on the first
        call with them, then kept: a planner plans with the same ones)."""
        key = (chain, zero_move, tols)
        if self._free_key is not None and self._free_key[0] is chain and self._free_key[1:] == key[1:]:
            return self._free_packed
        f64 = np.concatenate((
            [zero_move, *tols, self.ef_scale], np.asarray(chain.F, dtype=np.float64).ravel(), chain.lower,
            chain.upper, self.basis.ravel(), self.fractions.ravel(), self.half_range.ravel(),
        ))  # fmt: skip
        modes = self.basis.shape[1]
        ints = np.array(
            [self.dof, self.W, modes, int(self.silu), *chain.prismatic.astype(int), *self.widths],
            dtype=np.int64,
        )
        self._free_key, self._free_packed = key, (f64, self.net, ints)
        return self._free_packed

    def free_plan(self, a: np.ndarray, b: np.ndarray, chain, zero_move: float, tols: tuple) -> tuple | None:
        """A batch-1 free-space plan from the start ``a`` to the goal ``b`` (float64 ``(dof,)``) for a robot
        packed as ``chain`` (:class:`~kinlearn.body.fk.KernelChain`), ``tols`` (the verdict's limit, start,
        position and joint tolerances): ``(out, end effectors (T + 1, 3))``, ``out`` the rest of the plan
        in one buffer (:meth:`views` reads it); None where either end lies outside the limits or is not
        finite, or they are within ``zero_move`` of each other (for the general path to explain or plan)."""
        out = np.empty(self._size)
        done, ef = _free_plan(a, b, *self._packed(chain, zero_move, tols), out)
        return (out, ef) if done else None

    def views(self, out: np.ndarray, ef: np.ndarray) -> dict[str, np.ndarray]:
        """The plan's arrays by field name (:meth:`~kinlearn.planning.plan.Plan.deferred`'s) in a buffer
        :meth:`free_plan` filled, and its end effectors ``ef``."""
        dof, W = self.dof, self.W
        o, st, s, _ = _layout(dof, W)
        states = out[st:s].reshape(2, dof + 3)
        return {
            "goal": states[1], "waypoints": out[o:st].reshape(W, 3),
            "joints": out[:o].reshape(W + 2, dof), "ef": ef, "target": states[1, dof:],
            "goal_error": out[s : s + 1].reshape(()), "joint_error": out[s + 1 : s + 2].reshape(()),
            "success": np.array(out[s + 2] > 0.5),
        }  # fmt: skip
