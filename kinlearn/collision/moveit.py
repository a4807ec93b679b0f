"""MoveIt planning scenes and motion plan requests, in and out, without ROS.

A MoveIt ``PlanningScene`` (as YAML, or the dict PyYAML reads from it) holds its obstacles in
``world.collision_objects``; each object has an ``id``, an optional object ``pose`` (position and
orientation quaternion x, y, z, w: mappings by name, as ROS writes messages, or lists in that order, as
robowflex and MotionBenchMaker's scene files do) and ``primitives`` with one ``primitive_poses`` entry each, relative
to the object's pose (or to the scene frame where the object has no pose, as older MoveIt writes).
``SolidPrimitive`` types: BOX = 1 (``dimensions`` = full side lengths x, y, z), SPHERE = 2 ([radius]),
CYLINDER = 3 ([height, radius], axis along its local z), CONE = 4. Meshes, planes and cones are
refused with a :class:`~kinlearn.errors.SceneFormatError` naming the object (approximating them
silently would plan against something else than the scene), as is a sensed scene's octomap.

:func:`primitives_from_moveit` returns the primitives in the robot's base frame, given the base's pose
in the scene's frame, and :func:`primitives_to_moveit` writes them back; ``Scene.from_moveit`` and
``Scene.to_moveit`` are the same for a :class:`~kinlearn.collision.Scene`. A ``MotionPlanRequest``'s
start state and joint goal become joint vectors in the robot's order (:func:`request_joints`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import torch

from ..body.robot import Robot
from ..errors import MissingDependencyError, SceneFormatError
from .geometry import (
    Box,
    Cylinder,
    Plane,
    Primitive,
    Sphere,
    quaternion_from_rotation,
    rotation_from_quaternion,
)

__all__ = [
    "BOX",
    "CONE",
    "CYLINDER",
    "FLOOR_SLAB",
    "SPHERE",
    "pose_matrix",
    "primitives_from_moveit",
    "primitives_to_moveit",
    "read_yaml",
    "request_joints",
]

#: ``shape_msgs/SolidPrimitive`` type codes.
BOX, SPHERE, CYLINDER, CONE = 1, 2, 3, 4
#: Full side lengths (m) of the box a scene's floor is written as by :func:`primitives_to_moveit`.
FLOOR_SLAB = (10.0, 10.0, 1.0)
_NAMES = {"box": BOX, "sphere": SPHERE, "cylinder": CYLINDER, "cone": CONE}


def read_yaml(source: str | Path | Mapping, what: str) -> Mapping:
    """A YAML file (path) or an already-read mapping, as a mapping."""
    if isinstance(source, Mapping):
        return source
    if not isinstance(source, (str, Path)):
        raise SceneFormatError(f"{what} must be a YAML file path or a dict, got {type(source).__name__}")
    try:
        import yaml
    except ImportError as exc:  # pragma: no cover - pyyaml is a dependency
        raise MissingDependencyError("reading MoveIt YAML needs PyYAML: `pip install pyyaml`") from exc
    path = Path(source)
    try:
        text = path.read_text()
    except OSError as exc:
        raise SceneFormatError(f"cannot read {what} {path}: {exc.strerror or exc}") from exc
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise SceneFormatError(f"{path} is not valid YAML: {exc}") from exc
    if not isinstance(data, Mapping):
        raise SceneFormatError(f"{path} must hold a YAML mapping ({what}), got {type(data).__name__}")
    return data


def _number(value, where: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError) as exc:
        raise SceneFormatError(f"{where} must be a number, got {value!r}") from exc
    if not np.isfinite(v):
        raise SceneFormatError(f"{where} must be finite, got {value!r}")
    return v


def _components(value, names: str, where: str) -> list[float]:
    """A point (``names`` "xyz") or a quaternion ("xyzw") of a pose: a mapping by name (ROS messages as
    YAML; a missing name is 0, a missing w 1) or a list in that order (as robowflex, and so
    MotionBenchMaker's scene files, write them). ``None``: the origin, or the identity rotation."""
    if value is None:
        value = {}
    if isinstance(value, Mapping):
        return [_number(value.get(k, 1.0 if k == "w" else 0.0), f"{where}.{k}") for k in names]
    if isinstance(value, Sequence) and not isinstance(value, str) and len(value) == len(names):
        return [_number(v, f"{where}.{k}") for k, v in zip(names, value, strict=True)]
    raise SceneFormatError(
        f"{where} must be a mapping ({', '.join(names)}) or a list [{', '.join(names)}], got {value!r}"
    )


def pose_matrix(pose, where: str = "pose") -> np.ndarray:
    """A 4 × 4 transform from a MoveIt pose mapping (``position`` x, y, z; ``orientation`` x, y, z, w; each
    a mapping by name or a list in that order), a sequence ``[x, y, z, qx, qy, qz, qw]``, or a 4 × 4
    matrix. ``None`` is the identity."""
    T = np.eye(4)
    if pose is None:
        return T
    if isinstance(pose, Mapping):
        p = _components(pose.get("position"), "xyz", f"{where}.position")
        q = _components(pose.get("orientation"), "xyzw", f"{where}.orientation")
    else:
        a = (
            np.asarray(pose, dtype=np.float64)
            if not isinstance(pose, torch.Tensor)
            else pose.double().numpy()
        )
        if a.shape == (4, 4):
            if not np.isfinite(a).all() or not np.allclose(a[3], [0, 0, 0, 1]):
                raise SceneFormatError(f"{where}: a 4 × 4 pose must be finite with last row [0, 0, 0, 1]")
            R = a[:3, :3]
            if np.abs(R.T @ R - np.eye(3)).max() > 1e-6 or abs(np.linalg.det(R) - 1) > 1e-6:
                raise SceneFormatError(f"{where}: the 4 × 4 pose's rotation is not a rotation")
            return a.copy()
        if a.shape != (7,) or not np.isfinite(a).all():
            raise SceneFormatError(
                f"{where} must be a 4 × 4 matrix or [x, y, z, qx, qy, qz, qw], got shape {a.shape}"
            )
        p, q = a[:3].tolist(), a[3:].tolist()
    if np.linalg.norm(q) < 1e-9:
        raise SceneFormatError(f"{where}: the orientation quaternion is zero")
    T[:3, :3] = rotation_from_quaternion(q)
    T[:3, 3] = p
    return T


def _pose_dict(T: np.ndarray) -> dict:
    q = quaternion_from_rotation(T[:3, :3])
    return {
        "position": {k: float(v) for k, v in zip("xyz", T[:3, 3], strict=True)},
        "orientation": {k: float(v) for k, v in zip("xyzw", q, strict=True)},
    }


def _primitive(prim, T: np.ndarray, where: str) -> Primitive:
    if not isinstance(prim, Mapping):
        raise SceneFormatError(f"{where} must be a mapping with type and dimensions")
    kind = prim.get("type")
    if isinstance(kind, str):
        kind = _NAMES.get(kind.strip().lower(), kind)
    dims = prim.get("dimensions")
    if not isinstance(dims, Sequence) or isinstance(dims, str):
        raise SceneFormatError(f"{where}: dimensions must be a list of numbers, got {dims!r}")
    dims = [_number(d, f"{where}.dimensions") for d in dims]
    R, c = T[:3, :3], T[:3, 3]

    def need(n: int, layout: str) -> None:
        if len(dims) < n:
            raise SceneFormatError(f"{where}: a {layout} needs {n} dimension(s), got {dims}")
        if any(d <= 0 for d in dims[:n]):
            raise SceneFormatError(f"{where}: dimensions must be > 0 (metres), got {dims}")

    if kind == BOX:
        need(3, "box [x, y, z] (full side lengths)")
        return Box(c, [d / 2 for d in dims[:3]], R)
    if kind == SPHERE:
        need(1, "sphere [radius]")
        return Sphere(c, dims[0])
    if kind == CYLINDER:
        need(2, "cylinder [height, radius]")
        return Cylinder(c, dims[1], dims[0] / 2, R)
    if kind == CONE:
        raise SceneFormatError(f"{where} is a cone; kinlearn's scenes take boxes, spheres and cylinders")
    raise SceneFormatError(
        f"{where}: unknown primitive type {prim.get('type')!r} (box 1, sphere 2, cylinder 3)"
    )


def _frame_id(obj: Mapping, where: str) -> str:
    """An object's ``header.frame_id`` ('' where it gives none: it is in the scene's frame)."""
    header = obj.get("header")
    if header is None:
        return ""
    if not isinstance(header, Mapping):
        raise SceneFormatError(f"{where}: header must be a mapping (frame_id), got {header!r}")
    frame = header.get("frame_id") or ""
    if not isinstance(frame, str):
        raise SceneFormatError(f"{where}: header.frame_id must be a frame name, got {frame!r}")
    return frame.strip().lstrip("/")  # ROS 1 wrote a leading slash: '/world' is 'world'


def primitives_from_moveit(source: str | Path | Mapping, base_pose=None) -> list[Primitive]:
    """The obstacles of a MoveIt ``PlanningScene`` (YAML file or dict) as typed primitives in the robot's
    base frame (:meth:`Scene.from_moveit <kinlearn.collision.Scene.from_moveit>` makes them a scene).

    ``base_pose``: the robot base's pose in the scene's frame (4 × 4, ``[x, y, z, qx, qy, qz, qw]`` or a
    MoveIt pose mapping; default: the base is the scene's frame). The scene's frame is its objects'
    ``header.frame_id`` (an object without one is in it): objects given in different frames are a
    :class:`~kinlearn.errors.SceneFormatError` naming both (kinlearn holds no transform tree to relate
    them). The scene may be the whole message or its ``world`` part; objects whose ``operation`` is
    REMOVE (1) are skipped. Raises
    :class:`~kinlearn.errors.SceneFormatError` for a malformed file or an object holding meshes, planes
    or cones (named by its id).
    """
    data = read_yaml(source, "a MoveIt planning scene")
    world = data.get("world", data)
    if not isinstance(world, Mapping):
        raise SceneFormatError("the planning scene's world must be a mapping holding collision_objects")
    octomap = world.get("octomap")
    if isinstance(octomap, Mapping) and (octomap.get("octomap") or {}).get("data"):
        raise SceneFormatError(
            "the planning scene holds an octomap (a sensed scene); kinlearn's scenes take boxes, spheres and "
            "cylinders: give the scene's collision objects instead"
        )
    objects = world.get("collision_objects") or []
    if not isinstance(objects, Sequence) or isinstance(objects, str):
        raise SceneFormatError("world.collision_objects must be a list of collision objects")
    to_base = np.linalg.inv(pose_matrix(base_pose, "base_pose"))
    prims: list[Primitive] = []
    frame: tuple[str, str] | None = None  # the scene's frame, and the object that named it first
    for i, obj in enumerate(objects):
        if not isinstance(obj, Mapping):
            raise SceneFormatError(f"collision object {i} must be a mapping")
        name = obj.get("id", f"#{i}")
        where = f"collision object {name!r}"
        if obj.get("operation", 0) in (1, "REMOVE", "remove"):
            continue
        given = _frame_id(obj, where)
        if given:
            if frame is None:
                frame = (given, where)
            elif given != frame[0]:
                raise SceneFormatError(
                    f"{where} is given in frame {given!r}, {frame[1]} in {frame[0]!r}: kinlearn reads a scene "
                    "in one frame (base_pose places the robot's base in it); express every object in that "
                    "frame first"
                )
        for field in ("meshes", "planes"):
            if obj.get(field):
                raise SceneFormatError(
                    f"{where} holds {field}; kinlearn's scenes take boxes, spheres and cylinders "
                    f"(replace its {field} by primitives)"
                )
        shapes = obj.get("primitives") or []
        poses = obj.get("primitive_poses") or []
        if len(shapes) != len(poses):
            raise SceneFormatError(
                f"{where} has {len(shapes)} primitives and {len(poses)} primitive_poses; give one pose each"
            )
        T_obj = to_base @ pose_matrix(obj.get("pose"), f"{where}.pose")
        for k, (prim, pose) in enumerate(zip(shapes, poses, strict=True)):
            sub = f"{where} primitive {k}"
            prims.append(_primitive(prim, T_obj @ pose_matrix(pose, f"{sub} pose"), sub))
        if str(name).startswith("floor") and len(shapes) == 1:
            prims[-1] = _as_floor(prims[-1])
    return prims


def _as_floor(p: Primitive) -> Primitive:
    """A floor written by :func:`primitives_to_moveit` (a level box :data:`FLOOR_SLAB` under its height,
    its id ``floor_…``) read back as that floor (a :class:`Plane` at the slab's top), any other primitive as
    it is. As a box the floor would hold the robot's base, whose collision spheres reach below it, in
    collision at every configuration; as the floor it is the plane the base stands on (a scene's floor
    is not checked against the base's spheres)."""
    if (
        isinstance(p, Box)
        and np.allclose(2 * np.asarray(p.half_extents), FLOOR_SLAB, atol=1e-9)
        and np.allclose(np.reshape(p.rotation, (3, 3)), np.eye(3), atol=1e-9)
    ):
        return Plane((0.0, 0.0, 1.0), float(p.centre[2] + p.half_extents[2]))
    return p


def primitives_to_moveit(
    primitives: Sequence[Primitive], frame_id: str = "base_link", name: str = "kinlearn"
) -> dict:
    """Primitives (a scene's :meth:`~kinlearn.collision.Scene.primitives`) as a MoveIt ``PlanningScene``
    dict (``yaml.safe_dump`` writes it):
    one collision object per primitive (ids ``sphere_0``, ``box_0``, ``cylinder_0``, …), each posed in
    ``frame_id`` (the robot's base) with its primitive at the object's origin. A floor becomes a box
    :data:`FLOOR_SLAB` under its height (MoveIt scenes hold no usable planes), id ``floor_0``, which
    :func:`primitives_from_moveit` reads back as the floor."""
    objects = []
    for p in primitives:
        T = np.eye(4)
        if isinstance(p, Sphere):
            T[:3, 3] = p.centre
            prim = {"type": SPHERE, "dimensions": [p.radius]}
        elif isinstance(p, Box):
            T[:3, :3], T[:3, 3] = np.reshape(p.rotation, (3, 3)), p.centre
            prim = {"type": BOX, "dimensions": [2 * h for h in p.half_extents]}
        elif isinstance(p, Cylinder):
            T[:3, :3], T[:3, 3] = np.reshape(p.rotation, (3, 3)), p.centre
            prim = {"type": CYLINDER, "dimensions": [2 * p.half_length, p.radius]}
        else:  # the floor: a slab under its height
            T[:3, 3] = (0.0, 0.0, p.offset - FLOOR_SLAB[2] / 2)
            prim = {"type": BOX, "dimensions": list(FLOOR_SLAB)}
        kind = "floor" if isinstance(p, Plane) else p.kind
        objects.append(
            {
                "header": {"frame_id": frame_id},
                "id": f"{kind}_{sum(o['id'].startswith(kind + '_') for o in objects)}",
                "pose": _pose_dict(T),
                "primitives": [prim],
                "primitive_poses": [_pose_dict(np.eye(4))],
                "operation": 0,
            }
        )
    return {"name": name, "is_diff": True, "world": {"collision_objects": objects}}


def _joint_map(names, positions, where: str) -> dict[str, float]:
    if not isinstance(names, Sequence) or not isinstance(positions, Sequence) or isinstance(names, str):
        raise SceneFormatError(f"{where}: name and position must be lists")
    if len(names) != len(positions):
        raise SceneFormatError(f"{where}: {len(names)} names but {len(positions)} positions")
    return {str(n): _number(p, f"{where} position of {n!r}") for n, p in zip(names, positions, strict=True)}


def _in_order(values: dict[str, float], robot: Robot, where: str) -> torch.Tensor:
    missing = [j.name for j in robot.joints if j.name not in values]
    if missing:
        raise SceneFormatError(
            f"{where} gives no value for joint(s) {', '.join(missing)} of {robot.name} "
            f"(it names {', '.join(values) or 'none'})"
        )
    return torch.tensor([values[j.name] for j in robot.joints], dtype=torch.float64)


def request_joints(source: str | Path | Mapping, robot: Robot) -> tuple[torch.Tensor, torch.Tensor]:
    """Start and goal joints ``(dof,)`` (float64, the robot's joint order) of a MoveIt ``MotionPlanRequest``
    (YAML file or dict): ``start_state.joint_state`` (name, position) and the first
    ``goal_constraints[]`` entry whose ``joint_constraints`` name every joint of the robot. Joints the
    robot does not have (fingers, …) are ignored; a missing one is a
    :class:`~kinlearn.errors.SceneFormatError` naming it."""
    data = read_yaml(source, "a MoveIt motion plan request")
    data = data.get("motion_plan_request", data)
    state = (data.get("start_state") or {}).get("joint_state")
    if not isinstance(state, Mapping):
        raise SceneFormatError("the request has no start_state.joint_state (name, position)")
    start = _in_order(
        _joint_map(state.get("name"), state.get("position"), "start_state"), robot, "start_state"
    )
    goals = data.get("goal_constraints") or []
    if not isinstance(goals, Sequence) or not goals:
        raise SceneFormatError("the request has no goal_constraints with joint_constraints")
    last = None
    for g, goal in enumerate(goals):
        cons = (goal or {}).get("joint_constraints") or []
        try:
            values = {
                str(c["joint_name"]): _number(c["position"], f"goal {g} {c['joint_name']!r}") for c in cons
            }
        except (KeyError, TypeError) as exc:
            raise SceneFormatError(
                f"goal_constraints[{g}]: each joint constraint needs joint_name and position"
            ) from exc
        try:
            return start, _in_order(values, robot, f"goal_constraints[{g}]")
        except SceneFormatError as exc:
            last = exc
    raise last  # type: ignore[misc]
