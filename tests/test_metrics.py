"""Metrics on hand-built trajectories with known answers, and against a plain per-point loop."""

from __future__ import annotations

import dataclasses
import math

import pytest
import torch

from kinlearn.body.kinematics import kinematics
from kinlearn.body.robot import load_robot
from kinlearn.body.state import StateLayout
from kinlearn.errors import ConfigError, NonFiniteError, ShapeError
from kinlearn.evaluation.metrics import (
    INDICATORS,
    PAPER_TABLE2,
    TABLE2_COLUMNS,
    format_table,
    interior_angles,
    plan_metrics,
    summarize,
    trajectory_metrics,
)
from kinlearn.planning.plan import Plan


def metrics_of(points) -> dict[str, float]:
    """Metrics of one polyline given as a list of 3-D points (endpoints included)."""
    p = torch.tensor(points, dtype=torch.float64)
    out = trajectory_metrics(p[0], p[1:-1], p[-1])
    return {k: float(v) for k, v in out.items()}


def test_straight_evenly_spaced_line():
    points = [[0.1 * k, 0.0, 0.0] for k in range(12)]  # T = 11
    m = metrics_of(points)
    for key in ("init_distance", "final_distance", "avg_spacing"):
        assert m[key] == pytest.approx(0.1, abs=1e-12)
    assert m["max_spacing_deviation"] == pytest.approx(0.0, abs=1e-12)
    assert m["mean_angle"] == pytest.approx(180.0, abs=1e-9)
    assert m["min_angle"] == pytest.approx(180.0, abs=1e-9)
    assert m["waypoint_path_length"] == pytest.approx(1.1, abs=1e-12)
    assert m["endpoint_distance"] == pytest.approx(1.1, abs=1e-12)


def test_straight_line_in_any_direction():
    d = torch.tensor([0.3, -0.2, 0.5], dtype=torch.float64)
    points = (
        torch.tensor([0.1, 0.2, 0.3], dtype=torch.float64)
        + torch.arange(6.0, dtype=torch.float64)[:, None] * d
    )
    m = metrics_of(points.tolist())
    assert m["min_angle"] == pytest.approx(180.0, abs=1e-6)
    assert m["avg_spacing"] == pytest.approx(float(d.norm()), abs=1e-12)


def test_right_angle_corner():
    m = metrics_of([[0, 0, 0], [1, 0, 0], [1, 1, 0]])
    assert m["mean_angle"] == pytest.approx(90.0, abs=1e-9)
    assert m["min_angle"] == pytest.approx(90.0, abs=1e-9)
    assert m["max_spacing_deviation"] == pytest.approx(0.0, abs=1e-12)


def test_120_degree_turn_and_corner_in_a_longer_path():
    m = metrics_of([[0, 0, 0], [1, 0, 0], [1.5, math.sqrt(3) / 2, 0]])
    assert m["min_angle"] == pytest.approx(120.0, abs=1e-9)
    # Straight, then a right angle, then straight: angles 180, 90, 180.
    m = metrics_of([[0, 0, 0], [0, 0, 1], [0, 0, 2], [0, 1, 2], [0, 2, 2]])
    assert m["min_angle"] == pytest.approx(90.0, abs=1e-9)
    assert m["mean_angle"] == pytest.approx(150.0, abs=1e-9)


def test_hairpin_is_zero_degrees():
    m = metrics_of([[0, 0, 0], [1, 0, 0], [0, 0, 0]])
    assert m["min_angle"] == pytest.approx(0.0, abs=1e-9)
    angles = interior_angles(torch.tensor([[0, 0, 0], [2, 0, 0], [1, 0, 0], [3, 0, 0]], dtype=torch.float64))
    assert torch.allclose(angles, torch.zeros(2, dtype=torch.float64), atol=1e-9)


def test_repeated_points_give_no_nan_and_count_as_straight():
    m = metrics_of([[0, 0, 0], [0, 0, 0], [1, 0, 0], [1, 0, 0]])
    assert all(math.isfinite(v) for v in m.values())
    assert m["mean_angle"] == 180.0 and m["min_angle"] == 180.0
    # spacings 0, 1, 0: mean 1/3, max deviation 2/3
    assert m["avg_spacing"] == pytest.approx(1 / 3, abs=1e-12)
    assert m["max_spacing_deviation"] == pytest.approx(2 / 3, abs=1e-12)
    assert m["init_distance"] == 0.0 and m["final_distance"] == 0.0
    # Every point the same.
    m = metrics_of([[0.5, 0.5, 0.5]] * 12)
    assert all(math.isfinite(v) for v in m.values())
    assert m["avg_spacing"] == 0.0 and m["max_spacing_deviation"] == 0.0 and m["min_angle"] == 180.0


def test_known_spacing_deviation():
    m = metrics_of([[0, 0, 0], [1, 0, 0], [3, 0, 0]])  # spacings 1, 2
    assert m["avg_spacing"] == pytest.approx(1.5)
    assert m["max_spacing_deviation"] == pytest.approx(0.5)
    assert m["init_distance"] == pytest.approx(1.0) and m["final_distance"] == pytest.approx(2.0)
    m = metrics_of([[0, 0, 0], [0.1, 0, 0], [0.2, 0, 0], [0.6, 0, 0]])  # spacings .1 .1 .4, mean .2
    assert m["max_spacing_deviation"] == pytest.approx(0.2, abs=1e-12)


def reference_loop(points: torch.Tensor) -> dict[str, float]:
    """The definitions of the paper's Table 2 written out point by point with acos (valid away from 0/180°)."""
    d = [float((points[k + 1] - points[k]).norm()) for k in range(len(points) - 1)]
    mean = sum(d) / len(d)
    angles = []
    for k in range(1, len(points) - 1):
        u, v = points[k - 1] - points[k], points[k + 1] - points[k]
        c = float(u @ v) / (float(u.norm()) * float(v.norm()))
        angles.append(math.degrees(math.acos(max(-1.0, min(1.0, c)))))
    return {
        "init_distance": d[0],
        "final_distance": d[-1],
        "avg_spacing": mean,
        "max_spacing_deviation": max(abs(x - mean) for x in d),
        "mean_angle": sum(angles) / len(angles),
        "min_angle": min(angles),
    }


def test_batched_metrics_match_a_plain_loop():
    g = torch.Generator().manual_seed(0)
    points = torch.rand(20, 12, 3, generator=g, dtype=torch.float64)
    m = trajectory_metrics(points[:, 0], points[:, 1:-1], points[:, -1])
    for i in range(20):
        ref = reference_loop(points[i])
        for key, value in ref.items():
            assert float(m[key][i]) == pytest.approx(value, abs=1e-9), key


def test_leading_batch_dims_dtype_and_general_T():
    g = torch.Generator().manual_seed(1)
    points = torch.rand(2, 3, 6, 3, generator=g)  # float32, T = 5
    m = trajectory_metrics(points[..., 0, :], points[..., 1:-1, :], points[..., -1, :])
    for v in m.values():
        assert v.shape == (2, 3) and v.dtype == torch.float32
    assert interior_angles(points).shape == (2, 3, 4)


def test_input_validation():
    p = torch.zeros(4, 3)
    with pytest.raises(ShapeError):
        trajectory_metrics(torch.zeros(4, 2), torch.zeros(4, 10, 3), torch.zeros(4, 3))
    with pytest.raises(ShapeError):
        trajectory_metrics(p, torch.zeros(4, 0, 3), p)  # no waypoint
    with pytest.raises(ShapeError):
        trajectory_metrics(p, torch.zeros(5, 10, 3), p)  # batch mismatch
    with pytest.raises(ShapeError):
        trajectory_metrics(p, torch.zeros(4, 10, 3, dtype=torch.int64), p)
    bad = torch.zeros(4, 10, 3)
    bad[1, 2, 0] = float("nan")
    with pytest.raises(NonFiniteError):
        trajectory_metrics(p, bad, p)
    with pytest.raises(ShapeError):
        interior_angles(torch.zeros(2, 3))


# --------------------------------------------------------------------------------------------------
# Plans
# --------------------------------------------------------------------------------------------------


def hand_made_plan(robot, end_offsets: torch.Tensor) -> Plan:
    """Straight joint paths whose executed end is replaced by goal ef + offset (per trajectory)."""
    layout = StateLayout(robot.dof)
    n, T = end_offsets.shape[0], 4
    g = torch.Generator().manual_seed(2)
    q0 = robot.sample(n, generator=g, dtype=torch.float64, margin=0.2)
    qT = robot.sample(n, generator=g, dtype=torch.float64, margin=0.2)
    fk = kinematics(robot).position
    goal = layout.join(qT, fk(qT))
    frac = torch.linspace(0, 1, T + 1, dtype=torch.float64)[:, None]
    joints = q0[:, None] + frac * (qT - q0)[:, None]
    ef = fk(joints)
    ef[:, -1] = fk(qT) + end_offsets
    return Plan.from_joints(goal, joints, ef, waypoints=ef[:, 1:-1])


def test_goal_error_and_success_rate(robot):
    offsets = torch.tensor([[0.005, 0, 0], [0, 0.02, 0], [0, 0, 0], [0.006, 0.0079, 0]], dtype=torch.float64)
    m = plan_metrics(hand_made_plan(robot, offsets), robot)
    assert torch.allclose(
        m["goal_error"],
        torch.tensor([0.005, 0.02, 0.0, math.hypot(0.006, 0.0079)], dtype=torch.float64),
        atol=1e-12,
    )
    assert m["success"].tolist() == [1.0, 0.0, 1.0, 1.0]
    assert summarize(m)["success"]["rate"] == pytest.approx(0.75)
    assert torch.allclose(m["start_error"], torch.zeros(4, dtype=torch.float64), atol=1e-12)
    assert torch.allclose(m["tracking_error"], torch.zeros(4, dtype=torch.float64), atol=1e-12)
    tight = plan_metrics(hand_made_plan(robot, offsets), robot, success_radius=0.001)
    assert tight["success"].tolist() == [0.0, 0.0, 1.0, 0.0]


def test_path_lengths(robot):
    plan = hand_made_plan(robot, torch.zeros(3, 3, dtype=torch.float64))
    m = plan_metrics(plan, robot)
    expected = (plan.ef[:, 1:] - plan.ef[:, :-1]).norm(dim=-1).sum(-1)
    assert torch.allclose(m["path_length"], expected)
    # The waypoints here are the executed path's interior points, so both lengths agree.
    assert torch.allclose(m["waypoint_path_length"], expected)
    assert torch.all(m["path_length"] >= m["endpoint_distance"] - 1e-12)


def test_joint_limit_violations(robot):
    plan = hand_made_plan(robot, torch.zeros(3, 3, dtype=torch.float64))
    joints = plan.joints.clone()
    upper = torch.as_tensor(robot.upper)
    joints[0, 2, 3] = upper[3] + 0.01  # clearly outside
    joints[1, 1, 0] = upper[0]  # exactly at the limit: allowed
    joints[1, 2, 6] = -upper[6] - 1e-8  # within the tolerance
    plan = dataclasses.replace(plan, joints=joints)
    m = plan_metrics(plan, robot)
    assert m["limit_violation"].tolist() == [1.0, 0.0, 0.0]
    assert plan_metrics(plan, robot, limit_tol=0.0)["limit_violation"].tolist() == [1.0, 1.0, 0.0]


def test_sharp_turn_indicators(robot):
    plan = hand_made_plan(robot, torch.zeros(3, 3, dtype=torch.float64))
    layout = StateLayout(robot.dof)
    e0 = layout.split(plan.start)[1]
    waypoints = plan.waypoints.clone()
    # Trajectory 0: hairpin right after the start (0°); 1: a 80° corner; 2: unchanged.
    waypoints[0, 0] = e0[0] + torch.tensor([0.1, 0, 0], dtype=torch.float64)
    waypoints[0, 1] = e0[0] + torch.tensor([0.1 - 1e-3, 0, 0], dtype=torch.float64)
    a = math.radians(80)
    waypoints[1, 0] = e0[1] + torch.tensor([0.1, 0, 0], dtype=torch.float64)
    waypoints[1, 1] = waypoints[1, 0] + 0.1 * torch.tensor(
        [-math.cos(a), math.sin(a), 0], dtype=torch.float64
    )
    plan = dataclasses.replace(plan, waypoints=waypoints)
    m = plan_metrics(plan, robot)
    assert float(m["min_angle"][0]) == pytest.approx(0.0, abs=1e-6)
    assert float(m["min_angle"][1]) == pytest.approx(80.0, abs=1e-6)
    assert m["sharp_turn"][:2].tolist() == [1.0, 1.0]
    assert m["sharp_turn_paper"][:2].tolist() == [1.0, 0.0]


def test_plan_metrics_validation(robot):
    plan = hand_made_plan(robot, torch.zeros(2, 3, dtype=torch.float64))
    with pytest.raises(ShapeError):
        plan_metrics(dataclasses.replace(plan, waypoints=plan.waypoints[:, :-1]), robot)
    with pytest.raises(ShapeError):
        plan_metrics(plan, load_robot("ur5"))  # 6-DoF robot, 7-DoF plan
    ef = plan.ef.clone()
    ef[0, 1, 1] = float("inf")
    with pytest.raises(NonFiniteError):
        plan_metrics(dataclasses.replace(plan, ef=ef), robot)
    with pytest.raises(ShapeError):
        plan_metrics("not a plan", robot)


# --------------------------------------------------------------------------------------------------
# Summaries and tables
# --------------------------------------------------------------------------------------------------


def test_summarize_known_values():
    s = summarize(
        {"avg_spacing": torch.tensor([1.0, 2.0, 3.0, 4.0]), "success": torch.tensor([1.0, 0.0, 1.0, 1.0])}
    )
    a = s["avg_spacing"]
    assert a["mean"] == 2.5 and a["std"] == pytest.approx(math.sqrt(1.25)) and a["median"] in (2.0, 2.5)
    assert a["min"] == 1.0 and a["max"] == 4.0 and a["n"] == 4 and "rate" not in a
    assert s["success"]["rate"] == 0.75
    assert "success" in INDICATORS
    one = summarize({"x": torch.tensor([3.0])})["x"]
    assert one["std"] == 0.0  # population std: one trajectory gives 0, not NaN
    with pytest.raises(NonFiniteError):
        summarize({"x": torch.tensor([1.0, float("nan")])})
    with pytest.raises(ShapeError):
        summarize({"x": torch.tensor([])})


def test_format_table_puts_the_paper_beside_ours():
    ours = summarize(
        {
            "init_distance": torch.tensor([0.01, 0.03]),
            "mean_angle": torch.tensor([170.0, 176.0]),
            "sharp_turn_paper": torch.tensor([0.0, 1.0]),
        }
    )
    table = format_table({"paper (Table 2, #4)": PAPER_TABLE2[4], "ours": ours})
    lines = table.strip().splitlines()
    assert len(lines) == 4 and lines[0].count("|") == len(TABLE2_COLUMNS) + 2
    assert "0.134 ± 0.108" in lines[2] and "153.0 ± 8.8" in lines[2] and "69.9 ± 1.3" in lines[2]
    assert "54.0%" in lines[2]
    assert "0.020 ± 0.010" in lines[3] and "173.0 ± 3.0" in lines[3] and "50.0%" in lines[3]
    assert "—" in lines[3]  # avg_spacing missing from ours
    with pytest.raises(ConfigError):
        format_table({"ours": ours}, columns=["no_such_metric"])


def test_paper_rows_are_complete():
    assert set(PAPER_TABLE2) == {1, 2, 3, 4, 5, 6}
    for row in PAPER_TABLE2.values():
        assert set(TABLE2_COLUMNS[:5]) <= set(row)
