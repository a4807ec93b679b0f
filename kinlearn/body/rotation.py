"""Rotations of a URDF's joint origins: fixed-axis roll-pitch-yaw to a matrix and back, and a rotation
about an axis. One implementation, used wherever a URDF is parsed (:mod:`kinlearn.body.robot`) or
written (:mod:`kinlearn.body.perturb`).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["axis_rotation", "matrix_rpy", "rpy_matrix"]


def rpy_matrix(r: float, p: float, y: float) -> np.ndarray:
    """URDF fixed-axis roll-pitch-yaw: R = Rz(y) Ry(p) Rx(r)."""
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def matrix_rpy(R: np.ndarray) -> tuple[float, float, float]:
    """Roll, pitch, yaw with ``rpy_matrix(r, p, y) == R`` (pitch in [-π/2, π/2])."""
    cp = math.hypot(R[0, 0], R[1, 0])
    p = math.atan2(-R[2, 0], cp)
    if cp > 1e-9:
        return math.atan2(R[2, 1], R[2, 2]), p, math.atan2(R[1, 0], R[0, 0])
    # Gimbal lock (pitch ±π/2): only roll ∓ yaw is defined; take yaw = 0.
    return math.atan2(-R[1, 2], R[1, 1]), p, 0.0


def axis_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation by ``angle`` about the unit vector ``axis`` (Rodrigues)."""
    k = axis / np.linalg.norm(axis)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * (K @ K)
