"""``onboard``: a small arm written here goes from its URDF to a planner folder that plans among obstacles
(tiny sizes), a finished run resumes without redoing a step, and URDFs it cannot take are refused with
typed errors saying what to do, before anything is written."""

import pytest
import torch

import kinlearn
from kinlearn.body.robot import unregister_robot
from kinlearn.cli.main import main
from kinlearn.collision.body import body_spheres
from kinlearn.collision.check import in_collision
from kinlearn.collision.geometry import Box
from kinlearn.collision.mesh import judge_meshes
from kinlearn.collision.scene import Scene
from kinlearn.errors import ConfigError, RobotDescriptionError, RunDirectoryError
from kinlearn.planning.planner import Planner
from kinlearn.training.onboard import load_onboarded, onboard

ARM = """<?xml version="1.0"?>
<robot name="toy">
  <link name="base"><collision><origin xyz="0 0 0.05"/><geometry><cylinder radius="0.08" length="0.1"/></geometry></collision></link>
  <link name="l1"><collision><origin xyz="0 0 0.1"/><geometry><box size="0.08 0.08 0.2"/></geometry></collision></link>
  <link name="l2"><collision><origin xyz="0.15 0 0" rpy="0 1.5707963 0"/><geometry><cylinder radius="0.04" length="0.3"/></geometry></collision></link>
  <link name="l3"><collision><origin xyz="0.12 0 0"/><geometry><box size="0.24 0.06 0.06"/></geometry></collision></link>
  <link name="tool"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.1"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" velocity="2" effort="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0 0.2"/><axis xyz="0 1 0"/><limit lower="-1.8" upper="1.8" velocity="2" effort="1"/></joint>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/><origin xyz="0.3 0 0"/><axis xyz="0 1 0"/><limit lower="-2.5" upper="2.5" velocity="2" effort="1"/></joint>
  <joint name="tip" type="fixed"><parent link="l3"/><child link="tool"/><origin xyz="0.24 0 0"/></joint>
</robot>
"""


@pytest.fixture(scope="module")
def onboarded(tmp_path_factory):
    folder = tmp_path_factory.mktemp("onboard")
    urdf = folder / "toy.urdf"
    urdf.write_text(ARM)
    result = onboard(urdf, "tool", folder / "run", name="toy_onboard", config="tiny", progress=False)
    yield urdf, result
    unregister_robot("toy_onboard")


def test_the_planner_folder_plans_among_obstacles(onboarded):
    _, result = onboarded
    run = result.run_dir
    for f in (
        "planner/tm.pt",
        "planner/fm.pt",
        "planner/im.pt",
        "planner/tm_obstacles.pt",
        "planner/chain.pt",
    ):
        assert (run / f).is_file(), f
    assert (run / "robot" / "toy_onboard_spherized.urdf").is_file()
    robot = load_onboarded(run)
    assert robot.name == "toy_onboard" and body_spheres(robot).name == "fitted"
    planner = Planner.load(result.planner)
    assert planner.robot.name == "toy_onboard"
    scene = Scene.from_primitives([Box((0.3, 0.25, 0.3), (0.04, 0.04, 0.04))], floor=0.0)
    start = torch.tensor([-0.5, -0.4, 0.6], dtype=torch.float64)
    goal = torch.tensor([1.5, -0.2, 0.8], dtype=torch.float64)
    body = body_spheres(robot).double()
    assert not in_collision(body, torch.stack([start, goal]), scene.to(torch.float64)).any()
    plan = kinlearn.plan(start, goal, obstacles=scene, robot="toy_onboard")
    assert plan.robot == "toy_onboard" and bool(plan.success)
    assert torch.allclose(plan.joints[0].double(), start, atol=1e-6)
    # the plan the spheres passed is free under the URDF's own geometry too
    assert bool(judge_meshes(plan, scene))


def test_a_finished_run_resumes_without_redoing_a_step(onboarded):
    urdf, result = onboarded
    again = onboard(
        urdf, "tool", result.run_dir, name="toy_onboard", config="tiny", resume=True, progress=False
    )
    assert again.seconds == {}
    with pytest.raises(RunDirectoryError, match="--resume"):
        onboard(urdf, "tool", result.run_dir, name="toy_onboard", config="tiny", progress=False)
    with pytest.raises(RunDirectoryError, match="another configuration"):
        onboard(urdf, "tool", result.run_dir, name="toy_onboard", config="small", resume=True, progress=False)


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (
            lambda s: s.replace('name="j2" type="revolute"', 'name="j2" type="prismatic"'),
            "prismatic joints .*fix them",
        ),
        (
            lambda s: s.replace(
                "</robot>",
                '<link name="cam"/><joint name="pan" type="revolute"><parent link="l1"/><child link="cam"/>'
                '<axis xyz="0 0 1"/><limit lower="-1" upper="1" velocity="1" effort="1"/></joint></robot>',
            ),
            "not on the serial chain",
        ),
        (
            lambda s: s.replace("<collision>", "<visual>").replace("</collision>", "</visual>"),
            "no link of the chain",
        ),
    ],
)
def test_urdfs_it_cannot_take_are_refused_before_writing(tmp_path, edit, match):
    urdf = tmp_path / "bad.urdf"
    urdf.write_text(edit(ARM))
    with pytest.raises(RobotDescriptionError, match=match):
        onboard(urdf, "tool", tmp_path / "run", name="toy_bad", config="tiny", progress=False)
    assert not (tmp_path / "run" / "babble").exists()
    unregister_robot("toy_bad")


def test_a_builtin_name_and_an_unknown_size_are_refused(tmp_path):
    urdf = tmp_path / "xarm7.urdf"
    urdf.write_text(ARM)
    with pytest.raises(ConfigError, match="another name"):
        onboard(urdf, "tool", tmp_path / "run", config="tiny")
    with pytest.raises(ConfigError, match="tiny"):
        onboard(urdf, "tool", tmp_path / "run", name="toy_size", config="huge")


def test_the_command_refuses_a_missing_frame(tmp_path, capsys):
    urdf = tmp_path / "toy.urdf"
    urdf.write_text(ARM)
    code = main(
        ["onboard", str(urdf), "--ee-frame", "hand", "--size", "tiny", "--run-dir", str(tmp_path / "r")]
    )
    assert code == 2
    assert "'hand' is not a link" in capsys.readouterr().err
