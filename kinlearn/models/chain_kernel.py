"""The compiled (numba) kernel of the chain model's position solver, for planning on the CPU.

:func:`solve_position_numba` does what :func:`kinlearn.models.chain.solve_position` does in torch —
the same fixed restarts, the same projected damped least-squares steps on the chain's geometric
Jacobian, the same choice of solution — without a Python call per operation: a batch-1 position goal
costs microseconds instead of milliseconds. ``tests/test_chain.py`` holds the two to each other.
:func:`chain_positions` is the chain's FK on the same code (the retreat stage starts its vias from it,
:mod:`kinlearn.planning.retreat`). :func:`moves_keeping_orientation` moves the hand through targets
with its orientation held (the retreat stage's kept chains; compiled only, no torch twin). A rigid
chain only (the residual MLP runs in torch).

Nothing is compiled at import (and the planner imports this module only when it first solves a
position goal): the first call compiles (seconds) and caches the machine code beside this file
(``cache=True``), so later processes load it in a fraction of a second.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["chain_positions", "chain_retreats", "solve_position_numba"]


@numba.njit(cache=True, fastmath=False)
def _rot(w, c, s, out):
    x, y, z = w[0], w[1], w[2]
    t = 1.0 - c
    out[0, 0] = c + t * x * x
    out[0, 1] = t * x * y - s * z
    out[0, 2] = t * x * z + s * y
    out[1, 0] = t * x * y + s * z
    out[1, 1] = c + t * y * y
    out[1, 2] = t * y * z - s * x
    out[2, 0] = t * x * z - s * y
    out[2, 1] = t * y * z + s * x
    out[2, 2] = c + t * z * z


@numba.njit(cache=True, fastmath=False)
def _fk_jac(w, q, tip, ref, theta, p, J, R, Ri, RR, t, axes, pts):
    """p and J (3 × n) of the chain at theta (float64); R, Ri, RR (3 × 3), t (3), axes and pts (n × 3)
    are work space."""
    n = w.shape[0]
    for a in range(3):
        t[a] = 0.0
        for b in range(3):
            R[a, b] = 1.0 if a == b else 0.0
    for i in range(n):
        for a in range(3):
            axes[i, a] = R[a, 0] * w[i, 0] + R[a, 1] * w[i, 1] + R[a, 2] * w[i, 2]
            pts[i, a] = R[a, 0] * q[i, 0] + R[a, 1] * q[i, 1] + R[a, 2] * q[i, 2] + t[a]
        phi = theta[i] - ref[i]
        _rot(w[i], np.cos(phi), np.sin(phi), Ri)
        # t ← R (q − Ri q) + t ; R ← R Ri
        d0 = q[i, 0] - (Ri[0, 0] * q[i, 0] + Ri[0, 1] * q[i, 1] + Ri[0, 2] * q[i, 2])
        d1 = q[i, 1] - (Ri[1, 0] * q[i, 0] + Ri[1, 1] * q[i, 1] + Ri[1, 2] * q[i, 2])
        d2 = q[i, 2] - (Ri[2, 0] * q[i, 0] + Ri[2, 1] * q[i, 1] + Ri[2, 2] * q[i, 2])
        for a in range(3):
            t[a] += R[a, 0] * d0 + R[a, 1] * d1 + R[a, 2] * d2
        for a in range(3):
            for b in range(3):
                RR[a, b] = R[a, 0] * Ri[0, b] + R[a, 1] * Ri[1, b] + R[a, 2] * Ri[2, b]
        for a in range(3):
            for b in range(3):
                R[a, b] = RR[a, b]
    for a in range(3):
        p[a] = R[a, 0] * tip[0] + R[a, 1] * tip[1] + R[a, 2] * tip[2] + t[a]
    for i in range(n):
        v0, v1, v2 = p[0] - pts[i, 0], p[1] - pts[i, 1], p[2] - pts[i, 2]
        J[0, i] = axes[i, 1] * v2 - axes[i, 2] * v1
        J[1, i] = axes[i, 2] * v0 - axes[i, 0] * v2
        J[2, i] = axes[i, 0] * v1 - axes[i, 1] * v0


@numba.njit(cache=True, fastmath=False)
def _distance(a, b):
    return np.sqrt((a[0] - b[0]) ** 2 + (a[1] - b[1]) ** 2 + (a[2] - b[2]) ** 2)


@numba.njit(cache=True, fastmath=False)
def _solve3(A, b, x):
    """x = A⁻¹ b for a symmetric positive definite 3 × 3 A (Cramer's rule)."""
    c00 = A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1]
    c01 = A[1, 2] * A[2, 0] - A[1, 0] * A[2, 2]
    c02 = A[1, 0] * A[2, 1] - A[1, 1] * A[2, 0]
    det = A[0, 0] * c00 + A[0, 1] * c01 + A[0, 2] * c02
    c10 = A[0, 2] * A[2, 1] - A[0, 1] * A[2, 2]
    c11 = A[0, 0] * A[2, 2] - A[0, 2] * A[2, 0]
    c12 = A[0, 1] * A[2, 0] - A[0, 0] * A[2, 1]
    c20 = A[0, 1] * A[1, 2] - A[0, 2] * A[1, 1]
    c21 = A[0, 2] * A[1, 0] - A[0, 0] * A[1, 2]
    c22 = A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]
    x[0] = (c00 * b[0] + c10 * b[1] + c20 * b[2]) / det
    x[1] = (c01 * b[0] + c11 * b[1] + c21 * b[2]) / det
    x[2] = (c02 * b[0] + c12 * b[1] + c22 * b[2]) / det


@numba.njit(cache=True, fastmath=False)
def _solve(w, q, tip, ref, theta0, target, lo, hi, seeds, iterations, damping, tolerance, out, err_out):
    N, n = theta0.shape
    R = seeds.shape[0] + 1
    p = np.empty(3)
    J = np.empty((3, n))
    A = np.empty((3, 3))
    e = np.empty(3)
    y = np.empty(3)
    th = np.empty(n)
    R3, Ri, RR, t = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)), np.empty(3)
    axes, pts = np.empty((n, 3)), np.empty((n, 3))
    lam2 = damping * damping
    for k in range(N):
        best_score = np.inf
        for r in range(R):
            for i in range(n):
                th[i] = theta0[k, i] if r == 0 else seeds[r - 1, i]
            steps = iterations
            if r == 0:  # a start already at the target keeps its joints (a move of zero)
                _fk_jac(w, q, tip, ref, th, p, J, R3, Ri, RR, t, axes, pts)
                if _distance(target[k], p) <= tolerance:
                    steps = 0
            for _ in range(steps):
                _fk_jac(w, q, tip, ref, th, p, J, R3, Ri, RR, t, axes, pts)
                for a in range(3):
                    e[a] = target[k, a] - p[a]
                    for b in range(3):
                        s = 0.0
                        for i in range(n):
                            s += J[a, i] * J[b, i]
                        A[a, b] = s + (lam2 if a == b else 0.0)
                _solve3(A, e, y)
                moved = 0.0
                for i in range(n):
                    v = min(max(th[i] + J[0, i] * y[0] + J[1, i] * y[1] + J[2, i] * y[2], lo[i]), hi[i])
                    moved = max(moved, abs(v - th[i]))
                    th[i] = v
                if moved < 1e-13:  # a fixed point: further steps change nothing
                    break
            _fk_jac(w, q, tip, ref, th, p, J, R3, Ri, RR, t, axes, pts)
            err = _distance(target[k], p)
            if err <= tolerance:
                d = 0.0
                for i in range(n):
                    d += (th[i] - theta0[k, i]) ** 2
                score = np.sqrt(d)
            else:
                score = 1e6 + err
            if score < best_score:
                best_score = score
                err_out[k] = err
                for i in range(n):
                    out[k, i] = th[i]
            if r == 0 and err <= tolerance:  # the solution reached from the start itself is kept
                break


@numba.njit(cache=True, fastmath=False)
def _positions(w, q, tip, ref, theta, out):
    n = w.shape[0]
    p, J = np.empty(3), np.empty((3, n))
    R, Ri, RR, t = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)), np.empty(3)
    axes, pts = np.empty((n, 3)), np.empty((n, 3))
    for k in range(theta.shape[0]):
        _fk_jac(w, q, tip, ref, theta[k], p, J, R, Ri, RR, t, axes, pts)
        out[k] = p


def chain_positions(
    w: np.ndarray, q: np.ndarray, tip: np.ndarray, ref: np.ndarray, theta: np.ndarray
) -> np.ndarray:
    """The chain's end-effector positions ``(N, 3)`` at float64 joints ``theta (N, n)`` (the arrays of
    :meth:`~kinlearn.models.chain.ChainFM.kernel_arrays`): the rigid chain's FK, compiled."""
    theta = np.ascontiguousarray(theta, dtype=np.float64)
    out = np.empty((theta.shape[0], 3))
    _positions(w, q, tip, ref, theta, out)
    return out


def solve_position_numba(
    w: np.ndarray,
    q: np.ndarray,
    tip: np.ndarray,
    ref: np.ndarray,
    theta0: np.ndarray,
    target: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    seeds: np.ndarray,
    *,
    iterations: int,
    damping: float,
    tolerance: float,
) -> tuple[np.ndarray, np.ndarray]:
    """The compiled :func:`~kinlearn.models.chain.solve_position` (float64 arrays; ``seeds``: the restart
    configurations ``(R − 1, n)``, already scaled to the limits). Returns joints ``(N, n)`` and errors."""
    w, q, tip, ref, theta0, target, lower, upper, seeds = _float64(
        w, q, tip, ref, theta0, target, lower, upper, seeds
    )
    out = np.empty_like(theta0)
    err = np.empty(theta0.shape[0])
    _solve(
        w,
        q,
        tip,
        ref,
        theta0,
        target,
        lower,
        upper,
        seeds.reshape(-1, theta0.shape[1]),
        int(iterations),
        float(damping),
        float(tolerance),
        out,
        err,
    )
    return out, err


@numba.njit(cache=True, fastmath=False)
def _solve_chains(w, q, tip, ref, theta0, targets, lo, hi, seeds, iterations, damping, tolerance, out):
    """:func:`_solve` through ``targets (N, L, 3)`` in turn, each target's from the joints of the one before
    (the first's from ``theta0``), into ``out (N, L, n)``."""
    N, L = targets.shape[0], targets.shape[1]
    start, nxt = theta0.copy(), np.empty_like(theta0)
    target, err = np.empty((N, 3)), np.empty(N)
    for k in range(L):
        for m in range(N):
            for a in range(3):
                target[m, a] = targets[m, k, a]
        _solve(w, q, tip, ref, start, target, lo, hi, seeds, iterations, damping, tolerance, nxt, err)
        out[:, k] = nxt
        start, nxt = nxt, start


@numba.njit(cache=True, fastmath=False)
def _solve_spd(A, b, x):
    """x ← A⁻¹ b for a small symmetric positive-definite A (Cholesky; A is overwritten)."""
    m = A.shape[0]
    for j in range(m):
        s = A[j, j]
        for k in range(j):
            s -= A[j, k] * A[j, k]
        A[j, j] = np.sqrt(s)
        for i in range(j + 1, m):
            s = A[i, j]
            for k in range(j):
                s -= A[i, k] * A[j, k]
            A[i, j] = s / A[j, j]
    for i in range(m):  # forward: L y = b
        s = b[i]
        for k in range(i):
            s -= A[i, k] * x[k]
        x[i] = s / A[i, i]
    for i in range(m - 1, -1, -1):  # back: Lᵀ x = y
        s = x[i]
        for k in range(i + 1, m):
            s -= A[k, i] * x[k]
        x[i] = s / A[i, i]


@numba.njit(cache=True, fastmath=False)
def _moves_keeping(w, q, tip, ref, theta0, targets, lo, hi, iterations, damping, weight, out):
    N, n = theta0.shape
    L = targets.shape[1]
    p, J = np.empty(3), np.empty((3, n))
    R3, Ri, RR, t = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)), np.empty(3)
    axes, pts = np.empty((n, 3)), np.empty((n, 3))
    R0 = np.empty((3, 3))
    Jf = np.empty((6, n))
    A = np.empty((6, 6))
    e, y = np.empty(6), np.empty(6)
    th = np.empty(n)
    lam2 = damping * damping
    for k in range(N):
        for i in range(n):
            th[i] = theta0[k, i]
        _fk_jac(w, q, tip, ref, th, p, J, R3, Ri, RR, t, axes, pts)
        for a in range(3):
            for b in range(3):
                R0[a, b] = R3[a, b]
        for m in range(L):  # each target from the joints of the one before (continuation)
            for _ in range(iterations):
                _fk_jac(w, q, tip, ref, th, p, J, R3, Ri, RR, t, axes, pts)
                # E = R0 R3ᵀ, the rotation still to make; its axis times sin(angle) from its skew part
                for a in range(3):
                    for b in range(3):
                        RR[a, b] = R0[a, 0] * R3[b, 0] + R0[a, 1] * R3[b, 1] + R0[a, 2] * R3[b, 2]
                for a in range(3):
                    e[a] = targets[k, m, a] - p[a]
                e[3] = weight * 0.5 * (RR[2, 1] - RR[1, 2])
                e[4] = weight * 0.5 * (RR[0, 2] - RR[2, 0])
                e[5] = weight * 0.5 * (RR[1, 0] - RR[0, 1])
                for i in range(n):
                    for a in range(3):
                        Jf[a, i] = J[a, i]
                        Jf[3 + a, i] = weight * axes[i, a]
                for a in range(6):
                    for b in range(a + 1):
                        s = 0.0
                        for i in range(n):
                            s += Jf[a, i] * Jf[b, i]
                        A[a, b] = s + (lam2 if a == b else 0.0)
                        A[b, a] = A[a, b]
                _solve_spd(A, e, y)
                moved = 0.0
                for i in range(n):
                    s = 0.0
                    for a in range(6):
                        s += Jf[a, i] * y[a]
                    v = min(max(th[i] + s, lo[i]), hi[i])
                    moved = max(moved, abs(v - th[i]))
                    th[i] = v
                if moved < 1e-13:
                    break
            for i in range(n):
                out[k, m, i] = th[i]


@numba.njit(cache=True, fastmath=False)
def _retreats(w, q, tip, ref, theta0, targets, lo, hi, iterations, damping, tolerance, weight, out):
    """Both kinds of :func:`chain_retreats` into ``out (2, N, L, n)``."""
    _solve_chains(
        w, q, tip, ref, theta0, targets, lo, hi, np.zeros((0, theta0.shape[1])), iterations, damping, tolerance,
        out[0],
    )  # fmt: skip
    _moves_keeping(w, q, tip, ref, theta0, targets, lo, hi, iterations, damping, weight, out[1])


def chain_retreats(
    w: np.ndarray,
    q: np.ndarray,
    tip: np.ndarray,
    ref: np.ndarray,
    theta0: np.ndarray,
    targets: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    *,
    iterations: int,
    damping: float,
    tolerance: float,
    weight: float,
) -> np.ndarray:
    """Joints ``(2, N, L, n)`` that move the chain's end effector from joints ``theta0 (N, n)`` through
    ``targets (N, L, 3)`` in turn, each target's from the joints of the one before (a continuation), in one
    compiled call, two ways (the retreat stage's two kinds of hand):

    0. the hand free to turn: per target :func:`solve_position_numba` without restarts (``iterations``
       projected damped least-squares steps on the position alone, stopping within ``tolerance``);
    1. the hand's orientation at ``theta0`` kept: ``iterations`` projected damped least-squares steps per
       target on the position error and the orientation error (times ``weight``, metres per radian). The
       orientation error is the axis of the rotation still to make times the sine of its angle (the
       skew part of R₀Rᵀ: exact for small turns, which is all the steps see)."""
    w, q, tip, ref, theta0, targets, lower, upper = _float64(w, q, tip, ref, theta0, targets, lower, upper)
    out = np.empty((2, theta0.shape[0], targets.shape[1], theta0.shape[1]))
    _retreats(
        w, q, tip, ref, theta0, targets, lower, upper, int(iterations), float(damping), float(tolerance),
        float(weight), out,
    )  # fmt: skip
    return out


def _float64(*arrays) -> tuple[np.ndarray, ...]:
    """Each array as a C-contiguous float64 array (the kernels' arguments)."""
    return tuple(np.ascontiguousarray(a, dtype=np.float64) for a in arrays)
