"""Bounds on how a body's spheres move, proven over every configuration from the robot's kinematic
chain alone: how far a sphere can travel per radian (or metre) of each joint (:func:`_lever_arms`), how
far it lies from the axis of each joint that does not move it (:func:`_axis_distances`: a self-collision
pair approaches contact no faster than the smaller of the two), and which spheres the floor applies to
(:func:`floor_applies`). The dense path checks step along a path by these bounds, so each is an upper
bound by the triangle inequality (rotations keep lengths), never an estimate.
"""

from __future__ import annotations

import numpy as np

from ..body.kinematics import _z_to_axis, kinematics
from ..body.robot import Robot

__all__ = ["floor_applies"]


def _travel(robot: Robot) -> list[float]:
    """Per joint the farthest a prismatic joint moves its child link (its largest |limit|, m); 0 for a
    revolute joint, which keeps every length."""
    return [max(abs(j.lower), abs(j.upper)) if j.kind == "prismatic" else 0.0 for j in robot.joints]


def _lever_arms(robot: Robot, link: np.ndarray, local: np.ndarray) -> np.ndarray:
    """``(M, dof)``: an upper bound on sphere m's distance from joint j's axis, over all configurations.

    Joint j (0-based) moves the links after it. For a sphere on the link joint j itself moves, the
    distance is exact: the sphere's distance from the axis in that link. Further down the chain it is
    at most (distance of joint j+1's origin from axis j) + (the fixed origin-to-origin offsets from
    joint j+1 to the joint that moves the sphere's link) + (the sphere's offset in its link), by the
    triangle inequality (rotations keep lengths); a prismatic joint in between adds its largest
    displacement. A prismatic joint moves every point by exactly its displacement: lever 1.
    """
    F = kinematics(robot, "fast").F  # F[i]: fixed transform before joint i, in frames with the axis on z
    axes = [_z_to_axis(j.axis) for j in robot.joints]
    reach = _travel(robot)
    lever = np.zeros((len(link), robot.dof))
    for m, (lk, c) in enumerate(zip(link, local, strict=True)):
        own = lk - 1  # the joint that moves the sphere's link
        if own < 0:
            continue
        folded = axes[own].T @ c  # the centre in joint `own`'s frame, its axis along z
        for j in range(own + 1):
            if robot.joints[j].kind == "prismatic":
                lever[m, j] = 1.0
            elif j == own:
                lever[m, j] = float(np.hypot(folded[0], folded[1]))
            else:
                chain = sum(float(np.linalg.norm(F[i, :3, 3])) + reach[i] for i in range(j + 2, own + 1))
                lever[m, j] = (
                    float(np.hypot(F[j + 1, 0, 3], F[j + 1, 1, 3]))
                    + reach[j + 1]
                    + chain
                    + float(np.linalg.norm(c))
                )
    return lever


def _axis_distances(robot: Robot, link: np.ndarray, local: np.ndarray) -> np.ndarray:
    """``(M, dof)``: an upper bound on sphere m's distance from the axis of each joint j that does *not*
    move it (j ≥ its link; 0 for the joints that do), over all configurations.

    Why: a sphere A on a link before joint j and a sphere B after it change their distance ‖B − A‖, as
    θ_j turns, at a rate of at most the distance of A from axis j (write B − p = (B − A) + (A − p), p on
    the axis: ∂‖B − A‖/∂θ_j = û · (ω × (A − p)), û along B − A), as well as at most B's (``lever``). So
    a self-collision pair moves towards contact no faster than Σ_j |Δθ_j| min(lever_Bj, this_Aj): a
    pair whose lower sphere sits on the axes between them keeps its distance, however far its upper
    sphere swings.

    The joint right after the sphere's link: its exact distance from that axis (both fixed in the
    link). Further down: the largest distance from the next joint's origin as joint j turns it about
    its axis (exact: ‖(ρ_c + ρ_o, z_c − z_o)‖ in that joint's frame), plus the origin-to-origin offsets
    on to joint j's origin (triangle inequality; a prismatic joint between adds its reach). A prismatic
    joint j changes any distance at most by its displacement: 1.
    """
    F = kinematics(robot, "fast").F  # F[i]: fixed transform before joint i, in frames with the axis on z
    axes = [_z_to_axis(j.axis) for j in robot.joints]
    reach = _travel(robot)
    dof = robot.dof
    out = np.zeros((len(link), dof))
    for m, (lk, c) in enumerate(zip(link, local, strict=True)):
        lk = int(lk)
        if lk >= dof:
            continue
        own = c if lk == 0 else axes[lk - 1].T @ c  # the centre in its link's frame (frame T_lk)
        # in joint lk's frame (origin on its axis, axis along z)
        x = F[lk, :3, :3].T @ (own - F[lk, :3, 3])
        rho_c = float(np.hypot(x[0], x[1]))
        far = 0.0  # the largest distance from the next joint's origin, as joint lk moves it
        if lk + 1 < dof:
            t = F[lk + 1, :3, 3]
            far = float(np.hypot(rho_c + np.hypot(t[0], t[1]), x[2] - t[2]))
            if robot.joints[lk].kind == "prismatic":
                far = float(np.linalg.norm(x - t)) + reach[lk]
        for j in range(lk, dof):
            if robot.joints[j].kind == "prismatic":
                out[m, j] = 1.0
            elif j == lk:
                out[m, j] = rho_c
            else:
                out[m, j] = far + sum(
                    float(np.linalg.norm(F[i + 1, :3, 3])) + reach[i] for i in range(lk + 1, j)
                )
    return out


def floor_applies(robot: Robot, link: np.ndarray, local: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """``(M,)`` bool: which spheres (on links ``link``, centres ``local (M, 3)`` in their link's frame, radii
    ``(M,)``) the floor applies to. Not the base's (the base stands on the floor), nor those of link 1 that
    reach below the base plane (z = 0) where the first joint turns about a vertical axis: no joint changes
    their height, so they would make every configuration collide; they rest on the mount as the base does
    (a fitted shoulder's spheres may bulge a few mm below the plane the shoulder stands on)."""
    link = np.asarray(link)
    out = link > 0
    first = robot.joints[0]
    if first.kind == "revolute" and abs(abs(float((first.T_prev[:3, :3] @ first.axis)[2])) - 1.0) < 1e-9:
        z = (np.asarray(local, dtype=np.float64) @ first.T_prev[:3, :3].T + first.T_prev[:3, 3])[:, 2]
        out &= ~((link == 1) & (z - np.asarray(radii, dtype=np.float64) < 0.0))
    return out
