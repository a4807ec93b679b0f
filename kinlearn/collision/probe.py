"""Where only a path's verdict is wanted (:func:`~kinlearn.collision.kernel.first_free`, a sampler's
motions): a probe of a few grid configurations first, each proving its neighbours clear of the scene as
it goes, then the walk (:mod:`kinlearn.collision.walk`) of the body against itself and the proof of the
rest. Every configuration looked at is one of the dense check's grid, so the verdict is the same."""

from __future__ import annotations

import math

import numpy as np

from ..body.fk import _chain, _place, _point
from ..body.jit import jit
from ..body.travel import axis_speed, growth, window
from .kernel_body import _all_finite, _unpack_body, _within
from .kinds import sphere_scene, unpack
from .walk import _SLACK, _gap, _steps_at, _verdict, _verdict_packed

__all__ = ["first_free_boxed", "free_depths_boxed"]


#: How many halvings of each segment the probe looks at: its middle sub-step, then its quarters, eighths
#: and sixteenths (fewer let more colliding candidates through to the walk; more cost more probes than
#: they save).
_PROBE_LEVELS = 4


@jit(inline="always")
def _scene_hit(q, margin, body, scene, frames):
    """Whether some sphere of ``body`` at joints ``q`` is within ``margin`` of the scene (self-collision not
    looked at). Link by link: a link whose ball (holding its spheres ``l_start[l]`` to ``l_start[l + 1]``)
    is farther than ``margin`` from the scene has none there, and its spheres are not placed."""
    F, prismatic, _, folded, radii, on_floor = body[:6]
    l_start, l_folded, l_radius = body[18:21]
    tables, floor = scene
    _chain(q, F, prismatic, frames)
    for lk in range(l_start.shape[0] - 1):
        a, b = l_start[lk], l_start[lk + 1]
        if a == b:
            continue
        x, y, z = _point(frames, lk, l_folded[lk])
        if sphere_scene(x, y, z, l_radius[lk], lk > 0, tables, floor, True) > margin:
            continue
        for m in range(a, b):
            x, y, z = _point(frames, lk, folded[m])
            if sphere_scene(x, y, z, radii[m], on_floor[m], tables, floor) <= margin:
                return True
    return False


@jit(inline="always")
def _scene_clear(q, margin, body, scene, frames, link_lever, path, k, n):
    """:func:`_scene_hit` at a configuration ``q`` of segment ``k`` (``n`` sub-steps) that also says how far
    along the segment, either way, its clearances prove the body clear of the scene: −1 where some sphere is
    within ``margin``, else w > 0 such that every grid configuration of the segment fewer than w sub-steps
    from ``q`` is clear. A link whose ball is clear proves its spheres clear while the ball's clearance
    outlasts its centre's travel (``link_lever``: per link and joint the largest lever of its spheres, which
    bound the centre's); a sphere looked at alone, while its own clearance outlasts its own travel. Each
    travel is bounded at ``q`` (:mod:`kinlearn.body.travel`: the centre's distances from the axes there),
    where the global levers alone would give the shorter window."""
    F, prismatic, _, folded, radii, on_floor = body[:6]
    lever = body[7]
    l_start, l_folded, l_radius = body[18:21]
    tables, floor = scene
    dof = q.shape[0]
    _chain(q, F, prismatic, frames)
    w = np.inf
    for lk in range(l_start.shape[0] - 1):
        a, b = l_start[lk], l_start[lk + 1]
        if a == b:
            continue
        x, y, z = _point(frames, lk, l_folded[lk])
        d = sphere_scene(x, y, z, l_radius[lk], lk > 0, tables, floor, True)
        if d > margin:
            rate = 0.0
            for j in range(dof):
                rate += abs(path[k + 1, j] - path[k, j]) * link_lever[lk, j]
            e = d - margin - _SLACK
            if rate > 0.0 and e * n < w * rate:  # the global bound's window is shorter than w: the local one
                speed = axis_speed(frames, x, y, z, lk, path, k, prismatic)
                w = min(w, window(e, speed, growth(path, k, lk, link_lever, lk), rate) * n)
            continue
        for m in range(a, b):
            xm, ym, zm = _point(frames, lk, folded[m])
            d = sphere_scene(xm, ym, zm, radii[m], on_floor[m], tables, floor)
            if d <= margin:
                return -1.0
            rate = 0.0
            for j in range(dof):
                rate += abs(path[k + 1, j] - path[k, j]) * lever[m, j]
            e = d - margin - _SLACK
            if rate > 0.0 and e * n < w * rate:
                own = axis_speed(frames, xm, ym, zm, lk, path, k, prismatic)
                w = min(w, window(e, own, growth(path, k, lk, lever, m), rate) * n)
    return w


@jit(inline="always")
def _link_levers(body, out):
    """Into ``out``, per link (as ``l_start`` groups the spheres) and joint, the largest lever of the link's
    spheres."""
    lever, l_start = body[7], body[18]
    out[:] = 0.0
    for lk in range(l_start.shape[0] - 1):
        for m in range(l_start[lk], l_start[lk + 1]):
            for j in range(lever.shape[1]):
                out[lk, j] = max(out[lk, j], lever[m, j])


@jit(inline="always")
def _proven(cen, wid, cnt, k, i):
    """Whether grid sub-step ``i`` of segment ``k`` lies within a window a probed configuration proved clear."""
    for t in range(cnt[k]):
        if abs(i - cen[k, t]) < wid[k, t]:
            return True
    return False


@jit(inline="always")
def _self_hit(body, frames, c, cb):
    """Whether the body, its links placed at ``frames`` (:func:`_chain`'s, already computed), touches itself:
    every self-collision pair of the packing, a group's members only where the sphere reaches into
    their link's ball (``c``, ``cb``: room for the sphere centres and the balls' centres)."""
    link, folded, radii, pairs = body[2], body[3], body[4], body[6]
    g_sphere, g_ball, g_start, g_members, b_link, b_folded, b_radius = body[8:15]
    if pairs.shape[0] == 0 and g_sphere.shape[0] == 0:
        return False
    _place(frames, link, folded, c)
    _place(frames, b_link, b_folded, cb)
    for p in range(pairs.shape[0]):
        a, b = pairs[p, 0], pairs[p, 1]
        if _gap(c, a, radii[a], c, b, radii[b]) <= 0.0:
            return True
    for g in range(g_sphere.shape[0]):
        x, u = g_sphere[g], g_ball[g]
        if _gap(c, x, b_radius[u], cb, u, radii[x]) > 0.0:
            continue  # clear of the ball that holds the members
        for e in range(g_start[g], g_start[g + 1]):
            b = g_members[e]
            if _gap(c, x, radii[x], c, b, radii[b]) <= 0.0:
                return True
    return False


@jit(inline="always")
def _prove_clear(path, margin, body, scene, steps, cen, wid, cnt, link_lever, frames, q):
    """After the probe's levels: the rest of the grid (every segment's sub-steps ``steps``, counted, and the
    last knot) proven clear of the scene, or a configuration that is not. What the levels' windows
    (``cen``, ``wid``, ``cnt``) leave is filled gap by gap: the configuration in a gap's middle is looked
    at (:func:`_scene_clear`) and its window closes what it proves. Returns (hit, its segment, its
    fraction of the segment)."""
    W, dof = path.shape
    T = W - 1
    off = np.zeros(T + 1, dtype=np.int64)
    for k in range(T):
        off[k + 1] = off[k] + int(steps[k])
    covered = np.zeros(off[T] + 1, dtype=np.bool_)  # every segment's sub-steps, then the last knot
    for k in range(T):
        n = int(steps[k])
        for t in range(cnt[k]):
            _cover(covered, off[k], n, cen[k, t], wid[k, t])
    for k in range(T):
        n = int(steps[k])
        end = n + 1 if k == T - 1 else n  # the last segment's last sub-step is the last knot
        i = 0
        while i < end:
            if covered[off[k] + i]:
                i += 1
                continue
            e = i
            while e + 1 < end and not covered[off[k] + e + 1]:
                e += 1
            mid = (i + e) // 2
            if mid == n:  # the last knot, as the walk takes it
                for j in range(dof):
                    q[j] = path[T, j]
            else:
                for j in range(dof):
                    q[j] = path[k, j] + (mid / n) * (path[k + 1, j] - path[k, j])
            w = _scene_clear(q, margin, body, scene, frames, link_lever, path, k, n)
            if w < 0.0:
                return True, k, mid / n
            covered[off[k] + mid] = True
            _cover(covered, off[k], n, mid, w)
    return False, 0, 0.0


@jit(inline="always")
def _cover(covered, start, n, centre, width):
    """Mark the sub-steps 0…n of a segment (from ``start`` in ``covered``) fewer than ``width`` from ``centre``
    (n is the next segment's first: the same knot, to rounding far below the slack)."""
    if width > n + 1.0:  # the whole segment (also an unbounded window: a still segment, an empty scene)
        a, b = 0, n
    else:
        a = max(0, math.floor(centre - width) + 1)
        b = min(n, math.ceil(centre + width) - 1)
    for i in range(a, b + 1):
        covered[start + i] = True


@jit
def _probe(path, max_travel, margin, body, scene, hints, nh, fold=False):
    """Where a few configurations of the dense check's grid, spread along ``path (W, dof)``, already hit the
    scene: first the places other candidates hit (``hints[:nh]``, rows (segment, fraction of it), most
    recent first: candidates of one problem are alike and tend to collide in one place), then the inner
    knots, then each segment's middle sub-step, its quarters and so on (:data:`_PROBE_LEVELS`). Each is a
    configuration :func:`_verdict` checks (the same sub-step count and interpolation, to the bit; a hint
    is taken to the grid's sub-step at or before its fraction), so a hit means the path collides; none
    says nothing. Returns (hit, its segment, its fraction of the segment, the hint that hit or −1). Most
    colliding paths (a planner's candidates, a sampler's long edges) collide somewhere inside, where a
    walk from the start reaches late: a probe finds it in a few scene checks. At the hints (another
    candidate's hit may have been the body against itself) and, where ``fold`` (a walk's hit among the
    candidates was one), at the inner knots, it also looks at self-collision (:func:`_self_hit`): their
    candidates rarely fold on some arms, and a check at every knot of every candidate would cost those
    arms more than it saves. ``path`` is finite (as
    :func:`_verdict` takes it: :func:`_first_free_packed` checks every candidate first). Also returns the
    windows its clear configurations proved clear of the scene (:func:`_scene_clear`: per segment its
    sub-step count, the windows' centres and half-widths, their count, and the links' levers they were
    proved with), which :func:`_after_probe` goes on from."""
    lever = body[7]
    W, dof = path.shape
    T = max(W - 1, 0)
    # Where a probed configuration's clearances prove its neighbours clear (:func:`_scene_clear`), they
    # cannot hit and are not looked at: per segment, the windows (centre, half-width in sub-steps).
    n_win = 2**_PROBE_LEVELS
    steps = np.zeros(T)  # each segment's sub-steps, counted where first needed (a hint, a level)
    cen, wid, cnt = np.empty((T, n_win)), np.empty((T, n_win)), np.zeros(T, dtype=np.int64)
    link_lever = np.empty((body[18].shape[0] - 1, dof))  # filled where the levels start
    windows = (steps, cen, wid, cnt, link_lever)
    if W < 2:
        return False, 0, 0.0, -1, windows
    frames, q = np.empty((dof + 1, 3, 4)), np.empty(dof)
    c, cb = np.empty((body[2].shape[0], 3)), np.empty((body[12].shape[0], 3))
    for h in range(nh):
        k = int(hints[h, 0])
        n = _steps_at(steps, path, k, max_travel, lever)
        frac = min(math.floor(hints[h, 1] * n), n - 1.0) / n
        for j in range(dof):
            q[j] = path[k, j] + frac * (path[k + 1, j] - path[k, j])
        # where another candidate hit, the body against itself too: a walk's hit may be one
        if _scene_hit(q, margin, body, scene, frames) or _self_hit(body, frames, c, cb):
            return True, k, frac, h, windows
    for k in range(1, W - 1):  # the knots (against the body itself too where candidates fold)
        if _scene_hit(path[k], margin, body, scene, frames) or (fold and _self_hit(body, frames, c, cb)):
            return True, k, 0.0, -1, windows
    _link_levers(body, link_lever)
    parts = 2
    for _ in range(_PROBE_LEVELS):
        for k in range(W - 1):
            n = _steps_at(steps, path, k, max_travel, lever)
            for h in range(1, parts, 2):
                i = math.floor(n * h / parts)
                # Each grid configuration once: one a coarser level looked at (its neighbours h ± 1
                # are that level's points) or a knot is not looked at again (a short segment has fewer
                # sub-steps than a level has points).
                if (
                    i <= 0.0
                    or i >= n
                    or i == math.floor(n * (h - 1) / parts)
                    or i == math.floor(n * (h + 1) / parts)
                    or _proven(cen, wid, cnt, k, i)
                ):
                    continue
                frac = i / n
                for j in range(dof):
                    q[j] = path[k, j] + frac * (path[k + 1, j] - path[k, j])
                w = _scene_clear(q, margin, body, scene, frames, link_lever, path, k, n)
                if w < 0.0:
                    return True, k, frac, -1, windows
                if w > 1.0 and cnt[k] < n_win:
                    cen[k, cnt[k]], wid[k, cnt[k]] = i, w
                    cnt[k] += 1
        parts *= 2
    return False, 0, 0.0, -1, windows


@jit
def _after_probe(path, max_travel, margin, body, scene, windows):
    """The verdict of a path the probe (:func:`_probe`, which gave ``windows``) did not see collide: the walk
    of the body against itself first (:func:`_verdict` with the scene left out: a hit there ends it
    early), then the rest of the grid proven clear of the scene (:func:`_prove_clear`). Returns (first
    colliding segment or −1, the hit's fraction of it, whether the hit is the body against itself): a
    self-collision first found by the walk, a scene hit by the proof. The self-walk comes first: paths
    that fold the arm onto itself where the probe saw the scene clear (a retreat's joins) end there
    sooner than the scene's proof would."""
    W, dof = path.shape
    if W < 2:  # one configuration: the walk looks at it
        first, _, frac, itself = _verdict(path, max_travel, margin, body, scene)
        return first, frac, itself
    first, _, frac, itself = _verdict(path, max_travel, margin, body, scene, True)
    if first >= 0:
        return first, frac, True
    steps, cen, wid, cnt, link_lever = windows
    frames, q = np.empty((dof + 1, 3, 4)), np.empty(dof)
    hit, k, frac = _prove_clear(path, margin, body, scene, steps, cen, wid, cnt, link_lever, frames, q)
    if hit:
        return k, frac, False
    return -1, 0.0, False


#: No hints, for a probe of one path.
_NO_HINTS = np.empty((0, 2))

#: How many places where candidates hit the scene :func:`_first_free` keeps for the next one's probe.
_HINTS = 4


@jit
def _remember(hints, nh, h, k, frac):
    """Put the hit (segment ``k``, ``frac``) first in ``hints[:nh]`` (hint ``h`` moved up if it made the hit,
    else the oldest dropped when full); the new count."""
    if hints.shape[0] == 0:
        return 0
    last = h if h >= 0 else min(nh, hints.shape[0] - 1)
    for t in range(last, 0, -1):
        hints[t, 0], hints[t, 1] = hints[t - 1, 0], hints[t - 1, 1]
    hints[0, 0], hints[0, 1] = k, frac
    return nh if h >= 0 else min(nh + 1, hints.shape[0])


@jit
def _first_free(paths, order, max_travel, margin, body, scene, n_hints):
    """The first free path of ``order`` (−1: none), each probed (:func:`_probe`, with the ``n_hints`` last
    places candidates hit, found by a probe or by a walk) then walked (:func:`_verdict`)."""
    hints, nh = np.empty((n_hints, 2)), 0
    fold = False  # whether a walk's hit was the body against itself: the next probes look at the knots for it
    for i in range(order.shape[0]):
        path = paths[order[i]]
        hit, k, frac, h, windows = _probe(path, max_travel, margin, body, scene, hints, nh, fold)
        if hit:
            nh = _remember(hints, nh, h, k, frac)
            continue
        first, frac, itself = _after_probe(path, max_travel, margin, body, scene, windows)
        if first < 0:
            return order[i]
        # the walk or the proof found a hit the probe missed: the next candidates are probed there first
        last = paths.shape[1] - 2  # a hit at the final knot: the last sub-step before it
        nh = _remember(hints, nh, -1, min(first, last), frac if first <= last else 1.0)
        fold = fold or itself
    return -1


@jit
def _free_packed(path, max_travel, margin, f, n, s):
    """Whether ``path`` is free under the dense check (:func:`_verdict`'s answer), for callers that need no
    first colliding segment (a sampler's motions): its last knot first (a sampler's new state; OMPL's
    discrete motion validator also looks at it first), then the probe (:func:`_probe`), then the walk.
    Each is a configuration of the walk's grid: the same verdict."""
    body, scene = _unpack_body(f, n), unpack(s)
    if _scene_hit(path[path.shape[0] - 1], margin, body, scene, np.empty((path.shape[1] + 1, 3, 4))):
        return False
    hit, _, _, _, windows = _probe(path, max_travel, margin, body, scene, _NO_HINTS, 0)
    if hit:
        return False
    return _after_probe(path, max_travel, margin, body, scene, windows)[0] < 0


@jit
def _first_free_packed(paths, order, max_travel, margin, f, n, s, n_hints=_HINTS):
    """:func:`_first_free` on a packed body and scene; −2 if ``paths`` hold NaN or infinity."""
    if not _all_finite(paths):
        return -2
    return _first_free(paths, order, max_travel, margin, _unpack_body(f, n), unpack(s), n_hints)


@jit
def first_free_boxed(paths, order, max_travel, margin, box_lo, box_hi, f_in, n_in, f_all, n_all, s):
    """:func:`first_free`'s compiled core, for other compiled code to call (the planner's proposals):
    the body packed without the pairs proven apart (``f_in, n_in``) when every knot of ``paths`` lies in
    its box ``[box_lo, box_hi]``, else whole (``f_all, n_all``), as :meth:`KernelBody.packing_of` picks
    (:meth:`KernelBody.boxed` gives the six); the index of the first free path in ``order``, −1 if none
    is, −2 if ``paths`` hold NaN or infinity."""
    if _within(paths, box_lo, box_hi):
        return _first_free_packed(paths, order, max_travel, margin, f_in, n_in, s)
    return _first_free_packed(paths, order, max_travel, margin, f_all, n_all, s)


@jit
def free_depths_boxed(theta, vias, max_travel, margin, box_lo, box_hi, f_in, n_in, f_all, n_all, s, depth):
    """:func:`free_depths`' compiled core (the planner's retreat stage calls it with its own float64 arrays,
    as :func:`first_free_boxed`): each chain ``[theta, vias[d]]`` walked to its first collision
    (the body packed as :func:`first_free_boxed` packs it for the chain), the via before a hit in a
    later segment checked alone; ``depth (D,)`` filled. False if ``theta`` or ``vias`` hold NaN or
    infinity (nothing checked)."""
    D, L, dof = vias.shape
    if not (_all_finite(theta) and _all_finite(vias)):
        return False
    chain, one = np.empty((L + 1, dof)), np.empty((1, dof))
    for d in range(D):
        for j in range(dof):
            chain[0, j] = theta[j]
        for k in range(L):
            for j in range(dof):
                chain[k + 1, j] = vias[d, k, j]
        inside = _within(chain, box_lo, box_hi)
        first = _verdict_packed(
            chain, max_travel, margin, f_in if inside else f_all, n_in if inside else n_all, s
        )[0]
        if first < 0:
            depth[d] = L
        elif first == 0:
            depth[d] = 0
        else:  # a hit in segment f lies in it or at its first knot, via f − 1: checked alone, it tells which
            for j in range(dof):
                one[0, j] = vias[d, first - 1, j]
            inside = _within(one, box_lo, box_hi)
            hit = _verdict_packed(
                one, max_travel, margin, f_in if inside else f_all, n_in if inside else n_all, s
            )[0]
            depth[d] = first - 1 if hit >= 0 else first
    return True
