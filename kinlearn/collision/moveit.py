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

One validating reader: every field kinlearn reads is checked for its type and shape, and a field that
is wrong is a :class:`~kinlearn.errors.SceneFormatError` naming its key path
(``world.collision_objects[3].pose.position.x (object 'shelf')``), never a plain Python error (the
fields' checks and poses: :mod:`kinlearn.collision.moveit_fields`). Files are read with libyaml's safe
loader where it is installed (PyYAML's pure-Python safe loader otherwise), never constructing Python
objects from tags, and within a stated budget checked on the composed document before anything is built
from it: at most :data:`MAX_YAML_BYTES` bytes, :data:`MAX_YAML_NODES` values counting each use of an alias
(a "billion laughs" alias bomb is refused at once), nesting :data:`MAX_YAML_DEPTH` deep, and
:data:`MAX_PRIMITIVES` primitives in a scene. Positions and sizes must lie within ±:data:`MAX_METRES` m;
a pose's quaternion must have a norm within [:data:`QUATERNION_NORM`] (it is normalised within it; a norm
far from 1 is a garbled pose, refused rather than normalised).

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
from .geometry import Box, Cylinder, Plane, Primitive, Sphere
from .moveit_fields import (
    MAX_METRES,
    QUATERNION_NORM,
    _At,
    _describe,
    _list,
    _mapping,
    _name,
    _number,
    _pose,
    _pose_dict,
    pose_matrix,
)

__all__ = [
    "BOX",
    "CONE",
    "CYLINDER",
    "FLOOR_SLAB",
    "MAX_METRES",
    "MAX_PRIMITIVES",
    "MAX_YAML_BYTES",
    "MAX_YAML_DEPTH",
    "MAX_YAML_NODES",
    "QUATERNION_NORM",
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
#: The largest YAML file read (bytes); a larger one is refused before it is read.
MAX_YAML_BYTES = 256 * 2**20
#: The most values (scalars, lists and mappings; an alias counts as many as it stands for) a YAML
#: document may hold: a scene of 10⁵ objects of one primitive each, fully written, holds about 6 × 10⁶.
MAX_YAML_NODES = 10_000_000
#: The deepest nesting of lists and mappings a YAML document may hold (a scene needs 7).
MAX_YAML_DEPTH = 64
#: The most primitives a scene may hold.
MAX_PRIMITIVES = 100_000
_NAMES = {"box": BOX, "sphere": SPHERE, "cylinder": CYLINDER, "cone": CONE}
_OPERATIONS = {"add": 0, "remove": 1, "append": 2, "move": 3}


# --------------------------------------------------------------------------------------------------
# Reading YAML within a budget
# --------------------------------------------------------------------------------------------------


def _check_nodes(root, path) -> None:
    """Refuse a composed YAML document (node graph, aliases shared) that would build more than
    :data:`MAX_YAML_NODES` values, nest deeper than :data:`MAX_YAML_DEPTH` or refer to itself; counted on
    the graph, before any value is built, so an alias bomb costs the size of its text."""
    import yaml

    size: dict[int, int] = {}
    depth: dict[int, int] = {}
    open_: set[int] = set()  # the collections being counted: the current one's ancestors
    scalar = yaml.ScalarNode

    def children(node):
        if isinstance(node, yaml.MappingNode):
            return [n for pair in node.value for n in pair]
        return node.value

    def refuse(node, what: str) -> SceneFormatError:
        return SceneFormatError(f"{path} {what} (near line {node.start_mark.line + 1})")

    if isinstance(root, scalar):
        return
    stack = [(root, False)]
    while stack:
        node, done = stack.pop()
        key = id(node)
        if done:
            s, d = 1, 1
            for k in children(node):
                if isinstance(k, scalar):
                    s += 1
                    d = max(d, 2)
                else:
                    s += size[id(k)]
                    d = max(d, 1 + depth[id(k)])
            if s > MAX_YAML_NODES:
                raise refuse(
                    node,
                    f"would hold more than {MAX_YAML_NODES:,} values, its aliases expanded; a scene or "
                    "request is refused past that budget",
                )
            if d > MAX_YAML_DEPTH:
                raise refuse(
                    node,
                    f"nests lists and mappings more than {MAX_YAML_DEPTH} deep; a scene or request needs "
                    "fewer than 10",
                )
            size[key], depth[key] = s, d
            open_.discard(key)
            continue
        if key in size:
            continue
        open_.add(key)
        stack.append((node, True))
        for k in children(node):
            if isinstance(k, scalar):
                continue
            if id(k) in open_:
                raise refuse(k, "holds an alias to a value that holds it (a structure that contains itself)")
            if id(k) not in size:
                stack.append((k, False))


def _parse_yaml(text: str, path) -> object:
    """``text`` as plain data (mappings, lists, scalars) through the safe loader, within the budget."""
    try:
        import yaml
    except ImportError as exc:  # pragma: no cover - pyyaml is a dependency
        raise MissingDependencyError("reading MoveIt YAML needs PyYAML: `pip install pyyaml`") from exc
    # Every value but the first follows one of these characters: more of them than the budget is refused
    # before the text is composed (dense lists of tiny values would cost gigabytes of nodes).
    separators = sum(text.count(c) for c in ",:\n[{-")
    if separators > MAX_YAML_NODES:
        raise SceneFormatError(
            f"{path} would hold more than {MAX_YAML_NODES:,} values ({separators:,} separators); a scene or "
            "request is refused past that budget"
        )
    loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)(text)
    try:
        node = loader.get_single_node()
        if node is None:
            return None
        _check_nodes(node, path)
        return loader.construct_document(node)
    except SceneFormatError:
        raise
    except yaml.YAMLError as exc:
        raise SceneFormatError(f"{path} is not valid YAML: {exc}") from None
    except RecursionError:
        raise SceneFormatError(
            f"{path} nests lists and mappings more than {MAX_YAML_DEPTH} deep; a scene or request needs "
            "fewer than 10"
        ) from None
    except (ValueError, TypeError, OverflowError) as exc:  # a tagged scalar that is not what its tag says
        raise SceneFormatError(f"{path} is not valid YAML: {type(exc).__name__}: {exc}") from None
    finally:
        loader.dispose()


def read_yaml(source: str | Path | Mapping, what: str) -> Mapping:
    """A YAML file (path) or an already-read mapping, as a mapping: the file read as UTF-8 text, parsed by
    the safe loader within the budget (:data:`MAX_YAML_BYTES`, :data:`MAX_YAML_NODES`,
    :data:`MAX_YAML_DEPTH`); :class:`~kinlearn.errors.SceneFormatError` for anything else."""
    if isinstance(source, Mapping):
        return source
    if not isinstance(source, (str, Path)):
        raise SceneFormatError(f"{what} must be a YAML file path or a dict, got {type(source).__name__}")
    path = Path(source)
    try:
        size = path.stat().st_size
        if size > MAX_YAML_BYTES:
            raise SceneFormatError(
                f"{path} holds {size / 2**20:.0f} MiB; {what} is read up to {MAX_YAML_BYTES // 2**20} MiB"
            )
        raw = path.read_bytes()
    except OSError as exc:
        raise SceneFormatError(f"cannot read {what} {path}: {exc.strerror or exc}") from exc
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise SceneFormatError(
            f"{path} is not UTF-8 text ({exc.reason} at byte {exc.start}); {what} is a YAML file"
        ) from None
    data = _parse_yaml(text, path)
    if not isinstance(data, Mapping):
        raise SceneFormatError(f"{path} must hold a YAML mapping ({what}), got {type(data).__name__}")
    return data


# --------------------------------------------------------------------------------------------------
# Planning scenes
# --------------------------------------------------------------------------------------------------


def _primitive(prim, T: np.ndarray, at: _At) -> Primitive:
    prim = _mapping(prim, at, "type and dimensions", optional=False)
    raw = prim.get("type")
    kind = raw
    if isinstance(raw, str):
        kind = _NAMES.get(raw.strip().lower())
    elif isinstance(raw, (bool, np.bool_)) or not isinstance(raw, (int, np.integer)):
        kind = None
    if kind not in (BOX, SPHERE, CYLINDER, CONE):
        raise SceneFormatError(
            f"{at / 'type'}: unknown primitive type {_describe(raw)} (box 1, sphere 2, cylinder 3)"
        )
    dims_at = at / "dimensions"
    dims = [
        _number(d, dims_at / k, metres=True)
        for k, d in enumerate(_list(prim.get("dimensions"), dims_at, "numbers", optional=False))
    ]
    R, c = T[:3, :3], T[:3, 3]

    def need(n: int, layout: str) -> None:
        if len(dims) < n:
            raise SceneFormatError(f"{dims_at}: a {layout} needs {n} dimension(s), got {dims}")
        if any(d <= 0 for d in dims[:n]):
            raise SceneFormatError(f"{dims_at}: dimensions must be > 0 (metres), got {dims}")

    if kind == BOX:
        need(3, "box [x, y, z] (full side lengths)")
        return Box(c, [d / 2 for d in dims[:3]], R)
    if kind == SPHERE:
        need(1, "sphere [radius]")
        return Sphere(c, dims[0])
    if kind == CYLINDER:
        need(2, "cylinder [height, radius]")
        return Cylinder(c, dims[1], dims[0] / 2, R)
    raise SceneFormatError(f"{at} is a cone; kinlearn's scenes take boxes, spheres and cylinders")


def _frame_id(obj: Mapping, at: _At) -> str:
    """An object's ``header.frame_id`` ('' where it gives none: it is in the scene's frame)."""
    header = _mapping(obj.get("header"), at / "header", "frame_id")
    frame = header.get("frame_id")
    if frame is None or frame == "":
        return ""
    if not isinstance(frame, str):
        raise SceneFormatError(f"{at / 'header.frame_id'} must be a frame name, got {_describe(frame)}")
    return frame.strip().lstrip("/")  # ROS 1 wrote a leading slash: '/world' is 'world'


def _operation(value, at: _At) -> int:
    if value is None:
        return 0
    if isinstance(value, str) and value.strip().lower() in _OPERATIONS:
        return _OPERATIONS[value.strip().lower()]
    if isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_)) and 0 <= value <= 3:
        return int(value)
    raise SceneFormatError(
        f"{at} must be an operation: 0 ADD, 1 REMOVE, 2 APPEND or 3 MOVE, got {_describe(value)}"
    )


def _check_octomap(world: Mapping, at: _At) -> None:
    octomap = _mapping(world.get("octomap"), at / "octomap", "header, origin, octomap")
    inner = _mapping(octomap.get("octomap"), at / "octomap.octomap", "binary, id, resolution, data")
    data = inner.get("data")
    if data is not None and not isinstance(data, (str, bytes, list, tuple, np.ndarray)):
        raise SceneFormatError(
            f"{at / 'octomap.octomap.data'} must be the octree's bytes, got {_describe(data)}"
        )
    if data is not None and len(data):
        raise SceneFormatError(
            "the planning scene holds an octomap (a sensed scene); kinlearn's scenes take boxes, spheres and "
            "cylinders: give the scene's collision objects instead"
        )


def primitives_from_moveit(source: str | Path | Mapping, base_pose=None) -> list[Primitive]:
    """The obstacles of a MoveIt ``PlanningScene`` (YAML file or dict) as typed primitives in the robot's
    base frame (:meth:`Scene.from_moveit <kinlearn.collision.Scene.from_moveit>` makes them a scene).

    ``base_pose``: the robot base's pose in the scene's frame (4 × 4, ``[x, y, z, qx, qy, qz, qw]`` or a
    MoveIt pose mapping; default: the base is the scene's frame). The scene's frame is its objects'
    ``header.frame_id`` (an object without one is in it): objects given in different frames are a
    :class:`~kinlearn.errors.SceneFormatError` naming both (kinlearn holds no transform tree to relate
    them). The scene may be the whole message or its ``world`` part; objects whose ``operation`` is
    REMOVE (1) are skipped. Raises
    :class:`~kinlearn.errors.SceneFormatError` naming the key path of a malformed field, or the object
    holding meshes, planes or cones; and for a scene past the budget (:data:`MAX_PRIMITIVES`, and for a
    file :data:`MAX_YAML_BYTES`, :data:`MAX_YAML_NODES`, :data:`MAX_YAML_DEPTH`).
    """
    data = read_yaml(source, "a MoveIt planning scene")
    root = _At("world") if "world" in data else _At("")
    world = _mapping(data.get("world", data), root, "collision_objects", optional=False)
    _check_octomap(world, root)
    objects_at = root / "collision_objects"
    objects = _list(world.get("collision_objects"), objects_at, "collision objects")
    to_base = np.linalg.inv(_pose(base_pose, _At("base_pose")))
    prims: list[Primitive] = []
    frame: tuple[str, _At] | None = None  # the scene's frame, and the object that named it first
    for i, obj in enumerate(objects):
        at = objects_at / i
        obj = _mapping(obj, at, "id, pose, primitives, primitive_poses", optional=False)
        if obj.get("id") is not None:
            at = at.labelled(_name(obj["id"], at / "id"))
        if _operation(obj.get("operation"), at / "operation") == 1:
            continue
        given = _frame_id(obj, at)
        if given:
            if frame is None:
                frame = (given, at)
            elif given != frame[0]:
                raise SceneFormatError(
                    f"{at} is given in frame {given!r}, {frame[1]} in {frame[0]!r}: kinlearn reads a scene "
                    "in one frame (base_pose places the robot's base in it); express every object in that "
                    "frame first"
                )
        for field in ("meshes", "planes"):
            value = obj.get(field)
            if value is not None and not isinstance(value, (list, tuple)):
                raise SceneFormatError(f"{at / field} must be a list, got {_describe(value)}")
            if value:
                raise SceneFormatError(
                    f"{at} holds {field}; kinlearn's scenes take boxes, spheres and cylinders "
                    f"(replace its {field} by primitives)"
                )
        shapes = _list(obj.get("primitives"), at / "primitives", "primitives (type, dimensions)")
        poses = _list(obj.get("primitive_poses"), at / "primitive_poses", "poses")
        if len(shapes) != len(poses):
            raise SceneFormatError(
                f"{at} has {len(shapes)} primitives and {len(poses)} primitive_poses; give one pose each"
            )
        if len(prims) + len(shapes) > MAX_PRIMITIVES:
            raise SceneFormatError(
                f"the scene holds more than {MAX_PRIMITIVES:,} primitives (at {at}); kinlearn reads scenes of "
                f"up to {MAX_PRIMITIVES:,}"
            )
        T_obj = to_base @ _pose(obj.get("pose"), at / "pose")
        for k, (prim, pose) in enumerate(zip(shapes, poses, strict=True)):
            T = T_obj @ _pose(pose, at / "primitive_poses" / k)
            prims.append(_primitive(prim, T, at / "primitives" / k))
        if str(at.label).startswith("floor") and len(shapes) == 1:
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
        elif isinstance(p, Plane):  # the floor: a slab under its height
            T[:3, 3] = (0.0, 0.0, p.offset - FLOOR_SLAB[2] / 2)
            prim = {"type": BOX, "dimensions": list(FLOOR_SLAB)}
        else:
            raise SceneFormatError(
                f"a MoveIt scene holds spheres, boxes, cylinders and cones, no {p.kind}: {p!r} cannot be written"
            )
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


# --------------------------------------------------------------------------------------------------
# Motion plan requests
# --------------------------------------------------------------------------------------------------


def _joint_map(state: Mapping, at: _At) -> dict[str, float]:
    names = _list(state.get("name"), at / "name", "joint names", optional=False)
    positions = _list(state.get("position"), at / "position", "numbers (rad or m)", optional=False)
    if len(names) != len(positions):
        raise SceneFormatError(f"{at}: {len(names)} names but {len(positions)} positions")
    out = {}
    for k, (n, p) in enumerate(zip(names, positions, strict=True)):
        out[_name(n, at / "name" / k)] = _number(p, at / "position" / k)
    return out


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
    (YAML file or dict; the request itself or a mapping holding it as ``motion_plan_request``):
    ``start_state.joint_state`` (name, position) and the first ``goal_constraints[]`` entry whose
    ``joint_constraints`` name every joint of the robot. Joints the robot does not have (fingers, …) are
    ignored; a missing one is a :class:`~kinlearn.errors.SceneFormatError` naming it, as is a malformed
    field (named by its key path)."""
    if not isinstance(robot, Robot):
        raise SceneFormatError(
            f"request_joints needs the kinlearn Robot to plan for, got {type(robot).__name__}"
        )
    data = read_yaml(source, "a MoveIt motion plan request")
    root = _At("motion_plan_request") if "motion_plan_request" in data else _At("")
    req = _mapping(
        data.get("motion_plan_request", data), root, "start_state, goal_constraints", optional=False
    )
    start_at = root / "start_state"
    state_at = start_at / "joint_state"
    start_state = _mapping(req.get("start_state"), start_at, "joint_state")
    if start_state.get("joint_state") is None:
        raise SceneFormatError(f"the request has no {state_at} (name, position)")
    state = _mapping(start_state.get("joint_state"), state_at, "name, position", optional=False)
    start = _in_order(_joint_map(state, state_at), robot, str(start_at))
    goals_at = root / "goal_constraints"
    goals = _list(req.get("goal_constraints"), goals_at, "constraints (joint_constraints)")
    if not goals:
        raise SceneFormatError(f"the request has no {goals_at} with joint_constraints")
    last = None
    for g, goal in enumerate(goals):
        at = goals_at / g
        goal = _mapping(goal, at, "joint_constraints")
        values = {}
        cons_at = at / "joint_constraints"
        for c, con in enumerate(_list(goal.get("joint_constraints"), cons_at, "joint constraints")):
            con = _mapping(con, cons_at / c, "joint_name, position", optional=False)
            if "joint_name" not in con or "position" not in con:
                raise SceneFormatError(f"{cons_at / c}: each joint constraint needs joint_name and position")
            values[_name(con["joint_name"], cons_at / c / "joint_name")] = _number(
                con["position"], cons_at / c / "position"
            )
        try:
            return start, _in_order(values, robot, str(at))
        except SceneFormatError as exc:
            last = exc
    raise last  # type: ignore[misc]
