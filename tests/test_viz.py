"""The plan animation (GIF) and the browser viewer (viser) on the real robots and a real local server."""

import socket
import sys
import time
import urllib.error
import urllib.request

import numpy as np
import pytest
import torch
from conftest import ALL_ROBOTS

import kinlearn
from kinlearn.errors import ConfigError, MissingDependencyError, NonFiniteError, ObstacleError, ShapeError
from kinlearn.viz import animate_plan, show_plan

SPHERES = np.array([[0.5, 0.3, 0.6, 0.1], [0.3, -0.4, 0.3, 0.05]])
BOXES = np.array([[0.4, -0.3, 0.2, 0.1, 0.1, 0.2]])


def _path(robot, n: int, seed: int = 0) -> torch.Tensor:
    a, b = robot.sample(2, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
    return a + torch.linspace(0, 1, n, dtype=torch.float64)[:, None] * (b - a)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# ---------------------------------------------------------------------------------------------- animation


def test_animation_writes_one_gif_frame_per_configuration(tmp_path):
    pil = pytest.importorskip("PIL.Image")
    pytest.importorskip("matplotlib")
    robot = kinlearn.load_robot("iiwa14")
    joints = _path(robot, 7)
    ef = kinlearn.kinematics(robot, "fast").position(joints)
    out = animate_plan(
        robot,
        joints,
        tmp_path / "sub" / "plan.gif",
        waypoints=ef[1:-1],
        spheres=SPHERES,
        boxes=BOXES,
        times=np.linspace(0, 1.2, 7),
        fps=20,
        figsize=(4, 3),
        dpi=50,
    )
    assert out == tmp_path / "sub" / "plan.gif" and not list(out.parent.glob(".*"))
    with pil.open(out) as im:
        assert im.format == "GIF" and im.n_frames == 7 and im.size == (200, 150)
        assert im.info["duration"] == 50  # ms per frame at 20 fps
        im.seek(0)
        first = np.asarray(im.convert("RGB"), dtype=float)
        im.seek(6)
        last = np.asarray(im.convert("RGB"), dtype=float)
    assert np.abs(first - last).mean() > 1.0  # the arm moved between the first and the last frame


def test_animation_of_a_still_path_keeps_every_frame(tmp_path):
    pil = pytest.importorskip("PIL.Image")
    pytest.importorskip("matplotlib")
    robot = kinlearn.load_robot("ur5")
    joints = robot.sample(1, torch.Generator().manual_seed(1)).repeat(4, 1)  # four identical poses
    out = animate_plan(robot, joints.numpy(), tmp_path / "still.gif", figsize=(3, 3), dpi=40)
    with pil.open(out) as im:
        assert im.n_frames == 4


def test_animation_bad_inputs(tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")
    robot = kinlearn.load_robot("iiwa14")
    joints = _path(robot, 3)
    out = tmp_path / "x.gif"
    with pytest.raises(ObstacleError, match=r"\(n, 4\)"):
        animate_plan(robot, joints, out, spheres=np.zeros((2, 3)))
    with pytest.raises(ObstacleError, match=r"\(n, 6\)"):
        animate_plan(robot, joints, out, boxes=np.zeros(5))
    with pytest.raises(ObstacleError, match="radius"):
        animate_plan(robot, joints, out, spheres=[[0, 0, 0, -0.1]])
    with pytest.raises(ObstacleError, match="half extent"):
        animate_plan(robot, joints, out, boxes=[[0, 0, 0, 0.1, 0.0, 0.1]])
    with pytest.raises(ObstacleError, match="NaN"):
        animate_plan(robot, joints, out, boxes=[[0, 0, float("nan"), 0.1, 0.1, 0.1]])
    with pytest.raises(ShapeError, match=r"\(n, 3\)"):
        animate_plan(robot, joints, out, waypoints=np.zeros((2, 2)))
    with pytest.raises(NonFiniteError):
        animate_plan(robot, joints, out, waypoints=[[0.0, float("nan"), 0.0]])
    with pytest.raises(NonFiniteError):
        animate_plan(robot, joints * float("inf"), out)
    with pytest.raises(ShapeError, match=r"\(N, 7\)"):
        animate_plan(robot, joints[:, :6], out)
    with pytest.raises(ShapeError, match=r"\(N, 7\)"):
        animate_plan(robot, joints.unsqueeze(0), out)
    with pytest.raises(ShapeError, match="one entry per configuration"):
        animate_plan(robot, joints, out, times=[0.0, 1.0])
    with pytest.raises(ConfigError, match="non-decreasing"):
        animate_plan(robot, joints, out, times=[0.0, 2.0, 1.0])
    with pytest.raises(ConfigError, match="fps"):
        animate_plan(robot, joints, out, fps=0)
    assert not out.exists()
    monkeypatch.setitem(sys.modules, "matplotlib.animation", None)  # as if matplotlib were absent
    with pytest.raises(MissingDependencyError, match=r"kinlearn\[plots\]"):
        animate_plan(robot, joints, out)


# ---------------------------------------------------------------------------------------------- viewer


@pytest.mark.parametrize("name", ALL_ROBOTS)
def test_viewer_serves_the_scene(name):
    viser = pytest.importorskip("viser")
    robot = kinlearn.load_robot(name)
    joints = _path(robot, 5, seed=3)
    links = kinlearn.kinematics(robot, "fast").link_positions(joints).numpy()
    waypoints = links[1:-1, -1] + 0.01
    viewer = show_plan(
        robot, joints, waypoints=waypoints, spheres=SPHERES, boxes=BOXES, port=_free_port(), block=False
    )
    try:
        names = set(viewer.node_names())
        # The arm: a cylinder per non-degenerate segment between joint origins, a sphere per origin.
        seg = np.linalg.norm(np.diff(links[0], axis=0), axis=1)
        cylinders = {f"/arm/link_{i}" for i in np.flatnonzero(seg > 1e-6)}
        assert cylinders and cylinders == {n for n in names if n.startswith("/arm/link_")}
        assert {f"/arm/joint_{i}" for i in range(robot.dof + 1)} | {"/arm/ee"} <= names
        assert {f"/waypoints/{k}" for k in range(3)} == {n for n in names if n.startswith("/waypoints/")}
        assert {"/obstacles/sphere_0", "/obstacles/sphere_1", "/obstacles/box_0"} == {
            n for n in names if n.startswith("/obstacles/")
        }
        assert {"/path/executed", "/path/start", "/path/goal", "/grid"} <= names
        for n in cylinders:
            assert isinstance(viewer.nodes[n], viser.CylinderHandle)
        assert isinstance(viewer.nodes["/obstacles/box_0"], viser.BoxHandle)
        np.testing.assert_allclose(viewer.nodes["/obstacles/box_0"].position, BOXES[0, :3], atol=1e-6)
        path = viewer.nodes["/path/executed"].points  # the executed end-effector path, segment by segment
        np.testing.assert_allclose(path[:, 0], links[:-1, -1], atol=1e-6)
        np.testing.assert_allclose(path[:, 1], links[1:, -1], atol=1e-6)
        np.testing.assert_allclose(viewer.nodes["/waypoints/1"].position, waypoints[1], atol=1e-6)

        # The slider's frame puts the arm where the forward kinematics says.
        for k in (0, 3, -1):
            viewer.set_frame(k)
            p = links[k]
            np.testing.assert_allclose(viewer.nodes["/arm/ee"].position, p[-1], atol=1e-6)
            np.testing.assert_allclose(viewer.nodes[f"/arm/joint_{robot.dof}"].position, p[-2], atol=1e-6)
            i = int(min(cylinders)[len("/arm/link_") :])
            cyl = viewer.nodes[f"/arm/link_{i}"]
            np.testing.assert_allclose(cyl.position, (p[i] + p[i + 1]) / 2, atol=1e-6)
            w, x, y, z = cyl.wxyz  # the cylinder's z axis points along its segment
            axis = np.array([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)])
            np.testing.assert_allclose(axis, (p[i + 1] - p[i]) / np.linalg.norm(p[i + 1] - p[i]), atol=1e-6)
        assert viewer.frame == 4 and viewer.slider.value == 4

        with urllib.request.urlopen(viewer.url, timeout=10) as resp:
            assert resp.status == 200 and b"<html" in resp.read(4096).lower()
    finally:
        viewer.close()
    assert viewer.closed
    with pytest.raises((urllib.error.URLError, ConnectionError)):
        urllib.request.urlopen(viewer.url, timeout=2)


def test_viewer_playback_and_errors(monkeypatch):
    pytest.importorskip("viser")
    robot = kinlearn.load_robot("iiwa14")
    joints = _path(robot, 6, seed=4)
    with show_plan(
        robot, joints, times=np.linspace(0, 2, 6), port=_free_port(), fps=50, block=False
    ) as viewer:
        assert viewer.frame == 0
        viewer.playing.value = True
        deadline = time.monotonic() + 5
        while viewer.frame == 0 and time.monotonic() < deadline:
            time.sleep(0.02)
        assert viewer.frame > 0  # playback advanced the slider and the arm
        viewer.playing.value = False
        with pytest.raises(ConfigError, match="frame"):
            viewer.set_frame(6)
        with pytest.raises(ConfigError, match="frame"):
            viewer.set_frame(1.5)
    assert viewer.closed
    with pytest.raises(ConfigError, match="port"):
        show_plan(robot, joints, port=0, block=False)
    with pytest.raises(ConfigError, match="fps"):
        show_plan(robot, joints, fps=0.0, block=False)
    with pytest.raises(ObstacleError):
        show_plan(robot, joints, spheres=np.zeros((1, 3)), block=False)
    monkeypatch.setitem(sys.modules, "viser", None)  # as if viser were absent
    with pytest.raises(MissingDependencyError, match=r"kinlearn\[viewer\]"):
        show_plan(robot, joints, port=_free_port(), block=False)


def test_animation_draws_every_kind_of_primitive(tmp_path):
    pytest.importorskip("matplotlib")
    from kinlearn.collision import Scene
    from kinlearn.collision.geometry import Box, Cylinder, Sphere, rotation_from_quaternion

    robot = kinlearn.load_robot("iiwa14")
    R = rotation_from_quaternion([0.2, 0.1, 0.4, 0.9])
    scene = Scene.from_primitives(
        [
            Sphere((0.5, 0, 0.6), 0.1),
            Box((0.6, 0.3, 0.2), (0.1, 0.1, 0.2), R),
            Cylinder((0.4, -0.3, 0.3), 0.05, 0.2, R),
        ]
    )
    out = animate_plan(robot, _path(robot, 2), tmp_path / "s.gif", scene=scene, figsize=(2, 2), dpi=30)
    assert out.is_file()
    with pytest.raises(ObstacleError, match="not both"):
        animate_plan(robot, _path(robot, 2), tmp_path / "t.gif", scene=scene, spheres=[[0, 0, 0, 0.1]])
