"""Time parameterisation (toppra) on the real URDFs: limits, rest, path following, files, bad inputs."""

import csv

import numpy as np
import pytest
import torch
from conftest import ALL_ROBOTS

import kinlearn
from kinlearn.body.robot import Robot
from kinlearn.errors import (
    ConfigError,
    DatasetError,
    JointLimitError,
    NonFiniteError,
    ShapeError,
)
from kinlearn.planning.timing import DEFAULT_ACCELERATION_TIME, TimedTrajectory, time_parameterize

RTOL = 1e-5  # relative excess of a limit tolerated at dense samples
DT = 1e-3


def _lerp_path(robot: Robot, seed: int, steps: int = 11) -> torch.Tensor:
    a, b = robot.sample(2, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)
    f = torch.linspace(0.0, 1.0, steps + 1, dtype=torch.float64)[:, None]
    return a + f * (b - a)


def _curved_path(robot: Robot, seed: int) -> torch.Tensor:
    return robot.sample(6, generator=torch.Generator().manual_seed(seed), dtype=torch.float64, margin=0.1)


def _check_executable(robot: Robot, path: torch.Tensor, tr: TimedTrajectory) -> None:
    w = path.numpy()
    # Times: from 0 to duration, strictly increasing.
    assert tr.t[0] == 0.0 and tr.t[-1] == pytest.approx(tr.duration, abs=1e-12)
    assert np.all(np.diff(tr.t) > 0)
    assert np.all(np.diff(tr.waypoint_times) >= 0) and tr.waypoint_times[0] == 0.0
    assert tr.waypoint_times[-1] == pytest.approx(tr.duration, rel=1e-9)
    # Limits at every (dense) sample; positions within the position limits.
    v_ratio = np.abs(tr.qd) / tr.velocity_limits
    a_ratio = np.abs(tr.qdd) / tr.acceleration_limits
    assert v_ratio.max() <= 1 + RTOL and a_ratio.max() <= 1 + RTOL
    assert np.all(tr.q >= robot.lower) and np.all(tr.q <= robot.upper)
    # Time-optimal: some joint is at its velocity or acceleration limit (not a slow, safe timing).
    assert max(v_ratio.max(), a_ratio.max()) > 0.99
    # Starts and ends at rest, ends exactly at the last waypoint.
    np.testing.assert_allclose(tr.qd[0], 0.0, atol=1e-9)
    np.testing.assert_allclose(tr.qd[-1], 0.0, atol=1e-6)
    np.testing.assert_array_equal(tr.q[-1], w[-1])
    np.testing.assert_allclose(tr.q[0], w[0], atol=1e-12)
    # Passes every waypoint: the sample nearest in time to its passage is within one step's motion.
    step = np.abs(tr.qd).max(axis=0) * DT + 1e-9
    for k in range(len(w)):
        i = int(np.argmin(np.abs(tr.t - tr.waypoint_times[k])))
        assert np.all(np.abs(tr.q[i] - w[k]) <= step), f"waypoint {k} missed"
    # The velocities are the derivative of the positions (central differences, interior samples).
    fd = (tr.q[2:] - tr.q[:-2]) / (tr.t[2:] - tr.t[:-2])[:, None]
    err = np.abs(fd - tr.qd[1:-1])[:-2]  # the last interval is shorter than dt
    assert err.max() <= 1e-2 * tr.velocity_limits.max()


@pytest.mark.parametrize("name", ALL_ROBOTS)
def test_joint_interpolation_path_is_executable(name):
    robot = kinlearn.load_robot(name)
    path = _lerp_path(robot, seed=11)
    tr = time_parameterize(robot, path, dt=DT)
    _check_executable(robot, path, tr)
    assert tr.robot == name and tr.joint_names == robot.joint_names
    np.testing.assert_array_equal(tr.velocity_limits, robot.velocity_limits)
    np.testing.assert_allclose(tr.acceleration_limits, robot.velocity_limits / DEFAULT_ACCELERATION_TIME)
    # Collinear, evenly spaced waypoints: the timed path is the straight joint-space segment.
    a, b = path[0].numpy(), path[-1].numpy()
    u = (tr.q - a) @ (b - a) / np.dot(b - a, b - a)
    np.testing.assert_allclose(tr.q, a + u[:, None] * (b - a), atol=1e-9)
    assert tr.interpolant == "spline"


@pytest.mark.parametrize("name", ALL_ROBOTS)
def test_curved_path_is_executable(name):
    robot = kinlearn.load_robot(name)
    path = _curved_path(robot, seed=5)
    tr = time_parameterize(robot, path, dt=DT)
    _check_executable(robot, path, tr)


def test_limits_and_scale_are_respected():
    robot = kinlearn.load_robot("iiwa14")
    path = _lerp_path(robot, seed=3)
    full = time_parameterize(robot, path)
    half = time_parameterize(robot, path, velocity_scale=0.5)
    assert np.abs(half.qd / robot.velocity_limits).max() <= 0.5 * (1 + RTOL)
    assert half.duration > 1.2 * full.duration
    slow = time_parameterize(
        robot, torch.stack([path[0], path[-1]]), velocity_limits=0.2, acceleration_limits=0.5
    )
    np.testing.assert_array_equal(slow.velocity_limits, np.full(7, 0.2))
    assert np.abs(slow.qd).max() <= 0.2 * (1 + RTOL) and np.abs(slow.qdd).max() <= 0.5 * (1 + RTOL)
    # A rest-to-rest motion of the largest joint change cannot be faster than the bang-bang bound.
    d = np.abs((path[-1] - path[0]).numpy()).max()
    assert slow.duration >= d / 0.2 - 1e-9


def test_sampling_options_and_duplicates():
    robot = kinlearn.load_robot("panda")
    path = _lerp_path(robot, seed=8, steps=4)
    tr = time_parameterize(robot, path, samples=50)
    assert len(tr) == 50 and tr.t[-1] == tr.duration
    np.testing.assert_allclose(np.diff(tr.t), tr.duration / 49, rtol=1e-9)
    # A repeated waypoint is one waypoint: same timing, and both copies are passed at the same time.
    doubled = torch.cat([path[:3], path[2:]])
    tr2 = time_parameterize(robot, doubled, samples=50)
    assert tr2.duration == pytest.approx(tr.duration, rel=1e-9)
    assert tr2.waypoint_times[2] == tr2.waypoint_times[3]
    # A path that does not move: one sample at rest.
    still = time_parameterize(robot, path[:1].repeat(3, 1))
    assert still.duration == 0.0 and len(still) == 1 and np.all(still.qd == 0)
    # float32 input and a numpy array work too.
    tr3 = time_parameterize(robot, path.float().numpy(), samples=50)
    assert tr3.duration == pytest.approx(tr.duration, rel=1e-5)


def test_spline_overshoot_near_a_limit_falls_back_to_pchip():
    robot = kinlearn.load_robot("iiwa14")
    hi = robot.upper[1]
    path = torch.zeros(4, 7, dtype=torch.float64)
    path[:, 1] = torch.tensor([0.0, hi - 1e-3, hi - 1e-3, 0.0])
    path[:, 0] = torch.tensor([0.0, 0.3, 0.6, 0.9])
    with pytest.raises(JointLimitError, match="pchip"):
        time_parameterize(robot, path, interpolant="spline")
    tr = time_parameterize(robot, path, dt=DT)
    assert tr.interpolant == "pchip"
    assert tr.q[:, 1].max() <= hi - 1e-3 + 1e-12  # PCHIP does not overshoot its waypoints
    _check_executable(robot, path, tr)


def test_csv_and_json_round_trip(tmp_path):
    robot = kinlearn.load_robot("ur5")
    tr = time_parameterize(robot, _curved_path(robot, seed=2), dt=0.02)
    tr.to_csv(tmp_path / "traj.csv")
    with (tmp_path / "traj.csv").open() as f:
        rows = list(csv.reader(f))
    assert rows[0][:2] == ["t", f"q_{robot.joint_names[0]}"] and rows[0][-1] == f"qdd_{robot.joint_names[-1]}"
    table = np.array(rows[1:], dtype=np.float64)
    np.testing.assert_array_equal(table, np.concatenate([tr.t[:, None], tr.q, tr.qd, tr.qdd], axis=1))

    tr.to_json(tmp_path / "traj.json")
    back = TimedTrajectory.from_json(tmp_path / "traj.json")
    for f in ("t", "q", "qd", "qdd", "velocity_limits", "acceleration_limits", "waypoint_times"):
        np.testing.assert_array_equal(getattr(back, f), getattr(tr, f))
    assert (back.duration, back.robot, back.joint_names, back.interpolant) == (
        tr.duration,
        tr.robot,
        tr.joint_names,
        tr.interpolant,
    )
    assert not back.q.flags.writeable
    assert not list(tmp_path.glob(".*.tmp"))  # atomic writes leave no temporary file


def test_from_json_rejects_other_files(tmp_path):
    (tmp_path / "other.json").write_text('{"kind": "something else"}')
    with pytest.raises(DatasetError, match="not a kinlearn timed trajectory"):
        TimedTrajectory.from_json(tmp_path / "other.json")
    (tmp_path / "v9.json").write_text('{"kind": "kinlearn.timed_trajectory", "format": 9}')
    with pytest.raises(DatasetError, match="format 9"):
        TimedTrajectory.from_json(tmp_path / "v9.json")
    (tmp_path / "broken.json").write_text('{"kind": "kinlearn.timed_trajectory", "format": 1, "t": [0]}')
    with pytest.raises(DatasetError, match="malformed"):
        TimedTrajectory.from_json(tmp_path / "broken.json")
    (tmp_path / "bad.json").write_text("{")
    with pytest.raises(DatasetError, match="cannot read"):
        TimedTrajectory.from_json(tmp_path / "bad.json")


def test_bad_inputs_raise_typed_errors():
    robot = kinlearn.load_robot("iiwa14")
    path = _lerp_path(robot, seed=4)
    outside = path.clone()
    outside[5, 3] = robot.upper[3] + 0.1
    with pytest.raises(JointLimitError, match="outside iiwa14's limits"):
        time_parameterize(robot, outside)
    nan = path.clone()
    nan[2, 0] = float("nan")
    with pytest.raises(NonFiniteError):
        time_parameterize(robot, nan)
    with pytest.raises(ShapeError, match="one plan at a time"):
        time_parameterize(robot, path.unsqueeze(0))
    with pytest.raises(ShapeError):
        time_parameterize(robot, path[:, :6])
    with pytest.raises(ShapeError):
        time_parameterize(robot, path.tolist())
    with pytest.raises(ShapeError, match="floating-point"):
        time_parameterize(robot, torch.zeros(3, 7, dtype=torch.long))
    with pytest.raises(ConfigError, match="positive"):
        time_parameterize(robot, path, velocity_limits=0.0)
    with pytest.raises(ConfigError, match="positive"):
        time_parameterize(robot, path, acceleration_limits=-np.ones(7))
    with pytest.raises(ShapeError, match="7 numbers"):
        time_parameterize(robot, path, velocity_limits=np.ones(6))
    with pytest.raises(NonFiniteError):
        time_parameterize(robot, path, acceleration_limits=float("inf"))
    for scale in (0.0, 1.5, float("nan")):
        with pytest.raises(ConfigError, match="velocity_scale"):
            time_parameterize(robot, path, velocity_scale=scale)
    with pytest.raises(ConfigError, match="dt"):
        time_parameterize(robot, path, dt=0.0)
    with pytest.raises(ConfigError, match="not both"):
        time_parameterize(robot, path, dt=0.01, samples=10)
    with pytest.raises(ConfigError, match="samples"):
        time_parameterize(robot, path, samples=1)
    with pytest.raises(ConfigError, match="interpolant"):
        time_parameterize(robot, path, interpolant="linear")


def test_urdf_without_velocity_limits_needs_explicit_limits():
    robot = kinlearn.load_robot("iiwa14")
    urdf = robot.urdf.replace(b'velocity="1.7453" ', b"")
    bare = Robot("iiwa14-novel", urdf, robot.ee_frame)
    assert not np.isfinite(bare.velocity_limits[2])
    path = _lerp_path(robot, seed=6, steps=2)
    with pytest.raises(ConfigError, match="iiwa_joint_3"):
        time_parameterize(bare, path)
    tr = time_parameterize(bare, path, velocity_limits=1.0)
    assert np.abs(tr.qd).max() <= 1.0 * (1 + RTOL)
