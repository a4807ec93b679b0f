"""The obstacle network's proposals for one problem, compiled (numba): the batch-1 twin of
:meth:`~kinlearn.models.obstacle_path.ObstaclePathModel.forward` and of the candidates the planner
builds from it.

torch (:class:`~kinlearn.models.obstacle_path.ObstaclePathModel`) is the implementation for training and
large batches; a plan among obstacles runs the network on one problem at a time (a plan must not depend
on its batch-mates), where each of the few dozen array operations of an eager forward pass costs
microseconds of dispatch. This module is the one compiled twin, held to torch by a contract test
(``tests/test_proposals.py``): one call runs the scene encoder on every primitive, pools it, runs the
trunk for the problem and for the problem the other way round, turns both into knots and assembles
every candidate path the planner checks — the straight joint line first, the network's paths, the
reversed problem's paths walked backwards, each clipped to the problem's joint box, segments halved when
refining — with each path's joint-space length and the order of the candidates, shortest first.
A plan's stage 1 is one call, :meth:`CompiledObstacleModel.first_free`: the straight line checked
first (:func:`~kinlearn.collision.kernel.first_free_boxed`), and only where it collides the network and
its candidates' check, with no Python between them. The network's arithmetic is float32 as torch's (its
products through BLAS, ``np.dot``), the knots float64. Compiled, the proposals cost a fraction of the
same arithmetic as NumPy operations; most of what is left is reading the trunk's weights (about 1.4 MB).

numba is imported with this module, which the planner imports on its first plan among obstacles
(:mod:`kinlearn.collision.kernel` is imported there too); ``cache=True`` keeps the machine code on disk.
"""

from __future__ import annotations

import math

import numpy as np

from ..body.jit import jit
from ..collision.kernel import checked_tips, first_free_boxed
from ..errors import NonFiniteError
from ..models.obstacle_path import ObstaclePathModel
from .inference import _arr, mlp, packed_mlp

__all__ = ["CompiledObstacleModel"]

_jit = jit()  # stamped with the kernels it calls: their edits recompile it (kinlearn.body.jit)


@_jit
def _put(row, o, v):
    """``v`` into ``row`` from column ``o``; the column after it."""
    for j in range(v.shape[0]):
        row[o + j] = v[j]
    return o + v.shape[0]


@_jit
def _coefficients(a0, e0, aT, eT, rows, floor, columns, enc, enc_widths, trunk, trunk_widths, silu, emb_size):
    """The network's coefficients ``(2, C · modes · dof)`` float64 for the problem (row 0) and the problem
    the other way round (row 1): ``a0, aT (dof,)`` joints, ``e0, eT (3,)`` their end-effector positions,
    ``rows (P, ≥ columns)`` the scene's primitive rows, ``floor (2,)``."""
    P, dof = rows.shape[0], a0.shape[0]
    emb = np.zeros((2, emb_size), dtype=np.float32)
    if P:
        p = np.empty((2 * P, columns + 6), dtype=np.float32)
        for r in range(2):
            f, t = (e0, eT) if r == 0 else (eT, e0)
            for i in range(P):
                o = r * P + i
                for j in range(columns):
                    p[o, j] = rows[i, j]
                for j in range(3):
                    p[o, columns + j] = rows[i, j] - f[j]
                    p[o, columns + 3 + j] = rows[i, j] - t[j]
        h = mlp(p, enc, enc_widths, silu, True)
        for r in range(2):
            for j in range(emb_size):
                m = h[r * P, j]
                for i in range(1, P):
                    m = max(m, h[r * P + i, j])
                emb[r, j] = m
    x = np.empty((2, trunk_widths[0]), dtype=np.float32)  # θ0, ef0, θT, efT, θT − θ0, floor, scene
    for r in range(2):
        s, t = (a0, aT) if r == 0 else (aT, a0)
        es, et = (e0, eT) if r == 0 else (eT, e0)
        o = _put(x[r], 0, s)
        o = _put(x[r], o, es)
        o = _put(x[r], o, t)
        o = _put(x[r], o, et)
        for j in range(dof):
            x[r, o + j] = t[j] - s[j]
        o += dof
        x[r, o], x[r, o + 1] = floor[0], floor[1]
        o += 2
        for j in range(emb_size):
            x[r, o + j] = emb[r, j]
    return mlp(x, trunk, trunk_widths, silu, False).astype(np.float64)


@_jit
def _knots(s, t, coef, fractions, basis, half_range, out):
    """One direction's candidates' inner knots into ``out (C, T − 1, dof)``: the straight joint line from
    ``s`` to ``t`` at ``fractions (T − 1,)`` plus ``half_range`` times the basis ``(T − 1, modes)`` times
    each candidate's coefficients (``coef`` flat, ``(C, modes, dof)`` in order)."""
    C, inner, dof = out.shape
    modes = basis.shape[1]
    for c in range(C):
        for k in range(inner):
            for j in range(dof):
                v = 0.0
                for m in range(modes):
                    v += basis[k, m] * coef[(c * modes + m) * dof + j]
                out[c, k, j] = s[j] + fractions[k] * (t[j] - s[j]) + half_range[j] * v


@_jit
def _line_into(a0, aT, fractions, halve, path):
    """The straight joint line from ``a0`` to ``aT`` into ``path (K, dof)``: its knots at ``fractions``,
    each segment halved when ``halve`` (candidate 0 of :func:`_assemble`)."""
    K, dof = path.shape
    step = 2 if halve else 1
    for j in range(dof):
        path[0, j] = a0[j]
        path[K - 1, j] = aT[j]
    for k in range(fractions.shape[0]):
        for j in range(dof):
            path[step * (k + 1), j] = a0[j] + fractions[k] * (aT[j] - a0[j])
    if halve:
        for k in range(fractions.shape[0] + 1):
            for j in range(dof):
                path[2 * k + 1, j] = 0.5 * (path[2 * k, j] + path[2 * k + 2, j])


@_jit
def _assemble(a0, aT, ahead, back, fractions, lo, hi, halve, paths, length):
    """Every candidate path into ``paths (2C + 1, K, dof)``: the straight line, ``ahead (C, T − 1, dof)``,
    then ``back`` walked backwards, the network's knots clipped to ``[lo, hi]``, each segment halved when
    ``halve``; each path's joint-space length into ``length``."""
    n_paths, K, dof = paths.shape
    C, inner = ahead.shape[0], ahead.shape[1]
    T = inner + 1
    step = 2 if halve else 1
    _line_into(a0, aT, fractions, halve, paths[0])
    for c in range(1, n_paths):
        for j in range(dof):
            paths[c, 0, j] = a0[j]
            paths[c, K - 1, j] = aT[j]
        for k in range(inner):
            for j in range(dof):
                v = ahead[c - 1, k, j] if c <= C else back[c - 1 - C, inner - 1 - k, j]
                paths[c, step * (k + 1), j] = min(max(v, lo[j]), hi[j])
        if halve:
            for k in range(T):
                for j in range(dof):
                    paths[c, 2 * k + 1, j] = 0.5 * (paths[c, 2 * k, j] + paths[c, 2 * k + 2, j])
    for c in range(n_paths):
        total = 0.0
        for k in range(K - 1):
            ss = 0.0
            for j in range(dof):
                d = paths[c, k + 1, j] - paths[c, k, j]
                ss += d * d
            total += math.sqrt(ss)
        length[c] = total


@_jit
def _proposals(
    a0, e0, aT, eT, rows, floor, lo, hi, halve, columns, enc, enc_widths, trunk, trunk_widths, silu,
    emb_size, fractions, basis, half_range, paths,
):  # fmt: skip
    """The whole of :meth:`CompiledObstacleModel.proposals` but the argument checks: the candidates into
    ``paths`` and their order, shortest first (a stable sort: the line leads among equals)."""
    C, inner, dof = (paths.shape[0] - 1) // 2, fractions.shape[0], a0.shape[0]
    coef = _coefficients(
        a0, e0, aT, eT, rows, floor, columns, enc, enc_widths, trunk, trunk_widths, silu, emb_size
    )
    ahead, back = np.empty((C, inner, dof)), np.empty((C, inner, dof))
    _knots(a0, aT, coef[0], fractions, basis, half_range, ahead)
    _knots(aT, a0, coef[1], fractions, basis, half_range, back)
    length = np.empty(paths.shape[0])
    _assemble(a0, aT, ahead, back, fractions, lo, hi, halve, paths, length)
    return np.argsort(length, kind="mergesort")


@_jit
def _first_free_proposal(
    a0, e0, aT, eT, rows, floor, lo, hi, halve, columns, enc, enc_widths, trunk, trunk_widths, silu,
    emb_size, fractions, basis, half_range, paths, order, max_travel, margin, box_lo, box_hi, f_in, n_in,
    f_all, n_all, s,
):  # fmt: skip
    """The whole of :meth:`CompiledObstacleModel.first_free` but the argument checks: the straight joint
    line into ``paths[0]`` and its check; where it collides, every candidate (:func:`_proposals`) and the
    first free one in their order; where it is free, no network and every candidate a copy of the line.
    The index picked, −1 if none is free, −2 if a path holds NaN or infinity."""
    n_paths = paths.shape[0]
    _line_into(a0, aT, fractions, halve, paths[0])
    first = np.zeros(1, dtype=np.int64)
    k = first_free_boxed(paths[0:1], first, max_travel, margin, box_lo, box_hi, f_in, n_in, f_all, n_all, s)
    if k != -1:  # free (0), or not finite (−2): the line is the answer either way
        for c in range(n_paths):
            order[c] = c
            if c > 0:
                paths[c] = paths[0]
        return k
    order[:] = _proposals(
        a0, e0, aT, eT, rows, floor, lo, hi, halve, columns, enc, enc_widths, trunk, trunk_widths, silu,
        emb_size, fractions, basis, half_range, paths,
    )  # fmt: skip
    rest = np.empty(n_paths - 1, dtype=np.int64)
    r = 0
    for c in range(n_paths):
        if order[c] != 0:
            rest[r] = order[c]
            r += 1
    return first_free_boxed(paths, rest[:r], max_travel, margin, box_lo, box_hi, f_in, n_in, f_all, n_all, s)


@_jit
def _stage_one(
    q, F, prismatic, lower, upper, limit_tol, zero_move, body_lo, body_hi, ef, rows, floor, halve, columns,
    enc, enc_widths, trunk, trunk_widths, silu, emb_size, fractions, basis, half_range, paths, order, max_travel,
    margin, box_lo, box_hi, f_in, n_in, f_all, n_all, s,
):  # fmt: skip
    """A batch-1 plan's stage 1 from its start and goal joints ``q (2, dof)``, in one call (:meth:`CompiledObstacleModel.stage_one`):
    their end effectors into ``ef (2, 3)`` (:func:`~kinlearn.collision.kernel.checked_tips`); −3 where
    either is outside the limits widened by ``limit_tol`` (or not finite) or no joint moves more than
    ``zero_move``; else the problem's joint box (``body_lo``/``body_hi`` where both ends lie within them,
    else ``lower``/``upper``: :meth:`~kinlearn.collision.BodySpheres.joint_box`'s rule) and
    :func:`_first_free_proposal`'s answer."""
    ok = np.empty(2, dtype=np.bool_)
    tips = checked_tips(q, F, prismatic, lower, upper, limit_tol, ok)
    moved = 0.0
    for j in range(q.shape[1]):
        moved = max(moved, abs(q[1, j] - q[0, j]))
    if not (ok[0] and ok[1]) or moved <= zero_move:
        return -3
    ef[:] = tips
    inside = True
    for j in range(q.shape[1]):
        if not (min(q[0, j], q[1, j]) >= body_lo[j] and max(q[0, j], q[1, j]) <= body_hi[j]):
            inside = False
    lo, hi = (body_lo, body_hi) if inside else (lower, upper)
    return _first_free_proposal(
        q[0], ef[0], q[1], ef[1], rows, floor, lo, hi, halve, columns, enc, enc_widths, trunk, trunk_widths, silu,
        emb_size, fractions, basis, half_range, paths, order, max_travel, margin, box_lo, box_hi, f_in, n_in,
        f_all, n_all, s,
    )  # fmt: skip


@_jit
def _forward(a0, e0, aT, eT, rows, floor, columns, enc, enc_widths, trunk, trunk_widths, silu, emb_size, fractions,
             basis, half_range, out):  # fmt: skip
    """One problem's candidates' knots into ``out (C, T − 1, dof)`` (:meth:`CompiledObstacleModel.__call__`)."""
    coef = _coefficients(
        a0, e0, aT, eT, rows, floor, columns, enc, enc_widths, trunk, trunk_widths, silu, emb_size
    )
    _knots(a0, aT, coef[0], fractions, basis, half_range, out)


def _finite(k: int) -> int:
    """The index a compiled stage 1 picked (−1: none free); :class:`NonFiniteError` for its −2."""
    if k == -2:
        raise NonFiniteError(
            "a candidate path holds NaN or infinity (the problem's joints or the network's output)"
        )
    return int(k)


class CompiledObstacleModel:
    """An obstacle-aware TM packed for the compiled proposals (float32 weights with the input
    standardisation folded in, float64 knot constants), made once per planner."""

    def __init__(self, tm: ObstaclePathModel):
        self.silu = tm.config.activation == "silu"
        in_scale, prim_scale = tm.input_scales  # a feature that never varied in training held at its mean
        self.enc, self.enc_widths = packed_mlp(tm.encoder, tm.prim_mean, prim_scale)
        # Only the problem features are standardised; the pooled scene embedding follows them.
        self.trunk, self.trunk_widths = packed_mlp(tm.trunk, tm.in_mean, in_scale, rows=tm.n_problem_features)
        c = tm.config
        self.C, self.modes, self.dof = c.candidates, c.modes, c.dof
        self.half_range = np.ascontiguousarray(_arr(tm.half_range).reshape(-1))
        self.fractions = _arr(tm.fractions).reshape(-1)
        self.basis = np.ascontiguousarray(_arr(tm.basis))
        self.emb = c.encoder[-1]
        self.columns = tm.row_columns

    def candidates_shape(self, halve: bool) -> tuple[int, int, int]:
        """The shape ``(2C + 1, K, dof)`` of one problem's candidates: K = T + 1 knots, 2T + 1 when
        ``halve``."""
        T = self.fractions.shape[0] + 1
        return 2 * self.C + 1, 2 * T + 1 if halve else T + 1, self.dof

    def proposals(
        self, theta0, ef0, thetaT, efT, rows, floor, lo, hi, halve: bool
    ) -> tuple[np.ndarray, np.ndarray]:
        """One problem's candidate paths ``(2C + 1, K, dof)`` and their order, shortest first: the straight
        joint line, the network's C paths, and its C paths for the problem the other way round walked
        backwards (the network learned both directions), the network's knots clipped to the joint box
        ``[lo, hi]``; K = T + 1 knots, 2T + 1 when ``halve`` (each segment split in two: the knots a
        refined path is optimised on). ``theta0, thetaT, lo, hi (dof,)``, ``ef0, efT (3,)`` float64;
        ``rows (P, ≥ 14)`` the scene's primitive rows and ``floor (2,)``
        (:meth:`~kinlearn.collision.kernel.KernelScene.model_rows`)."""
        paths = np.empty(self.candidates_shape(halve))
        order = _proposals(
            theta0, ef0, thetaT, efT, rows, floor, lo, hi, bool(halve), self.columns, self.enc, self.enc_widths,
            self.trunk, self.trunk_widths, self.silu, self.emb, self.fractions, self.basis, self.half_range, paths,
        )  # fmt: skip
        return paths, order

    def first_free(
        self, theta0, ef0, thetaT, efT, lo, hi, halve: bool, body, scene, max_travel: float
    ) -> tuple[np.ndarray, np.ndarray, int]:
        """One problem's first collision-free candidate, in one compiled call: the straight joint line
        checked first, and only where it collides the network run (:meth:`proposals`, the same candidates
        and order) and its candidates checked in their order (:func:`~kinlearn.collision.kernel.first_free`'s
        verdicts). ``body``: a :class:`~kinlearn.collision.kernel.KernelBody`, ``scene`` a
        :class:`~kinlearn.collision.kernel.KernelScene` (its rows feed the network); the other arguments as
        :meth:`proposals`'s; the network reads the scene's primitives within the body's reach
        (:meth:`~kinlearn.collision.kernel.KernelScene.model_rows`: one the robot cannot touch is no part
        of its problem, and none of its training scenes held one). Returns the candidates ``(2C + 1, K, dof)`` (copies of the line where it is
        free), their order and the index of the first free one (−1: none is). Raises
        :class:`~kinlearn.errors.NonFiniteError` if a candidate holds NaN or infinity."""
        paths = np.empty(self.candidates_shape(halve))
        order = np.empty(paths.shape[0], dtype=np.int64)
        k = _first_free_proposal(
            theta0, ef0, thetaT, efT, scene.model_rows(body.reach), scene.floor, lo, hi, bool(halve), self.columns,
            self.enc, self.enc_widths, self.trunk, self.trunk_widths, self.silu, self.emb, self.fractions,
            self.basis, self.half_range, paths, order, float(max_travel), 0.0, *body.boxed, scene.packed,
        )  # fmt: skip
        return paths, order, _finite(k)

    def stage_one(
        self,
        q,
        chain,
        body_limits,
        halve: bool,
        body,
        scene,
        max_travel: float,
        limit_tol: float,
        zero_move: float,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
        """A batch-1 plan's stage 1 in one compiled call, from its start and goal joints ``q (2, dof)``
        (float64, C-contiguous): the ends' FK and limits (``chain``: a
        :class:`~kinlearn.collision.kernel.KernelChain`; ``limit_tol``), the problem's joint box
        (``body_limits``: the planning body's :attr:`~kinlearn.collision.BodySpheres.limits`), then
        :meth:`first_free`. Returns the ends' end effectors ``(2, 3)``, the candidates ``(2C + 1, K, dof)``,
        the one picked ``(1,)`` (the first free in their order, else the shortest) and whether it is free
        ``(1,)`` (:meth:`~kinlearn.planning.around.ObstacleStages._learned`'s answer for the problem), or
        None where an end is outside the limits or not finite or no joint moves more than ``zero_move``
        (for the caller's general path to explain). Raises :class:`NonFiniteError` as
        :meth:`first_free` does."""
        paths = np.empty(self.candidates_shape(halve))
        order = np.empty(paths.shape[0], dtype=np.int64)
        ef = np.empty((2, 3))
        k = _stage_one(
            q, chain.F, chain.prismatic, chain.lower, chain.upper, float(limit_tol), float(zero_move),
            *body_limits, ef, scene.model_rows(body.reach), scene.floor, bool(halve), self.columns, self.enc,
            self.enc_widths, self.trunk, self.trunk_widths, self.silu, self.emb, self.fractions, self.basis,
            self.half_range, paths, order, float(max_travel), 0.0, *body.boxed, scene.packed,
        )  # fmt: skip
        if k == -3:
            return None
        k = _finite(k)
        pick, free = np.empty(1, dtype=np.int64), np.empty(1, dtype=np.bool_)
        pick[0], free[0] = k if k >= 0 else order[0], k >= 0
        return ef, paths, pick, free

    def __call__(self, theta0, ef0, thetaT, efT, rows, mask, floor) -> np.ndarray:
        """The network's forward pass on a batch (:meth:`ObstaclePathModel.forward`, unclipped):
        ``theta0, thetaT (N, dof)``, ``ef0, efT (N, 3)``, ``rows (N, P, 14)``, ``mask (N, P)``,
        ``floor (N, 2)`` (as :func:`~kinlearn.models.obstacle_path.scene_primitives`)
        → every candidate's inner knots ``(N, C, T − 1, dof)``."""
        f64 = lambda a: np.ascontiguousarray(a, dtype=np.float64)  # noqa: E731
        theta0, ef0, thetaT, efT, rows, floor = map(f64, (theta0, ef0, thetaT, efT, rows, floor))
        mask = np.asarray(mask, dtype=bool)
        out = np.empty((theta0.shape[0], self.C, self.fractions.shape[0], self.dof))
        for i in range(theta0.shape[0]):
            _forward(
                theta0[i], ef0[i], thetaT[i], efT[i], np.ascontiguousarray(rows[i][mask[i]]), floor[i],
                self.columns, self.enc, self.enc_widths, self.trunk, self.trunk_widths, self.silu, self.emb,
                self.fractions, self.basis, self.half_range, out[i],
            )  # fmt: skip
        return out
