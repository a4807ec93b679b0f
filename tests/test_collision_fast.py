"""The NumPy path check against torch's check_path: the same free flags, first colliding segments and
clearances on benchmark problems (straight and perturbed paths), self-collisions, every kind of scene,
touching contacts; first_free against its definition; the same sub-step counts; typed errors."""

from pathlib import Path

import numpy as np
import pytest
import torch

from kinlearn import load_robot
from kinlearn.collision import (
    BodySpheres,
    NumpyBody,
    NumpyScene,
    Scene,
    body_spheres,
    check_path,
    check_paths,
    fast,
    first_free,
    segment_steps,
)
from kinlearn.collision.problems import ProblemSet
from kinlearn.errors import ConfigError, DTypeError, NonFiniteError, ObstacleError, ShapeError

HELDOUT = Path(__file__).resolve().parents[1] / "benchmarks" / "data" / "obstacle_problems_heldout.npz"
F64 = torch.float64


@pytest.fixture(scope="module")
def robot():
    return load_robot("iiwa14")


@pytest.fixture(scope="module")
def body(robot):
    return body_spheres(robot).double()


@pytest.fixture(scope="module")
def nbody(body):
    return NumpyBody(body)


@pytest.fixture(scope="module")
def problems():
    """Every 10th held-out problem: 102 problems of all three families."""
    return ProblemSet.load(HELDOUT)[list(range(0, 1020, 10))]


def _knots(start, goal, n=11):
    f = torch.linspace(0, 1, n, dtype=F64)[:, None]
    return start[..., None, :] + f * (goal - start)[..., None, :]


def _row(ref, i):
    """Entry ``i`` (an index or slice) of every field of a PathCheck."""
    return type(ref)(*(getattr(ref, f)[i] for f in ref.__dataclass_fields__))


def _assert_agree(nbody, paths, ref, scene, **kw):
    """check_paths on each (paths, scene) equals check_path's result ``ref`` for it."""
    free, clearance, first = check_paths(nbody, paths.numpy(), scene, **kw)
    assert np.array_equal(free, ref.collision_free.numpy())
    assert np.array_equal(first, ref.first_collision.numpy())
    rc = ref.clearance.numpy()
    assert np.array_equal(np.isinf(clearance), np.isinf(rc))
    fin = np.isfinite(rc)
    np.testing.assert_allclose(clearance[fin], rc[fin], rtol=1e-9, atol=0)
    return free


def test_centres_match_the_torch_body(robot):
    q = robot.sample(300, torch.Generator().manual_seed(0), dtype=F64)
    for dense in (False, True):
        for base in (True, False):
            b = body_spheres(robot, dense=dense, base=base).double()
            nb = NumpyBody(b)
            np.testing.assert_allclose(nb.centres(q.numpy()), b(q).numpy(), rtol=0, atol=1e-13)
            np.testing.assert_allclose(nb.centres(q[:1].numpy()), b(q[:1]).numpy(), rtol=0, atol=1e-13)
    assert nb.centres(np.zeros((0, 7))).shape == (0, nb.radii.shape[0], 3)


@pytest.mark.parametrize("name", ["panda", "ur5"])
def test_other_chains_with_made_up_spheres(name):
    """Chains whose fixed rotations are not axis permutations (and a 6-joint arm): centres and checks."""
    r = load_robot(name)
    rng = np.random.default_rng(0)
    link = np.sort(rng.integers(0, r.dof + 1, 14))
    link[-1] = r.dof
    table = np.column_stack([link, rng.normal(0, 0.05, (14, 3)), rng.uniform(0.02, 0.06, 14)])
    pairs = np.array([(a, b) for a in range(14) for b in range(a + 1, 14) if link[b] - link[a] >= 2])
    b = BodySpheres(r, table, pairs).double()
    nb = NumpyBody(b)
    q = r.sample(60, torch.Generator().manual_seed(1), dtype=F64)
    np.testing.assert_allclose(nb.centres(q.numpy()), b(q).numpy(), rtol=0, atol=1e-13)
    paths = q.reshape(20, 3, r.dof)
    scene = Scene(
        torch.tensor([[0.3, 0.2, 0.4, 0.15]], dtype=F64),
        torch.tensor([[0.4, -0.3, 0.2, 0.1, 0.2, 0.2]], dtype=F64),
        floor=0.0,
    )
    ref = check_path(b, paths, scene)
    _assert_agree(nb, paths, ref, NumpyScene.from_scene(scene))


def test_sub_step_counts_are_those_of_segment_steps(body, nbody):
    rng = np.random.default_rng(1)
    joints = rng.standard_normal((3000, 11, 7))
    for max_travel in (0.01, 0.003, 0.05):
        ref = segment_steps(body, torch.as_tensor(joints), max_travel).numpy()
        assert np.array_equal(fast._Paths(nbody, joints, max_travel).steps, ref)


def test_agrees_with_check_path_on_benchmark_straight_lines(body, nbody, problems):
    paths = _knots(problems.start, problems.goal)  # (N, 11, 7)
    ref = check_path(body, paths, problems.scene)
    scenes = problems.scene.unstack()
    free = [
        _assert_agree(nbody, paths[i : i + 1], _row(ref, slice(i, i + 1)), NumpyScene.from_scene(scenes[i]))
        for i in range(len(problems))
    ]
    assert 0.15 < np.mean(free) < 0.85  # both outcomes are exercised


def test_agrees_with_check_path_on_perturbed_paths(body, nbody, problems):
    sub = problems[list(range(0, len(problems), 4))]
    gen = torch.Generator().manual_seed(2)
    line = _knots(sub.start, sub.goal)[:, None]
    bump = torch.sin(torch.pi * torch.linspace(0, 1, 11, dtype=F64))[:, None]
    paths = line + 0.25 * torch.randn(len(sub), 2, 11, 7, generator=gen, dtype=F64) * bump
    ref = check_path(body, paths, sub.scene.unsqueeze(-1))
    free = []
    for i, scene in enumerate(sub.scene.unstack()):
        ns = NumpyScene.from_scene(scene)
        free.append(_assert_agree(nbody, paths[i], _row(ref, i), ns))
        # first_free over a random order is the first path in that order that check_path finds free.
        order = torch.randperm(2, generator=gen).numpy()
        expect = next((int(j) for j in order if bool(ref.collision_free[i, j])), -1)
        assert first_free(nbody, paths[i].numpy(), ns, order) == expect
    free = np.concatenate(free)
    assert 0.1 < free.mean() < 0.9


def test_self_collisions_along_paths(robot, body, nbody):
    q = robot.sample(120, torch.Generator().manual_seed(3), dtype=F64).reshape(40, 3, 7)
    ref = check_path(body, q, Scene())
    assert 0 < int(ref.self_collision.sum()) < 40  # some paths self-collide, some do not
    free = _assert_agree(nbody, q, ref, NumpyScene())
    assert np.isinf(check_paths(nbody, q.numpy(), NumpyScene())[1]).all()  # nothing in the scene
    assert free.sum() == int(ref.collision_free.sum())


@pytest.mark.parametrize("kind", ["spheres", "boxes", "floor", "empty"])
def test_scenes_of_one_kind(body, nbody, problems, kind):
    sub = problems[:10]
    extra = torch.tensor([[0.5, 0.0, 0.4, 0.1]], dtype=F64)
    scenes = {
        "spheres": [Scene(spheres=torch.cat([s.spheres, extra])) for s in sub.scene.unstack()],
        "boxes": [Scene(boxes=s.boxes) for s in sub.scene.unstack()],
        "floor": [Scene(floor=torch.tensor(0.2, dtype=F64))] * 10,
        "empty": [Scene(spheres=torch.zeros(0, 4, dtype=F64))] * 10,
    }[kind]
    gen = torch.Generator().manual_seed(4)
    paths = _knots(sub.start, sub.goal)[:, None] + 0.3 * torch.randn(10, 2, 11, 7, generator=gen, dtype=F64)
    stacked = Scene.stack(scenes).unsqueeze(-1)
    for margin in (0.0, 0.02):
        ref = check_path(body, paths, stacked, margin=margin)
        for i, scene in enumerate(scenes):
            _assert_agree(nbody, paths[i], _row(ref, i), NumpyScene.from_scene(scene), margin=margin)


def test_touching_counts_as_a_collision(nbody):
    down = np.array([[0.0, 1.9, 0.0, 0.3, 0.0, 1.5, 0.0]])
    c = nbody.centres(down)[0]
    arm = nbody.link > 0
    lowest = float((c[arm, 2] - nbody.radii[arm]).min())  # the arm's lowest point (z − r exactly)
    path = np.repeat(down[None], 3, axis=1)
    assert not check_paths(nbody, path, NumpyScene(floor=lowest))[0][0]
    assert check_paths(nbody, path, NumpyScene(floor=np.nextafter(lowest, -1.0)))[0][0]


def test_contact_with_a_box_agrees_with_check_path(body, nbody):
    down = torch.tensor([[0.0, 1.9, 0.0, 0.3, 0.0, 1.5, 0.0]], dtype=F64)
    w, r = body(down)[0, -1], float(body.radii[-1])
    path = down.expand(3, 7)[None]
    for gap in (-1e-9, 0.0, 1e-12, 1e-9):  # a box whose top face is `gap` below the wrist sphere
        box = torch.tensor([[w[0], w[1], w[2] - r - 0.1 - gap, 0.1, 0.1, 0.1]], dtype=F64)
        ref = check_path(body, path, Scene(boxes=box))
        _assert_agree(nbody, path, ref, NumpyScene(boxes=box.numpy()))
        if gap:
            assert bool(ref.collision_free) == (gap > 0)


def test_first_free_follows_the_definition(body, nbody, problems):
    i = int(np.flatnonzero(problems.hard.numpy())[0])  # a problem whose straight line collides
    start, goal, scene = problems.problem(i)
    gen = torch.Generator().manual_seed(5)
    line = _knots(start, goal)
    paths = torch.stack(
        [line, *(line + 0.15 * torch.randn(11, 7, generator=gen, dtype=F64) for _ in range(7))]
    )
    paths[:, 0], paths[:, -1] = start, goal
    ref = check_path(body, paths, scene).collision_free.numpy()
    ns = NumpyScene.from_scene(scene)
    assert not ref[0]
    for order in (None, [0], [3, 1, 2], np.arange(8)[::-1], [0, 7]):
        idx = np.arange(8) if order is None else np.asarray(order)
        expect = next((int(j) for j in idx if ref[j]), -1)
        assert first_free(nbody, paths.numpy(), ns, order) == expect
    assert first_free(nbody, paths.numpy(), ns, []) == -1
    # A scene that swallows the fixed base spheres: nothing is free.
    assert first_free(nbody, paths.numpy(), NumpyScene(spheres=[[0.0, 0.0, 0.05, 0.2]])) == -1


def test_far_fewer_configurations_are_evaluated_than_checked(body, nbody, problems, monkeypatch):
    seen = []
    fk = NumpyBody._fk

    def counting(self, q):
        seen.append(q.shape[0])
        return fk(self, q)

    monkeypatch.setattr(NumpyBody, "_fk", counting)
    paths = _knots(problems.start[:20], problems.goal[:20])
    checked = int(check_path(body, paths, problems.scene[:20]).checked.sum())
    for i, s in enumerate(problems.scene[:20].unstack()):
        check_paths(nbody, paths[i : i + 1].numpy(), NumpyScene.from_scene(s))
    assert sum(seen) < checked / 3


def test_edge_cases(body, nbody, problems):
    start, goal, scene = problems.problem(0)
    ns = NumpyScene.from_scene(scene)
    empty = check_paths(nbody, np.zeros((0, 11, 7)), ns)
    assert [a.shape for a in empty] == [(0,), (0,), (0,)]
    single = _knots(start, goal)[::5][:, None]  # three one-knot paths
    _assert_agree(nbody, single, check_path(body, single, scene), ns)
    assert first_free(nbody, np.zeros((0, 11, 7)), ns) == -1


def test_bad_inputs_raise_typed_errors(nbody, problems):
    start, goal, scene = problems.problem(0)
    ns = NumpyScene.from_scene(scene)
    path = _knots(start, goal)[None].numpy()
    with pytest.raises(ShapeError):
        check_paths(nbody, path[..., :6], ns)
    with pytest.raises(ShapeError):
        check_paths(nbody, path[0], ns)
    with pytest.raises(NonFiniteError):
        check_paths(nbody, path * np.nan, ns)
    with pytest.raises(NonFiniteError):
        first_free(nbody, np.where(np.arange(7) == 3, np.inf, path), ns)
    with pytest.raises(DTypeError):
        check_paths(nbody, path.astype(np.int64), ns)
    with pytest.raises(ConfigError, match="max_travel"):
        check_paths(nbody, path, ns, max_travel=0.0)
    with pytest.raises(ConfigError, match="margin"):
        check_paths(nbody, path, ns, margin=float("nan"))
    with pytest.raises(ConfigError, match="NumpyBody"):
        check_paths(body_spheres(load_robot("iiwa14")), path, ns)
    with pytest.raises(ObstacleError, match="NumpyScene"):
        check_paths(nbody, path, scene)
    with pytest.raises(ConfigError, match="order"):
        first_free(nbody, path, ns, [1])
    with pytest.raises(ConfigError, match="order"):
        first_free(nbody, np.repeat(path, 2, axis=0), ns, [0, 0])
    with pytest.raises(ShapeError):
        nbody.centres(np.zeros(7))


def test_numpy_scene_from_arrays_and_scenes(problems):
    with pytest.raises(ObstacleError):
        NumpyScene(spheres=[[0.0, 0.0, 0.0]])
    with pytest.raises(ObstacleError):
        NumpyScene(boxes=[[0.0, 0.0, 0.0, 0.1, -0.1, 0.1]])
    with pytest.raises(ObstacleError):
        NumpyScene(spheres=[[0.0, np.nan, 0.0, 0.1]])
    with pytest.raises(ObstacleError):
        NumpyScene(floor=float("inf"))
    with pytest.raises(ObstacleError, match="batch"):
        NumpyScene.from_scene(problems.scene)
    # Padding of a stacked scene is dropped.
    i = int(np.argmin(problems.scene.box_mask.sum(-1).numpy()))
    ns = NumpyScene.from_scene(problems.scene[i])
    assert ns.num_boxes == int(problems.scene.box_mask[i].sum()) < problems.scene.num_boxes
    assert ns.floor == float(problems.scene.floor[i])
