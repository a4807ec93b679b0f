"""A plan's end in contact with a cloud: taken to touch the surface its points sample where no point lies
deeper inside the arm than the cloud's contact depth, refused where one does, on the real iiwa14 body."""

import warnings

import numpy as np
import pytest
import torch

from kinlearn.collision import Scene, kernel
from kinlearn.collision.cloud import DEFAULT_CONTACT, PointCloud
from kinlearn.collision.cloud_contact import CONTACT_MARGIN, ends_in_contact
from kinlearn.collision.scene_file import write_scene
from kinlearn.errors import CollidingEndWarning, DatasetError, EndContactWarning, PointCloudError
from kinlearn.planning.planner import Planner

START = np.array([-1.2, 0.9, 0.5, -1.6, 0.3, 1.2, -2.0])
GOAL = np.array([1.5, -0.4, -0.8, 1.1, -1.9, -0.6, 2.4])
WALL = np.array([[-0.6, y, z] for y in np.arange(-0.7, -0.5, 0.02) for z in np.arange(0.0, 0.2, 0.02)])


@pytest.fixture(scope="module")
def planner():
    return Planner.default("iiwa14")


def _hand(planner, q, depth):
    """A point ``depth`` (m) inside the hand's last sphere at ``q`` (negative: outside it), along +z from its
    centre, and that sphere's centre and radius."""
    body = planner.body.double()
    c = body(torch.as_tensor(q)[None])[0].numpy()[-1]
    r = float(body.radii[-1])
    return c + np.array([0.0, 0.0, r - depth]), c, r


@pytest.mark.parametrize("depth", [-0.008, 0.003])
def test_a_goal_touching_the_points_within_the_contact_depth_is_planned(planner, depth):
    point, _, _ = _hand(planner, GOAL, depth)
    scene = Scene.from_points(np.vstack([WALL, point]))
    assert scene.cloud.contact == DEFAULT_CONTACT
    with pytest.warns(EndContactWarning, match="goal") as caught:
        plan = planner.plan(START, GOAL, obstacles=scene)
    assert bool(plan.success) and bool(plan.collision_free)
    assert caught[0].filename == __file__  # the warning points at the caller's plan()
    # the points it touched are dropped for the plan, no other: the wall is checked as before
    kept, found = ends_in_contact(planner._np_body, scene, np.stack([START, GOAL]))
    assert [c.end for c in found] == ["goal"] and found[0].depth == pytest.approx(depth, abs=1e-9)
    assert kept.cloud.num_points == len(WALL)


def test_a_point_deeper_than_the_contact_depth_is_refused(planner):
    point, _, _ = _hand(planner, GOAL, 0.012)
    scene = Scene.from_points(np.vstack([WALL, point]))
    with warnings.catch_warnings():
        warnings.simplefilter("error", EndContactWarning)
        with pytest.warns(CollidingEndWarning, match="goal"):
            plan = planner.plan(START, GOAL, obstacles=scene, refine_steps=0)
    assert not bool(plan.collision_free) and not bool(plan.success)
    kept, found = ends_in_contact(planner._np_body, scene, np.stack([START, GOAL]))
    assert kept is scene and found == []


def test_contact_zero_refuses_every_end_the_balls_touch(planner):
    point, _, _ = _hand(planner, GOAL, -0.008)
    scene = Scene.from_points(np.vstack([WALL, point]), contact=0.0)
    with pytest.warns(CollidingEndWarning, match="goal"):
        plan = planner.plan(START, GOAL, obstacles=scene, refine_steps=0)
    assert not bool(plan.collision_free)


def test_only_the_points_near_the_end_are_dropped(planner):
    point, c, _ = _hand(planner, START, -0.006)
    body = planner.body.double()
    centres, radii = body(torch.as_tensor(START)[None])[0].numpy(), body.radii.numpy()
    near = c + np.random.default_rng(0).uniform(-0.08, 0.08, (400, 3))
    gap = np.linalg.norm(near[:, None] - centres[None], axis=2) - radii  # to each sphere's surface
    near = near[(gap > 0.0).all(axis=1)]  # outside the arm: within the contact depth
    scene = Scene.from_points(np.vstack([WALL, point, near]))
    kept, found = ends_in_contact(planner._np_body, scene, np.stack([START, GOAL]))
    assert [c.end for c in found] == ["start"]
    dropped = (gap[(gap > 0.0).all(axis=1)] <= CONTACT_MARGIN + scene.cloud.radius).any(axis=1)
    assert 0 < dropped.sum() < len(dropped)
    assert kept.cloud.num_points == len(WALL) + int((~dropped).sum())
    kb = kernel.KernelBody.of(body)
    d, _ = kernel.clearances(kb, kernel.KernelScene.of(kept), START[None])
    assert d[0] > 0.0  # the start is free among what is left
    # the kept cloud reuses the grid, its dropped points moved out of reach: within the exact reach its
    # distances are those of a cloud built from the points left
    built = PointCloud(kept.cloud.points)
    q = c + np.random.default_rng(1).uniform(-0.1, 0.1, (2000, 3))
    r = np.full(len(q), 0.03)
    a, b = kept.cloud.distance(q, r), built.distance(q, r)
    exact = np.minimum(a, b) < r + 0.01
    assert exact.sum() > 100
    np.testing.assert_allclose(a[exact], b[exact], rtol=0, atol=1e-12)
    assert (a[~exact] >= r[~exact] + 0.01).all() and (b[~exact] >= r[~exact] + 0.01).all()


def test_a_cloud_out_of_reach_leaves_the_scene_alone(planner):
    scene = Scene.from_points(WALL)
    kept, found = ends_in_contact(planner._np_body, scene, np.stack([START, GOAL]))
    assert kept is scene and found == []


def test_a_bad_contact_depth_is_refused():
    for bad in (-0.001, float("nan"), True):
        with pytest.raises(PointCloudError, match="contact"):
            PointCloud(WALL, contact=bad)


def test_the_contact_depth_is_saved_with_the_scene(tmp_path):
    scene = Scene.from_points(WALL, contact=0.002)
    path = scene.save(tmp_path / "cloud.npz")
    assert Scene.load(path).cloud.contact == 0.002
    arrays = scene.arrays()
    arrays["cloud_sizes"] = arrays["cloud_sizes"][:2]  # a file written before the contact depth
    assert Scene.load(write_scene(tmp_path / "two.npz", arrays)).cloud.contact == DEFAULT_CONTACT
    arrays["cloud_sizes"] = np.array([0.01, 0.02, 0.006, 1.0])
    with pytest.raises(DatasetError, match="cloud_sizes"):
        Scene.load(write_scene(tmp_path / "four.npz", arrays))
