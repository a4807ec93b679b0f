"""The MoveIt reader held to typed errors: every malformed field of a scene or a request is a SceneFormatError
naming its key path (never a plain Python error), files are read within a stated budget (an alias bomb is
refused from its composed graph, before anything is built), and numbers given as NumPy or torch values
are numbers."""

import numpy as np
import pytest
import torch
import yaml

from kinlearn import load_robot
from kinlearn.collision import Scene
from kinlearn.collision.moveit import (
    MAX_PRIMITIVES,
    MAX_YAML_DEPTH,
    MAX_YAML_NODES,
    read_yaml,
    request_joints,
)
from kinlearn.errors import SceneFormatError

BOX = {"type": 1, "dimensions": [0.2, 0.2, 0.2]}
POSE = {"position": {"x": 0.5, "y": 0.0, "z": 0.3}, "orientation": {"w": 1.0}}


def _scene(*objects) -> dict:
    return {"world": {"collision_objects": list(objects)}}


def _obj(name="box", **fields) -> dict:
    return {"id": name, "primitives": [BOX], "primitive_poses": [POSE], **fields}


@pytest.mark.parametrize(
    "scene, match",
    [
        (_scene(_obj(pose="abc")), r"world\.collision_objects\[0\]\.pose \(object 'box'\) must be a mapping"),
        (_scene(_obj(pose=[1, 2, [3]])), r"collision_objects\[0\]\.pose \(object 'box'\) must be"),
        (_scene(_obj(primitives=5)), r"collision_objects\[0\]\.primitives \(object 'box'\) must be a list"),
        (
            _scene(_obj(primitives={"type": 1}, primitive_poses={"a": POSE})),
            r"collision_objects\[0\]\.primitives .*must be a list",
        ),
        (_scene(_obj(primitives=[5])), r"collision_objects\[0\]\.primitives\[0\] .*must be a mapping"),
        (
            _scene(_obj(primitives=[{"type": [1], "dimensions": [1, 1, 1]}])),
            r"primitives\[0\]\.type .*unknown primitive type",
        ),
        (
            _scene(_obj(primitives=[{"type": 1, "dimensions": [1, "x", 1]}])),
            r"primitives\[0\]\.dimensions\[1\] .*must be a number",
        ),
        (
            _scene(_obj(primitives=[{"type": 1, "dimensions": 1}])),
            r"primitives\[0\]\.dimensions .*must be a list",
        ),
        (
            _scene(_obj(pose={"position": {"x": [1]}})),
            r"collision_objects\[0\]\.pose\.position\.x \(object 'box'\) must be a number",
        ),
        (_scene(_obj(pose={"position": {"x": True}})), r"pose\.position\.x .*must be a number"),
        (_scene(_obj(header=[1])), r"collision_objects\[0\]\.header .*must be a mapping"),
        (_scene(_obj(operation=[1])), r"collision_objects\[0\]\.operation .*must be an operation"),
        (_scene(_obj(name=[1])), r"collision_objects\[0\]\.id must be a name"),
        (_scene(_obj(meshes=5)), r"collision_objects\[0\]\.meshes .*must be a list"),
        (_scene(5), r"world\.collision_objects\[0\] must be a mapping"),
        ({"world": {"collision_objects": 5}}, r"world\.collision_objects must be a list"),
        ({"world": [1]}, r"world must be a mapping"),
        ({"world": {"octomap": {"octomap": [1, 2]}}}, r"world\.octomap\.octomap must be a mapping"),
        ({"world": {"octomap": 3}}, r"world\.octomap must be a mapping"),
        # a quaternion of absurd norm is a garbled pose, not the identity rotation
        (
            _scene(_obj(pose={"orientation": {"x": 1e200, "w": 1e200}})),
            r"pose\.orientation \(object 'box'\): the orientation quaternion has norm 1\.41.*e\+200",
        ),
        # a box of 1e300 m is refused as a size, not reported as NaN in a candidate path later
        (
            _scene(_obj(primitives=[{"type": 1, "dimensions": [1e300, 1, 1]}])),
            r"primitives\[0\]\.dimensions\[0\] \(object 'box'\) is 1e\+300 m",
        ),
    ],
)
def test_a_malformed_scene_field_is_a_typed_error_naming_its_key_path(scene, match):
    with pytest.raises(SceneFormatError, match=match):
        Scene.from_moveit(scene)


def test_the_fourth_object_is_named_by_its_index():
    objects = [_obj(f"o{i}") for i in range(3)] + [_obj("o3", pose={"position": "here"})]
    with pytest.raises(
        SceneFormatError, match=r"world\.collision_objects\[3\]\.pose\.position \(object 'o3'\)"
    ):
        Scene.from_moveit(_scene(*objects))


@pytest.mark.parametrize("base_pose", ["abc", [1, 2, [3]], [1, 2, 3], {"position": "x"}, torch.zeros(3, 3)])
def test_a_malformed_base_pose_is_a_typed_error(base_pose):
    with pytest.raises(SceneFormatError, match="base_pose"):
        Scene.from_moveit(_scene(_obj()), base_pose=base_pose)


def test_numbers_given_as_numpy_or_torch_values_read_as_numbers():
    plain = Scene.from_moveit(_scene(_obj()), base_pose=[0.1, 0, 0, 0, 0, 0, 1])
    pose = {
        "position": {"x": np.float32(0.5), "y": np.int64(0), "z": torch.tensor(0.3, dtype=torch.float64)},
        "orientation": np.array([0.0, 0.0, 0.0, 1.0]),
    }
    prim = {"type": np.int64(1), "dimensions": np.array([0.2, 0.2, 0.2])}
    numpy_scene = _scene({"id": "box", "primitives": [prim], "primitive_poses": [pose]})
    for base in (
        np.array([0.1, 0, 0, 0, 0, 0, 1]),
        torch.tensor([0.1, 0, 0, 0, 0, 0, 1.0], dtype=torch.float64),
    ):
        got = Scene.from_moveit(numpy_scene, base_pose=base)
        torch.testing.assert_close(got.boxes, plain.boxes, rtol=0, atol=1e-7)


def test_random_bytes_deep_nesting_and_self_reference_are_typed(tmp_path):
    rng = np.random.default_rng(0)
    cases = {
        "bytes.yaml": rng.integers(0, 256, 4096, dtype=np.uint8).tobytes(),
        "nested.yaml": b"world: " + b"[" * 100_000 + b"]" * 100_000,
        "blocks.yaml": "".join(f"{'  ' * i}k:\n" for i in range(MAX_YAML_DEPTH + 5)).encode(),
        "cycle.yaml": b"world: &w {collision_objects: [*w]}",
        "tag.yaml": b"world: !!python/object/apply:os.system ['true']",
        "float.yaml": b"world: {collision_objects: [{id: a, pose: !!float abc}]}",
        "list.yaml": b"[1, 2]",
        "empty.yaml": b"",
    }
    for name, content in cases.items():
        path = tmp_path / name
        path.write_bytes(content)
        with pytest.raises(SceneFormatError, match=str(path).replace("\\", "\\\\")):
            Scene.from_moveit(path)


def test_an_alias_bomb_is_refused_from_its_composed_graph(tmp_path):
    """10⁴ objects of 10³ primitives each, in 2 KB of aliases: refused by counting the composed graph
    (it would build 10⁷ values) before a single object is constructed."""
    text = (
        "p: &p {type: 1, dimensions: [0.1, 0.1, 0.1]}\n"
        "q: &q {position: {x: 0.5}, orientation: {w: 1}}\n"
        f"ps: &ps [{', '.join(['*p'] * 1000)}]\n"
        f"qs: &qs [{', '.join(['*q'] * 1000)}]\n"
        "o: &o {id: bomb, primitives: *ps, primitive_poses: *qs}\n"
        f"world: {{collision_objects: [{', '.join(['*o'] * 10_000)}]}}\n"
    )
    path = tmp_path / "bomb.yaml"
    path.write_text(text)
    assert path.stat().st_size < 100_000
    with pytest.raises(SceneFormatError, match=f"bomb.yaml would hold more than {MAX_YAML_NODES:,} values"):
        Scene.from_moveit(path)


def test_more_primitives_than_the_budget_are_refused():
    many = {
        "id": "many",
        "primitives": [BOX] * (MAX_PRIMITIVES + 1),
        "primitive_poses": [POSE] * (MAX_PRIMITIVES + 1),
    }
    with pytest.raises(SceneFormatError, match="more than 100,000 primitives"):
        Scene.from_moveit(_scene(many))


def test_a_large_plain_scene_reads(tmp_path):
    objects = [
        {
            "id": f"b{i}",
            "primitives": [BOX],
            "primitive_poses": [{"position": [i * 0.01, 0, 0], "orientation": [0, 0, 0, 1]}],
        }
        for i in range(300)
    ]
    path = tmp_path / "many.yaml"
    path.write_text(yaml.safe_dump(_scene(*objects)))
    assert Scene.from_moveit(path).num_boxes == 300
    assert read_yaml(path, "a scene")["world"]["collision_objects"][299]["id"] == "b299"


ROBOT = load_robot("iiwa14")
NAMES = [j.name for j in ROBOT.joints]


def _request(**fields) -> dict:
    request = {
        "start_state": {"joint_state": {"name": NAMES, "position": [0.1] * 7}},
        "goal_constraints": [{"joint_constraints": [{"joint_name": n, "position": -0.1} for n in NAMES]}],
    }
    request.update(fields)
    return request


@pytest.mark.parametrize(
    "request_, match",
    [
        ({"motion_plan_request": [1]}, r"motion_plan_request must be a mapping"),
        (_request(start_state=[1, 2]), r"start_state must be a mapping"),
        (_request(start_state={"joint_state": [1]}), r"start_state\.joint_state must be a mapping"),
        (
            _request(start_state={"joint_state": {"name": NAMES, "position": 5}}),
            r"start_state\.joint_state\.position must be a list",
        ),
        (
            _request(start_state={"joint_state": {"name": [[1]] * 7, "position": [0.0] * 7}}),
            r"start_state\.joint_state\.name\[0\] must be a name",
        ),
        (
            _request(start_state={"joint_state": {"name": NAMES, "position": ["a"] * 7}}),
            r"start_state\.joint_state\.position\[0\] must be a number",
        ),
        (_request(goal_constraints=[[1]]), r"goal_constraints\[0\] must be a mapping"),
        (_request(goal_constraints=5), r"goal_constraints must be a list"),
        (
            _request(goal_constraints=[{"joint_constraints": [5]}]),
            r"goal_constraints\[0\]\.joint_constraints\[0\]",
        ),
        (
            _request(goal_constraints=[{"joint_constraints": [{"joint_name": NAMES[0]}]}]),
            r"joint_constraints\[0\]: each joint constraint needs joint_name and position",
        ),
    ],
)
def test_a_malformed_request_field_is_a_typed_error_naming_its_key_path(request_, match):
    with pytest.raises(SceneFormatError, match=match):
        request_joints(request_, ROBOT)


def test_request_positions_as_numpy_arrays():
    start, goal = request_joints(
        _request(start_state={"joint_state": {"name": np.array(NAMES), "position": np.full(7, 0.2)}}), ROBOT
    )
    assert start.tolist() == [0.2] * 7 and goal.tolist() == [-0.1] * 7


def test_cli_refuses_bad_moveit_files_with_their_message_and_no_traceback(tmp_path, capsys):
    from kinlearn.cli.main import main

    scene = tmp_path / "scene.yaml"
    scene.write_bytes(b"world: {collision_objects: [{id: a, pose: abc, primitives: 5}]}")
    request = tmp_path / "request.yaml"
    request.write_bytes(b"motion_plan_request: [1]")
    ends = ["--start", ",".join(["0.1"] * 7), "--goal", ",".join(["-0.1"] * 7)]
    for args, match in (
        (["--scene", str(scene), *ends], "world.collision_objects[0].primitives (object 'a') must be a list"),
        (["--request", str(request)], "motion_plan_request must be a mapping"),
        (["--obstacles", str(scene), *ends], "--scene"),
    ):
        assert main(["plan", *args]) == 2  # a raw error would propagate here
        assert match in capsys.readouterr().err


def test_a_moveit_file_loaded_as_a_kinlearn_scene_points_to_from_moveit(tmp_path):
    from kinlearn.errors import DatasetError

    path = tmp_path / "scene.yaml"
    path.write_text(yaml.safe_dump(_scene(_obj())))
    with pytest.raises(
        DatasetError, match=r"looks like YAML: a MoveIt planning scene is read with Scene\.from_moveit"
    ):
        Scene.load(path)


def test_a_dense_list_past_the_budget_is_refused_before_it_is_composed(tmp_path, monkeypatch):
    import kinlearn.collision.moveit as moveit

    monkeypatch.setattr(moveit, "MAX_YAML_NODES", 1000)
    path = tmp_path / "dense.yaml"
    path.write_text("world: [" + ",".join(["0"] * 3000) + "]")
    composed = []
    monkeypatch.setattr(moveit, "_check_nodes", lambda *a: composed.append(a))
    with pytest.raises(SceneFormatError, match=r"more than 1,000 values \(3,00\d separators\)"):
        Scene.from_moveit(path)
    assert not composed
