"""Identification that knows when its data cannot identify the chain: repeated rows, a joint that never
moves, a sample budget that leaves too few, degrees and millimetres given as tensors are refused with
typed errors; weak motion warns naming the joints; the report says how each joint was excited; names are
written XML-escaped and generated link names never collide with the prior's."""

from __future__ import annotations

import warnings
import xml.etree.ElementTree as ET

import numpy as np
import pytest
import torch

from kinlearn.body.kinematics import kinematics
from kinlearn.body.robot import load_robot
from kinlearn.data.recorded import Observations, save_recorded
from kinlearn.errors import (
    ConfigError,
    DatasetError,
    PoorExcitationWarning,
    RecordedDataError,
    UnidentifiableError,
)
from kinlearn.training.identify import IdentifyConfig, identify

ROBOT = load_robot("iiwa14")
FAST = IdentifyConfig(iterations=8)


def _data(n=2000, seed=0, noise=1e-3):
    gen = torch.Generator().manual_seed(seed)
    q = ROBOT.sample(n, gen, dtype=torch.float64)
    ef = kinematics(ROBOT, "pinocchio").position(q)
    return q, ef + noise * torch.randn(n, 3, generator=gen, dtype=torch.float64)


def test_copies_of_one_row_are_refused_not_a_perfect_fit():
    q, ef = _data(1)
    with pytest.raises(UnidentifiableError, match=r"3000 rows but only 1 distinct"):
        identify((q.repeat(3000, 1), ef.repeat(3000, 1)), robot=ROBOT, config=FAST)


def test_a_joint_that_never_moves_is_refused_naming_it():
    q, ef = _data()
    q[:, 2] = 0.4
    ef = kinematics(ROBOT, "pinocchio").position(q)
    with pytest.raises(UnidentifiableError, match=r"joint\(s\) 3 \(0 rad\) never move"):
        identify((q, ef), robot=ROBOT, config=FAST)


def test_a_budget_that_leaves_too_few_samples_is_refused_after_subsampling():
    with pytest.raises(UnidentifiableError, match=r"max_samples = 10 leaves 10 samples.*at least 900"):
        identify(_data(), robot=ROBOT, config=IdentifyConfig(max_samples=10))


@pytest.mark.parametrize(
    "change, match",
    [
        (lambda q, ef: (torch.rad2deg(q), ef), "convert it"),
        (lambda q, ef: (q, ef * 1000), "divide by 1000"),
        (lambda q, ef: (q.clamp(max=3.0) + 0.2, ef), "outside iiwa14's limits"),
    ],
)
def test_tensors_get_the_unit_and_limit_checks_of_files(change, match):
    with pytest.raises(RecordedDataError, match=match):
        identify(change(*_data()), robot=ROBOT, config=FAST)


def test_numbers_and_bad_arrays():
    q, ef = _data(100)
    # a NumPy joint count is a joint count: the next check (too few samples) is reached
    with pytest.raises(DatasetError, match="at least 900"):
        identify((q, ef), dof=np.int64(7), config=FAST)
    with pytest.raises(ConfigError, match="dof"):
        identify((q, ef), dof=7.5)
    with pytest.raises(DatasetError, match="real numbers"):
        identify((q.bool(), ef), dof=7)
    with pytest.raises(DatasetError, match="array of numbers"):
        identify((["a"] * 100, ef), dof=7)
    assert IdentifyConfig(max_samples=np.int64(5000), holdout=np.float32(0.25)).max_samples == 5000
    with pytest.raises(ConfigError, match="max_samples"):
        IdentifyConfig(max_samples=True)


def test_a_file_with_a_numpy_joint_count(tmp_path):
    q, ef = _data(100)
    path = save_recorded(tmp_path / "log.csv", Observations(q, ef))
    with pytest.raises(DatasetError, match="at least 900"):
        identify(path, dof=np.int64(7), config=FAST)


def test_weak_motion_warns_naming_the_joint_and_the_report_holds_the_excitation():
    q, ef = _data()
    q[:, 2] = 0.4 + 0.05 * torch.rand(len(q), generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    ef = kinematics(ROBOT, "pinocchio").position(q)
    with pytest.warns(PoorExcitationWarning, match=r"joint\(s\) 3 \(0.05 rad\) moved less than 0.1 rad"):
        result = identify((q, ef), robot=ROBOT, config=FAST)
    ex = result.report["excitation"]
    assert ex["joint_range"][2] < 0.05 and min(ex["joint_range"][:2]) > 3.0
    assert ex["expected_rank"] == 4 * 7 + 3 and ex["parameter_rank"] <= ex["expected_rank"]
    with warnings.catch_warnings():
        warnings.simplefilter("error", PoorExcitationWarning)
        full = identify(_data(), robot=ROBOT, config=FAST)
    assert full.report["excitation"]["parameter_rank"] == 31 and full.report["excitation"]["condition"] > 1
    assert full.report["duplicates_dropped"] == 0


def test_repeated_rows_count_once_and_never_straddle_the_held_out_split():
    q, ef = _data()
    result = identify((torch.cat((q, q[:500])), torch.cat((ef, ef[:500]))), robot=ROBOT, config=FAST)
    assert result.report["duplicates_dropped"] == 500 and result.report["samples"] == 2000


def test_urdf_names_are_escaped_and_link_names_do_not_collide(tmp_path):
    result = identify(_data(), robot=ROBOT, config=FAST)
    text = result.urdf(name='arm"<x>&')
    assert ET.fromstring(text).get("name") == 'arm"<x>&'
    result.ee_frame = "link2"  # a prior whose end effector is named as the generated links are
    result.base_link = "link1"
    root = ET.fromstring(result.urdf("r"))
    links = [el.get("name") for el in root.iter("link")]
    assert len(links) == len(set(links)) == 9 and "link2" in links
    path = tmp_path / "r.urdf"
    path.write_text(result.urdf('arm"<x>&'))
    back = load_robot(path, "link2")
    q = ROBOT.sample(50, torch.Generator().manual_seed(1), dtype=torch.float64)
    got = kinematics(back, "pinocchio").position(q)
    torch.testing.assert_close(got, result.model.rigid_position(q).detach(), atol=1e-9, rtol=0)
