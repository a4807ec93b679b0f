"""What both the animation and the browser viewer draw, computed once from plain inputs.

A joint path ``(N, dof)`` becomes the arm's joint origins at every configuration (analytic FK of the
fast backend), the end-effector path, and validated optional extras: waypoints ``(M, 3)`` and the
obstacles, either a :class:`~kinlearn.collision.Scene` (``scene=``, every kind of primitive) or plain
tables: spheres ``(K, 4)`` as ``[x, y, z, r]``, boxes ``(B, 6)`` as ``[cx, cy, cz, hx, hy, hz]``
(axis-aligned: centre and half extents) or ``(B, 15)`` (with a row-major rotation), cylinders
``(C, 14)`` (:mod:`kinlearn.collision.geometry`'s layouts), all in metres in the robot's base frame. Joint paths outside the joint
limits are drawn as they are: showing such a plan is one reason to look at it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from ..body.kinematics import kinematics
from ..body.robot import Robot
from ..collision.geometry import IDENTITY, Box, Cylinder, aabb_half_extents
from ..collision.scene import Scene
from ..errors import ConfigError, NonFiniteError, ObstacleError, ShapeError


@dataclass(frozen=True, eq=False)
class PlanScene:
    """Arrays for drawing one joint path (float64, metres, base frame).

    Attributes:
        robot: the robot's name.
        links: ``(N, dof + 2, 3)`` base, every joint origin and the end effector, per configuration.
        ee: ``(N, 3)`` the end-effector path (``links[:, -1]``).
        waypoints: ``(M, 3)`` (``M = 0`` when none were given).
        spheres: ``(K, 4)``; boxes: ``(B, 15)``; cylinders: ``(C, 14)`` (the layouts of
            :mod:`kinlearn.collision.geometry`).
        times: ``(N,)`` seconds, or ``None`` when the path has no time stamps.
    """

    robot: str
    links: np.ndarray
    ee: np.ndarray
    waypoints: np.ndarray
    spheres: np.ndarray
    boxes: np.ndarray
    times: np.ndarray | None
    cylinders: np.ndarray = field(default_factory=lambda: np.zeros((0, 14)))

    @property
    def frames(self) -> int:
        return self.links.shape[0]

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned bounds ``(lo, hi)`` of everything drawn."""
        pts = [self.links.reshape(-1, 3), self.waypoints]
        if len(self.spheres):
            c, r = self.spheres[:, :3], self.spheres[:, 3:]
            pts += [c - r, c + r]
        for kind, rows in ((Box, self.boxes), (Cylinder, self.cylinders)):
            if len(rows):
                c, h = rows[:, :3], aabb_half_extents(kind, torch.from_numpy(rows)).numpy()
                pts += [c - h, c + h]
        allp = np.concatenate(pts)
        return allp.min(axis=0), allp.max(axis=0)


def _array(x: Any, width: int, what: str, layout: str, obstacle: bool = False) -> np.ndarray:
    shape_error = ObstacleError if obstacle else ShapeError
    if x is None:
        return np.zeros((0, width))
    if isinstance(x, torch.Tensor):
        x = x.detach().cpu().double().numpy()
    try:
        arr = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise shape_error(
            f"{what} must be an array of shape (n, {width}) {layout}, got {type(x).__name__}"
        ) from exc
    if arr.ndim == 1 and arr.shape[0] == width:
        arr = arr[None]
    if arr.ndim != 2 or arr.shape[1] != width:
        raise shape_error(f"{what} must have shape (n, {width}) {layout}, got {arr.shape}")
    if not np.isfinite(arr).all():
        raise (ObstacleError if obstacle else NonFiniteError)(
            f"{what} holds NaN/inf; all values must be finite"
        )
    return arr


def plan_scene(
    robot: Robot,
    joints: Any,
    *,
    waypoints: Any = None,
    spheres: Any = None,
    boxes: Any = None,
    times: Any = None,
    cylinders: Any = None,
    scene: Scene | None = None,
) -> PlanScene:
    """Validate the inputs and compute the arm's joint origins along the path (see the module docstring)."""
    if isinstance(joints, np.ndarray):
        joints = torch.from_numpy(np.array(joints, dtype=np.float64))
    if not isinstance(joints, torch.Tensor) or joints.ndim != 2 or joints.shape[-1] != robot.dof:
        shape = tuple(joints.shape) if isinstance(joints, torch.Tensor) else type(joints).__name__
        raise ShapeError(
            f"joints must be a joint path of shape (N, {robot.dof}) for {robot.name}, got {shape}"
        )
    if joints.shape[0] < 1 or not joints.is_floating_point():
        raise ShapeError(
            f"joints must hold at least one floating-point configuration, got {joints.dtype} {tuple(joints.shape)}"
        )
    if not bool(torch.isfinite(joints).all()):
        raise NonFiniteError("joints hold NaN/inf; all joint values must be finite")
    q = joints.detach().cpu().to(torch.float64)
    links = kinematics(robot, "fast").link_positions(q).numpy()
    wp = _array(waypoints, 3, "waypoints", "(x, y, z in metres)")
    sph = _array(spheres, 4, "spheres", "[x, y, z, radius] in metres", obstacle=True)
    if scene is not None:
        if not isinstance(scene, Scene) or len(scene.batch_shape):
            raise ObstacleError(
                "scene must be one kinlearn Scene (batch shape ()); index a batched one first"
            )
        if any(t is not None for t in (spheres, boxes, cylinders)):
            raise ObstacleError("give the obstacles as scene= or as spheres=/boxes=/cylinders=, not both")
        tables = {kind.kind: rows for kind, rows, _ in scene.tables(live=True)}
        undrawn = [k for k, rows in tables.items() if k not in ("sphere", "box", "cylinder") and len(rows)]
        if undrawn:
            raise ObstacleError(
                f"the views draw spheres, boxes and cylinders; this scene also holds {', '.join(undrawn)}"
            )
        spheres, boxes, cylinders = tables["sphere"], tables["box"], tables["cylinder"]
    if boxes is not None and np.shape(boxes)[-1:] == (6,):
        b6 = _array(boxes, 6, "boxes", "[centre x, y, z, half extents x, y, z] in metres", obstacle=True)
        boxes = np.concatenate((b6, np.tile(IDENTITY, (len(b6), 1))), axis=1)
    box = _array(
        boxes,
        15,
        "boxes",
        "[centre, half extents, rotation (9)] in metres (or (n, 6) [centre, half extents], axis-aligned)",
        obstacle=True,
    )
    cyl = _array(cylinders, 14, "cylinders", "[centre, radius, half length, rotation (9)]", obstacle=True)
    try:  # the scene's own checks: sizes > 0, rotations orthonormal
        Scene(spheres=sph, boxes=box, cylinders=cyl)
    except ObstacleError as exc:
        raise ObstacleError(f"obstacles to draw: {exc}") from exc
    t = None
    if times is not None:
        t = _array(np.asarray(times, dtype=np.float64).reshape(-1, 1), 1, "times", "(seconds)")[:, 0]
        if t.shape[0] != q.shape[0]:
            raise ShapeError(f"times must have one entry per configuration ({q.shape[0]}), got {t.shape[0]}")
        if (np.diff(t) < 0).any():
            raise ConfigError("times must be non-decreasing")
    return PlanScene(robot.name, links, links[:, -1].copy(), wp, sph, box, t, cyl)
