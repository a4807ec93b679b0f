"""The compiled kernels held to torch: sphere FK, every kind of primitive's distance on random scenes
(≤ 1e-9 m over more than 10,000 configurations), dense path checks with the verdicts, first
collisions and clearances of check_path, and first_free over candidates; the planner's results on the
committed held-out problems unchanged."""

from pathlib import Path

import numpy as np
import pytest
import torch

from kinlearn import load_robot
from kinlearn.collision import (
    Scene,
    body_obstacle_distance,
    body_spheres,
    check_path,
    self_collision_distance,
)
from kinlearn.collision import kernel as K
from kinlearn.collision.geometry import Box, Cylinder, Sphere, rotation_from_quaternion
from kinlearn.errors import ConfigError, NonFiniteError, ObstacleError, ShapeError

TOL = 1e-9
HELDOUT = Path(__file__).resolve().parents[1] / "benchmarks" / "data" / "obstacle_problems_heldout.npz"


def random_scene(
    rng: np.random.Generator, kinds=("sphere", "box", "cylinder"), n: int = 4, floor=True
) -> Scene:
    lo, hi = [0.2, -0.6, 0.1], [0.8, 0.6, 1.1]
    prims = []
    for _ in range(n):
        kind = kinds[int(rng.integers(len(kinds)))]
        R = rotation_from_quaternion(rng.normal(size=4))
        c = rng.uniform(lo, hi)
        if kind == "sphere":
            prims.append(Sphere(c, rng.uniform(0.03, 0.15)))
        elif kind == "box":
            prims.append(Box(c, rng.uniform(0.02, 0.2, 3), R))
        else:
            prims.append(Cylinder(c, rng.uniform(0.02, 0.12), rng.uniform(0.03, 0.25), R))
    return Scene.from_primitives(prims, floor=rng.uniform(-0.05, 0.2) if floor else None)


@pytest.fixture(scope="module", params=["iiwa14", "panda", "ur5"])
def arm(request):
    robot = load_robot(request.param)
    body = body_spheres(robot).double()
    return robot, body, K.KernelBody(body)


@pytest.mark.parametrize("kinds", [("sphere",), ("box",), ("cylinder",), ("sphere", "box", "cylinder")])
def test_distances_match_torch_on_random_scenes(arm, kinds):
    robot, body, kb = arm
    rng = np.random.default_rng(len(kinds) + robot.dof)
    worst, cases, signs = 0.0, 0, set()
    for s in range(12):
        scene = random_scene(rng, kinds, n=int(rng.integers(1, 8)), floor=bool(s % 2))
        q = robot.sample(1000, torch.Generator().manual_seed(s), dtype=torch.float64)
        d, sc, per = K.clearances(kb, K.KernelScene(scene), q.numpy(), per_sphere=True)
        c = body(q)
        dt, pt = body_obstacle_distance(c, body.radii, scene, per_sphere=True, floor_mask=body.floor_mask)
        st = self_collision_distance(c, body.radii, body.pairs)
        worst = max(
            worst, np.abs(per - pt.numpy()).max(), np.abs(d - dt.numpy()).max(), np.abs(sc - st.numpy()).max()
        )
        cases += q.shape[0]
        signs |= set(np.sign(d).tolist())
    assert cases >= 10_000 and worst <= TOL and {-1.0, 1.0} <= signs
    assert np.abs(K.centres(kb, q.numpy()) - c.numpy()).max() <= TOL


def _random_paths(robot, n: int, knots: int, seed: int, spread: float = 0.6) -> np.ndarray:
    mid = (robot.lower + robot.upper) / 2
    gen = torch.Generator().manual_seed(seed)
    pts = mid + spread * (robot.sample((n, knots), gen, dtype=torch.float64).numpy() - mid)
    return np.ascontiguousarray(pts)


def test_path_checks_match_check_path(arm):
    robot, body, kb = arm
    rng = np.random.default_rng(11)
    frees = []
    for s in range(4):
        scene = random_scene(rng, n=int(rng.integers(1, 6)), floor=bool(s % 2))
        ks = K.KernelScene(scene)
        paths = _random_paths(robot, 16, int(rng.integers(2, 6)), seed=s, spread=0.1 + 0.1 * s)
        ref = check_path(body, torch.from_numpy(paths), scene)
        free, clear, first = K.check_paths(kb, paths, ks)
        assert np.array_equal(free, ref.collision_free.numpy())
        assert np.array_equal(first, ref.first_collision.numpy())
        assert np.abs(clear - ref.clearance.numpy()).max() <= TOL
        fast_free, _, fast_first = K.check_paths(kb, paths, ks, exact=False)  # skips what cannot collide
        assert np.array_equal(fast_free, free) and np.array_equal(fast_first, first)
        order = rng.permutation(len(paths))
        expect = next((int(i) for i in order if free[i]), -1)
        assert K.first_free(kb, paths, ks, order) == expect
        margin = 0.03
        ref_m = check_path(body, torch.from_numpy(paths), scene, margin=margin)
        assert np.array_equal(
            K.check_paths(kb, paths, ks, margin=margin, exact=False)[0], ref_m.collision_free.numpy()
        )
        frees += free.tolist()
    assert 0 < sum(frees) < len(frees)


def test_the_walk_reports_a_colliding_configuration_of_its_grid(arm):
    """The walk's hit (segment, fraction) is a configuration of the dense check's grid that collides (it
    becomes a probe hint for the next candidates: a hint that did not collide would only cost probes,
    but one off the grid would make the probe see what the dense check does not)."""
    robot, _, kb = arm
    rng = np.random.default_rng(5)
    f, n = kb.packed
    hits = 0
    for s in range(3):
        scene = random_scene(rng, n=int(rng.integers(2, 6)))
        ks = K.KernelScene(scene)
        for path in _random_paths(robot, 12, int(rng.integers(2, 6)), seed=20 + s, spread=0.3):
            first, _, frac, itself = K._verdict_packed(path, 0.01, 0.0, f, n, ks.packed)
            if first < 0:
                continue
            hits += 1
            if first == len(path) - 1:  # the final knot
                q = path[-1]
            else:
                steps = np.empty(len(path) - 1)
                K._grid_steps(path, 0.01, kb.lever, steps)
                assert float(frac * steps[first]) == pytest.approx(round(frac * steps[first]), abs=1e-9)
                q = path[first] + frac * (path[first + 1] - path[first])
            d, sc = K.clearances(kb, ks, q[None])
            assert (sc[0] if itself else d[0]) <= 0.0  # the kind of hit it says: against itself or the scene
    assert hits >= 5


def test_the_planners_verdicts_on_the_heldout_problems_are_unchanged():
    """On the committed held-out problems the kernel picks the candidate torch's check_path picks (the
    first collision-free one in the planner's order), as the NumPy check before it did."""
    from kinlearn.data.problem import positions
    from kinlearn.data.problems import ProblemSet
    from kinlearn.models.obstacle_path import scene_primitives
    from kinlearn.planning.planner import Planner

    problems = ProblemSet.load(HELDOUT)
    planner = Planner.default("iiwa14")
    body = planner.body
    kb = K.KernelBody(body)
    found = 0
    for i in range(0, len(problems.start), 30):  # 34 problems of every family
        start, goal, scene = problems.problem(i)
        ef = positions(planner.robot, torch.stack((start, goal)).double().numpy())
        rows, _, floor = (t.numpy() for t in scene_primitives(scene, 1, torch.float64))
        paths, order = planner._proposals(
            start.double().numpy()[None],
            ef[:1],
            goal.double().numpy()[None],
            ef[1:],
            [(rows[0], floor[0])],
            0,
        )
        free = check_path(body, torch.from_numpy(paths[0]), scene, max_travel=0.01).collision_free.numpy()
        expect = next((int(k) for k in order[0] if free[k]), -1)
        assert K.first_free(kb, paths[0], K.KernelScene(scene), order[0], max_travel=0.01) == expect, i
        found += expect >= 0
    assert found > 0


def test_point_distances_match_torch():
    """Points' signed distances to random scenes of every kind (floor included) are torch's, the body
    distance of a zero-radius sphere."""
    from kinlearn.collision import body_obstacle_distance

    rng = np.random.default_rng(5)
    signs = set()
    for s in range(4):
        scene = random_scene(rng, n=int(rng.integers(1, 6)), floor=bool(s % 2))
        points = rng.uniform(-1.0, 1.0, (200, 3))
        _, ref = body_obstacle_distance(
            torch.from_numpy(points)[:, None], torch.zeros(1, dtype=torch.float64), scene, per_sphere=True
        )
        got = K.point_distances(K.KernelScene(scene), points)
        assert np.abs(got - ref[:, 0].numpy()).max() <= TOL
        signs |= set(np.sign(got).tolist())
    assert {-1.0, 1.0} <= signs  # points inside and outside
    with pytest.raises(ShapeError):
        K.point_distances(K.KernelScene(scene), np.zeros((3, 2)))
    with pytest.raises(ObstacleError):
        K.point_distances(scene, np.zeros((3, 3)))
    with pytest.raises(NonFiniteError):
        K.point_distances(K.KernelScene(scene), np.array([[0.0, np.nan, 0.0]]))


def test_every_sphere_at_once_is_each_sphere_alone():
    """The distances of all a body's spheres computed together (the walk's vector loop) are those of each
    sphere computed alone (bounding-ball culling and all), to the bit, floor included."""
    rng = np.random.default_rng(11)
    signs = set()
    for s in range(6):
        ks = K.KernelScene(random_scene(rng, n=int(rng.integers(1, 9)), floor=bool(s % 2)))
        tables, floor = ks.args()
        c = rng.uniform([0.1, -0.7, 0.0], [0.9, 0.7, 1.2], (40, 3))
        radii, on_floor = rng.uniform(0.0, 0.1, 40), rng.random(40) < 0.7
        out = np.empty(40)
        K._spheres_scene(c, radii, on_floor, tables, floor, np.empty((3, 40)), out)
        alone = [K._sphere_scene(*c[m], radii[m], on_floor[m], tables, floor) for m in range(40)]
        assert np.array_equal(out, alone)
        signs |= set(np.sign(out).tolist())
    assert {-1.0, 1.0} <= signs  # spheres inside and outside


def test_typed_errors():
    robot = load_robot("iiwa14")
    kb = K.KernelBody(body_spheres(robot).double())
    ks = K.KernelScene(Scene.from_spheres([[0.5, 0.0, 0.5, 0.1]]))
    path = np.zeros((1, 3, 7))
    with pytest.raises(ShapeError):
        K.check_paths(kb, np.zeros((1, 3, 6)), ks)
    with pytest.raises(NonFiniteError):
        K.check_paths(kb, np.full((1, 3, 7), np.nan), ks)
    with pytest.raises(ConfigError, match="max_travel"):
        K.check_paths(kb, path, ks, max_travel=0.0)
    with pytest.raises(ConfigError, match="distinct"):
        K.first_free(kb, path, ks, order=[0, 0])
    with pytest.raises(ObstacleError, match="one scene"):
        K.KernelScene(Scene.stack([Scene(), Scene()]))
    with pytest.raises(ObstacleError, match="KernelScene"):
        K.check_paths(kb, path, Scene())
    assert K.first_free(kb, path, ks, order=[]) == -1


def test_rrt_checker_compiled_answers_as_torch():
    from kinlearn.collision.ompl import RrtChecker

    robot = load_robot("iiwa14")
    body = body_spheres(robot).double()
    rng = np.random.default_rng(3)
    scene = random_scene(rng, n=6)
    fast, slow = RrtChecker(body, scene), RrtChecker(body, scene, compiled=False)
    q = robot.sample(60, torch.Generator().manual_seed(2), dtype=torch.float64).numpy()
    states = [fast.state_valid(x) for x in q]
    assert states == [slow.state_valid(x) for x in q] and 0 < sum(states) < len(states)
    far = q[1:]
    near = q[:-1] + 0.2 * (far - q[:-1])  # short and long motions
    ends = [*zip(q[:-1], near, strict=True), *zip(q[:-1], far, strict=True)]
    motions = [fast.motion_valid(a, b) for a, b in ends]
    ref = [slow.motion_valid(a, b) for a, b in ends]
    assert motions == ref and 0 < sum(motions) < len(motions)


def test_near_pairs_finds_exactly_the_pairs_within_the_cut():
    """The broad phase returns every (configuration, pair) closer than the cut, and nothing else."""
    from kinlearn import load_robot
    from kinlearn.collision import body_spheres

    body = body_spheres(load_robot("panda")).double()
    q = load_robot("panda").sample(40, torch.Generator().manual_seed(3), dtype=torch.float64)
    c = body(q)
    i, j = body.pairs[:, 0], body.pairs[:, 1]
    gap = (c[:, i] - c[:, j]).norm(dim=-1) - body.radii[i] - body.radii[j]
    for cut in (0.0, 0.03):
        b, k = K.near_pairs(c.numpy(), body.radii.numpy(), body.pairs.numpy(), cut)
        want = (gap < cut).nonzero(as_tuple=True)
        assert np.array_equal(b, want[0].numpy()) and np.array_equal(k, want[1].numpy())
    assert len(K.near_pairs(c.numpy(), body.radii.numpy(), body.pairs.numpy(), 0.03)[0]) > 0
    with pytest.raises(ShapeError):
        K.near_pairs(c.numpy()[0], body.radii.numpy(), body.pairs.numpy(), 0.03)


@pytest.mark.parametrize("margin", [0.0, 0.03])
def test_the_probes_proof_of_a_clear_scene_answers_as_every_sub_step(arm, margin):
    """The probe proves a path clear of the scene from the windows its configurations' clearances cover
    (link balls, then spheres) and fills the gaps; the walk then looks at the body against itself alone.
    On many paths through cluttered scenes, near misses among them (a share free, a share not), the
    verdict of each path alone and of first_free over them is that of checking every sub-step."""
    robot, body, kb = arm
    rng = np.random.default_rng(5)
    counts = [0, 0]
    for s in range(6):
        scene = random_scene(rng, n=int(rng.integers(2, 6)), floor=bool(s % 2))
        ks = K.KernelScene(scene)
        knots = int(rng.integers(2, 8))
        paths = np.concatenate([_random_paths(robot, 24, knots, seed=40 + s, spread=w) for w in (0.1, 0.4)])
        ref = check_path(body, torch.from_numpy(paths), scene, margin=margin).collision_free.numpy()
        alone = [bool(K._free_packed(p, 0.01, margin, *kb.packed, ks.packed)) for p in paths]
        assert alone == ref.tolist(), s
        order = rng.permutation(len(paths))
        expect = next((int(i) for i in order if ref[i]), -1)
        assert K.first_free(kb, paths, ks, order, margin=margin) == expect
        counts[0] += int(ref.sum())
        counts[1] += len(ref)
    assert 0.05 * counts[1] < counts[0] < 0.95 * counts[1]


def test_verdicts_where_self_collision_decides(arm):
    """Long motions across the whole joint range with no obstacle (then with one): the verdict, which
    spends each self-collision pair's distance by its own bound, answers as check_path does, for paths
    that collide with themselves and paths that do not."""
    robot, body, kb = arm
    counts = []
    for s, scene in enumerate((Scene(), Scene.from_spheres([[0.45, 0.1, 0.5, 0.1]], floor=0.0))):
        paths = np.concatenate(
            [_random_paths(robot, 24, 2 + s, seed=20 + s, spread=w) for w in (1.0, 0.4)]
        )  # whole-range motions, then shorter ones
        ks = K.KernelScene(scene)
        ref = check_path(body, torch.from_numpy(paths), scene)
        free, _, first = K.check_paths(kb, paths, ks, exact=False)
        assert np.array_equal(free, ref.collision_free.numpy())
        assert np.array_equal(first, ref.first_collision.numpy())
        counts.append((int(free.sum()), len(free)))
        verdicts = [bool(K._free_packed(p, 0.01, 0.0, *kb.packed, ks.packed)) for p in paths]
        assert verdicts == free.tolist()  # probed first, the same answers
    assert 0 < sum(f for f, _ in counts) < sum(n for _, n in counts)
    if robot.name != "iiwa14":  # its sparse set leaves out the pairs that can meet: rarely self-colliding
        assert counts[0][0] < counts[0][1]  # with no obstacle, some paths collide with themselves


def test_first_free_where_candidates_fold_onto_themselves(arm):
    """Candidates of several knots, alike (base paths and small variations, as a network proposes), many
    colliding with themselves where no obstacle is: the probe looks for self-collision at the hints and
    the knots, and the first free one is the one check_path picks, whatever the order."""
    robot, body, kb = arm
    rng = np.random.default_rng(5)
    picked, colliding = [], []
    for s, scene in enumerate((Scene(), Scene.from_spheres([[0.45, 0.1, 0.5, 0.1]], floor=0.0))):
        base = np.concatenate(  # whole-range paths (most fold onto themselves), then shorter ones
            [
                _random_paths(robot, 3, 6, seed=40 + s, spread=1.0),
                _random_paths(robot, 3, 6, seed=50 + s, spread=0.1),
            ]
        )
        noise = rng.normal(0.0, 0.05, (24, 6, robot.dof))
        paths = np.ascontiguousarray(np.clip(np.repeat(base, 4, axis=0) + noise, robot.lower, robot.upper))
        ks = K.KernelScene(scene)
        free = check_path(body, torch.from_numpy(paths), scene).collision_free.numpy()
        colliding.append(int((~free).sum()))
        for _ in range(4):
            order = rng.permutation(len(paths))
            expect = next((int(i) for i in order if free[i]), -1)
            assert K.first_free(kb, paths, ks, order) == expect
            picked.append(expect)
    assert sum(colliding) > 0 and max(picked) >= 0
    if robot.name != "iiwa14":  # its sparse set leaves out the pairs that can meet
        assert colliding[0] > 0  # with no obstacle: against themselves


def _pair_gaps(body, q: torch.Tensor) -> torch.Tensor:
    """``(N, P)``: each self-collision pair's distance at configurations ``q``, by torch."""
    c, p = body(q), body.pairs
    return (c[:, p[:, 0]] - c[:, p[:, 1]]).norm(dim=-1) - body.radii[p[:, 0]] - body.radii[p[:, 1]]


def test_pairs_proven_apart_never_touch_within_the_limits(arm):
    """The pairs the verdict leaves out (proven apart by branch and bound) keep a positive distance at
    configurations the proof never saw; every pair seen touching is kept."""
    robot, body, kb = arm
    apart = kb.apart
    assert 0 < apart.sum() < len(apart)
    q = robot.sample(20_000, torch.Generator().manual_seed(7), dtype=torch.float64)
    with torch.no_grad():
        gap = _pair_gaps(body, q).numpy()
    assert gap[:, apart].min() > 0.0
    assert not (apart & (gap <= 0.0).any(0)).any()
    assert K.proven_apart(kb) is apart or np.array_equal(K.proven_apart(kb), apart)  # one proof per body


def test_verdicts_without_the_pairs_proven_apart_are_those_with_every_pair(arm):
    """Whole-range motions in the limits, many colliding with themselves: the packing without the pairs
    proven apart gives every path the same verdict and the same first colliding configuration."""
    robot, _, kb = arm
    paths = [p for k in range(4) for p in _random_paths(robot, 60, 2 + k % 3, seed=40 + k, spread=1.0)]
    s = K.KernelScene(Scene()).packed  # self-collision alone decides
    full = [K._verdict_packed(p, 0.01, 0.0, *kb.packed, s) for p in paths]
    cut = [K._verdict_packed(p, 0.01, 0.0, *kb.packed_within, s) for p in paths]
    assert [(f, x, t) for f, _, x, t in full] == [(f, x, t) for f, _, x, t in cut]  # (only the work differs)
    assert sum(e for _, e, _, _ in cut) <= sum(e for _, e, _, _ in full)
    assert kb.packing_of(paths[0]) is kb.packed_within
    hits = sum(f[0] >= 0 for f in full)
    assert hits < len(full) and (hits > 0 or robot.name == "iiwa14")  # its sparse set: rarely self-colliding
    assert all(itself for f, _, _, itself in full if f >= 0)  # no scene: every hit is the body against itself


def test_a_path_beyond_the_limits_is_checked_with_every_pair():
    """Where a pair proven apart within the limits does touch (a configuration beyond them), the dense
    check still finds the self-collision: a path with a knot outside the proof's box gets every pair."""
    robot = load_robot("panda")
    body = body_spheres(robot).double()
    kb = K.KernelBody(body)
    q = torch.rand(20_000, robot.dof, generator=torch.Generator().manual_seed(3), dtype=torch.float64) * 2 - 1
    q = q * np.pi
    with torch.no_grad():
        touch = _pair_gaps(body, q) <= 0.0
    apart = torch.as_tensor(kb.apart.copy())
    only = touch[:, apart].any(1) & ~touch[:, ~apart].any(1)  # only pairs proven apart (in the limits) touch
    assert only.any()
    qo = q[only][0].numpy()
    lo, hi = kb.box
    assert ((qo < lo) | (qo > hi)).any()
    path = np.ascontiguousarray(np.stack([qo, qo])[None])
    ks = K.KernelScene(Scene())
    assert kb.packing_of(path) is kb.packed
    assert not check_path(body, torch.from_numpy(path), Scene()).collision_free.item()
    assert K.first_free(kb, path, ks) == -1
    assert not K.check_paths(kb, path, ks, exact=False)[0][0]
    assert (
        K._verdict_packed(path[0], 0.01, 0.0, *kb.packed_within, ks.packed)[0] < 0
    )  # what pruning would say
    assert kb.packing_of(np.stack([robot.lower, robot.upper])) is kb.packed_within
    assert kb.packing_of(np.stack([robot.lower - 0.1, robot.upper])) is kb.packed


def test_a_motion_whose_end_state_collides_is_not_free(arm):
    """The sampler's motion check looks at the last knot first: a motion from a free state to one that
    collides (an obstacle put on its last sphere there) is refused, as check_path refuses it."""
    robot, body, kb = arm
    q0 = (robot.lower + robot.upper) / 2
    q1 = q0 + 0.3 * (robot.upper - robot.lower) / 2
    tip = K.centres(kb, q1[None])[0, -1]  # the last sphere's centre there
    scene = Scene.from_spheres([[*tip, 0.03]], floor=None)
    ks = K.KernelScene(scene)
    d, sc = K.clearances(kb, ks, np.stack([q0, q1]))
    assert d[0] > 0 and sc[0] > 0 and d[1] <= 0  # free start, colliding end
    path = np.ascontiguousarray(np.stack([q0, q1]))
    assert not check_path(body, torch.from_numpy(path[None]), scene).collision_free.item()
    assert not K._free_packed(path, 0.01, 0.0, *kb.packed_within, ks.packed)
    assert not K._free_packed(path, 0.01, 0.0, *kb.packed, ks.packed)


def test_kernel_scene_is_one_buffer_with_each_primitive_s_bounding_radius():
    """A packed scene's tables are views of its one buffer ``[rows and columns per kind…, has floor, height,
    tables…]``, each box and cylinder followed by the radius of its bounding ball (the kernels cull by it)."""
    scene = random_scene(np.random.default_rng(5), n=9)
    ks = K.KernelScene(scene)
    tables = {k.table: t.numpy() for k, t, _ in scene.tables(live=True)}
    k, b, c = (len(tables[t]) for t in ("spheres", "boxes", "cylinders"))
    assert k and b and c
    shapes = [s for t in ks.tables for s in t.shape]
    S = len(ks.tables)
    np.testing.assert_array_equal(ks.packed[: 2 * S + 2], [*shapes, 1.0, float(scene.floor)])
    assert shapes[:6] == [k, 4, b, 16, c, 15]
    np.testing.assert_array_equal(ks.spheres, tables["spheres"])
    np.testing.assert_array_equal(ks.boxes[:, :-1], tables["boxes"])
    np.testing.assert_array_equal(ks.cylinders[:, :-1], tables["cylinders"])
    np.testing.assert_allclose(ks.boxes[:, -1], np.linalg.norm(tables["boxes"][:, 3:6], axis=1), rtol=1e-15)
    np.testing.assert_allclose(
        ks.cylinders[:, -1], np.hypot(tables["cylinders"][:, 3], tables["cylinders"][:, 4])
    )
    for t in (ks.spheres, ks.boxes, ks.cylinders, ks.floor):
        assert np.shares_memory(t, ks.packed)
    bare = K.KernelScene(Scene.from_spheres([[0.5, 0.0, 0.5, 0.25]], floor=None))
    head = [1, 4] + [s for t in bare.tables[1:] for s in t.shape] + [0, 0]
    np.testing.assert_array_equal(bare.packed, [*head, 0.5, 0.0, 0.5, 0.25])


def test_free_depths_refuse_nan_and_count_every_via_in_an_empty_scene():
    robot = load_robot("panda")
    kb = K.KernelBody(body_spheres(robot))
    far = K.KernelScene(Scene.from_spheres([[5.0, 5.0, 5.0, 0.1]], floor=None))
    theta = (robot.lower + robot.upper) / 2
    vias = theta + np.linspace(0.02, 0.1, 3)[None, :, None] * np.ones((4, 1, robot.dof))
    assert K.free_depths(kb, theta, vias, far).tolist() == [3] * 4
    bad = vias.copy()
    bad[2, 1, 0] = np.nan
    with pytest.raises(NonFiniteError):
        K.free_depths(kb, theta, bad, far)
    with pytest.raises(ShapeError):
        K.free_depths(kb, theta[:3], vias, far)
