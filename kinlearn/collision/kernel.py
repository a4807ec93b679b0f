"""Compiled CPU kernels (numba) for batch-1 planning: the body's sphere FK, signed distances to every
kind of primitive, and the dense path check.

torch (:mod:`kinlearn.collision.distance`, :func:`~kinlearn.collision.check_path`) stays the
implementation for training and large batches; this module is the one compiled twin for a single scene
and a handful of paths, where torch's per-operation dispatch (microseconds) dominates. A contract test
(``tests/test_collision_kernel.py``) holds the two to each other on random scenes of every primitive
kind. numba is a dependency (a wheel on every platform kinlearn supports): one kernel set, no NumPy twin
to keep in step. It is imported with this module, which the planner imports only when it first checks a
path; every function is compiled on its first call (nothing at import), and ``cache=True`` keeps the
machine code on disk, so a later process loads it instead of compiling again (all kernels: 21 s the
first time on a shared 2-core machine, 1.6 s from the cache; :func:`warm_up` does it ahead).

**The dense check** (:func:`check_paths`, :func:`first_free`) checks the configurations
:func:`~kinlearn.collision.check_path` checks: segment k is cut into n_k = ⌈L_k / max_travel⌉ sub-steps,
L_k the largest lever bound Σ_j |Δθ_j| · lever_mj over the spheres; every sub-step's start and the last
knot are checked; one collides when its body–scene distance is ≤ ``margin`` or a self-collision pair's
distance is ≤ 0. Where only the verdict is wanted (``first_free``, and ``check_paths(..., exact=False)``)
sub-steps that provably cannot collide are skipped: along a segment sphere m moves at most
t_m = Σ_j |Δθ_j| lever_mj, so t_m / n_k per sub-step, and its distance to the scene (1-Lipschitz in its
centre) can fall by no more than that; a pair's distance by no more than the sum of its spheres'. From a
checked configuration whose per-sphere clearances above ``margin`` (and pair distances above 0) are
d_m, the next ⌊min_m (d_m − slack) / (t_m / n_k)⌋ sub-steps are free and are not evaluated. The verdict
and the first colliding segment are those of checking every sub-step; only the clearance (a minimum
over the evaluated configurations) needs ``exact=True``.

Four refinements keep the verdict that of every sub-step and cut the work (``benchmarks/candidate_check_speed.py``):

- **Many spheres at once.** Where at least :data:`_VECTOR_MIN` spheres are due at a configuration, the
  walk computes every sphere's distance in one loop over the spheres per primitive
  (:func:`_spheres_scene`, vector instructions; the same values to the bit); fewer are computed one by
  one. On motions like the sampler's (300 from each tuning problem's trees, seeds 3004–3010, by turns in
  one process) the walks took 0.84 / 0.85 / 0.94 of the time (ur5 with its gripper, panda, iiwa14;
  thresholds of 2 to 16 within 0.02 of each other).

- **A self-collision pair closes at its own rate.** Turning joint j changes the distance ‖B − A‖ of a
  sphere B after it from a sphere A before it by at most |Δθ_j| times A's distance from the joint's
  axis (as well as B's lever; :func:`~kinlearn.collision.body._axis_distances`), so a pair's budget is
  spent at Σ_j |Δθ_j| min(lever_Bj, axis_Aj) over the joints between them: a pair whose lower sphere
  sits on those axes keeps its budget however far the upper one swings (the panda's hand and forearm).
- **Pairs that cannot touch are left out.** Within the joint limits many self-collision pairs can never
  meet (the panda's hand and its upper arm): :func:`proven_apart` proves it for each pair by branch and
  bound over the limits' box with the pairs' own rates, and the verdict drops them for paths whose
  knots all lie in that box (:attr:`KernelBody.packed_within`; any other path gets every pair). The
  verdicts and first colliding configurations are the same; the compiled sampler's searches take 0.87 /
  0.90 / 0.96× the time at the median (panda, ur5 with its gripper, iiwa14; ``benchmarks/sampler_speed.py``).
- **A probe first, where only the verdict is wanted** (:func:`first_free`, the sampler's motions): a
  few grid configurations spread along the path — its inner knots, then each segment's middle
  sub-step, its quarters, eighths and sixteenths — are checked against the scene, link by link behind a
  ball around each link's spheres. A colliding candidate usually collides inside, where the walk from
  its start arrives late; a probe hit is a grid configuration that collides, so the answer is the
  same. Among a problem's candidates (:func:`first_free`) the probe looks first where the last
  candidates hit (the same segment, the same share of it): alike paths collide in one place. There,
  and at the inner knots once a walk's hit among them was the body against itself, it also looks for
  self-collision: a network's candidates can all fold the arm onto itself, where no scene point tells,
  and each was then walked to its hit. With the segments' sub-steps counted only where the probe needs
  them, the candidate checks of fixed-time plans take 0.51 / 0.96 / 0.96 of stop 37's time (ur5 with
  its gripper, panda, iiwa14; tuning problems, by turns; the same answers).
- **The probe proves the scene clear as it goes.** Each configuration it looks at and finds clear also
  says how far along its segment, either way, the body stays clear: a link's ball clear of the scene
  by d keeps the link's spheres clear while their fastest travel is below d, a sphere looked at alone
  while its own travel is below its clearance (the walk's bounds). Grid configurations inside such a
  window cannot hit and are not looked at. A path the probe passes is walked for the body against
  itself alone, then the gaps the windows left are filled, each from its middle, until every
  configuration of the grid is proven clear of the scene or one is found that is not (a hit, as any
  other). On a free path, the part of every check a plan cannot skip, the probe's levels looked at every
  configuration they reach and the walk then did the scene again. Replaying every ``first_free`` call
  of the fixed-time plans on the held-out scene problems (each kernel in its own process, by turns): 0.72
  / 0.83 / 0.78 of the time (panda, ur5 with its gripper, iiwa14), the same picks; proving the scene
  before the self-collision walk instead cost the ur5 1.21 (its retreat joins fold onto themselves by
  the thousand where the probe sees the scene clear).
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Sequence

import numba
import numpy as np
import torch

from ..errors import ConfigError, DTypeError, NonFiniteError, ObstacleError, ShapeError
from .body import BodySpheres
from .scene import Scene

__all__ = [
    "KernelBody",
    "KernelChain",
    "KernelScene",
    "centres",
    "check_paths",
    "checked_tips",
    "clearances",
    "first_free",
    "first_free_boxed",
    "free_depths",
    "free_depths_boxed",
    "near_pairs",
    "point_distances",
    "proven_apart",
    "warm_up",
]

_TINY = float(np.finfo(np.float64).tiny)
#: Metres of slack in the skipping bound (the float64 error of a distance is ~1e-15 m).
_SLACK = 1e-9

#: A lower link's spheres are grouped against each higher sphere from this many on (fewer: a looser
#: ball bound costs more evaluations than the pairs it saves).
_GROUP_MIN = 4
#: Share of its budget's span after which an item is recomputed at a configuration evaluated anyway.
_REFRESH = 0.5
#: From this many spheres due at a configuration, the walk computes every sphere's distance at once
#: (:func:`_spheres_scene`), else those due one by one.
_VECTOR_MIN = 8

#: Metres of slack when a primitive is culled by its bounding ball (far above a distance's rounding).
_CULL = 1e-9
#: The column of a packed box (15 columns of the Scene's table, then its bounding radius ‖h‖) and of a
#: packed cylinder (14, then √(r² + h²)).
_BOX_BOUND, _CYL_BOUND = 15, 14

_jit = numba.njit(cache=True, nogil=True, fastmath=False)
#: For the small functions the walk and the probe call at every configuration: put into their callers
#: by numba, not called (a call passes each array as a structure; on motions like the sampler's, 300
#: from each tuning problem's trees by turns in one process, the checks took 0.86 / 0.87 / 0.89 of the
#: time, ur5 with its gripper, panda, iiwa14).
_jit_inline = numba.njit(cache=True, nogil=True, fastmath=False, inline="always")


# --------------------------------------------------------------------------------------------------
# One signed distance per kind (the compiled rows of the dispatch table), then the body's FK
# --------------------------------------------------------------------------------------------------


@_jit
def _sd_sphere(x, y, z, t, i):
    dx, dy, dz = x - t[i, 0], y - t[i, 1], z - t[i, 2]
    return math.sqrt(max(dx * dx + dy * dy + dz * dz, _TINY)) - t[i, 3]


@_jit
def _sd_box(x, y, z, t, i):
    dx, dy, dz = x - t[i, 0], y - t[i, 1], z - t[i, 2]
    qx = abs(dx * t[i, 6] + dy * t[i, 9] + dz * t[i, 12]) - t[i, 3]
    qy = abs(dx * t[i, 7] + dy * t[i, 10] + dz * t[i, 13]) - t[i, 4]
    qz = abs(dx * t[i, 8] + dy * t[i, 11] + dz * t[i, 14]) - t[i, 5]
    ox, oy, oz = max(qx, 0.0), max(qy, 0.0), max(qz, 0.0)
    return math.sqrt(max(ox * ox + oy * oy + oz * oz, _TINY)) + min(max(max(qx, qy), qz), 0.0)


@_jit
def _sd_cylinder(x, y, z, t, i):
    dx, dy, dz = x - t[i, 0], y - t[i, 1], z - t[i, 2]
    lx = dx * t[i, 5] + dy * t[i, 8] + dz * t[i, 11]
    ly = dx * t[i, 6] + dy * t[i, 9] + dz * t[i, 12]
    lz = dx * t[i, 7] + dy * t[i, 10] + dz * t[i, 13]
    radial = math.sqrt(max(lx * lx + ly * ly, _TINY)) - t[i, 3]
    axial = abs(lz) - t[i, 4]
    o_r, o_a = max(radial, 0.0), max(axial, 0.0)
    return math.sqrt(max(o_r * o_r + o_a * o_a, _TINY)) + min(max(radial, axial), 0.0)


@_jit_inline
def _gap(p, a, ra, q, b, rb):
    """The distance between two spheres, of centres ``p[a]`` and ``q[b]`` and radii ``ra`` and ``rb`` (the
    centres' distance never below √tiny, as torch's self-collision distance takes it)."""
    dx, dy, dz = p[a, 0] - q[b, 0], p[a, 1] - q[b, 1], p[a, 2] - q[b, 2]
    return math.sqrt(max(dx * dx + dy * dy + dz * dz, _TINY)) - ra - rb


@_jit
def _beyond(x, y, z, t, i, bound, d):
    """Whether primitive ``i`` of table ``t`` (centre in columns 0–2, held in a ball of radius ``bound``
    about it) provably lies farther than ``d`` from the point: a convex set inside a ball has a signed
    distance no smaller than the ball's, ‖p − c‖ − bound (compared squared, with :data:`_CULL` of slack
    for rounding, so a culled primitive could never have lowered the minimum)."""
    lim = d + bound + _CULL
    if not lim > 0.0:  # also d = +inf: nothing to compare with yet
        return False
    dx, dy, dz = x - t[i, 0], y - t[i, 1], z - t[i, 2]
    return dx * dx + dy * dy + dz * dz > lim * lim


@_jit
def _sphere_scene(x, y, z, r, on_floor, spheres, boxes, cylinders, floor):
    """One sphere's signed distance to the scene (+inf when empty). Boxes and cylinders carry their
    bounding radius in their last column (:class:`KernelScene`): one whose bounding ball is already
    farther than the nearest primitive so far is not evaluated (the minimum is the same, to the bit)."""
    d = np.inf
    for i in range(spheres.shape[0]):
        d = min(d, _sd_sphere(x, y, z, spheres, i))
    for i in range(boxes.shape[0]):
        if not _beyond(x, y, z, boxes, i, boxes[i, _BOX_BOUND], d):
            d = min(d, _sd_box(x, y, z, boxes, i))
    for i in range(cylinders.shape[0]):
        if not _beyond(x, y, z, cylinders, i, cylinders[i, _CYL_BOUND], d):
            d = min(d, _sd_cylinder(x, y, z, cylinders, i))
    d = d - r
    if floor[0] > 0.5 and on_floor:
        d = min(d, z - r - floor[1])
    return d


@_jit
def _spheres_scene(c, radii, on_floor, spheres, boxes, cylinders, floor, xyz, out):
    """Every sphere's signed distance to the scene, ``out (M,)`` for centres ``c (M, 3)`` (``xyz (3, M)``:
    work space): :func:`_sphere_scene`'s values to the bit, primitive by primitive over all the spheres,
    a loop the compiler turns into vector instructions. Where many spheres are wanted it is the faster:
    on the ur5 with its gripper (40 spheres) among ten boxes, 0.9 against 3.5 µs per configuration."""
    M = c.shape[0]
    X, Y, Z = xyz[0], xyz[1], xyz[2]
    for m in range(M):
        X[m], Y[m], Z[m] = c[m, 0], c[m, 1], c[m, 2]
        out[m] = np.inf
    for i in range(spheres.shape[0]):
        for m in range(M):
            out[m] = min(out[m], _sd_sphere(X[m], Y[m], Z[m], spheres, i))
    for i in range(boxes.shape[0]):
        for m in range(M):
            out[m] = min(out[m], _sd_box(X[m], Y[m], Z[m], boxes, i))
    for i in range(cylinders.shape[0]):
        for m in range(M):
            out[m] = min(out[m], _sd_cylinder(X[m], Y[m], Z[m], cylinders, i))
    for m in range(M):
        out[m] = out[m] - radii[m]
    if floor[0] > 0.5:
        for m in range(M):
            if on_floor[m]:
                out[m] = min(out[m], Z[m] - radii[m] - floor[1])


@_jit_inline
def _chain(q, F, prismatic, frames):
    """Frames ``(dof + 1, 3, 4)`` of joints ``q (dof,)``: T_0 = I, T_i = T_{i−1} F_i Z(q_i), Z a rotation
    about (or a shift along) z."""
    dof = q.shape[0]
    for a in range(3):
        for b in range(4):
            frames[0, a, b] = 1.0 if a == b else 0.0
    for i in range(dof):
        c, s = (1.0, 0.0) if prismatic[i] else (math.cos(q[i]), math.sin(q[i]))
        for a in range(3):
            p0, p1, p2 = frames[i, a, 0], frames[i, a, 1], frames[i, a, 2]
            a0 = p0 * F[i, 0, 0] + p1 * F[i, 1, 0] + p2 * F[i, 2, 0]
            a1 = p0 * F[i, 0, 1] + p1 * F[i, 1, 1] + p2 * F[i, 2, 1]
            a2 = p0 * F[i, 0, 2] + p1 * F[i, 1, 2] + p2 * F[i, 2, 2]
            a3 = p0 * F[i, 0, 3] + p1 * F[i, 1, 3] + p2 * F[i, 2, 3] + frames[i, a, 3]
            frames[i + 1, a, 0] = c * a0 + s * a1
            frames[i + 1, a, 1] = c * a1 - s * a0
            frames[i + 1, a, 2] = a2
            frames[i + 1, a, 3] = a3 + q[i] * a2 if prismatic[i] else a3


@_jit_inline
def _place(frames, link, folded, out):
    """Points ``out (M, 3)``, each at R_k · folded + p_k of its link k's frame."""
    for m in range(link.shape[0]):
        k = link[m]
        f0, f1, f2 = folded[m, 0], folded[m, 1], folded[m, 2]
        for a in range(3):
            out[m, a] = frames[k, a, 0] * f0 + frames[k, a, 1] * f1 + frames[k, a, 2] * f2 + frames[k, a, 3]


@_jit
def _fk(q, F, prismatic, link, folded, out, frames):
    """Sphere centres ``out (M, 3)`` at joints ``q (dof,)`` (``frames (dof + 1, 3, 4)``: work space); each
    ``folded`` centre is in its link's frame turned so that the joint axis is z (base spheres: as is)."""
    _chain(q, F, prismatic, frames)
    _place(frames, link, folded, out)


@_jit
def _evaluate(
    q, F, prismatic, link, folded, radii, on_floor, pairs, spheres, boxes, cylinders, floor, c, dm, dp, frames, xyz
):  # fmt: skip
    """FK and every distance at ``q``: fills ``c (M, 3)``, ``dm (M,)`` (per sphere, to the scene) and
    ``dp (P,)`` (per self-collision pair); returns (scene clearance, self clearance). ``frames``, ``xyz``:
    work space."""
    _fk(q, F, prismatic, link, folded, c, frames)
    _spheres_scene(c, radii, on_floor, spheres, boxes, cylinders, floor, xyz, dm)
    d = np.inf
    for m in range(link.shape[0]):
        d = min(d, dm[m])
    s = np.inf
    for p in range(pairs.shape[0]):
        a, b = pairs[p, 0], pairs[p, 1]
        dp[p] = _gap(c, a, radii[a], c, b, radii[b])
        s = min(s, dp[p])
    return d, s


@_jit
def _clearances(
    qs, F, prismatic, link, folded, radii, on_floor, pairs, spheres, boxes, cylinders, floor, per
):
    """Configurations ``qs (N, dof)`` → scene and self clearances ``(N,)`` each; ``per (N, M)`` filled with
    each sphere's distance to the scene."""
    n, M = qs.shape[0], link.shape[0]
    d, s = np.empty(n), np.empty(n)
    c, dp, frames = np.empty((M, 3)), np.empty(pairs.shape[0]), np.empty((qs.shape[1] + 1, 3, 4))
    xyz = np.empty((3, M))
    for i in range(n):
        d[i], s[i] = _evaluate(
            qs[i], F, prismatic, link, folded, radii, on_floor, pairs, spheres, boxes, cylinders, floor, c, per[i], dp,
            frames, xyz,
        )  # fmt: skip
    return d, s


@_jit
def _tip_positions(qs, F, prismatic):
    """End-effector positions ``(N, 3)`` of joints ``qs (N, dof)``: the chain's frames (``F[:dof]``), then
    the tip's offset in the last one (``F[dof]``'s translation)."""
    n, dof = qs.shape
    out = np.empty((n, 3))
    frames = np.empty((dof + 1, 3, 4))
    tx, ty, tz = F[dof, 0, 3], F[dof, 1, 3], F[dof, 2, 3]
    for i in range(n):
        _chain(qs[i], F, prismatic, frames)
        for a in range(3):
            out[i, a] = (
                frames[dof, a, 0] * tx + frames[dof, a, 1] * ty + frames[dof, a, 2] * tz + frames[dof, a, 3]
            )
    return out


@_jit
def checked_tips(qs, F, prismatic, lower, upper, tol, ok):
    """(Compiled; other compiled code calls it too: a batch-1 plan's stage 1 checks its ends with it.)
    :func:`_tip_positions`, and ``ok (N,)`` filled with whether each configuration is finite and within
    ``[lower − tol, upper + tol]`` (a comparison with NaN is false)."""
    n, dof = qs.shape
    for i in range(n):
        good = True
        for j in range(dof):
            v = qs[i, j]
            if not (v >= lower[j] - tol and v <= upper[j] + tol):
                good = False
        ok[i] = good
    return _tip_positions(qs, F, prismatic)


@_jit
def _judged(
    flat, K, start, goal, state_goal, F, prismatic, lower, upper, limit_tol, start_tol, position_tol, joint_tol,
    found, free, scores, ok,
):  # fmt: skip
    """The verdict of ``n`` joint paths of ``K`` configurations, ``flat (n · K, dof)`` (:meth:`KernelChain.judged`):
    their end effectors ``(n · K, 3)`` (:func:`checked_tips`) returned, and per path ``scores (2, n)`` its
    goal error (m) and joint error (rad; NaN for a position goal) and ``ok (n,)`` whether it succeeds:
    it stays within the limits (widened by ``limit_tol``), was ``found``, starts within ``start_tol`` of
    ``start (n, dof + 3)``'s joints, is ``free``, its last end effector lies within ``position_tol`` of the
    target, and, for ``state_goal``, its last joints within ``joint_tol`` of the goal's: ``goal (n, dof +
    3)`` the goal states (``state_goal``) or ``(n, 3)`` the target positions. Also whether every value of
    ``flat`` is finite."""
    nK, dof = flat.shape
    knots = np.empty(nK, dtype=np.bool_)
    ef = checked_tips(flat, F, prismatic, lower, upper, limit_tol, knots)
    finite = True
    for i in range(nK // K):
        good = found[i] and free[i]
        for k in range(i * K, (i + 1) * K):
            if not knots[k]:
                good = False
                for j in range(dof):
                    if not math.isfinite(flat[k, j]):
                        finite = False
        far = 0.0
        for j in range(dof):
            far = max(far, abs(flat[i * K, j] - start[i, j]))
        last = (i + 1) * K - 1
        t = dof if state_goal else 0  # the target's first column
        e0, e1, e2 = ef[last, 0] - goal[i, t], ef[last, 1] - goal[i, t + 1], ef[last, 2] - goal[i, t + 2]
        scores[0, i] = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
        good = good and far <= start_tol and scores[0, i] <= position_tol
        if state_goal:
            off = 0.0
            for j in range(dof):
                off = max(off, abs(flat[last, j] - goal[i, j]))
            scores[1, i] = off
            good = good and off <= joint_tol
        else:
            scores[1, i] = np.nan
        ok[i] = good
    return ef, finite


@_jit
def _extent_tensor(out, r, e0, e1, e2, R, o):
    """Columns 7–12 of a model row: L = R diag(e) Rᵀ of rotation ``R[o:o + 9]`` (row-major), summed
    term by term in the order of :func:`~kinlearn.collision.geometry.shape_tensor`."""
    e = (e0, e1, e2)
    ab = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))
    for m in range(6):
        a, b = ab[m]
        t0 = R[o + 3 * a] * e[0] * R[o + 3 * b]
        t1 = R[o + 3 * a + 1] * e[1] * R[o + 3 * b + 1]
        t2 = R[o + 3 * a + 2] * e[2] * R[o + 3 * b + 2]
        out[r, 7 + m] = (t0 + t1) + t2


def _float64(t: torch.Tensor) -> np.ndarray:
    """A tensor's values as a C-contiguous float64 array (a view where the tensor already is one)."""
    if t.dtype != torch.float64 or t.device.type != "cpu" or t.requires_grad:
        t = t.detach().cpu().double()
    return np.ascontiguousarray(t.numpy())


@_jit
def _pack_scene(spheres, boxes, cylinders, has_floor, height):
    """A scene's tables in one buffer ``[K, B, C, has floor, height, spheres…, boxes…, cylinders…]``
    (:attr:`KernelScene.packed`): each box (15 columns) and cylinder followed by the radius of its
    bounding ball, ‖half extents‖ and hypot(radius, half length)."""
    K, B, C, cw = spheres.shape[0], boxes.shape[0], cylinders.shape[0], cylinders.shape[1]
    buf = np.empty(5 + 4 * K + 16 * B + (cw + 1) * C)
    buf[0], buf[1], buf[2], buf[3], buf[4] = K, B, C, has_floor, height
    o = 5
    for i in range(K):
        for j in range(4):
            buf[o + j] = spheres[i, j]
        o += 4
    for i in range(B):
        for j in range(15):
            buf[o + j] = boxes[i, j]
        buf[o + 15] = math.sqrt(
            boxes[i, 3] * boxes[i, 3] + boxes[i, 4] * boxes[i, 4] + boxes[i, 5] * boxes[i, 5]
        )
        o += 16
    for i in range(C):
        for j in range(cw):
            buf[o + j] = cylinders[i, j]
        buf[o + cw] = math.hypot(cylinders[i, 3], cylinders[i, 4])
        o += cw + 1
    return buf


@_jit
def _model_rows(spheres, boxes, cylinders, reach):
    """The obstacle TM's rows ``(P, 14)`` of packed tables (see :meth:`KernelScene.model_rows`): every
    primitive's whose bounding ball comes within ``reach`` of the origin."""
    K, B, C = spheres.shape[0], boxes.shape[0], cylinders.shape[0]
    out = np.zeros((K + B + C, 14))
    for i in range(K):
        for a in range(3):
            out[i, a] = spheres[i, a]
            out[i, 3 + a] = spheres[i, 3]
            out[i, 7 + a] = spheres[i, 3]
        out[i, 6] = 1.0
    for i in range(B):
        r = K + i
        for a in range(3):
            out[r, a] = boxes[i, a]
            # Σ_b |R_ab| h_b, summed in the order b = 0, 1, 2 (as torch and NumPy sum three terms)
            out[r, 3 + a] = (
                abs(boxes[i, 6 + 3 * a]) * boxes[i, 3]
                + abs(boxes[i, 7 + 3 * a]) * boxes[i, 4]
                + abs(boxes[i, 8 + 3 * a]) * boxes[i, 5]
            )
        _extent_tensor(out, r, boxes[i, 3], boxes[i, 4], boxes[i, 5], boxes[i], 6)
    for i in range(C):
        r = K + B + i
        for a in range(3):
            out[r, a] = cylinders[i, a]
            ax = cylinders[i, 7 + 3 * a]  # the axis: column 2 of R
            out[r, 3 + a] = cylinders[i, 3] * math.sqrt(max(1.0 - ax * ax, _TINY)) + cylinders[i, 4] * abs(ax)
        _extent_tensor(out, r, cylinders[i, 3], cylinders[i, 3], cylinders[i, 4], cylinders[i], 5)
        out[r, 13] = 1.0
    if reach == np.inf:
        return out
    kept = 0  # the rows of the primitives within reach, moved up in place
    for r in range(K + B + C):
        if r < K:
            bound = spheres[r, 3]
        elif r < K + B:
            bound = boxes[r - K, _BOX_BOUND]
        else:
            bound = cylinders[r - K - B, _CYL_BOUND]
        if math.sqrt(out[r, 0] ** 2 + out[r, 1] ** 2 + out[r, 2] ** 2) - bound <= reach:
            out[kept] = out[r]
            kept += 1
    return out[:kept].copy()


@_jit
def _centres(qs, F, prismatic, link, folded):
    out = np.empty((qs.shape[0], link.shape[0], 3))
    frames = np.empty((qs.shape[1] + 1, 3, 4))
    for i in range(qs.shape[0]):
        _fk(qs[i], F, prismatic, link, folded, out[i], frames)
    return out


@_jit
def _check(
    path, max_travel, margin, exact, F, prismatic, link, folded, radii, on_floor, pairs, lever,
    spheres, boxes, cylinders, floor,
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
                q, F, prismatic, link, folded, radii, on_floor, pairs, spheres, boxes, cylinders, floor, c, dm, dp,
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


@_jit_inline
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


@_jit
def _grid_steps(path, max_travel, lever, steps):
    """Fill ``steps (W − 1,)`` with each segment's number of sub-steps (:func:`_segment_steps`)."""
    for k in range(path.shape[0] - 1):
        steps[k] = _segment_steps(path, k, max_travel, lever)


@_jit_inline
def _steps_at(steps, path, k, max_travel, lever):
    """Segment k's sub-steps from ``steps``, counted there on first use (0: not yet). A probe that hits at
    a hint or a knot, as most candidates' probes do (the median looks at one configuration), counts no
    segment or one, not every one: the candidate checks of fixed-time plans on the tuning problems
    (seeds 3004–3010) took 0.97 / 0.95 of the time (ur5 with its gripper / panda; the same answers)."""
    if steps[k] == 0.0:
        steps[k] = _segment_steps(path, k, max_travel, lever)
    return steps[k]


@_jit_inline
def _stale(due, since, pos):
    """Whether an item of the walk is recomputed at global sub-step ``pos``: its budget is spent (``due``),
    or more than :data:`_REFRESH` of its span from ``since`` (where it was last computed) has passed."""
    return due <= pos or pos - since >= _REFRESH * (due - since)


@_jit_inline
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


@_jit
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
    ``body``: the arrays of :func:`_unpack_body`; ``scene``: those of :func:`_unpack_scene`.
    ``scene_clear``: every configuration of the grid is already proven clear of the scene (the probe's
    :func:`_prove_clear`): only the body against itself is walked."""
    F, prismatic, link, folded, radii, on_floor, pairs, lever = body[:8]
    g_sphere, g_ball, g_start, g_members, b_link, b_folded, b_radius, p_lever, g_lever, m_lever = body[8:18]
    spheres, boxes, cylinders, floor = scene
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
            _spheres_scene(c, radii, on_floor, spheres, boxes, cylinders, floor, xyz, dm)
        for m in range(M):
            if _stale(due_m[m], from_m[m], pos):
                from_m[m] = pos
                if every:
                    d = dm[m]
                else:
                    d = _sphere_scene(
                        c[m, 0], c[m, 1], c[m, 2], radii[m], on_floor[m], spheres, boxes, cylinders, floor
                    )
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


#: How many halvings of each segment the probe looks at: its middle sub-step, then its quarters, eighths
#: and sixteenths (on the panda's held-out candidates 4 let 18 of 1,382 colliding ones through to the
#: walk, 2 let 325; more cost more probes than they save).
_PROBE_LEVELS = 4


@_jit_inline
def _scene_hit(q, margin, body, scene, frames):
    """Whether some sphere of ``body`` at joints ``q`` is within ``margin`` of the scene (self-collision not
    looked at). Link by link: a link whose ball (holding its spheres ``l_start[l]`` to ``l_start[l + 1]``)
    is farther than ``margin`` from the scene has none there, and its spheres are not placed."""
    F, prismatic, _, folded, radii, on_floor = body[:6]
    l_start, l_folded, l_radius = body[18:21]
    spheres, boxes, cylinders, floor = scene
    _chain(q, F, prismatic, frames)
    for lk in range(l_start.shape[0] - 1):
        a, b = l_start[lk], l_start[lk + 1]
        if a == b:
            continue
        x, y, z = _point(frames, lk, l_folded[lk])
        if _sphere_scene(x, y, z, l_radius[lk], lk > 0, spheres, boxes, cylinders, floor) > margin:
            continue
        for m in range(a, b):
            x, y, z = _point(frames, lk, folded[m])
            if _sphere_scene(x, y, z, radii[m], on_floor[m], spheres, boxes, cylinders, floor) <= margin:
                return True
    return False


@_jit_inline
def _scene_clear(q, margin, body, scene, frames, link_lever, path, k, n):
    """:func:`_scene_hit` at a configuration ``q`` of segment ``k`` (``n`` sub-steps) that also says how far
    along the segment, either way, its clearances prove the body clear of the scene: −1 where some sphere is
    within ``margin``, else w > 0 such that every grid configuration of the segment fewer than w sub-steps
    from ``q`` is clear. A link whose ball is clear proves its spheres clear while the ball's clearance
    outlasts their fastest travel (``link_lever``: per link and joint the largest lever of its spheres);
    a sphere looked at alone, while its own clearance outlasts its own travel (the walk's bound)."""
    F, prismatic, _, folded, radii, on_floor = body[:6]
    lever = body[7]
    l_start, l_folded, l_radius = body[18:21]
    spheres, boxes, cylinders, floor = scene
    dof = q.shape[0]
    _chain(q, F, prismatic, frames)
    w = np.inf
    for lk in range(l_start.shape[0] - 1):
        a, b = l_start[lk], l_start[lk + 1]
        if a == b:
            continue
        x, y, z = _point(frames, lk, l_folded[lk])
        d = _sphere_scene(x, y, z, l_radius[lk], lk > 0, spheres, boxes, cylinders, floor)
        if d > margin:
            rate = 0.0
            for j in range(dof):
                rate += abs(path[k + 1, j] - path[k, j]) * link_lever[lk, j]
            if rate > 0.0:
                w = min(w, (d - margin - _SLACK) * n / rate)
            continue
        for m in range(a, b):
            x, y, z = _point(frames, lk, folded[m])
            d = _sphere_scene(x, y, z, radii[m], on_floor[m], spheres, boxes, cylinders, floor)
            if d <= margin:
                return -1.0
            rate = 0.0
            for j in range(dof):
                rate += abs(path[k + 1, j] - path[k, j]) * lever[m, j]
            if rate > 0.0:
                w = min(w, (d - margin - _SLACK) * n / rate)
    return w


@_jit_inline
def _link_levers(body, out):
    """Into ``out``, per link (as ``l_start`` groups the spheres) and joint, the largest lever of the link's
    spheres."""
    lever, l_start = body[7], body[18]
    out[:] = 0.0
    for lk in range(l_start.shape[0] - 1):
        for m in range(l_start[lk], l_start[lk + 1]):
            for j in range(lever.shape[1]):
                out[lk, j] = max(out[lk, j], lever[m, j])


@_jit_inline
def _proven(cen, wid, cnt, k, i):
    """Whether grid sub-step ``i`` of segment ``k`` lies within a window a probed configuration proved clear."""
    for t in range(cnt[k]):
        if abs(i - cen[k, t]) < wid[k, t]:
            return True
    return False


@_jit_inline
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


@_jit_inline
def _point(frames, k, v):
    """R_k · v + p_k: a point fixed in link k's frame, placed."""
    return (
        frames[k, 0, 0] * v[0] + frames[k, 0, 1] * v[1] + frames[k, 0, 2] * v[2] + frames[k, 0, 3],
        frames[k, 1, 0] * v[0] + frames[k, 1, 1] * v[1] + frames[k, 1, 2] * v[2] + frames[k, 1, 3],
        frames[k, 2, 0] * v[0] + frames[k, 2, 1] * v[1] + frames[k, 2, 2] * v[2] + frames[k, 2, 3],
    )


@_jit_inline
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


@_jit_inline
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


@_jit
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


@_jit
def _after_probe(path, max_travel, margin, body, scene, windows):
    """The verdict of a path the probe (:func:`_probe`, which gave ``windows``) did not see collide: the walk
    of the body against itself first (:func:`_verdict` with the scene left out: a hit there ends it
    early), then the rest of the grid proven clear of the scene (:func:`_prove_clear`). Returns (first
    colliding segment or −1, the hit's fraction of it, whether the hit is the body against itself): a
    self-collision first found by the walk, a scene hit by the proof. Which comes first matters on the
    ur5 with its gripper, whose retreat joins fold onto themselves by the thousand where the probe saw the
    scene clear: proving the scene clear before the walk cost the ``first_free`` calls of its fixed-time
    plans 1.21× the time of probe-then-walk, where the self-walk first answers them sooner than that walk
    did."""
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

#: How many places where candidates hit the scene :func:`_first_free` keeps for the next one's probe (on the
#: panda's candidates for its tuning problems, seeds 3004–3010: 1 cut the probe's configurations from 737 to
#: 359 per problem, 2 to 283, 4 to 272, 8 no further).
_HINTS = 4


@_jit
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


@_jit
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


@_jit
def _unpack_scene(buf):
    """A scene packed by :attr:`KernelScene.packed`: [K, B, C, has floor, height, rows…] → its tables."""
    K, B, C = int(buf[0]), int(buf[1]), int(buf[2])
    o = 5
    spheres = buf[o : o + 4 * K].reshape(K, 4)
    o += 4 * K
    boxes = buf[o : o + 16 * B].reshape(B, 16)
    o += 16 * B
    cylinders = buf[o : o + 15 * C].reshape(C, 15)
    return spheres, boxes, cylinders, buf[3:5]


@_jit
def _unpack_body(f, n):
    """A body packed by :attr:`KernelBody.packed` (floats ``f``, integers ``n``) → the verdict's arrays."""
    dof, M, P, G, E, L = n[0], n[1], n[2], n[3], n[4], n[5]
    o = 0
    F = f[o : o + 16 * dof].reshape(dof, 4, 4)
    o += 16 * dof
    folded = f[o : o + 3 * M].reshape(M, 3)
    o += 3 * M
    radii = f[o : o + M]
    o += M
    lever = f[o : o + M * dof].reshape(M, dof)
    o += M * dof
    b_folded = f[o : o + 3 * L].reshape(L, 3)
    o += 3 * L
    b_radius = f[o : o + L]
    o += L
    p_lever = f[o : o + P * dof].reshape(P, dof)
    o += P * dof
    g_lever = f[o : o + G * dof].reshape(G, dof)
    o += G * dof
    m_lever = f[o : o + E * dof].reshape(E, dof)
    o += E * dof
    l_folded = f[o : o + 3 * (dof + 1)].reshape(dof + 1, 3)
    o += 3 * (dof + 1)
    l_radius = f[o : o + dof + 1]
    i = 6
    prismatic = n[i : i + dof] != 0
    i += dof
    link = n[i : i + M]
    i += M
    on_floor = n[i : i + M] != 0
    i += M
    pairs = n[i : i + 2 * P].reshape(P, 2)
    i += 2 * P
    g_sphere = n[i : i + G]
    i += G
    g_ball = n[i : i + G]
    i += G
    g_start = n[i : i + G + 1]
    i += G + 1
    g_members = n[i : i + E]
    i += E
    b_link = n[i : i + L]
    i += L
    l_start = n[i : i + dof + 2]
    return (
        F, prismatic, link, folded, radii, on_floor, pairs, lever,
        g_sphere, g_ball, g_start, g_members, b_link, b_folded, b_radius, p_lever, g_lever, m_lever,
        l_start, l_folded, l_radius,
    )  # fmt: skip


@_jit
def _verdict_packed(path, max_travel, margin, f, n, s):
    """:func:`_verdict` on a packed body and scene (few arguments: each costs a call about 0.25 µs)."""
    return _verdict(path, max_travel, margin, _unpack_body(f, n), _unpack_scene(s))


@_jit
def _free_packed(path, max_travel, margin, f, n, s):
    """Whether ``path`` is free under the dense check (:func:`_verdict`'s answer), for callers that need no
    first colliding segment (a sampler's motions): its last knot first (a sampler's new state; OMPL's
    discrete motion validator also looks at it first), then the probe (:func:`_probe`), then the walk.
    Each is a configuration of the walk's grid: the same verdict. The compiled RRT-Connect on the tuning
    scenes (seeds 3004–3010, the same searches, in one process by turns), against the probe without the
    last knot first: total time 0.76 / 0.86 / 0.89 (ur5 with its gripper, panda, iiwa14), median problem
    0.98 / 1.01 / 1.02; one halving in the probe instead of four, 0.85 / 0.94 / 0.90 and 1.07 / 1.33 / 0.98."""
    body, scene = _unpack_body(f, n), _unpack_scene(s)
    if _scene_hit(path[path.shape[0] - 1], margin, body, scene, np.empty((path.shape[1] + 1, 3, 4))):
        return False
    hit, _, _, _, windows = _probe(path, max_travel, margin, body, scene, _NO_HINTS, 0)
    if hit:
        return False
    return _after_probe(path, max_travel, margin, body, scene, windows)[0] < 0


@_jit
def _first_free_packed(paths, order, max_travel, margin, f, n, s, n_hints=_HINTS):
    """:func:`_first_free` on a packed body and scene; −2 if ``paths`` hold NaN or infinity."""
    if not _all_finite(paths):
        return -2
    return _first_free(paths, order, max_travel, margin, _unpack_body(f, n), _unpack_scene(s), n_hints)


@_jit
def first_free_boxed(paths, order, max_travel, margin, box_lo, box_hi, f_in, n_in, f_all, n_all, s):
    """:func:`first_free`'s compiled core, for other compiled code to call (the planner's proposals):
    the body packed without the pairs proven apart (``f_in, n_in``) when every knot of ``paths`` lies in
    its box ``[box_lo, box_hi]``, else whole (``f_all, n_all``), as :meth:`KernelBody.packing_of` picks
    (:meth:`KernelBody.boxed` gives the six); the index of the first free path in ``order``, −1 if none
    is, −2 if ``paths`` hold NaN or infinity."""
    if _within(paths, box_lo, box_hi):
        return _first_free_packed(paths, order, max_travel, margin, f_in, n_in, s)
    return _first_free_packed(paths, order, max_travel, margin, f_all, n_all, s)


@_jit
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


@_jit
def _within(paths, lo, hi):
    """Whether every value of ``paths (..., dof)`` lies in ``[lo, hi]`` (NaN does not)."""
    dof = lo.shape[0]
    flat = paths.reshape(-1, dof)
    for i in range(flat.shape[0]):
        for j in range(dof):
            v = flat[i, j]
            if not (v >= lo[j] and v <= hi[j]):
                return False
    return True


@_jit
def _apart(F, prismatic, a_link, a_folded, b_link, b_folded, gap, rates, lo, hi, max_cells):
    """Whether two spheres (centres fixed in links ``a_link`` and ``b_link``, radii summing to ``gap``)
    stay apart for every configuration in the box ``[lo, hi]``: 1 proven (branch and bound), −1 a
    configuration where they touch found, 0 undecided within ``max_cells`` cells. A cell (centre c,
    half-widths h) holds no contact when d(c) − Σ_j h_j · ``rates[j]`` > 0: ``rates[j]`` bounds how fast
    the pair's distance changes per unit of joint j over all configurations (the verdict's own pair
    rates, 0 for the joints that move both spheres or neither); else the cell is halved along the joint
    that spends most of the bound."""
    dof = lo.shape[0]
    C, H = np.empty((max_cells + 2, dof)), np.empty((max_cells + 2, dof))
    for j in range(dof):
        C[0, j] = 0.5 * (lo[j] + hi[j])
        H[0, j] = 0.5 * (hi[j] - lo[j]) if rates[j] > 0.0 else 0.0
    frames, c, h = np.empty((dof + 1, 3, 4)), np.empty(dof), np.empty(dof)
    n, used = 1, 0
    while n > 0:
        n -= 1
        used += 1
        if used > max_cells:
            return 0
        for j in range(dof):
            c[j], h[j] = C[n, j], H[n, j]
        _chain(c, F, prismatic, frames)
        ax, ay, az = _point(frames, a_link, a_folded)
        bx, by, bz = _point(frames, b_link, b_folded)
        d = math.sqrt((ax - bx) ** 2 + (ay - by) ** 2 + (az - bz) ** 2) - gap
        if d <= 0.0:
            return -1
        spend, best, widest = 0.0, -1, 0.0
        for j in range(dof):
            w = h[j] * rates[j]
            spend += w
            if w > widest:
                widest, best = w, j
        if d - spend > _SLACK:
            continue
        h[best] *= 0.5
        for side in (-1.0, 1.0):
            for j in range(dof):
                C[n, j], H[n, j] = c[j], h[j]
            C[n, best] = c[best] + side * h[best]
            n += 1
    return 1


# --------------------------------------------------------------------------------------------------
# Python side: the body and the scene packed once, checked arguments
# --------------------------------------------------------------------------------------------------


class KernelBody:
    """A :class:`BodySpheres` packed for the kernels (float64 arrays): the canonical fixed transforms
    ``F (dof, 4, 4)`` of its chain, each sphere's link and centre in its link's canonical frame, radii,
    the spheres the floor applies to, self-collision pairs and lever bounds."""

    @classmethod
    def of(cls, body: BodySpheres) -> KernelBody:
        """The packed ``body``, made on the first call for that body object and kept while it lives
        (a body's buffers are not changed after it is made)."""
        hit = _BODIES.get(body) if isinstance(body, BodySpheres) else None
        if hit is None:
            hit = cls(body)
            _BODIES[body] = hit
        return hit

    def __init__(self, body: BodySpheres):
        if not isinstance(body, BodySpheres):
            raise ConfigError(f"KernelBody needs a BodySpheres, got {type(body).__name__}")
        from ..body.kinematics import _z_to_axis
        from .body import _axis_distances

        robot = body.robot
        self.robot, self.name, self.dof = robot, body.name, robot.dof
        #: How far from the base's origin the body can reach (:attr:`BodySpheres.reach`, m): the obstacle
        #: network reads the primitives within it (:meth:`KernelScene.model_rows`).
        self.reach = body.reach
        local = body.local.detach().cpu().double().numpy()
        self.link = np.ascontiguousarray(body.link.cpu().numpy().astype(np.int64))
        folded = local.copy()
        for m, k in enumerate(self.link):
            if k > 0:
                folded[m] = _z_to_axis(robot.joints[k - 1].axis).T @ local[m]
        self.folded = np.ascontiguousarray(folded)
        self.F = np.ascontiguousarray(np.asarray(body._kin.F[: robot.dof], dtype=np.float64))
        self.prismatic = np.array([j.kind == "prismatic" for j in robot.joints], dtype=np.bool_)
        self.radii = np.ascontiguousarray(body.radii.detach().cpu().double().numpy())
        self.on_floor = np.ascontiguousarray(body.floor_mask.cpu().numpy().astype(np.bool_))
        self.pairs = np.ascontiguousarray(body.pairs.cpu().numpy().astype(np.int64).reshape(-1, 2))
        self.lever = np.ascontiguousarray(body.lever.detach().cpu().double().numpy())
        self._packed = None
        # A ball per link around its spheres (centre: their mean, in the link's frame; the spheres are
        # sorted by link, those of link l are l_start[l] to l_start[l + 1]): the probe's broad phase, and
        # the bound of a group of pairs with that link's spheres.
        self.l_start = np.ascontiguousarray(
            np.searchsorted(self.link, np.arange(self.dof + 2)).astype(np.int64)
        )
        self.l_folded = np.zeros((self.dof + 1, 3))
        self.l_radius = np.zeros(self.dof + 1)
        for lk in range(self.dof + 1):
            a, b = self.l_start[lk], self.l_start[lk + 1]
            if b > a:
                self.l_folded[lk] = self.folded[a:b].mean(axis=0)
                self.l_radius[lk] = float(
                    (np.linalg.norm(self.folded[a:b] - self.l_folded[lk], axis=1) + self.radii[a:b]).max()
                )
        self._axis = _axis_distances(robot, self.link, local)
        # The joint box the pairs below are proven apart in: the robot's limits, widened by BOX_SLACK.
        self.box = (
            np.asarray(robot.lower, dtype=np.float64) - BOX_SLACK,
            np.asarray(robot.upper, dtype=np.float64) + BOX_SLACK,
        )
        self._apart = None
        self._packed_within = None
        self._boxed = None

    def _items(self, pairs: np.ndarray) -> dict:
        """The verdict's self-collision items of ``pairs``, by name: a sphere's pairs with the
        spheres of one lower link (one that has at least _GROUP_MIN) go as one item, bounded by a ball
        around that link's spheres (centre: their mean, in its frame); the other pairs one by one."""
        la, lb = self.link[pairs[:, 0]], self.link[pairs[:, 1]]
        upper = np.where(la > lb, pairs[:, 0], pairs[:, 1])  # the sphere on the higher link
        lower = np.where(la > lb, pairs[:, 1], pairs[:, 0])
        counts = np.bincount(self.link, minlength=self.dof + 1)
        grouped = counts[self.link[lower]] >= _GROUP_MIN
        ball_links = np.unique(self.link[lower[grouped]])
        index = {int(l): b for b, l in enumerate(ball_links)}
        up, low = upper[grouped], lower[grouped]
        key = up * (self.dof + 1) + self.link[low]
        order = np.argsort(key, kind="stable")
        keys, starts = np.unique(key[order], return_index=True)
        it = {
            "pairs": np.ascontiguousarray(pairs[~grouped]),
            "b_link": np.ascontiguousarray(ball_links.astype(np.int64)),
            "b_folded": np.ascontiguousarray(self.l_folded[ball_links].reshape(-1, 3)),
            "b_radius": np.ascontiguousarray(self.l_radius[ball_links]),
            "g_sphere": np.ascontiguousarray((keys // (self.dof + 1)).astype(np.int64)),
            "g_ball": np.array([index[int(l)] for l in keys % (self.dof + 1)], dtype=np.int64),
            "g_start": np.ascontiguousarray(np.append(starts, len(order)).astype(np.int64)),
            "g_members": np.ascontiguousarray(low[order].astype(np.int64)),
        }
        # How fast each self-collision item can close, per radian of each joint between its links: the
        # smaller of the upper sphere's lever and the lower sphere's distance from the joint's axis
        # (:func:`~kinlearn.collision.body._axis_distances`); a group's, the largest over its members.
        g_lever = np.zeros((len(it["g_sphere"]), self.dof))
        m_lever = np.zeros((len(it["g_members"]), self.dof))
        for g, x in enumerate(it["g_sphere"]):
            span = slice(it["g_start"][g], it["g_start"][g + 1])
            members = it["g_members"][span]
            m_lever[span] = self._item_lever(np.stack([np.full(len(members), x), members], axis=1))
            g_lever[g] = m_lever[span].max(axis=0)
        it["pair_lever"] = np.ascontiguousarray(self._item_lever(it["pairs"]))
        it["group_lever"] = np.ascontiguousarray(g_lever)
        it["member_lever"] = np.ascontiguousarray(m_lever)
        return it

    def _item_lever(self, pairs: np.ndarray) -> np.ndarray:
        """``(P, dof)``: per pair and joint, min(lever of its upper sphere, axis distance of its lower one)
        for the joints between their links (those that move one and not the other), 0 for the rest."""
        la, lb = self.link[pairs[:, 0]], self.link[pairs[:, 1]]
        up = np.where(la > lb, pairs[:, 0], pairs[:, 1])
        low = np.where(la > lb, pairs[:, 1], pairs[:, 0])
        j = np.arange(self.dof)
        between = (j[None] >= self.link[low][:, None]) & (j[None] < self.link[up][:, None])
        return np.where(between, np.minimum(self.lever[up], self._axis[low]), 0.0)

    @property
    def apart(self) -> np.ndarray:
        """``(P,)`` bool: the self-collision pairs proven never to touch while every joint is in
        :attr:`box` (see :func:`proven_apart`); made on first use, kept per body's numbers."""
        if self._apart is None:
            self._apart = proven_apart(self)
        return self._apart

    @property
    def num_spheres(self) -> int:
        return int(self.radii.shape[0])

    def fk_args(self) -> tuple:
        return self.F, self.prismatic, self.link, self.folded

    def args(self) -> tuple:
        return self.F, self.prismatic, self.link, self.folded, self.radii, self.on_floor, self.pairs

    @property
    def packed(self) -> tuple[np.ndarray, np.ndarray]:
        """The verdict's arrays in two buffers (floats, integers), for the packed entry points: every
        self-collision pair, right for any path."""
        if self._packed is None:
            self._packed = self._pack(self._items(self.pairs))
        return self._packed

    @property
    def packed_within(self) -> tuple[np.ndarray, np.ndarray]:
        """:attr:`packed` without the pairs proven apart (:attr:`apart`): the same verdicts, for paths
        whose every knot lies in :attr:`box` (the box is convex: so does every configuration between)."""
        if self._packed_within is None:
            self._packed_within = self._pack(self._items(self.pairs[~self.apart]))
        return self._packed_within

    def packing_of(self, paths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The packing for ``paths (..., dof)`` (float64, C-contiguous): :attr:`packed_within` when every
        knot lies in :attr:`box`, else :attr:`packed`. Paths between points that all lie in the box stay
        in it (the box is convex): pass those points to choose for them all."""
        if _within(paths, *self.box):
            return self.packed_within
        return self.packed

    @property
    def boxed(self) -> tuple[np.ndarray, ...]:
        """What :func:`first_free_boxed` takes of the body: :attr:`box`, :attr:`packed_within`,
        :attr:`packed` (made once)."""
        if self._boxed is None:
            self._boxed = (*self.box, *self.packed_within, *self.packed)
        return self._boxed

    def _pack(self, it: dict) -> tuple[np.ndarray, np.ndarray]:
        """The body and self-collision items ``it`` (:meth:`_items`) in two buffers (:func:`_unpack_body`)."""
        M, P, G = len(self.radii), len(it["pairs"]), len(it["g_sphere"])
        E, L = len(it["g_members"]), len(it["b_link"])
        f = np.concatenate(
            [
                self.F.ravel(),
                self.folded.ravel(),
                self.radii,
                self.lever.ravel(),
                it["b_folded"].ravel(),
                it["b_radius"],
                it["pair_lever"].ravel(),
                it["group_lever"].ravel(),
                it["member_lever"].ravel(),
                self.l_folded.ravel(),
                self.l_radius,
            ]
        )
        n = np.concatenate(
            [
                [self.dof, M, P, G, E, L],
                self.prismatic.astype(np.int64),
                self.link,
                self.on_floor.astype(np.int64),
                it["pairs"].ravel(),
                it["g_sphere"],
                it["g_ball"],
                it["g_start"],
                it["g_members"],
                it["b_link"],
                self.l_start,
            ]
        ).astype(np.int64)
        return np.ascontiguousarray(f), np.ascontiguousarray(n)

    def __repr__(self) -> str:
        return f"KernelBody(robot={self.robot.name!r}, set={self.name!r}, spheres={self.num_spheres}, pairs={len(self.pairs)})"


class KernelChain:
    """A robot's end-effector FK for the kernels: its canonical fixed transforms ``F (dof + 1, 4, 4)`` (the
    last one to the tip) and which joints are prismatic. :meth:`of` packs a robot once."""

    __slots__ = ("F", "__weakref__", "dof", "lower", "prismatic", "upper")

    @classmethod
    def of(cls, robot) -> KernelChain:
        """The packed chain of ``robot`` (a :class:`~kinlearn.body.robot.Robot`), made on its first call and
        kept while the robot lives."""
        hit = _CHAINS.get(robot)
        if hit is None:
            hit = _CHAINS[robot] = cls(robot)
        return hit

    def __init__(self, robot):
        from ..body.kinematics import kinematics

        kin = kinematics(robot, "fast")
        self.F = np.ascontiguousarray(np.asarray(kin.F, dtype=np.float64))
        self.prismatic = np.array(kin.prismatic, dtype=np.bool_)
        self.dof = int(robot.dof)
        self.lower = np.ascontiguousarray(robot.lower, dtype=np.float64)
        self.upper = np.ascontiguousarray(robot.upper, dtype=np.float64)

    def checked(self, q: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray]:
        """``(positions (N, 3), ok (N,))`` of float64 joints ``q (N, dof)``: :meth:`position`, and whether
        each configuration is finite and within the joint limits widened by ``tol`` (one call)."""
        ok = np.empty(q.shape[0], dtype=np.bool_)
        q = q if q.flags.c_contiguous else np.ascontiguousarray(q)
        return checked_tips(q, self.F, self.prismatic, self.lower, self.upper, float(tol), ok), ok

    def judged(
        self, flat, K: int, start, goal, state_goal: bool, tols: tuple, found, free
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
        """The arithmetic of a plan's verdict in one call (:func:`~kinlearn.planning.plan.verdict_small`
        holds the rule): ``flat (n · K, dof)`` float64 joint paths of K configurations, start states
        ``start (n, dof + 3)``, goal states ``goal (n, dof + 3)`` (``state_goal``) or target positions
        ``(n, 3)``, ``tols`` (limit, start, position, joint tolerance), ``found``, ``free (n,)`` bool
        (C-contiguous, as every array: one compiled version) → end effectors ``(n · K, 3)``, ``scores (2, n)`` (goal error,
        joint error: NaN unless ``state_goal``), ``ok (n,)`` (success) and whether every joint value is
        finite."""
        n = flat.shape[0] // K
        scores, ok = np.empty((2, n)), np.empty(n, dtype=np.bool_)
        ef, finite = _judged(
            flat, K, start, goal, state_goal, self.F, self.prismatic, self.lower, self.upper, *tols, found,
            free, scores, ok,
        )  # fmt: skip
        return ef, scores, ok, finite

    def position(self, q: np.ndarray) -> np.ndarray:
        """End-effector positions ``(N, 3)`` of float64 joints ``q (N, dof)`` (the caller's checked
        values: no conversion here), the numbers of :meth:`FastKinematics.position` to rounding."""
        return _tip_positions(q if q.flags.c_contiguous else np.ascontiguousarray(q), self.F, self.prismatic)


class KernelScene:
    """One (unbatched) :class:`Scene` packed for the kernels: a float64 table per kind, padding dropped,
    and ``floor = [has floor, height]``. :meth:`of` packs a scene once and reuses it (scenes are
    immutable)."""

    __slots__ = ("__weakref__", "_buf", "_rows", "boxes", "cylinders", "floor", "spheres")

    @classmethod
    def of(cls, scene: Scene) -> KernelScene:
        """The packed ``scene``, made on the first call for that scene object and kept while it lives."""
        hit = _PACKED.get(scene) if isinstance(scene, Scene) else None
        if hit is None:
            hit = cls(scene)
            _PACKED[scene] = hit
        return hit

    def __init__(self, scene: Scene):
        if not isinstance(scene, Scene):
            raise ObstacleError(f"expected a kinlearn Scene, got {type(scene).__name__}")
        if len(scene.batch_shape):
            raise ObstacleError(
                f"a KernelScene holds one scene, got batch shape {tuple(scene.batch_shape)}; index it first"
            )
        s, b, c = (_float64(t) for _, t, _ in scene.tables(live=True))
        floor = (0.0, 0.0) if scene.floor is None else (1.0, float(scene.floor))
        # One buffer [K, B, C, has floor, height, spheres…, boxes…, cylinders…], each box and cylinder
        # with the radius of its bounding ball last (the kernels cull by it); the tables are views of it.
        self._buf = buf = _pack_scene(s, b, c, floor[0], floor[1])
        K, B, C = s.shape[0], b.shape[0], c.shape[0]
        o = 5 + 4 * K
        self.spheres = buf[5:o].reshape(K, 4)
        self.boxes = buf[o : o + 16 * B].reshape(B, 16)
        o += 16 * B
        self.cylinders = buf[o : o + (c.shape[1] + 1) * C].reshape(C, c.shape[1] + 1)
        self.floor = buf[3:5]
        self._rows = None

    def model_rows(self, reach: float = math.inf) -> np.ndarray:
        """The scene as the obstacle-aware TM reads it, float64 ``(P, 14)``: per primitive its centre, the
        half extents of its axis-aligned bounding box, whether it is a sphere, its extent tensor and
        whether it is a cylinder; spheres first, then boxes, then cylinders (the rows of
        :func:`~kinlearn.models.obstacle_path.scene_primitives` without padding, computed from this
        packing: the scene is converted once). ``reach``: only the primitives whose bounding ball comes
        within it of the base's origin (:attr:`~kinlearn.collision.BodySpheres.reach`: those the robot can
        touch)."""
        if self._rows is None:
            self._rows = {}
        rows = self._rows.get(reach)
        if rows is None:  # per reach asked (a planner asks with its body's, every plan)
            rows = self._rows[reach] = _model_rows(self.spheres, self.boxes, self.cylinders, float(reach))
        return rows

    def args(self) -> tuple:
        return self.spheres, self.boxes, self.cylinders, self.floor

    @property
    def packed(self) -> np.ndarray:
        """The scene in one buffer: [K, B, C, has floor, height, spheres…, boxes…, cylinders…]."""
        return self._buf

    def __repr__(self) -> str:
        return (
            f"KernelScene(spheres={len(self.spheres)}, boxes={len(self.boxes)}, cylinders={len(self.cylinders)}, "
            f"floor={'none' if not self.floor[0] else f'{self.floor[1]:.3f} m'})"
        )


#: Radians the box self-collision pairs are proven apart in reaches past each joint limit (a planner's
#: paths keep within ``LIMIT_TOLERANCE``, 1e-6 rad, of them).
BOX_SLACK = 1e-3
#: Configurations (uniform in the box, seeded) every pair is first tried at: one that touches at any
#: needs no proof. Then the most cells one pair's proof may split into before the pair is kept as
#: undecided. Panda, iiwa14, ur5 with its gripper: 718 of 1,050, 73 of 103 and 194 of 434 pairs proven
#: apart, in 0.4, 0.01 and 0.3 s on a shared 2-core machine (2,000 cells: 706, 73 and 150 in a quarter of
#: the time; 60,000: 720, 73 and 204 in twice it).
_APART_SAMPLES, _APART_CELLS = 4096, 20000
#: Proofs made, by the numbers they depend on (bodies alike share them).
_APART: dict[bytes, np.ndarray] = {}


def proven_apart(body: KernelBody) -> np.ndarray:
    """``(P,)`` bool: which of ``body``'s self-collision pairs are proven never to touch while every joint
    lies in ``body.box`` (an SRDF's "never in collision" pairs, proven rather than sampled).

    Each pair is first looked at in :data:`_APART_SAMPLES` configurations; one that touches in any is
    kept. The others go to a branch and bound over the box (:func:`_apart`) bounded by the verdict's own
    rates (how fast the pair's distance can change per radian of each joint between their links), so a
    pair is dropped only where no configuration of the box brings it to contact; one undecided within
    :data:`_APART_CELLS` cells is kept. A pair so dropped changes no verdict of a path inside the box:
    its distance there is > 0 at every configuration."""
    lo, hi = body.box
    P = len(body.pairs)
    if P == 0 or not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        return np.zeros(P, dtype=bool)
    key = b"".join(
        np.ascontiguousarray(a).tobytes()
        for a in (body.F, body.prismatic, body.link, body.folded, body.radii, body.pairs, body._axis, lo, hi)
    )
    hit = _APART.get(key)
    if hit is None:
        qs = lo + (hi - lo) * np.random.default_rng(0).random((_APART_SAMPLES, body.dof))
        # touching: a distance ≤ 0, i.e. below the smallest positive float
        touch = _near_pairs(
            _centres(qs, *body.fk_args()), body.radii, body.pairs, np.nextafter(0.0, 1.0)
        ).any(0)
        rates = np.ascontiguousarray(body._item_lever(body.pairs))
        hit = np.zeros(P, dtype=bool)
        for p in np.flatnonzero(~touch):
            a, b = body.pairs[p]
            found = _apart(
                body.F, body.prismatic, body.link[a], body.folded[a], body.link[b], body.folded[b],
                body.radii[a] + body.radii[b], rates[p], lo, hi, _APART_CELLS,
            )  # fmt: skip
            hit[p] = found == 1
        hit.flags.writeable = False
        _APART[key] = hit
    return hit


#: Bodies packed by :meth:`KernelBody.of`, dropped with their body.
_BODIES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
#: Chains packed by :meth:`KernelChain.of`, dropped with their robot.
_CHAINS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
#: Scenes packed by :meth:`KernelScene.of`, dropped with their scene.
_PACKED: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


@_jit
def _distinct_indices(idx, n):
    """Every entry of ``idx`` in 0…n−1, none twice."""
    seen = np.zeros(n, dtype=np.bool_)
    for i in idx:
        if i < 0 or i >= n or seen[i]:
            return False
        seen[i] = True
    return True


@_jit
def _all_finite(a):
    for v in a.flat:
        if not math.isfinite(v):
            return False
    return True


def _joints(x, dof: int, what: str, ndim: int, finite: bool = True) -> np.ndarray:
    """``x`` as a C-contiguous float64 array of ``ndim`` dimensions, the last of size ``dof``; its values
    checked finite unless ``finite=False`` (the caller's kernel checks them)."""
    if type(x) is np.ndarray and x.dtype == np.float64 and x.ndim == ndim and x.flags.c_contiguous:
        if x.shape[-1] != dof:  # the common case (a planner's own arrays): no conversion at all
            raise ShapeError(f"{what} must have {ndim} dimensions, the last of size {dof}; got {x.shape}")
        if finite and not _all_finite(x):
            raise NonFiniteError(f"{what} holds {int((~np.isfinite(x)).sum())} NaN/inf value(s)")
        return x
    if isinstance(x, torch.Tensor):
        x = x.detach().cpu().numpy()
    a = np.asarray(x)
    if a.dtype.kind != "f":
        raise DTypeError(f"{what} must hold real floating-point numbers, got dtype {a.dtype}")
    if a.ndim != ndim or a.shape[-1] != dof:
        raise ShapeError(f"{what} must have {ndim} dimensions, the last of size {dof}; got {a.shape}")
    a = np.ascontiguousarray(a, dtype=np.float64)
    if not _all_finite(a):
        raise NonFiniteError(f"{what} holds {int((~np.isfinite(a)).sum())} NaN/inf value(s)")
    return a


def _check_args(body, scene, max_travel, margin) -> None:
    if (
        type(body) is KernelBody
        and type(scene) is KernelScene
        and type(max_travel) is float
        and type(margin) is float
        and 0.0 < max_travel < math.inf
        and -math.inf < margin < math.inf
    ):
        return  # the common case, in a few comparisons
    if not isinstance(body, KernelBody):
        raise ConfigError(
            f"body must be a KernelBody (KernelBody(body_spheres(robot))), got {type(body).__name__}"
        )
    if not isinstance(scene, KernelScene):
        raise ObstacleError(f"scene must be a KernelScene (KernelScene(scene)), got {type(scene).__name__}")
    if not (isinstance(max_travel, (int, float)) and math.isfinite(max_travel) and max_travel > 0):
        raise ConfigError(f"max_travel must be a finite number of metres > 0, got {max_travel!r}")
    if not (isinstance(margin, (int, float)) and math.isfinite(margin)):
        raise ConfigError(f"margin must be a finite number of metres, got {margin!r}")


def centres(body: KernelBody, q) -> np.ndarray:
    """World sphere centres ``(N, M, 3)`` of joints ``q (N, dof)``."""
    return _centres(_joints(q, body.dof, "joint values q", 2), *body.fk_args())


@_jit
def _near_pairs(c, radii, pairs, cut):
    """``(B, P)`` bool: pair k of configuration b closer than ``cut`` (signed)."""
    B, P = c.shape[0], pairs.shape[0]
    out = np.empty((B, P), dtype=np.bool_)
    for b in range(B):
        for k in range(P):
            i, j = pairs[k, 0], pairs[k, 1]
            dx, dy, dz = c[b, i, 0] - c[b, j, 0], c[b, i, 1] - c[b, j, 1], c[b, i, 2] - c[b, j, 2]
            out[b, k] = math.sqrt(dx * dx + dy * dy + dz * dz) - radii[i] - radii[j] < cut
    return out


def near_pairs(centres, radii, pairs, cut: float) -> tuple[np.ndarray, np.ndarray]:
    """The sphere pairs closer than ``cut`` (m, signed: centre distance less both radii): for centres
    ``(B, M, 3)``, radii ``(M,)`` and pairs ``(P, 2)``, the configuration and pair indices ``(A,)`` of each
    such pair, in order. A broad phase for losses that a pair adds to only within a margin."""
    c = np.ascontiguousarray(np.asarray(centres, dtype=np.float64))
    r = np.ascontiguousarray(np.asarray(radii, dtype=np.float64))
    pr = np.ascontiguousarray(np.asarray(pairs, dtype=np.int64))
    if c.ndim != 3 or c.shape[-1] != 3 or r.shape != (c.shape[1],) or pr.ndim != 2 or pr.shape[-1] != 2:
        raise ShapeError(
            f"near_pairs takes centres (B, M, 3), radii (M,), pairs (P, 2); got {c.shape}, {r.shape}, {pr.shape}"
        )
    b, k = np.nonzero(_near_pairs(c, r, pr, float(cut)))
    return b.astype(np.int64), k.astype(np.int64)


@_jit
def _point_distances(points, spheres, boxes, cylinders, floor, out):
    for i in range(points.shape[0]):
        out[i] = _sphere_scene(
            points[i, 0], points[i, 1], points[i, 2], 0.0, True, spheres, boxes, cylinders, floor
        )


def point_distances(scene: KernelScene, points) -> np.ndarray:
    """Signed distances ``(N,)`` of points ``(N, 3)`` (m, the robot's base frame) to ``scene``, its floor
    included (negative inside a primitive; +inf for an empty scene without a floor)."""
    if not isinstance(scene, KernelScene):
        raise ObstacleError(f"scene must be a KernelScene (KernelScene(scene)), got {type(scene).__name__}")
    pts = _joints(points, 3, "points", 2)
    out = np.empty(pts.shape[0])
    _point_distances(pts, *scene.args(), out)
    return out


def clearances(body: KernelBody, scene: KernelScene, q, per_sphere: bool = False):
    """``(scene clearance (N,), self clearance (N,))`` of configurations ``q (N, dof)`` (and, with
    ``per_sphere``, each sphere's distance to the scene ``(N, M)``): the numbers of
    :func:`kinlearn.collision.clearances`."""
    _check_args(body, scene, 1.0, 0.0)
    qs = _joints(q, body.dof, "joint values q", 2)
    per = np.empty((qs.shape[0], body.num_spheres))
    d, s = _clearances(qs, *body.args(), *scene.args(), per)
    return (d, s, per) if per_sphere else (d, s)


def check_paths(
    body: KernelBody,
    paths,
    scene: KernelScene,
    max_travel: float = 0.01,
    margin: float = 0.0,
    exact: bool = True,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Check joint paths ``paths (P, T+1, dof)`` against one scene and self-collision, densely.

    Returns ``(free (P,) bool, clearance (P,), first_collision (P,) int64)``: per path the
    ``collision_free``, ``clearance`` and ``first_collision`` of :func:`~kinlearn.collision.check_path`
    (the same sub-steps, pairs and floor rule; touching counts as a collision). ``exact=False`` skips the
    sub-steps that cannot collide and stops at a path's first collision: the same ``free`` and
    ``first_collision``, and no clearance (NaN).
    """
    _check_args(body, scene, max_travel, margin)
    arr = _joints(paths, body.dof, "joint paths", 3)
    P = arr.shape[0]
    free, clear, first = np.zeros(P, dtype=bool), np.empty(P), np.empty(P, dtype=np.int64)
    for i in range(P):
        if exact:
            first[i], clear[i], _, _ = _check(
                arr[i], float(max_travel), float(margin), True, *body.args(), body.lever, *scene.args()
            )
        else:
            first[i], _, _, _ = _verdict_packed(
                arr[i], float(max_travel), float(margin), *body.packing_of(arr[i]), scene.packed
            )
            clear[i] = np.nan
        free[i] = first[i] < 0
    return free, clear, first


def free_depths(
    body: KernelBody,
    theta,
    vias,
    scene: KernelScene,
    max_travel: float = 0.01,
    margin: float = 0.0,
) -> np.ndarray:
    """``(D,)``: per chain of ``vias (D, L, dof)`` from ``theta (dof,)``, how many of its vias the polyline
    ``[theta, vias[d]]`` reaches through segments :func:`check_paths` finds free (0: its first segment
    collides; L: all free), in one compiled call. Each chain is walked once to its first collision: a
    hit found in segment f (f > 0) lies in it or at its first knot, via f − 1, which the segment before
    ends at; checked alone, that via tells which (the depths of checking every segment apart, to the
    bit). Raises :class:`~kinlearn.errors.NonFiniteError` for NaN or infinity."""
    _check_args(body, scene, max_travel, margin)
    theta = _joints(theta, body.dof, "theta", 1, finite=False)
    vias = _joints(vias, body.dof, "vias", 3, finite=False)
    depth = np.empty(vias.shape[0], dtype=np.int64)
    if not free_depths_boxed(theta, vias, float(max_travel), float(margin), *body.boxed, scene.packed, depth):
        raise NonFiniteError("theta or the vias hold NaN or infinity")
    return depth


def first_free(
    body: KernelBody,
    paths,
    scene: KernelScene,
    order: Sequence[int] | np.ndarray | None = None,
    max_travel: float = 0.01,
    margin: float = 0.0,
) -> int:
    """The index of the first path in ``order`` (default 0, 1, …) that :func:`check_paths` finds
    collision-free, or −1 if none is. ``order`` must hold distinct indices into ``paths`` (a
    :class:`~kinlearn.errors.ConfigError` otherwise); it may leave paths out."""
    _check_args(body, scene, max_travel, margin)
    arr = _joints(paths, body.dof, "joint paths", 3, finite=False)  # the kernel checks finiteness
    P = arr.shape[0]
    if order is None:
        idx = _NATURAL[P] if P < len(_NATURAL) else np.arange(P, dtype=np.int64)
    else:
        idx = np.asarray(order)
        if idx.ndim != 1 or (idx.size and idx.dtype.kind not in "iu"):
            raise ConfigError(f"order must be a 1-D sequence of path indices, got {order!r}")
        idx = np.ascontiguousarray(idx, dtype=np.int64)
        if idx.size and not _distinct_indices(idx, P):
            raise ConfigError(f"order must hold distinct path indices in 0…{P - 1}, got {idx.tolist()}")
    if idx.shape[0] == 0:
        if not _all_finite(arr):
            raise NonFiniteError(f"joint paths hold {int((~np.isfinite(arr)).sum())} NaN/inf value(s)")
        return -1
    k = int(first_free_boxed(arr, idx, float(max_travel), float(margin), *body.boxed, scene.packed))
    if k == -2:
        raise NonFiniteError(f"joint paths hold {int((~np.isfinite(arr)).sum())} NaN/inf value(s)")
    return k


#: The order 0, 1, …, P − 1 of a few paths, made once (never written: the kernels only read it).
_NATURAL = [np.arange(P, dtype=np.int64) for P in range(33)]


def warm_up() -> None:
    """Compile (or load from numba's cache) every kernel now, on a tiny problem."""
    from ..body.robot import load_robot
    from .body import body_spheres

    robot = load_robot("iiwa14")
    body = KernelBody(body_spheres(robot).double())
    scene = KernelScene(Scene.from_spheres([[0.5, 0.0, 0.5, 0.1]], floor=0.0))
    path = np.zeros((1, 2, body.dof))
    check_paths(body, path, scene)
    check_paths(body, path, scene, exact=False)
    first_free(body, path, scene)
    first_free(body, path, scene, order=[0])
    free_depths(body, path[0, 0], path, scene)
    clearances(body, scene, path[0])
    centres(body, path[0])
    point_distances(scene, np.zeros((1, 3)))
    scene.model_rows()
    chain = KernelChain.of(robot)
    chain.position(path[0])
    chain.checked(path[0], 1e-6)
