"""The compiled twin of the body's forward kinematics (:mod:`kinlearn.body.kinematics` is its torch
reference): a chain's frames from its canonical fixed transforms, points fixed in its links placed, and
the end effector's position, one configuration at a time. The collision kernels place a body's spheres
with it; :class:`KernelChain` packs a robot's chain for the end effector once."""

from __future__ import annotations

import math
import weakref

import numpy as np

from .jit import jit

__all__ = ["KernelChain", "checked_tips"]


@jit(inline="always")
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


@jit(inline="always")
def _place(frames, link, folded, out):
    """Points ``out (M, 3)``, each at R_k · folded + p_k of its link k's frame."""
    for m in range(link.shape[0]):
        k = link[m]
        f0, f1, f2 = folded[m, 0], folded[m, 1], folded[m, 2]
        for a in range(3):
            out[m, a] = frames[k, a, 0] * f0 + frames[k, a, 1] * f1 + frames[k, a, 2] * f2 + frames[k, a, 3]


@jit
def _fk(q, F, prismatic, link, folded, out, frames):
    """Sphere centres ``out (M, 3)`` at joints ``q (dof,)`` (``frames (dof + 1, 3, 4)``: work space); each
    ``folded`` centre is in its link's frame turned so that the joint axis is z (base spheres: as is)."""
    _chain(q, F, prismatic, frames)
    _place(frames, link, folded, out)


@jit(inline="always")
def _point(frames, k, v):
    """R_k · v + p_k: a point fixed in link k's frame, placed."""
    return (
        frames[k, 0, 0] * v[0] + frames[k, 0, 1] * v[1] + frames[k, 0, 2] * v[2] + frames[k, 0, 3],
        frames[k, 1, 0] * v[0] + frames[k, 1, 1] * v[1] + frames[k, 1, 2] * v[2] + frames[k, 1, 3],
        frames[k, 2, 0] * v[0] + frames[k, 2, 1] * v[1] + frames[k, 2, 2] * v[2] + frames[k, 2, 3],
    )


@jit
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


@jit
def checked_tips(qs, F, prismatic, lower, upper, tol, ok):
    """(Compiled; other compiled code calls it too.) :func:`_tip_positions`, and ``ok (N,)`` filled with whether each configuration is finite and within
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


@jit
def _centres(qs, F, prismatic, link, folded):
    out = np.empty((qs.shape[0], link.shape[0], 3))
    frames = np.empty((qs.shape[1] + 1, 3, 4))
    for i in range(qs.shape[0]):
        _fk(qs[i], F, prismatic, link, folded, out[i], frames)
    return out


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
        from .kinematics import kinematics

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

    def position(self, q: np.ndarray) -> np.ndarray:
        """End-effector positions ``(N, 3)`` of float64 joints ``q (N, dof)`` (the caller's checked
        values: no conversion here), the numbers of :meth:`FastKinematics.position` to rounding."""
        return _tip_positions(q if q.flags.c_contiguous else np.ascontiguousarray(q), self.F, self.prismatic)


#: Chains packed by :meth:`KernelChain.of`, dropped with their robot.
_CHAINS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
