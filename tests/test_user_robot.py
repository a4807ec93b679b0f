"""A user's own arm, from a URDF written here, through the whole pipeline: register → babble → FM/IM →
endpoint pairs → TM (the paper's, and the joint-path one) → plan, checked against the analytic robot."""

import pytest
import torch

import kinlearn
from kinlearn.body.kinematics import kinematics
from kinlearn.body.robot import load_robot, register_robot, unregister_robot
from kinlearn.data.babbling import BabblingConfig, babble
from kinlearn.data.endpoints import EndpointConfig, default_home, make_endpoints
from kinlearn.errors import (
    CheckpointError,
    ConfigError,
    JointLimitError,
    RobotDescriptionError,
    UnknownRobotError,
)
from kinlearn.evaluation.workspace import heldout_pairs
from kinlearn.models.forward_inverse import fm_config, im_config, load_fm
from kinlearn.planning.planner import Planner
from kinlearn.training.forward_inverse import train_config, train_fm, train_im
from kinlearn.training.joint_path import PathTrainConfig, train_path_model
from kinlearn.training.tm import tm_preset, train_tm

#: A 4-joint arm: a base yaw, then three pitch joints, links of 0.30, 0.25, 0.20 m and a 0.10 m tool.
URDF = """<?xml version="1.0"?>
<robot name="toy4">
  <link name="base"/><link name="l1"/><link name="l2"/><link name="l3"/><link name="l4"/><link name="tool"/>
  <joint name="yaw" type="revolute"><parent link="base"/><child link="l1"/>
    <origin xyz="0 0 0.1"/><axis xyz="0 0 1"/><limit lower="-2.5" upper="2.5" velocity="2.0" effort="10"/></joint>
  <joint name="shoulder" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0 0 0.30"/><axis xyz="0 1 0"/><limit lower="-1.8" upper="1.8" velocity="2.0" effort="10"/></joint>
  <joint name="elbow" type="revolute"><parent link="l2"/><child link="l3"/>
    <origin xyz="0 0 0.25"/><axis xyz="0 1 0"/><limit lower="-2.2" upper="2.2" velocity="2.5" effort="10"/></joint>
  <joint name="wrist" type="revolute"><parent link="l3"/><child link="l4"/>
    <origin xyz="0 0 0.20"/><axis xyz="0 1 0"/><limit lower="-2.0" upper="2.0" velocity="3.0" effort="10"/></joint>
  <joint name="flange" type="fixed"><parent link="l4"/><child link="tool"/><origin xyz="0 0 0.10"/></joint>
</robot>
"""
HOME = (0.0, 0.5, 1.0, 0.6)


@pytest.fixture
def toy(tmp_path):
    path = tmp_path / "toy4.urdf"
    path.write_text(URDF)
    robot = register_robot("toy4", path, "tool", home=HOME)
    yield robot, path
    unregister_robot("toy4")


def test_registered_robot_is_known_by_name(toy):
    robot, _ = toy
    assert load_robot("toy4") is robot and "toy4" in kinlearn.available_robots()
    assert robot.dof == 4 and robot.joint_names == ("yaw", "shoulder", "elbow", "wrist")
    assert torch.equal(default_home(robot), torch.tensor(HOME, dtype=torch.float64))
    # straight up at zero: the end effector is the sum of the links along z
    ef = kinematics(robot).position(torch.zeros(1, 4, dtype=torch.float64))
    torch.testing.assert_close(ef, torch.tensor([[0.0, 0.0, 0.95]], dtype=torch.float64))


def test_register_robot_refuses_bad_input(toy, tmp_path):
    _, path = toy
    with pytest.raises(ConfigError, match="one of kinlearn's own"):
        register_robot("iiwa14", path, "tool")
    with pytest.raises(ConfigError, match="registered already"):
        register_robot("toy4", path, "tool")
    with pytest.raises(RobotDescriptionError, match="not a link"):
        register_robot("toy4b", path, "gripper")
    with pytest.raises(UnknownRobotError, match="no URDF"):
        register_robot("toy4b", tmp_path / "missing.urdf", "tool")
    with pytest.raises(JointLimitError, match="limits"):
        register_robot("toy4b", path, "tool", home=(0.0, 0.0, 3.0, 0.0))
    with pytest.raises(ConfigError, match="4 finite"):
        register_robot("toy4b", path, "tool", home=(0.0, 0.0))
    with pytest.raises(ConfigError, match="region"):
        register_robot("toy4b", path, "tool", region=(1, 0, 0, 1, 0, 1))
    assert "toy4b" not in kinlearn.available_robots()
    with pytest.raises(ConfigError, match="one of kinlearn's own"):
        unregister_robot("panda")


def test_a_urdf_arm_goes_through_the_whole_pipeline(toy, tmp_path):
    robot, _ = toy
    data = babble(BabblingConfig(robot="toy4", walkers=200, steps=60, seed=0))
    assert data.s.shape[1] == robot.dof + 3
    models = tmp_path / "models"
    fm = train_fm(
        data,
        fm_config("toy4", "tiny"),
        train_config("fm", "tiny", epochs=3, progress=False),
        run_dir=models / "fm",
    ).model
    im = train_im(
        data,
        im_config("toy4", "tiny"),
        train_config("im", "tiny", epochs=3, progress=False),
        run_dir=models / "im",
    ).model
    models.joinpath("fm.pt").write_bytes((models / "fm" / "fm.pt").read_bytes())
    models.joinpath("im.pt").write_bytes((models / "im" / "im.pt").read_bytes())
    # the learned FM has learned something of this arm: its next end effector beats "does not move" on
    # fresh transitions
    fresh = babble(BabblingConfig(robot="toy4", walkers=50, steps=20, seed=1))
    pred = fm(fresh.s, fresh.a)[:, robot.dof :]
    err, still = (
        (pred - fresh.s_next[:, robot.dof :]).abs().mean(),
        (fresh.s - fresh.s_next)[:, robot.dof :].abs().mean(),
    )
    assert err < still

    # the paper's TM, on paper-task pairs around the registered home
    pairs = make_endpoints(EndpointConfig(robot="toy4", n=96, seed=0))
    run = tmp_path / "tm"
    train_tm(
        tm_preset("default", robot="toy4", models_dir=str(models), epochs=1, batch_size=32),
        run,
        pairs,
        progress=False,
    )
    planner = Planner.load(run)
    assert planner.robot is robot
    plan = planner.plan(pairs.start[:8], pairs.goal[:8])
    assert plan.joints.shape[-1] == 4 and plan.success.shape == (8,)
    lo, hi = robot.limits(plan.joints.dtype)
    assert bool(((plan.joints >= lo - 1e-6) & (plan.joints <= hi + 1e-6)).all())

    # the joint-path TM through the learned FM: every plan ends at the goal state, judged by the analytic FK
    cfg = PathTrainConfig(
        robot="toy4", fm="learned", fm_checkpoint=str(models / "fm.pt"), iterations=20, batch_size=64
    )
    tm = train_path_model(cfg, tmp_path / "path", progress=False)
    held = heldout_pairs(robot, n=32)
    plan = Planner(robot, tm, load_fm(models / "fm.pt", robot="toy4"), im).plan(held.start, held.goal)
    assert bool(plan.success.all()), plan.summary()
    end = kinematics(robot).position(plan.joints[:, -1].double())
    torch.testing.assert_close(end, held.goal[:, robot.dof :].double(), atol=1e-5, rtol=0)

    # the checkpoints name the arm: once it is forgotten, they say which robot they need
    unregister_robot("toy4")
    with pytest.raises((UnknownRobotError, CheckpointError), match="toy4"):
        Planner.load(run)
