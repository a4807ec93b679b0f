"""The non-learned baselines: shapes, endpoints, reaching the goal, and their metrics."""

from __future__ import annotations

import sys

import pytest
import torch

from kinlearn.body.kinematics import kinematics
from kinlearn.body.state import StateLayout
from kinlearn.errors import (
    ConfigError,
    JointLimitError,
    MissingDependencyError,
    NonFiniteError,
    ShapeError,
)
from kinlearn.evaluation.metrics import plan_metrics
from kinlearn.planning.baselines import (
    cartesian_line,
    joint_line,
    rrt_connect,
    rrt_connect_timed,
)

HOME = torch.tensor([0.0, 0.5, 0.0, -1.2, 0.0, 1.0, 0.0], dtype=torch.float64)


def pairs(robot, n: int, seed: int = 0, dtype=torch.float64):
    """Starts within 0.3 rad of a home configuration, goals uniform within the joint limits."""
    g = torch.Generator().manual_seed(seed)
    q0 = HOME.to(dtype) + 0.3 * (2 * torch.rand(n, robot.dof, generator=g, dtype=dtype) - 1)
    qT = robot.sample(n, generator=g, dtype=dtype)
    fk = kinematics(robot).position
    layout = StateLayout(robot.dof)
    return layout.join(q0, fk(q0)), layout.join(qT, fk(qT))


def check_plan(robot, plan, start, goal, steps):
    n = start.shape[:-1]
    assert torch.allclose(plan.start, start) and plan.goal is goal
    assert plan.waypoints.shape == (*n, steps - 1, 3)
    assert plan.actions.shape == (*n, steps, robot.dof)
    assert plan.joints.shape == (*n, steps + 1, robot.dof)
    assert plan.ef.shape == (*n, steps + 1, 3)
    assert plan.steps == steps
    layout = StateLayout(robot.dof)
    assert torch.equal(plan.joints[..., 0, :], layout.split(start)[0])
    assert torch.allclose(plan.joints[..., 1:, :] - plan.joints[..., :-1, :], plan.actions)
    assert torch.allclose(plan.ef, kinematics(robot).position(plan.joints), atol=1e-12)
    for value in plan_metrics(plan, robot).values():
        assert torch.isfinite(value).all()


def test_joint_interpolation(robot):
    start, goal = pairs(robot, 32)
    plan = joint_line(robot, start, goal)
    check_plan(robot, plan, start, goal, 11)
    layout = StateLayout(robot.dof)
    q0, qT = layout.split(start)[0], layout.split(goal)[0]
    assert torch.allclose(plan.joints[:, -1], qT, atol=1e-12)
    assert torch.allclose(plan.actions, ((qT - q0) / 11)[:, None].expand(-1, 11, -1), atol=1e-12)
    # The waypoints are the executed path's interior: no tracking error, no goal error.
    m = plan_metrics(plan, robot)
    assert float(m["tracking_error"].max()) < 1e-12 and float(m["goal_error"].max()) < 1e-12
    assert float(m["limit_violation"].sum()) == 0


def test_joint_interpolation_batch_shape_dtype_and_steps(robot):
    start, goal = pairs(robot, 6, dtype=torch.float32)
    start, goal = start.reshape(2, 3, -1), goal.reshape(2, 3, -1)
    plan = joint_line(robot, start, goal, steps=5)
    assert plan.joints.shape == (2, 3, 6, robot.dof) and plan.ef.dtype == torch.float32
    assert plan.waypoints.shape == (2, 3, 4, 3)


def test_cartesian_dls_follows_the_line_and_reaches_the_goal(robot):
    start, goal = pairs(robot, 64, seed=1)
    plan = cartesian_line(robot, start, goal)
    check_plan(robot, plan, start, goal, 11)
    m = plan_metrics(plan, robot)
    # Waypoints on the straight line: evenly spaced, straight.
    assert torch.allclose(m["mean_angle"], torch.full_like(m["mean_angle"], 180.0), atol=1e-4)
    assert float(m["max_spacing_deviation"].max()) < 1e-9
    assert torch.allclose(m["avg_spacing"], m["endpoint_distance"] / 11, atol=1e-12)
    # Executed: reaches the goal position within 1 cm and stays near the line, within the limits.
    assert float(m["goal_error"].max()) < 0.01
    assert float(m["success"].mean()) == 1.0
    assert float(m["tracking_error"].median()) < 1e-3
    assert float(m["limit_violation"].sum()) == 0


def test_baseline_validation(robot):
    start, goal = pairs(robot, 4)
    with pytest.raises(ShapeError):
        joint_line(robot, start, goal[:3])
    with pytest.raises(ShapeError):
        cartesian_line(robot, start[:, :7], goal[:, :7])
    with pytest.raises(ConfigError):
        joint_line(robot, start, goal, steps=1)
    with pytest.raises(ConfigError):
        cartesian_line(robot, start, goal, iterations=0)
    with pytest.raises(ConfigError):
        cartesian_line(robot, start, goal, damping=0.0)
    bad = start.clone()
    bad[0, 0] = float("nan")
    with pytest.raises(NonFiniteError):
        joint_line(robot, bad, goal)


# --------------------------------------------------------------------------------------------------
# RRT-Connect (optional: needs `pip install ompl`)
# --------------------------------------------------------------------------------------------------


def test_rrt_connect(robot):
    pytest.importorskip("ompl")
    start, goal = pairs(robot, 16, seed=2)
    plan, times = rrt_connect_timed(robot, start, goal, seed=3)
    check_plan(robot, plan, start, goal, 11)
    assert torch.equal(plan.joints[:, -1], StateLayout(robot.dof).split(goal)[0])
    assert times.shape == (16,) and bool((times > 0).all()) and bool((times < 1.0).all())
    assert float(plan_metrics(plan, robot)["limit_violation"].sum()) == 0


def test_rrt_connect_is_reproducible_with_a_seed(robot):
    pytest.importorskip("ompl")
    start, goal = pairs(robot, 8, seed=4)
    a = rrt_connect(robot, start, goal, seed=7)
    b = rrt_connect(robot, start, goal, seed=7)
    assert torch.equal(a.joints, b.joints)


def test_rrt_connect_simplified_is_joint_interpolation(robot):
    pytest.importorskip("ompl")
    start, goal = pairs(robot, 8, seed=5)
    plan = rrt_connect(robot, start, goal, simplify=True)
    assert torch.allclose(plan.joints, joint_line(robot, start, goal).joints, atol=1e-9)


def test_rrt_connect_rejects_joints_outside_the_limits(robot):
    pytest.importorskip("ompl")
    start, goal = pairs(robot, 2)
    start = start.clone()
    start[0, 1] = 3.0  # joint 2's limit is 2.094 rad
    with pytest.raises(JointLimitError):
        rrt_connect(robot, start, goal)
    with pytest.raises(ConfigError):
        rrt_connect(robot, goal, goal, time_limit=0.0)


def test_rrt_connect_without_ompl_says_how_to_install(robot, monkeypatch):
    for name in ("ompl", "ompl.base", "ompl.geometric", "ompl.util"):
        monkeypatch.setitem(sys.modules, name, None)  # makes `import ompl` fail
    start, goal = pairs(robot, 2)
    with pytest.raises(MissingDependencyError, match="pip install ompl"):
        rrt_connect(robot, start, goal)
