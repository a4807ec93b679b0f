"""The shortcut pass (kinlearn.collision.shortcut) on the real iiwa14 body and the compiled checker: the
paths it gives stay free, never grow, keep their ends, and are the same on every call."""

import numpy as np
import pytest
import torch

import kinlearn
from kinlearn.collision import Scene, body_spheres, kernel
from kinlearn.collision.rrt import rrt_connect
from kinlearn.collision.shortcut import shorten
from kinlearn.errors import ConfigError, ShapeError


def _length(p: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())


@pytest.fixture(scope="module")
def setting():
    robot = kinlearn.load_robot("iiwa14")
    body = kernel.KernelBody(body_spheres(robot).double())
    scene = kernel.KernelScene(
        Scene.from_spheres([[0.5, 0.0, 0.6, 0.2], [-0.3, 0.4, 0.9, 0.15]], floor=0.0).to(torch.float64)
    )
    rng = np.random.default_rng(5)
    paths = []
    while len(paths) < 4:
        a, b = (rng.uniform(robot.lower * 0.8, robot.upper * 0.8) for _ in range(2))
        path, _, _ = rrt_connect(
            body, scene, a, b, robot.lower, robot.upper, time_limit=float("inf"), max_iterations=3000,
            seed=len(paths), shortcut=False,
        )  # fmt: skip
        if path is not None and path.shape[0] >= 4:
            paths.append(path)
    return robot, body, scene, paths


def test_shortened_paths_are_free_no_longer_and_keep_their_ends(setting):
    _robot, body, scene, paths = setting
    gained = 0.0
    for path in paths:
        short = shorten(body, scene, path)
        assert 2 <= short.shape[0] <= path.shape[0]
        np.testing.assert_array_equal(short[0], path[0])
        np.testing.assert_array_equal(short[-1], path[-1])
        assert _length(short) <= _length(path) + 1e-12
        free, _, _ = kernel.check_paths(body, short[None], scene)
        assert free[0]
        gained += _length(path) - _length(short)
    assert gained > 0.1  # a sampler's zig-zags are gone


def test_shortcut_is_deterministic_and_its_seed_and_budget_matter(setting):
    _, body, scene, paths = setting
    path = paths[0]
    a = shorten(body, scene, path, seed=3)
    np.testing.assert_array_equal(a, shorten(body, scene, path, seed=3))
    none = shorten(body, scene, path, attempts=0)  # vertex skipping alone
    assert _length(a) <= _length(none) + 1e-12


def test_draws_that_save_too_little_are_not_checked(setting):
    _, body, scene, paths = setting
    for path in paths:
        every = shorten(body, scene, path, min_gain=0.0)
        assert _length(every) <= _length(path) + 1e-12
        # no draw can save nearly all of a path's length: the pass is vertex skipping alone
        np.testing.assert_array_equal(
            shorten(body, scene, path, min_gain=0.999), shorten(body, scene, path, attempts=0)
        )
    with pytest.raises(ConfigError, match="min_gain"):
        shorten(body, scene, paths[0], min_gain=1.0)
    with pytest.raises(ConfigError, match="min_gain"):
        shorten(body, scene, paths[0], min_gain=float("nan"))


def test_a_cap_bounds_the_vertices(setting):
    _, body, scene, paths = setting
    path = paths[1]
    short = shorten(body, scene, path, cap=path.shape[0] + 6)
    assert short.shape[0] <= path.shape[0] + 6


def test_shortcut_refuses_bad_paths(setting):
    _, body, scene, paths = setting
    with pytest.raises(ShapeError):
        shorten(body, scene, paths[0][:1])
    with pytest.raises(ShapeError):
        shorten(body, scene, paths[0][:, :3])
    bad = paths[0].copy()
    bad[1, 0] = np.nan
    with pytest.raises(ShapeError, match="finite"):
        shorten(body, scene, bad)
    with pytest.raises(ConfigError, match="cap"):
        shorten(body, scene, paths[0], cap=2)
