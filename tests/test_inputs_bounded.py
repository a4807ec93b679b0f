"""Inputs held to one standard: numbers that are numbers, bounded work, typed errors for files and odd
batches, and answers that do not depend on what else is in the batch."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import kinlearn
from kinlearn.checks import as_int, as_real
from kinlearn.errors import ConfigError
from kinlearn.planning.timing import MAX_SAMPLES, time_parameterize

START = torch.tensor([-1.2, 0.9, 0.5, -1.6, 0.3, 1.2, -2.0], dtype=torch.float64)
GOAL = torch.tensor([1.5, -0.4, -0.8, 1.1, -1.9, -0.6, 2.4], dtype=torch.float64)


@pytest.fixture(scope="module")
def robot():
    return kinlearn.load_robot("iiwa14")


# ------------------------------------------------------------------------------------------- numbers


@pytest.mark.parametrize("value", [25, np.int64(25), np.int32(25), torch.tensor(25), np.array(25)])
def test_integers_of_every_kind_are_integers(value):
    assert as_int(value, "n", minimum=0) == 25 and type(as_int(value, "n")) is int


@pytest.mark.parametrize("value", [0.5, np.float32(0.5), np.float64(0.5), torch.tensor(0.5), 1, np.int8(1)])
def test_reals_of_every_kind_are_reals(value):
    assert as_real(value, "x", minimum=0.0, open_minimum=True) == pytest.approx(float(value))


@pytest.mark.parametrize(
    "value",
    [True, np.bool_(True), torch.tensor(True), 1 + 0j, np.complex64(1), "3", None, torch.ones(2), 2.5],
)
def test_bools_complex_and_non_numbers_are_no_integers(value):
    with pytest.raises(ConfigError, match="n must be an integer"):
        as_int(value, "n")


@pytest.mark.parametrize("value", [False, 1j, torch.tensor(1j), float("nan"), float("inf"), "0.5"])
def test_bools_complex_nan_are_no_reals(value):
    with pytest.raises(ConfigError, match="x must be a finite real number"):
        as_real(value, "x")


def test_bounds_are_named():
    with pytest.raises(ConfigError, match=r"in \[0, 10\], got 11"):
        as_int(11, "n", minimum=0, maximum=10)
    with pytest.raises(ConfigError, match="> 0"):
        as_real(0.0, "x", minimum=0.0, open_minimum=True)
    with pytest.raises(ConfigError, match="≤ 1"):
        as_real(1.5, "x", maximum=1.0)


def test_plan_options_take_numpy_and_torch_scalars(robot):
    ball = [[0.58, -0.11, 1.03, 0.12]]
    a = kinlearn.plan(START, GOAL, obstacles=ball, refine_steps=3)
    for steps in (np.int64(3), torch.tensor(3)):
        b = kinlearn.plan(START, GOAL, obstacles=ball, refine_steps=steps)
        assert torch.equal(a.joints, b.joints)
    for bad in (-5, True, 2.0, torch.tensor(3.0), 10**9):  # refused with or without obstacles
        with pytest.raises(ConfigError, match="refine_steps"):
            kinlearn.plan(START, GOAL, refine_steps=bad)
    path = a.joints
    t = time_parameterize(robot, path, velocity_scale=0.5)
    for scale in (np.float32(0.5), torch.tensor(0.5)):
        assert time_parameterize(robot, path, velocity_scale=scale).duration == pytest.approx(t.duration)
    assert len(time_parameterize(robot, path, samples=np.int64(7))) == 7
    with pytest.raises(ConfigError, match="velocity_scale"):
        time_parameterize(robot, path, velocity_scale=True)


# ---------------------------------------------------------------------------------------- work budgets


def test_timing_refuses_more_samples_than_its_budget_before_allocating(robot):
    path = torch.stack((START, GOAL))
    with pytest.raises(ConfigError, match="samples"):
        time_parameterize(robot, path, samples=10**9)
    with pytest.raises(ConfigError, match="MAX_SAMPLES"):
        time_parameterize(robot, path, dt=1e-9)
    with pytest.raises(ConfigError, match="larger velocity/acceleration limits"):
        time_parameterize(robot, path, velocity_limits=1e-12)
    assert len(time_parameterize(robot, path, samples=MAX_SAMPLES // 1000)) == MAX_SAMPLES // 1000


# ------------------------------------------------------------------------------ what readers believe


def _timed_json(robot, tmp_path, edit):
    import json

    tr = time_parameterize(robot, torch.stack((START, GOAL)), dt=0.1)
    obj = tr.to_dict()
    edit(obj)
    path = tmp_path / "t.json"
    path.write_text(json.dumps(obj))
    return path


@pytest.mark.parametrize(
    "edit",
    [
        lambda o: o["t"].reverse(),  # decreasing times
        lambda o: o["t"].__setitem__(0, 0.05),  # not from 0
        lambda o: o["q"][1].__setitem__(0, float("nan")),  # NaN position
        lambda o: o.__setitem__("duration", -1.0),
        lambda o: o["waypoint_times"].reverse(),
    ],
)
def test_from_json_refuses_times_that_do_not_increase_and_nan_positions(robot, tmp_path, edit):
    from kinlearn.errors import DatasetError
    from kinlearn.planning.timing import TimedTrajectory

    with pytest.raises(DatasetError, match="malformed"):
        TimedTrajectory.from_json(_timed_json(robot, tmp_path, edit))
    assert TimedTrajectory.from_json(_timed_json(robot, tmp_path, lambda o: None)).duration > 0
