"""Shortening a collision-free joint path on the compiled checker: a deterministic, fixed-budget pass.

Every path a planner hands over among obstacles goes through :func:`shorten` (the planner's shortcut
stage, and the compiled sampler's own paths), whatever stage made it. The pass works on the polyline of
joint configurations and keeps it free under the same dense check every plan is judged by
(:mod:`kinlearn.collision.kernel`: at most ``max_travel`` of body-sphere travel between checked
configurations, self-collision and the floor included). Two phases:

1. **Vertex skipping**: from the first vertex, the later vertices are tried from the last one down;
   the first one it sees along a free straight segment becomes the next vertex, then from there. It
   removes the detours of a stage that backs out, crosses and goes in, and a sampler's zig-zags. A
   segment that collides usually costs the check little (its probe finds the contact early), one that
   is free a full walk, so trying the far vertices first spends the walks on the segments kept.
2. **Partial shortcuts** (Geraerts and Overmars, "Creating high-quality paths for motion planning",
   IJRR 2007): two points drawn along the path's length, on different segments, are joined where the
   straight segment between them is free and shorter (and the pieces of the two segments left before
   and after it, checked as segments of their own). Corners that no two vertices see past are cut.
   The points come from a counter-based generator seeded by ``seed``: the same path, seed and budget
   give the same result on every machine. A draw whose shortcut, if free, would save less than
   ``min_gain`` of the path's length (:data:`MIN_GAIN`, 1%) is not checked: most draws on a path
   that vertex skipping has already straightened save slivers, and each costs a walk.

The joint-space length (the sum of the segments' Euclidean norms) never grows: a change is kept only
where it shortens the path. The result starts at the path's first configuration and ends at its last,
exactly. The pass works on the path's corners (vertices on the straight segment between their
neighbours are dropped first), so a polyline gives the same result however finely it is split.
"""

from __future__ import annotations

import math

import numpy as np

from ..body.jit import jit
from ..checks import as_int
from ..errors import ConfigError, ShapeError
from . import kernel

__all__ = ["DEFAULT_ATTEMPTS", "MIN_GAIN", "shorten", "shorten_packed"]

_jit = jit(error_model="numpy")  # stamped with the kernels it calls (kinlearn.body.jit)

#: Partial shortcuts tried per path by default (a budget of work, not of time): each free one costs a
#: walk of its new segment, so a few cut the corners vertex skipping leaves (``benchmarks/executable.py``).
DEFAULT_ATTEMPTS = 8
#: A change must shorten the path by more than this (rad) to be kept: rounding never loops.
_GAIN = 1e-9
#: The share of the path's joint-space length a partial shortcut must save, if free, to be checked.
#: Against 0, on the planner's 140 held-out problems per arm (iiwa14, panda, ur5): the median plan
#: 10–23% faster, the paths 0.1–0.2% longer in sum.
MIN_GAIN = 0.01
#: A vertex within this share of its neighbours' distance (plus 1 rad) of the straight segment between
#: them, in excess length, is no corner (:func:`_corners`).
_COLLINEAR = 1e-12


@_jit
def _uniform(counter) -> float:
    """A number in [0, 1) from a splitmix64 step of ``counter[0]``."""
    counter[0] += 1
    z = np.uint64(counter[0]) * np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    z = z ^ (z >> np.uint64(31))
    return float(z >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@_jit
def _seg_free(a, b, seg, max_travel, margin, f, n, s) -> bool:
    for j in range(a.shape[0]):
        seg[0, j], seg[1, j] = a[j], b[j]
    return kernel._free_packed(seg, max_travel, margin, f, n, s)


@_jit
def _norm(a, b) -> float:
    d = 0.0
    for j in range(a.shape[0]):
        e = a[j] - b[j]
        d += e * e
    return math.sqrt(d)


@_jit
def _corners(path, out, merged) -> int:
    """The vertices of ``path`` that are corners, written to ``out``; returns their count: a vertex that
    lies on the straight segment between the vertices kept before it and after it (to rounding) is
    dropped, so a path and the same polyline split more finely give the same corners. ``merged[j]``: the
    segment from corner j to corner j + 1 spans dropped vertices (as one segment it was never checked)."""
    V = path.shape[0]
    out[0] = path[0]
    m = 1
    merged[0] = False
    for k in range(1, V - 1):
        a, b, c = out[m - 1], path[k], path[k + 1]
        if _norm(a, b) + _norm(b, c) - _norm(a, c) <= _COLLINEAR * (_norm(a, c) + 1.0):
            merged[m - 1] = True
            continue
        out[m] = b
        merged[m] = False
        m += 1
    out[m] = path[V - 1]
    return m + 1


@_jit
def _skip(cur, m, merged, out, seg, max_travel, margin, f, n, s) -> int:
    """Phase 1 on ``cur[:m]``: the vertices kept, written to ``out``; returns their count, or −1 where a
    segment joining merged pieces (``merged``) is not free as one segment (the dense check's grid on it
    differs from its pieces': the pass then leaves the path alone)."""
    out[0] = cur[0]
    count, i = 1, 0
    while i < m - 1:
        nxt = -1
        for k in range(m - 1, i + 1, -1):
            if _seg_free(cur[i], cur[k], seg, max_travel, margin, f, n, s):
                nxt = k
                break
        if nxt < 0:
            if merged[i] and not _seg_free(cur[i], cur[i + 1], seg, max_travel, margin, f, n, s):
                return -1
            nxt = i + 1
        out[count] = cur[nxt]
        count += 1
        i = nxt
    return count


@_jit
def _shorten(path, cap, attempts, seed, max_travel, margin, min_gain, f, n, s, out) -> int:
    """:func:`shorten`'s compiled core: the shortened path in ``out[:count]`` (``out (cap, dof)``, ``cap``
    at least the path's vertex count); returns ``count``."""
    V, dof = path.shape
    seg = np.empty((2, dof))
    cur = np.empty((cap, dof))
    nxt = np.empty((cap, dof))
    corners, merged = np.empty((V, dof)), np.empty(V, dtype=np.bool_)
    m = _skip(corners, _corners(path, corners, merged), merged, cur, seg, max_travel, margin, f, n, s)
    if m < 0:
        for k in range(V):
            out[k] = path[k]
        return V
    counter = np.array([seed * 0x100000001 + 7], dtype=np.int64)
    cum = np.empty(cap)
    a, b = np.empty(dof), np.empty(dof)
    for _ in range(attempts):
        if m < 3:
            break
        cum[0] = 0.0
        for k in range(1, m):
            cum[k] = cum[k - 1] + _norm(cur[k - 1], cur[k])
        total = cum[m - 1]
        u1, u2 = _uniform(counter) * total, _uniform(counter) * total
        if u1 > u2:
            u1, u2 = u2, u1
        i1, i2 = 0, 0
        while i1 < m - 2 and cum[i1 + 1] <= u1:
            i1 += 1
        while i2 < m - 2 and cum[i2 + 1] <= u2:
            i2 += 1
        if i1 == i2:
            continue
        if m + 2 - (i2 - i1) > cap:
            continue
        for which in range(2):
            u, i, p = (u1, i1, a) if which == 0 else (u2, i2, b)
            span = cum[i + 1] - cum[i]
            t = 0.0 if span <= 0.0 else min(max((u - cum[i]) / span, 0.0), 1.0)
            for j in range(dof):
                p[j] = cur[i, j] + t * (cur[i + 1, j] - cur[i, j])
        gain = (cum[i2 + 1] - cum[i1]) - (_norm(cur[i1], a) + _norm(a, b) + _norm(b, cur[i2 + 1]))
        if not gain > max(_GAIN, min_gain * total):
            continue
        # the new segment, and the pieces of the two segments it starts and ends on (a piece's grid is
        # not its segment's)
        if not (
            _seg_free(a, b, seg, max_travel, margin, f, n, s)
            and _seg_free(cur[i1], a, seg, max_travel, margin, f, n, s)
            and _seg_free(b, cur[i2 + 1], seg, max_travel, margin, f, n, s)
        ):
            continue
        c = 0
        for k in range(i1 + 1):
            nxt[c] = cur[k]
            c += 1
        nxt[c] = a
        nxt[c + 1] = b
        c += 2
        for k in range(i2 + 1, m):
            nxt[c] = cur[k]
            c += 1
        # drop vertices that repeat their predecessor (a point drawn on a vertex)
        m = 1
        cur[0] = nxt[0]
        for k in range(1, c):
            if _norm(nxt[k], cur[m - 1]) > 0.0 or k == c - 1:
                cur[m] = nxt[k]
                m += 1
        if m >= 2 and _norm(cur[m - 1], cur[m - 2]) == 0.0:  # the last vertex kept once
            cur[m - 2] = cur[m - 1]
            m -= 1
    for k in range(m):
        out[k] = cur[k]
    return m


def shorten(
    body,
    scene,
    path,
    *,
    cap: int | None = None,
    attempts: int = DEFAULT_ATTEMPTS,
    seed: int = 0,
    max_travel: float = 0.01,
    margin: float = 0.0,
    min_gain: float = MIN_GAIN,
) -> np.ndarray:
    """The collision-free joint path ``path (V, dof)`` shortened (see the module docstring), as ``(V', dof)``
    with ``2 <= V' <= cap`` (default: ``V``): its first and last configurations exactly, every segment
    free under the dense check of ``body`` (a :class:`~kinlearn.collision.kernel.KernelBody`) among
    ``scene`` (a :class:`~kinlearn.collision.kernel.KernelScene`), and a joint-space length no greater
    than the input's. The input's own segments are trusted as free (the caller checked them: the pass
    only ever replaces segments by checked ones). ``attempts``: partial shortcuts drawn; ``seed``: their
    draws; ``min_gain``: the share of the path's length a drawn shortcut must save to be checked (0:
    every one that saves anything)."""
    p = np.ascontiguousarray(path, dtype=np.float64)
    if p.ndim != 2 or p.shape[0] < 2 or p.shape[1] != body.dof:
        raise ShapeError(f"shorten needs a joint path (V >= 2, {body.dof}), got shape {p.shape}")
    if not np.isfinite(p).all():
        raise ShapeError("shorten needs a finite joint path")
    cap = p.shape[0] if cap is None else as_int(cap, "cap", minimum=2)
    if cap < p.shape[0]:
        raise ConfigError(f"cap ({cap}) must be at least the path's {p.shape[0]} vertices")
    attempts = as_int(attempts, "attempts", minimum=0)
    seed = as_int(seed, "seed", minimum=0)
    if not 0.0 <= float(min_gain) < 1.0:
        raise ConfigError(f"min_gain must be a share in [0, 1), got {min_gain}")
    f, nn = body.packing_of(p)  # every point of the pass lies in the path's convex hull
    return shorten_packed(
        p, f, nn, scene.packed, cap, attempts, seed, float(max_travel), float(margin), float(min_gain)
    )


def shorten_packed(path, f, n, s, cap, attempts, seed, max_travel, margin, min_gain=MIN_GAIN) -> np.ndarray:
    """:func:`shorten` on a checked float64 path and a packed body (``f, n``: a packing right for every
    point of the path's convex hull) and scene (``s``), for callers holding those (the sampler)."""
    out = np.empty((cap, path.shape[1]))
    count = _shorten(path, cap, attempts, seed, max_travel, margin, float(min_gain), f, n, s, out)
    return out[:count].copy()
