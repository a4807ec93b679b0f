"""The executed motion of a plan among obstacles is what was checked: verified timing and its repairs, on
the real iiwa14 body, the compiled kernels and the torch reference check."""

import itertools

import numpy as np
import pytest
import torch

import kinlearn
from kinlearn.collision import Scene, body_spheres, kernel
from kinlearn.collision.check import clearances
from kinlearn.errors import ConfigError, ShapeError, UnsafeTrajectoryError
from kinlearn.planning.plan import CHECK_TRAVEL, executed_check
from kinlearn.planning.timing import time_parameterize

RTOL = 1e-5


@pytest.fixture(scope="module")
def iiwa():
    return kinlearn.load_robot("iiwa14")


@pytest.fixture(scope="module")
def ibody(iiwa):
    return body_spheres(iiwa).double()


def _corner(iiwa) -> np.ndarray:
    """An L-shaped joint path: joint 2 out, then joint 1 across (a sharp corner at the middle)."""
    a = np.zeros(iiwa.dof)
    a[1], a[3] = 0.3, -1.2
    b = a.copy()
    b[1] += 0.9
    c = b.copy()
    c[0] += 1.4
    return np.stack([a, b, c])


def _dense(path: np.ndarray, step: float = 0.002) -> np.ndarray:
    out = [path[:1]]
    for a, b in itertools.pairwise(path):
        m = max(1, int(np.ceil(np.abs(b - a).max() / step)))
        out.append(a + (np.arange(1, m + 1)[:, None] / m) * (b - a))
    return np.concatenate(out)


def _ball_on_cut(iiwa, ibody, path: np.ndarray) -> Scene:
    """A ball that the corner-cutting spline's motion passes through and the polyline's does not: at the
    body sphere that strays farthest from where the polyline puts the spheres, sized to clear the
    polyline's every configuration by 5 mm."""
    plain = time_parameterize(iiwa, path)
    poly = ibody(torch.from_numpy(_dense(path)), validate=False).numpy()  # (P, M, 3)
    cut = ibody(torch.tensor(plain.q), validate=False).numpy()  # (K, M, 3)
    # per sample and sphere: the distance to the nearest polyline sphere centre (sample by sample)
    flat = poly.reshape(-1, 3)
    far = np.stack([np.linalg.norm(c[:, None, :] - flat[None], axis=-1).min(axis=1) for c in cut])
    k, m = np.unravel_index(int(np.argmax(far)), far.shape)
    centre = cut[k, m]
    radii = ibody.radii.numpy()
    gap = (np.linalg.norm(poly - centre, axis=-1) - radii).min()
    assert gap > 0.01, "the spline does not stray from the polyline far enough for this test"
    return Scene.from_spheres([[*centre.tolist(), gap - 0.005]], floor=None)


def _collides(ibody, q: np.ndarray, scene: Scene) -> bool:
    d, s = clearances(ibody, torch.from_numpy(_dense(q)), scene.to(torch.float64), validate=False)
    return bool(((d <= 0) | (s <= 0)).any())


def test_a_spline_that_cuts_a_corner_is_caught_and_repaired(iiwa, ibody):
    path = _corner(iiwa)
    scene = _ball_on_cut(iiwa, ibody, path)
    # the polyline itself is free under the dense check; the plain spline's motion is not
    free, _, _ = kernel.check_paths(kernel.KernelBody.of(ibody), path[None], kernel.KernelScene.of(scene))
    assert free[0]
    plain = time_parameterize(iiwa, path)
    assert _collides(ibody, plain.q, scene) and not plain.verified
    verify = executed_check(ibody, scene)
    assert verify(plain.q).any()
    tr = time_parameterize(iiwa, path, verify=verify)
    assert tr.verified
    assert not verify(tr.q).any()
    assert not _collides(ibody, tr.q, scene)  # the torch reference agrees, densified to 2 mrad
    # still executable: at rest at both ends, at the start and the goal, within every limit
    np.testing.assert_allclose(tr.qd[[0, -1]], 0.0, atol=1e-6)
    np.testing.assert_array_equal(tr.q[-1], path[-1])
    np.testing.assert_allclose(tr.q[0], path[0], atol=1e-12)
    assert (np.abs(tr.qd) / tr.velocity_limits).max() <= 1 + RTOL
    assert (np.abs(tr.qdd) / tr.acceleration_limits).max() <= 1 + RTOL
    assert np.all(tr.q >= iiwa.lower) and np.all(tr.q <= iiwa.upper)
    assert np.all(np.diff(tr.waypoint_times) >= 0) and tr.waypoint_times[-1] == pytest.approx(tr.duration)
    # the repair costs time: at least the plain motion's, at most the polyline's with a rest at its corner
    straight = time_parameterize(iiwa, path[:2]).duration + time_parameterize(iiwa, path[1:]).duration
    assert plain.duration <= tr.duration <= straight + 1e-9


def test_a_path_that_itself_collides_cannot_be_timed_as_safe(iiwa, ibody):
    path = _corner(iiwa)
    body = ibody(torch.from_numpy(path[1]), validate=False).numpy()  # the corner's own configuration
    scene = Scene.from_spheres([[*body[-1].tolist(), 0.02]], floor=None)
    with pytest.raises(UnsafeTrajectoryError, match="path itself collides"):
        time_parameterize(iiwa, path, verify=executed_check(ibody, scene))
    time_parameterize(iiwa, path)  # unverified, it times (nothing was asked of it)


def test_executed_check_refuses_what_it_cannot_check(ibody):
    scene = Scene.from_spheres([[1.0, 1.0, 1.0, 0.1]], floor=None)
    with pytest.raises(ConfigError, match="body"):
        executed_check(None, scene)
    with pytest.raises(ShapeError, match="one scene"):
        executed_check(ibody, scene.expand(2))


def test_a_plan_among_obstacles_keeps_its_scene_and_body_and_times_clean(iiwa):
    start = torch.tensor([-1.2, 0.9, 0.5, -1.6, 0.3, 1.2, -2.0], dtype=torch.float64)
    goal = torch.tensor([1.5, -0.4, -0.8, 1.1, -1.9, -0.6, 2.4], dtype=torch.float64)
    ball = Scene.from_spheres([[0.58, -0.11, 1.03, 0.12]], floor=None)
    plan = kinlearn.plan(start, goal, obstacles=ball)
    assert plan.success and plan.scene is ball and plan.body is not None
    tr = plan.timed()
    assert tr.verified and not executed_check(plan.body, ball)(tr.q).any()
    batch = kinlearn.plan(torch.stack([start, start]), torch.stack([goal, goal]), obstacles=ball)
    assert torch.equal(batch[1].scene.spheres, ball.spheres.double())  # the problem's float64 copy
    assert batch[1].timed().verified
    free = kinlearn.plan(start, goal)
    assert free.scene is None and not free.timed().verified


def test_the_iiwa14s_plans_of_held_out_scene_problems_all_time_and_recheck_clean():
    """A few held-out problems of the scene families (spread over the set): every successful plan times,
    and its executed samples are free under the torch reference check densified to 2 mrad."""
    from pathlib import Path

    from kinlearn.data.problems import ProblemSet

    data = Path(__file__).resolve().parents[1] / "benchmarks" / "data" / "scene_problems_iiwa14.npz"
    problems = ProblemSet.load(data, robot="iiwa14")
    pick = np.linspace(0, len(problems) - 1, 6).astype(int)
    robot = kinlearn.load_robot("iiwa14")
    body = problems.body(robot).double()
    planner = kinlearn.Planner.load(kinlearn.planning.planner.DEFAULT_CHECKPOINTS / "iiwa14", body=body)
    solved = 0
    for i in pick:
        start, goal, scene = problems.problem(int(i))
        plan = planner.plan(start, goal, obstacles=scene, refine_steps=0)
        if not bool(plan.success):
            continue
        solved += 1
        tr = plan.timed()
        assert tr.verified
        assert not _collides(body, tr.q, scene)
    assert solved >= 4


def test_executed_check_travel_is_the_plans():
    assert CHECK_TRAVEL == 0.01
