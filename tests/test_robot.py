"""Robots by name or path: joints, limits, sampling and errors."""

import math

import numpy as np
import pytest
import torch
from conftest import ALL_ROBOTS

from kinlearn import (
    JointLimitError,
    NonFiniteError,
    ShapeError,
    UnknownRobotError,
    available_robots,
    load_robot,
)
from kinlearn.body import ROBOTS
from kinlearn.errors import RobotDescriptionError


def test_iiwa14_published_numbers():
    r = load_robot("iiwa14")
    assert r.dof == 7 and r.state_dim == 10
    assert r.joint_names == tuple(f"iiwa_joint_{i}" for i in range(1, 8))
    np.testing.assert_allclose(r.upper, [2.96706, 2.09440, 2.96706, 2.09440, 2.96706, 2.09440, 3.05433])
    np.testing.assert_allclose(r.lower, -r.upper)
    np.testing.assert_allclose(r.velocity_limits, [1.4835, 1.4835, 1.7453, 1.3090, 2.2689, 2.3562, 2.3562])
    assert r.ee_frame == "iiwa_link_ee"
    assert all(np.array_equal(j.axis, [0.0, 0.0, 1.0]) for j in r.joints)


@pytest.mark.parametrize("name", ALL_ROBOTS)
def test_named_robots_load(name):
    r = load_robot(name)
    assert r.dof in (6, 7)
    assert len(r.joint_names) == r.dof == len(r.lower)
    assert np.all(r.lower < r.upper)
    assert load_robot(name) is r  # cached


def test_registry_lists_at_least_four_arms():
    assert {"iiwa14", "panda", "ur5"} <= set(available_robots())
    assert len(ROBOTS) >= 4


def test_sample_within_limits_and_reproducible():
    r = load_robot("panda")
    a = r.sample((50, 4), torch.Generator().manual_seed(3), dtype=torch.float64)
    b = r.sample((50, 4), torch.Generator().manual_seed(3), dtype=torch.float64)
    assert a.shape == (50, 4, 7)
    assert torch.equal(a, b)
    lo, hi = r.limits(torch.float64)
    assert bool(((a >= lo) & (a <= hi)).all())
    m = r.sample(100, torch.Generator().manual_seed(3), margin=0.1)
    assert bool(((m >= lo.float() + 0.1 - 1e-6) & (m <= hi.float() - 0.1 + 1e-6)).all())


def test_load_from_path(tmp_path):
    src = load_robot("iiwa14").urdf_path
    dst = tmp_path / "my_arm.urdf"
    dst.write_bytes(src.read_bytes())
    r = load_robot(str(dst), ee_frame="iiwa_link_7")
    assert r.dof == 7 and r.name == "my_arm"
    with pytest.raises(RobotDescriptionError, match="ee_frame"):
        load_robot(dst)


def test_unknown_robot_lists_valid_names():
    with pytest.raises(UnknownRobotError, match="iiwa14") as info:
        load_robot("r2d2")
    assert "panda" in str(info.value)
    with pytest.raises(UnknownRobotError, match="no URDF file"):
        load_robot("/nonexistent/arm.urdf", ee_frame="x")


def test_missing_end_effector_frame_lists_links():
    with pytest.raises(RobotDescriptionError, match="iiwa_link_ee"):
        load_robot("iiwa14", ee_frame="gripper_tip")


def test_malformed_urdf(tmp_path):
    p = tmp_path / "broken.urdf"
    p.write_text("<robot><link name='a'/>")
    with pytest.raises(RobotDescriptionError, match="XML"):
        load_robot(p, ee_frame="a")
    p.write_text("<robot name='x'><link name='a'/></robot>")
    with pytest.raises(RobotDescriptionError, match="no movable joint"):
        load_robot(p, ee_frame="a")


def test_check_joints():
    r = load_robot("iiwa14")
    r.check_joints(torch.zeros(5, 7))
    q = torch.zeros(7)
    q[3] = 2.5
    with pytest.raises(JointLimitError, match="iiwa_joint_4"):
        r.check_joints(q)
    with pytest.raises(ShapeError):
        r.check_joints(torch.zeros(6))
    with pytest.raises(NonFiniteError):
        r.check_joints(torch.full((7,), math.nan))


def test_within_limits_per_configuration():
    robot = load_robot("iiwa14")
    lo, hi = robot.limits(torch.float64)
    q = torch.stack((lo, hi, hi + 1e-7, hi + 1e-3, torch.full_like(lo, float("nan"))))
    assert robot.within_limits(q).tolist() == [True, True, True, False, False]
    assert robot.within_limits(q, tol=1e-2).tolist() == [True, True, True, True, False]
    assert robot.within_limits(q.reshape(1, 5, -1)).shape == (1, 5)


def test_within_limits_given_narrower_limits():
    robot = load_robot("iiwa14")
    lo, hi = robot.limits(torch.float64)
    narrow = (lo.numpy() / 2, hi.numpy() / 2)
    q = torch.stack((lo / 4, hi / 2, hi * 0.75))
    assert robot.within_limits(q).tolist() == [True, True, True]
    assert robot.within_limits(q, limits=narrow).tolist() == [True, True, False]


def test_a_robot_with_other_limits_keeps_its_chain_and_refuses_bad_limits():
    """``Robot.with_limits``: the same robot (name, chain) with other position limits, checked by them;
    its own limits give the robot itself; limits of the wrong shape, or with lower ≥ upper, are a
    ConfigError."""
    from kinlearn.errors import ConfigError, JointLimitError

    panda = load_robot("panda")
    assert panda.with_limits(panda.lower, panda.upper) is panda
    wide = panda.with_limits(panda.lower - 0.1, panda.upper + 0.1)
    assert wide is not panda and wide.name == panda.name and wide.joints is panda.joints
    q = torch.as_tensor(panda.upper + 0.05)
    wide.check_joints(q)  # within the wider limits
    with pytest.raises(JointLimitError):
        panda.check_joints(q)  # the robot keeps its own
    for lo, hi in ((panda.lower[:6], panda.upper), (panda.upper, panda.lower), (panda.lower, panda.lower)):
        with pytest.raises(ConfigError, match="lower < upper"):
            panda.with_limits(lo, hi)
