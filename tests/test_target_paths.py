"""Teachers' paths of a problem set, kept beside it (:mod:`kinlearn.data.target_paths`)."""

from __future__ import annotations

import numpy as np
import pytest

from kinlearn.data.target_paths import (
    load_target_paths,
    read_target_paths,
    save_target_paths,
    target_paths_file,
)
from kinlearn.errors import ConfigError, DatasetError


def test_paths_are_kept_beside_their_set_and_read_only_as_made(tmp_path):
    problems = tmp_path / "cubby_00.npz"
    assert target_paths_file(problems, "sampler", 11) == tmp_path / "cubby_00.experts11.npz"
    assert target_paths_file(problems, "planner", 4) == tmp_path / "cubby_00.planner4.npz"
    with pytest.raises(ConfigError, match="teacher"):
        target_paths_file(problems, "oracle", 4)
    paths = np.random.default_rng(0).normal(size=(3, 5, 6))
    found = np.array([True, False, True])
    want = {"problems": "cubby_00.npz", "n": 3, "knots": 4, "plan": "default"}
    assert load_target_paths(problems, "ur5", "planner", 4, want) is None  # nothing there yet
    with pytest.raises(DatasetError):
        read_target_paths(problems, "ur5", "planner", 4, 3)
    out = save_target_paths(problems, "ur5", "planner", 4, want, paths, found)
    assert out == target_paths_file(problems, "planner", 4)
    got = load_target_paths(problems, "ur5", "planner", 4, want)
    np.testing.assert_array_equal(got[0], paths)
    np.testing.assert_array_equal(got[1], found)
    # made otherwise: another record, another teacher, another robot or size is not these paths
    assert load_target_paths(problems, "ur5", "planner", 4, {**want, "plan": "fixed"}) is None
    assert load_target_paths(problems, "ur5", "sampler", 4, want) is None
    assert load_target_paths(problems, "panda", "planner", 4, want) is None
    with pytest.raises(DatasetError, match="another problem set"):
        read_target_paths(problems, "ur5", "planner", 4, 5)
    with pytest.raises(ConfigError, match="target paths must be"):
        save_target_paths(problems, "ur5", "planner", 5, want, paths, found)  # 5 knots need 6 points
