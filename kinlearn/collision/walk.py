"""The dense check's walk along a path (compiled): the configurations :func:`~kinlearn.collision.check_path`
checks, each sphere's clearance and each self-collision pair's distance spent as a budget along the path,
so that only the configurations where some budget may run out are evaluated (:func:`_verdict`), or every
one (:func:`_check`, for the clearance). The module docstring of :mod:`kinlearn.collision.kernel` says
why the verdict is that of checking every sub-step."""

from __future__ import annotations

import math

import numpy as np

from ..body.fk import _chain, _fk, _place
from ..body.jit import jit
from .kernel_body import _unpack_body
from .kinds import sphere_scene, spheres_scene, unpack

__all__: list[str] = []

#: Metres of slack in the skipping bound (the float64 error of a distance is ~1e-15 m).
_SLACK = 1e-9
#: Share of its budget's span after which an item is recomputed at a configuration evaluated anyway.
_REFRESH = 0.5
#: From this many spheres due at a configuration, the walk computes every sphere's distance at once
#: (:func:`~kinlearn.collision.kinds.spheres_scene`), else those due one by one.
_VECTOR_MIN = 8
_TINY = float(np.finfo(np.float64).tiny)


@jit(inline="always")
def _gap(p, a, ra, q, b, rb):
    """The distance between two spheres, of centres ``p[a]`` and ``q[b]`` and radii ``ra`` and ``rb`` (the
    centres' distance never below √tiny, as torch's self-collision distance takes it)."""
    dx, dy, dz = p[a, 0] - q[b, 0], p[a, 1] - q[b, 1], p[a, 2] - q[b, 2]
    return math.sqrt(max(dx * dx + dy * dy + dz * dz, _TINY)) - ra - rb


@jit
def _evaluate(
    q, F, prismatic, link, folded, radii, on_floor, pairs, tables, floor, c, dm, dp, frames, xyz
):  # fmt: skip
    """FK and every distance at ``q``: fills ``c (M, 3)``, ``dm (M,)`` (per sphere, to the scene) and
    ``dp (P,)`` (per self-collision pair); returns (scene clearance, self clearance). ``frames``, ``xyz``:
    work space."""
    _fk(q, F, prismatic, link, folded, c, frames)
    spheres_scene(c, radii, on_floor, tables, floor, xyz, dm)
    d = np.inf
    for m in range(link.shape[0]):
        d = min(d, dm[m])
    s = np.inf
    for p in range(pairs.shape[0]):
        a, b = pairs[p, 0], pairs[p, 1]
        dp[p] = _gap(c, a, radii[a], c, b, radii[b])
        s = min(s, dp[p])
    return d, s


@jit
def _clearances(qs, F, prismatic, link, folded, radii, on_floor, pairs, tables, floor, per):
    """Configurations ``qs (N, dof)`` → scene and self clearances ``(N,)`` each; ``per (N, M)`` filled with
    each sphere's distance to the scene."""
    n, M = qs.shape[0], link.shape[0]
    d, s = np.empty(n), np.empty(n)
    c, dp, frames = np.empty((M, 3)), np.empty(pairs.shape[0]), np.empty((qs.shape[1] + 1, 3, 4))
    xyz = np.empty((3, M))
    for i in range(n):
        d[i], s[i] = _evaluate(
            qs[i], F, prismatic, link, folded, radii, on_floor, pairs, tables, floor, c, per[i], dp,
            frames, xyz,
        )  # fmt: skip
    return d, s


@jit
def _check(
    path, max_travel, margin, exact, F, prismatic, link, folded, radii, on_floor, pairs, lever,
    tables, floor,
):  # fmt: skip
    """One path ``(W, dof)``: (first colliding segment or −1, scene clearance, self clearance, configurations
    evaluated). ``exact``: evaluate every sub-step (the clearance is then check_path's); else stop at the
    first collision and skip the sub-steps that provably cannot collide (see the module docstring)."""
    W, dof = path.shape
    M, P = link.shape[0], pairs.shape[0]
    c, dm, dp = np.empty((M, 3)), np.empty(M), np.empty(P)
    frames, xyz = np.empty((dof + 1, 3, 4)), np.empty((3, M))
    travel = np.empty(M)
    q = np.empty(dof)
    first = -1
    clear, self_clear = np.inf, np.inf
    evaluated = 0
    for k in range(W):
        if k < W - 1:
            bound = 0.0
            for m in range(M):
                t = 0.0
                for j in range(dof):
                    t += abs(path[k + 1, j] - path[k, j]) * lever[m, j]
                travel[m] = t
                bound = max(bound, t)
            n = max(1.0, math.ceil(bound / max_travel))
        else:  # the last knot alone
            n = 1.0
        i = 0.0
        while i < n:
            frac = i / n
            for j in range(dof):
                q[j] = path[k, j] + frac * (path[k + 1, j] - path[k, j]) if k < W - 1 else path[k, j]
            d, s = _evaluate(
                q, F, prismatic, link, folded, radii, on_floor, pairs, tables, floor, c, dm, dp,
                frames, xyz,
            )  # fmt: skip
            evaluated += 1
            clear, self_clear = min(clear, d), min(self_clear, s)
            if d <= margin or s <= 0.0:
                if first < 0:
                    first = k
                if not exact:
                    return first, clear, self_clear, evaluated
                i += 1.0
                continue
            if exact or k == W - 1:
                i += 1.0
                continue
            skip = np.inf
            for m in range(M):
                if travel[m] > 0.0:
                    skip = min(skip, (dm[m] - margin - _SLACK) * n / travel[m])
            for p in range(P):
                t = travel[pairs[p, 0]] + travel[pairs[p, 1]]
                if t > 0.0:
                    skip = min(skip, (dp[p] - _SLACK) * n / t)
            i += 1.0 + max(math.floor(skip), 0.0) if skip < n else n
    return first, clear, self_clear, evaluated


@jit(inline="always")
def _segment_steps(path, k, max_travel, lever):
    """Segment k's number of sub-steps, n_k = max(1, ⌈L_k / max_travel⌉), L_k the largest lever bound
    Σ_j |Δθ_j| lever_mj over the spheres."""
    M, dof = lever.shape
    bound = 0.0
    for m in range(M):
        t = 0.0
        for j in range(dof):
            t += abs(path[k + 1, j] - path[k, j]) * lever[m, j]
        bound = max(bound, t)
    return max(1.0, math.ceil(bound / max_travel))


@jit
def _grid_steps(path, max_travel, lever, steps):
    """Fill ``steps (W − 1,)`` with each segment's number of sub-steps (:func:`_segment_steps`)."""
    for k in range(path.shape[0] - 1):
        steps[k] = _segment_steps(path, k, max_travel, lever)


@jit(inline="always")
def _steps_at(steps, path, k, max_travel, lever):
    """Segment k's sub-steps from ``steps``, counted there on first use (0: not yet). A probe that hits at
    a hint or a knot, as most candidates' probes do, counts no segment or one, not every one."""
    if steps[k] == 0.0:
        steps[k] = _segment_steps(path, k, max_travel, lever)
    return steps[k]


@jit(inline="always")
def _stale(due, since, pos):
    """Whether an item of the walk is recomputed at global sub-step ``pos``: its budget is spent (``due``),
    or more than :data:`_REFRESH` of its span from ``since`` (where it was last computed) has passed."""
    return due <= pos or pos - since >= _REFRESH * (due - since)


@jit(inline="always")
def _expiry_lever(b, k, i, absd, left, lever, row, steps, offset):
    """The global sub-step index at which an item with ``b`` metres of budget at sub-step ``i`` of segment
    ``k`` must be looked at again: where its travel bound may have used the budget up (+inf if it lasts
    to the path's end). Its bound on segment k is Σ_j |Δθ_kj| · ``lever[row, j]``, spread evenly over the
    segment's sub-steps; ``left[k, j]``: joint j's travel from segment k on (the whole bound, to see at
    once that it lasts)."""
    dof = absd.shape[1]
    total = 0.0
    for j in range(dof):
        total += left[k, j] * lever[row, j]
    if b > total:
        return np.inf
    T = steps.shape[0] if absd.shape[0] else 0
    while k < T:
        rate = 0.0
        for j in range(dof):
            rate += absd[k, j] * lever[row, j]
        if rate > 0.0:
            per = rate / steps[k]
            rest = steps[k] - i
            if b < rest * per:
                return offset[k] + i + max(1.0, math.floor(b / per))
            b -= rest * per
        k += 1
        i = 0.0
    return np.inf


@jit
def _verdict(path, max_travel, margin, body, scene, scene_clear=False):
    """One path ``(W, dof)``: (first colliding segment or −1, configurations evaluated, the colliding
    configuration's fraction of that segment (a sub-step of the grid), whether that hit is the body against
    itself rather than the scene or the floor), the verdict of checking every sub-step. Each sphere's
    clearance and each pair's distance, once computed, is a budget that the spheres' travel bounds use up
    along the path; a configuration is evaluated only
    where some budget may be spent, and then only the spent items are recomputed. The pairs of a
    sphere with the spheres of one lower link go as one item, group g: sphere ``g_sphere[g]`` against
    ``g_members[g_start[g]:g_start[g + 1]]``, whose link's ball ``g_ball[g]`` (a sphere of radius
    ``b_radius`` around ``b_folded`` in link ``b_link``'s frame) holds them: far from that ball (farther
    than its radius) the group's budget is its distance to the ball, spent at its members' fastest rate;
    nearer, each member's own distance, spent at its own rate. ``pairs`` are the pairs not grouped.
    ``body``: the arrays of :func:`_unpack_body`; ``scene``: those of :func:`~kinlearn.collision.kinds.unpack`.
    ``scene_clear``: every configuration of the grid is already proven clear of the scene (the probe's
    :func:`_prove_clear`): only the body against itself is walked."""
    F, prismatic, link, folded, radii, on_floor, pairs, lever = body[:8]
    g_sphere, g_ball, g_start, g_members, b_link, b_folded, b_radius, p_lever, g_lever, m_lever = body[8:18]
    tables, floor = scene
    W, dof = path.shape
    M, P, T = link.shape[0], pairs.shape[0], W - 1
    G, L = g_sphere.shape[0], b_link.shape[0]
    cb = np.empty((L, 3))
    absd = np.empty((T, dof))
    steps = np.ones(max(T, 1))
    for k in range(T):
        for j in range(dof):
            absd[k, j] = abs(path[k + 1, j] - path[k, j])
    _grid_steps(path, max_travel, lever, steps)
    offset = np.zeros(max(T, 1) + 1)
    for k in range(T):
        offset[k + 1] = offset[k] + steps[k]
    end = offset[T] if T else 0.0  # the last knot's global index
    # What is left of each joint's travel from each segment on: an item (a sphere, a pair, a group) whose
    # budget exceeds its bound from there, Σ_j left[k, j] · lever_j, needs no walk along the segments.
    left = np.zeros((T + 1, dof))
    for k in range(T - 1, -1, -1):
        for j in range(dof):
            left[k, j] = left[k + 1, j] + absd[k, j]
    due_m = np.full(M, np.inf) if scene_clear else np.zeros(M)  # where each item must be recomputed
    due_p = np.zeros(P)
    due_g = np.zeros(G)
    from_g = np.zeros(G)
    # Where each item was last computed: an evaluated configuration also refreshes the items that have
    # spent more than ``REFRESH`` of their budget's span, so that far items do not each call for one.
    from_m = np.zeros(M)
    from_p = np.zeros(P)
    c, frames, q = np.empty((M, 3)), np.empty((dof + 1, 3, 4)), np.empty(dof)
    dm, xyz = np.empty(M), np.empty((3, M))
    pos, evaluated = 0.0, 0
    k = 0
    while True:
        while k < T and pos >= offset[k + 1]:
            k += 1
        i = pos - offset[k]
        frac = 0.0
        if k < T:
            frac = i / steps[k]
            for j in range(dof):
                q[j] = path[k, j] + frac * (path[k + 1, j] - path[k, j])
        else:
            for j in range(dof):
                q[j] = path[T, j]
        _chain(q, F, prismatic, frames)
        _place(frames, link, folded, c)
        _place(frames, b_link, b_folded, cb)
        evaluated += 1
        nxt = np.inf
        due = 0
        for m in range(M):
            if _stale(due_m[m], from_m[m], pos):
                due += 1
        every = due >= _VECTOR_MIN
        if every:  # many spheres to look at: all of them at once, in vector instructions
            spheres_scene(c, radii, on_floor, tables, floor, xyz, dm)
        for m in range(M):
            if _stale(due_m[m], from_m[m], pos):
                from_m[m] = pos
                if every:
                    d = dm[m]
                else:
                    d = sphere_scene(c[m, 0], c[m, 1], c[m, 2], radii[m], on_floor[m], tables, floor)
                if d <= margin:
                    return k, evaluated, frac, False
                due_m[m] = _expiry_lever(d - margin - _SLACK, k, i, absd, left, lever, m, steps, offset)
            nxt = min(nxt, due_m[m])
        for p in range(P):
            if _stale(due_p[p], from_p[p], pos):
                from_p[p] = pos
                a, b = pairs[p, 0], pairs[p, 1]
                d = _gap(c, a, radii[a], c, b, radii[b])
                if d <= 0.0:
                    return k, evaluated, frac, True
                due_p[p] = _expiry_lever(d - _SLACK, k, i, absd, left, p_lever, p, steps, offset)
            nxt = min(nxt, due_p[p])
        for g in range(G):
            if _stale(due_g[g], from_g[g], pos):
                from_g[g] = pos
                x, u = g_sphere[g], g_ball[g]
                d = _gap(c, x, b_radius[u], cb, u, radii[x])
                if d > b_radius[u]:  # far from that link: the ball's budget, at its members' fastest rate
                    due_g[g] = _expiry_lever(d - _SLACK, k, i, absd, left, g_lever, g, steps, offset)
                else:  # near it (the ball a loose bound): its spheres one by one, each with its own rate
                    due = np.inf
                    for e in range(g_start[g], g_start[g + 1]):
                        b = g_members[e]
                        d = _gap(c, x, radii[x], c, b, radii[b])
                        if d <= 0.0:
                            return k, evaluated, frac, True
                        due = min(due, _expiry_lever(d - _SLACK, k, i, absd, left, m_lever, e, steps, offset))
                    due_g[g] = due
            nxt = min(nxt, due_g[g])
        if nxt > end:
            return -1, evaluated, 0.0, False
        pos = nxt


@jit
def _verdict_packed(path, max_travel, margin, f, n, s):
    """:func:`_verdict` on a packed body and scene (few arguments: each one costs a call time)."""
    return _verdict(path, max_travel, margin, _unpack_body(f, n), unpack(s))
