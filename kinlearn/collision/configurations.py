"""Many configurations checked at once (compiled): the dense check's verdict at each of ``N`` joint
configurations — collides when some sphere is within ``margin`` of the scene or the floor, or a
self-collision pair touches — with the configurations in lanes (structure of arrays: every loop runs over
the configurations still in question, a loop the compiler turns into vector instructions), each link's
bounding ball looked at before its spheres, and a configuration dropped at its first contact.

The numbers are those of the walk (:mod:`kinlearn.collision.walk`) to the bit: the same FK arithmetic
lane by lane, the same distances; so the verdicts are the dense check's at those configurations
(``tests/test_collision_configurations.py``). :func:`~kinlearn.collision.kernel.free_configurations` is the
entry from Python; :func:`free_lanes` the one for compiled code.
"""

from __future__ import annotations

import math

import numpy as np

from ..body.jit import jit
from .kernel_body import _unpack_body
from .kinds import spheres_scene, unpack

__all__ = ["free_lanes"]

_TINY = float(np.finfo(np.float64).tiny)


@jit
def _chain_lanes(Q, F, prismatic, T):
    """Frames ``T (dof + 1, 12, N)`` (each a 3 × 4 matrix, row-major, per lane) of joints ``Q (dof, N)``:
    :func:`~kinlearn.body.fk._chain`'s arithmetic, lane by lane."""
    dof, N = Q.shape
    for a in range(3):
        for b in range(4):
            v = 1.0 if a == b else 0.0
            for n in range(N):
                T[0, 4 * a + b, n] = v
    c, s = np.empty(N), np.empty(N)
    for i in range(dof):
        if prismatic[i]:
            for n in range(N):
                c[n], s[n] = 1.0, 0.0
        else:
            for n in range(N):
                c[n], s[n] = math.cos(Q[i, n]), math.sin(Q[i, n])
        f00, f01, f02, f03 = F[i, 0, 0], F[i, 0, 1], F[i, 0, 2], F[i, 0, 3]
        f10, f11, f12, f13 = F[i, 1, 0], F[i, 1, 1], F[i, 1, 2], F[i, 1, 3]
        f20, f21, f22, f23 = F[i, 2, 0], F[i, 2, 1], F[i, 2, 2], F[i, 2, 3]
        pr = prismatic[i]
        for a in range(3):
            r = 4 * a
            for n in range(N):
                p0, p1, p2 = T[i, r, n], T[i, r + 1, n], T[i, r + 2, n]
                a0 = p0 * f00 + p1 * f10 + p2 * f20
                a1 = p0 * f01 + p1 * f11 + p2 * f21
                a2 = p0 * f02 + p1 * f12 + p2 * f22
                a3 = p0 * f03 + p1 * f13 + p2 * f23 + T[i, r + 3, n]
                T[i + 1, r, n] = c[n] * a0 + s[n] * a1
                T[i + 1, r + 1, n] = c[n] * a1 - s[n] * a0
                T[i + 1, r + 2, n] = a2
                T[i + 1, r + 3, n] = a3 + Q[i, n] * a2 if pr else a3


@jit(inline="always")
def _place_lane(T, k, v0, v1, v2, n, out, row):
    """``out[row] = R_k · v + p_k`` of lane ``n`` (:func:`~kinlearn.body.fk._point`'s arithmetic)."""
    for a in range(3):
        r = 4 * a
        out[row, a] = T[k, r, n] * v0 + T[k, r + 1, n] * v1 + T[k, r + 2, n] * v2 + T[k, r + 3, n]


@jit
def free_lanes(qs, margin, f, nb, s, free):
    """``free (N,)`` filled with whether each configuration of ``qs (N, dof)`` is free under the dense
    check (no sphere within ``margin`` of the scene, no self-collision pair touching), for a body packed
    as :attr:`~kinlearn.collision.kernel.KernelBody.packed` (``f``, ``nb``; its packing without the pairs
    proven apart is right where every configuration lies in its box) and a scene packed as
    :attr:`~kinlearn.collision.kernel.KernelScene.packed` (``s``). ``qs`` is finite."""
    body = _unpack_body(f, nb)
    F, prismatic, link, folded, radii, on_floor, pairs = body[:7]
    g_sphere, g_ball, g_start, g_members, b_link, b_folded, b_radius = body[8:15]
    l_start, l_folded, l_radius = body[18:21]
    tables, floor = unpack(s)
    N, dof = qs.shape
    M, L = link.shape[0], l_start.shape[0] - 1
    Q = np.empty((dof, N))
    for n in range(N):
        for j in range(dof):
            Q[j, n] = qs[n, j]
    T = np.empty((dof + 1, 12, N))
    _chain_lanes(Q, F, prismatic, T)
    alive = np.empty(N, dtype=np.int64)  # the lanes still in question, in order
    for n in range(N):
        alive[n] = n
        free[n] = True
    A = N
    # the scene: link by link, each link's ball first, then the spheres of the lanes whose ball is near
    c = np.empty((max(N, 1), 3))
    r = np.empty(max(N, 1))
    fl = np.empty(max(N, 1), dtype=np.bool_)
    d = np.empty(max(N, 1))
    xyz = np.empty((3, max(N, 1)))
    near = np.empty(N, dtype=np.int64)
    for lk in range(L):
        a, b = l_start[lk], l_start[lk + 1]
        if a == b or A == 0:
            continue
        v0, v1, v2 = l_folded[lk, 0], l_folded[lk, 1], l_folded[lk, 2]
        for e in range(A):
            _place_lane(T, lk, v0, v1, v2, alive[e], c, e)
            r[e], fl[e] = l_radius[lk], lk > 0
        spheres_scene(c[:A], r[:A], fl[:A], tables, floor, xyz, d[:A], True)  # the links' balls
        K = 0
        for e in range(A):
            if not d[e] > margin:
                near[K] = alive[e]
                K += 1
        if K == 0:
            continue
        for m in range(a, b):  # sphere by sphere over the near lanes
            for e in range(K):
                _place_lane(T, lk, folded[m, 0], folded[m, 1], folded[m, 2], near[e], c, e)
                r[e], fl[e] = radii[m], on_floor[m]
            spheres_scene(c[:K], r[:K], fl[:K], tables, floor, xyz, d[:K])
            for e in range(K):
                if not d[e] > margin:
                    free[near[e]] = False
        A2 = 0  # the lanes that hit leave
        for e in range(A):
            if free[alive[e]]:
                alive[A2] = alive[e]
                A2 += 1
        A = A2
    if A == 0 or (pairs.shape[0] == 0 and g_sphere.shape[0] == 0):
        return
    # the body against itself, for the lanes still free: every sphere and link ball placed
    C = np.empty((M, 3, A))
    for m in range(M):
        k = link[m]
        for e in range(A):
            n = alive[e]
            for ax in range(3):
                row = 4 * ax
                C[m, ax, e] = (
                    T[k, row, n] * folded[m, 0] + T[k, row + 1, n] * folded[m, 1]
                    + T[k, row + 2, n] * folded[m, 2] + T[k, row + 3, n]
                )  # fmt: skip
    B = b_link.shape[0]
    CB = np.empty((B, 3, A))
    for u in range(B):
        k = b_link[u]
        for e in range(A):
            n = alive[e]
            for ax in range(3):
                row = 4 * ax
                CB[u, ax, e] = (
                    T[k, row, n] * b_folded[u, 0] + T[k, row + 1, n] * b_folded[u, 1]
                    + T[k, row + 2, n] * b_folded[u, 2] + T[k, row + 3, n]
                )  # fmt: skip
    hit = np.zeros(A, dtype=np.bool_)
    for p in range(pairs.shape[0]):
        i, j = pairs[p, 0], pairs[p, 1]
        for e in range(A):
            dx, dy, dz = C[i, 0, e] - C[j, 0, e], C[i, 1, e] - C[j, 1, e], C[i, 2, e] - C[j, 2, e]
            if math.sqrt(max(dx * dx + dy * dy + dz * dz, _TINY)) - radii[i] - radii[j] <= 0.0:
                hit[e] = True
    for g in range(g_sphere.shape[0]):
        x, u = g_sphere[g], g_ball[g]
        for e in range(A):
            if hit[e]:
                continue
            dx, dy, dz = C[x, 0, e] - CB[u, 0, e], C[x, 1, e] - CB[u, 1, e], C[x, 2, e] - CB[u, 2, e]
            if math.sqrt(max(dx * dx + dy * dy + dz * dz, _TINY)) - b_radius[u] - radii[x] > 0.0:
                continue  # clear of the ball that holds the members
            for t in range(g_start[g], g_start[g + 1]):
                m = g_members[t]
                dx, dy, dz = C[x, 0, e] - C[m, 0, e], C[x, 1, e] - C[m, 1, e], C[x, 2, e] - C[m, 2, e]
                if math.sqrt(max(dx * dx + dy * dy + dz * dz, _TINY)) - radii[x] - radii[m] <= 0.0:
                    hit[e] = True
                    break
    for e in range(A):
        if hit[e]:
            free[alive[e]] = False
