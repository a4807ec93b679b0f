"""MoveIt planning scenes and motion plan requests: a round trip, a scene file in MoveIt's published
YAML layout against an independent parse (pinocchio's quaternions, written out here), base poses, and
the typed errors."""

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import torch
import yaml

import kinlearn
from kinlearn import load_robot
from kinlearn.collision import Scene
from kinlearn.collision.geometry import Box, Cylinder, Sphere, rotation_from_quaternion
from kinlearn.collision.moveit import FLOOR_SLAB, request_joints
from kinlearn.collision.scene import as_scene
from kinlearn.data.problems import ProblemSet
from kinlearn.errors import SceneFormatError

DATA = Path(__file__).resolve().parents[1] / "benchmarks" / "data"

# A planning scene as MoveIt writes it (moveit_msgs/PlanningScene): one object with an object pose and
# two primitives posed relative to it, one written the older way (no object pose), one sphere.
SCENE_YAML = """
name: shelf
robot_model_name: panda
is_diff: true
world:
  collision_objects:
    - header: {frame_id: world}
      id: shelf
      pose:
        position: {x: 0.6, y: 0.1, z: 0.2}
        orientation: {x: 0.0, y: 0.0, z: 0.3826834324, w: 0.9238795325}
      primitives:
        - type: 1
          dimensions: [0.4, 0.8, 0.02]
        - type: 3
          dimensions: [0.5, 0.03]
      primitive_poses:
        - position: {x: 0.0, y: 0.0, z: 0.3}
          orientation: {x: 0.0, y: 0.0, z: 0.0, w: 1.0}
        - position: {x: 0.1, y: -0.2, z: 0.0}
          orientation: {x: 0.7071067812, y: 0.0, z: 0.0, w: 0.7071067812}
      operation: 0
    - header: {frame_id: world}
      id: old_style_box
      primitives:
        - type: 1
          dimensions: [0.1, 0.2, 0.3]
      primitive_poses:
        - position: {x: -0.3, y: 0.4, z: 0.5}
          orientation: {x: 0.1, y: 0.2, z: 0.3, w: 0.9}
    - id: ball
      primitives:
        - {type: 2, dimensions: [0.07]}
      primitive_poses:
        - position: {x: 0.2, y: 0.2, z: 0.9}
          orientation: {w: 1.0}
"""


def _pin_pose(pose: dict | None) -> pin.SE3:
    """An independent reading of a MoveIt pose: pinocchio's quaternion (w, x, y, z order)."""
    if pose is None:
        return pin.SE3.Identity()
    p, o = pose.get("position", {}), pose.get("orientation", {})
    q = pin.Quaternion(o.get("w", 1.0), o.get("x", 0.0), o.get("y", 0.0), o.get("z", 0.0))
    q.normalize()
    return pin.SE3(q.toRotationMatrix(), np.array([p.get("x", 0.0), p.get("y", 0.0), p.get("z", 0.0)]))


def _independent(data: dict, base: pin.SE3) -> dict[str, list]:
    """Per kind: (centre, rotation, sizes) of every primitive, in the base frame."""
    out = {"box": [], "sphere": [], "cylinder": []}
    for obj in data["world"]["collision_objects"]:
        T_obj = base.inverse() * _pin_pose(obj.get("pose"))
        for prim, pose in zip(obj["primitives"], obj["primitive_poses"], strict=True):
            T = T_obj * _pin_pose(pose)
            d = prim["dimensions"]
            if prim["type"] == 1:
                out["box"].append((T.translation, T.rotation, [d[0] / 2, d[1] / 2, d[2] / 2]))
            elif prim["type"] == 2:
                out["sphere"].append((T.translation, np.eye(3), [d[0]]))
            else:
                out["cylinder"].append((T.translation, T.rotation, [d[1], d[0] / 2]))
    return out


def _check_against(scene: Scene, ref: dict[str, list]) -> None:
    assert (scene.num_boxes, scene.num_spheres, scene.num_cylinders) == tuple(
        len(ref[k]) for k in ("box", "sphere", "cylinder")
    )
    for row, (c, R, h) in zip(scene.boxes.numpy(), ref["box"], strict=True):
        np.testing.assert_allclose(row[:3], c, atol=1e-12)
        np.testing.assert_allclose(row[3:6], h, atol=1e-12)
        np.testing.assert_allclose(row[6:].reshape(3, 3), R, atol=1e-9)
    for row, (c, _, r) in zip(scene.spheres.numpy(), ref["sphere"], strict=True):
        np.testing.assert_allclose(row, [*c, *r], atol=1e-12)
    for row, (c, R, rh) in zip(scene.cylinders.numpy(), ref["cylinder"], strict=True):
        np.testing.assert_allclose(row[:5], [*c, *rh], atol=1e-12)
        np.testing.assert_allclose(row[5:].reshape(3, 3), R, atol=1e-9)


def test_published_layout_matches_an_independent_parse(tmp_path):
    path = tmp_path / "scene.yaml"
    path.write_text(SCENE_YAML)
    data = yaml.safe_load(SCENE_YAML)
    scene = Scene.from_moveit(path)
    _check_against(scene, _independent(data, pin.SE3.Identity()))
    # The same from the dict, and with the base somewhere in the scene's frame (4 × 4 or 7 numbers).
    base_q = np.array([0.0, 0.0, np.sin(0.3), np.cos(0.3)])
    base = pin.SE3(rotation_from_quaternion(base_q), np.array([0.1, -0.2, 0.05]))
    for pose in (base.homogeneous, [0.1, -0.2, 0.05, *base_q]):
        _check_against(Scene.from_moveit(data, base_pose=pose), _independent(data, base))


def test_round_trip_through_moveit_yaml():
    rng = np.random.default_rng(0)
    Rs = [rotation_from_quaternion(q) for q in rng.normal(size=(4, 4))]
    prims = [
        Sphere((0.5, 0.0, 0.6), 0.1),
        Sphere((0.1, 0.2, 0.3), 0.05),
        Box((0.6, 0.3, 0.2), (0.1, 0.1, 0.2), Rs[0]),
        Box((0.0, -0.3, 0.4), (0.3, 0.05, 0.01), Rs[1]),
        Cylinder((0.4, -0.3, 0.3), 0.05, 0.2, Rs[2]),
    ]
    scene = Scene.from_primitives(prims)
    text = yaml.safe_dump(scene.to_moveit(frame_id="panda_link0"))
    back = Scene.from_moveit(yaml.safe_load(text))
    assert torch.allclose(back.spheres, scene.spheres, atol=1e-12)
    assert torch.allclose(back.boxes, scene.boxes, atol=1e-12)
    assert torch.allclose(back.cylinders, scene.cylinders, atol=1e-12)
    # A floor goes out as a slab under its height and comes back as the floor, not as a box (which would
    # hold the robot's base in collision); a box of other sizes named floor stays a box.
    floored = Scene.from_primitives(prims[:1], floor=0.1).to_moveit()
    slab = floored["world"]["collision_objects"][-1]
    assert slab["id"] == "floor_0" and slab["primitives"][0]["dimensions"] == list(FLOOR_SLAB)
    back = Scene.from_moveit(floored)
    assert back.num_boxes == 0 and float(back.floor) == pytest.approx(0.1, abs=1e-12)
    slab["primitives"][0]["dimensions"] = [2.0, 2.0, 0.1]
    assert Scene.from_moveit(floored).num_boxes == 1 and Scene.from_moveit(floored).floor is None


def test_a_scene_read_back_from_moveit_plans_as_the_scene_itself():
    """A held-out scene problem written to a MoveIt file and read back (the floor as the floor) is planned
    as it was: the same stage and verdict. Before, the floor came back as a box that held the base's
    spheres in collision, and every plan of every such scene failed."""
    ps = ProblemSet.load(DATA / "scene_problems_panda.npz", robot="panda")
    planner = kinlearn.Planner.default("panda")
    solved = 0
    for i in (0, 1, 2):
        start, goal, scene = ps.problem(i)
        back = Scene.from_moveit(yaml.safe_load(yaml.safe_dump(as_scene(scene).to_moveit())))
        a = planner.plan(start, goal, obstacles=scene, refine_steps=0)
        b = planner.plan(start, goal, obstacles=back, refine_steps=0)
        assert (a.stage, bool(a.success), bool(a.collision_free)) == (
            b.stage,
            bool(b.success),
            bool(b.collision_free),
        )
        assert torch.equal(a.joints, b.joints)
        solved += bool(b.success)
    assert solved >= 2


def _as_lists(data):
    """``data`` with every pose's position and orientation written as lists (x, y, z / x, y, z, w) and
    primitive types as names: the layout robowflex writes, and so MotionBenchMaker's scene files."""
    if isinstance(data, dict):
        out = {k: _as_lists(v) for k, v in data.items()}
        if "position" in out and isinstance(out["position"], dict):
            out["position"] = [out["position"].get(k, 0.0) for k in "xyz"]
        if "orientation" in out and isinstance(out["orientation"], dict):
            out["orientation"] = [out["orientation"].get(k, 1.0 if k == "w" else 0.0) for k in "xyzw"]
        if out.get("type") in (1, 2, 3):
            out["type"] = {1: "box", 2: "sphere", 3: "cylinder"}[out["type"]]
        return out
    if isinstance(data, list):
        return [_as_lists(v) for v in data]
    return data


def test_poses_written_as_lists_read_as_their_mappings(tmp_path):
    """position: [x, y, z] and orientation: [x, y, z, w] (robowflex's layout) are the same poses."""
    data = yaml.safe_load(SCENE_YAML)
    listed = _as_lists(data)
    assert listed["world"]["collision_objects"][0]["pose"]["orientation"] == [
        0.0,
        0.0,
        0.3826834324,
        0.9238795325,
    ]
    path = tmp_path / "listed.yaml"
    path.write_text(yaml.safe_dump(listed, default_flow_style=None))
    base = [0.1, -0.2, 0.05, 0.0, 0.0, np.sin(0.3), np.cos(0.3)]
    for a, b in (
        (Scene.from_moveit(path), Scene.from_moveit(data)),
        (Scene.from_moveit(listed, base), Scene.from_moveit(data, base)),
    ):
        for t in ("spheres", "boxes", "cylinders"):
            assert torch.equal(getattr(a, t), getattr(b, t))
    bad = _as_lists(data)
    bad["world"]["collision_objects"][1]["primitive_poses"][0]["orientation"] = [0.0, 0.0, 1.0]
    with pytest.raises(
        SceneFormatError,
        match=r"collision_objects\[1\]\.primitive_poses\[0\]\.orientation \(object 'old_style_box'\) must be",
    ):
        Scene.from_moveit(bad)
    bad["world"]["collision_objects"][1]["primitive_poses"][0]["orientation"] = "up"
    with pytest.raises(SceneFormatError, match=r"orientation \(object 'old_style_box'\) must be a mapping"):
        Scene.from_moveit(bad)


@pytest.mark.parametrize(
    "obj, match",
    [
        ({"id": "bowl", "meshes": [{"triangles": []}]}, r"\(object 'bowl'\) holds meshes"),
        ({"id": "wall", "planes": [{"coef": [0, 0, 1, 0]}]}, r"\(object 'wall'\) holds planes"),
        (
            {"id": "funnel", "primitives": [{"type": 4, "dimensions": [1, 1]}], "primitive_poses": [{}]},
            r"primitives\[0\] \(object 'funnel'\) is a cone",
        ),
        ({"id": "odd", "primitives": [{"type": 1, "dimensions": [1, 1, 1]}]}, "one pose each"),
        (
            {"id": "flat", "primitives": [{"type": 1, "dimensions": [1, 0, 1]}], "primitive_poses": [{}]},
            "'flat'.*> 0",
        ),
        (
            {"id": "nine", "primitives": [{"type": 9, "dimensions": [1]}], "primitive_poses": [{}]},
            "unknown primitive type",
        ),
    ],
)
def test_unsupported_geometry_is_a_typed_error_naming_the_object(obj, match):
    with pytest.raises(SceneFormatError, match=match):
        Scene.from_moveit({"world": {"collision_objects": [obj]}})


def test_a_sensed_scene_is_refused_not_read_as_empty():
    octomap = {"origin": {}, "octomap": {"binary": True, "id": "OcTree", "resolution": 0.02, "data": "78DA"}}
    with pytest.raises(SceneFormatError, match="octomap"):
        Scene.from_moveit({"world": {"octomap": octomap}})


def test_unreadable_files(tmp_path):
    with pytest.raises(SceneFormatError, match="cannot read"):
        Scene.from_moveit(tmp_path / "absent.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("world: [unclosed")
    with pytest.raises(SceneFormatError, match="not valid YAML"):
        Scene.from_moveit(bad)
    with pytest.raises(SceneFormatError, match="base_pose"):
        Scene.from_moveit({"world": {}}, base_pose=[1, 2, 3])


def test_motion_plan_request_joints_in_the_robots_order():
    robot = load_robot("panda")
    names = [j.name for j in robot.joints]
    start = np.linspace(-0.5, 0.5, robot.dof)
    goal = np.linspace(0.3, -0.3, robot.dof)
    order = np.random.default_rng(1).permutation(robot.dof)
    request = {
        "start_state": {
            "joint_state": {
                "name": [names[i] for i in order] + ["panda_finger_joint1"],
                "position": [float(start[i]) for i in order] + [0.04],
            }
        },
        "goal_constraints": [
            {"joint_constraints": [{"joint_name": names[0], "position": 0.0}]},  # incomplete: skipped
            {
                "joint_constraints": [
                    {"joint_name": names[i], "position": float(goal[i]), "tolerance_above": 0.01}
                    for i in order
                ]
            },
        ],
    }
    s, g = request_joints({"motion_plan_request": request}, robot)
    np.testing.assert_array_equal(s.numpy(), start)
    np.testing.assert_array_equal(g.numpy(), goal)
    request["start_state"]["joint_state"]["name"][0] = "elbow"
    with pytest.raises(SceneFormatError, match=names[order[0]]):
        request_joints(request, robot)


def test_cli_plans_a_moveit_scene_and_request(tmp_path, capsys):
    from kinlearn.cli.main import main

    robot = load_robot("iiwa14")
    names = [j.name for j in robot.joints]
    start = [-1.2, 0.9, 0.5, -1.6, 0.3, 1.2, -2.0]
    goal = [1.5, -0.4, -0.8, 1.1, -1.9, -0.6, 2.4]
    request = {
        "start_state": {"joint_state": {"name": names, "position": start}},
        "goal_constraints": [
            {
                "joint_constraints": [
                    {"joint_name": n, "position": v} for n, v in zip(names, goal, strict=True)
                ]
            }
        ],
    }
    (tmp_path / "request.yaml").write_text(yaml.safe_dump(request))
    scene = Scene.from_primitives([Sphere((2.0, 2.0, 2.0), 0.1), Box((-1.5, 0.0, 0.3), (0.1, 0.1, 0.3))])
    (tmp_path / "scene.yaml").write_text(yaml.safe_dump(scene.to_moveit(frame_id="iiwa_link_0")))
    args = ["plan", "--robot", "iiwa14", "--scene", str(tmp_path / "scene.yaml")]
    code = main([*args, "--request", str(tmp_path / "request.yaml")])
    out = capsys.readouterr().out
    assert code == 0 and "collision" in out.lower()
    assert main([*args, "--request", str(tmp_path / "request.yaml"), "--start", "0,0,0,0,0,0,0"]) == 2
    assert "leave out --start" in capsys.readouterr().err
    assert main(args) == 2
    assert "--request" in capsys.readouterr().err


@pytest.mark.parametrize("name", ["panda", "ur5"])
def test_arm_without_an_obstacle_network_says_so_and_checks_densely(name, tmp_path):
    """A planner without an obstacle network (the shipped arm's, its obstacle network left out) says so,
    plans the straight line and samples, and flags what it could not clear."""
    from kinlearn.collision import body_spheres, check_path
    from kinlearn.errors import NoObstacleModelWarning
    from kinlearn.planning.planner import Planner

    robot = load_robot(name)
    base = Planner.default(name)
    plain = Planner(robot, base.tm, base.fm, base.im)
    mid = (robot.lower + robot.upper) / 2
    start = torch.tensor(mid + 0.1 * (robot.upper - mid), dtype=torch.float64)
    goal = torch.tensor(mid - 0.1 * (robot.upper - mid), dtype=torch.float64)
    R = rotation_from_quaternion([0.0, 0.0, 0.3826834324, 0.9238795325])
    far = Scene.from_primitives(
        [Box((2.0, 2.0, 0.5), (0.1, 0.1, 0.5), R), Cylinder((-2.0, 0.0, 0.5), 0.1, 0.5)]
    )
    path = tmp_path / "scene.yaml"
    path.write_text(yaml.safe_dump(far.to_moveit()))
    body = body_spheres(robot).double()
    for scene in (Scene.from_moveit(path), Scene.from_primitives([Sphere((0.0, 0.0, 0.0), 3.0)])):
        with pytest.warns(NoObstacleModelWarning, match="no obstacle-trained network"):
            plan = plain.plan(start, goal, obstacles=scene)
        dense = check_path(body, plan.joints.double(), scene)
        assert bool(plan.collision_free) == bool(dense.collision_free)
    assert not bool(plan.collision_free)  # inside a ball that holds the whole arm: flagged, not silent
    with pytest.warns(NoObstacleModelWarning, match=r"alone \(refine_steps=0\)"):
        plain.plan(start, goal, obstacles=scene, refine_steps=0)


def test_objects_in_different_frames_are_refused_and_one_frame_reads():
    """Every object in one frame (or none named) reads; an object in another frame is a typed error naming
    both objects and frames, never silently taken in the first one's frame."""
    box = {"type": 1, "dimensions": [0.2, 0.2, 0.2]}
    pose = {"position": {"x": 0.5, "y": 0.0, "z": 0.3}, "orientation": {"w": 1.0}}

    def obj(name, frame):
        o = {"id": name, "primitives": [box], "primitive_poses": [pose]}
        if frame is not None:
            o["header"] = {"frame_id": frame}
        return o

    same = {"world": {"collision_objects": [obj("a", "world"), obj("b", "/world"), obj("c", None)]}}
    assert Scene.from_moveit(same).num_boxes == 3
    mixed = {"world": {"collision_objects": [obj("a", "world"), obj("b", "panda_link0")]}}
    with pytest.raises(SceneFormatError, match=r"'b'.*'panda_link0'.*'a'.*'world'"):
        Scene.from_moveit(mixed)
    with pytest.raises(SceneFormatError, match="frame_id"):
        Scene.from_moveit({"world": {"collision_objects": [{**obj("a", None), "header": {"frame_id": 3}}]}})
