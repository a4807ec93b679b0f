"""The compiled RRT-Connect: paths free by the torch dense check (an independent implementation of the
rule), from the start to the goal inside the limits; reproducible by seed whatever the rounds; ends
that collide refused."""

import numpy as np
import pytest
import torch

from kinlearn import load_robot
from kinlearn.collision import Scene, body_spheres, check_path
from kinlearn.collision import kernel as K
from kinlearn.collision.geometry import Box, Cylinder
from kinlearn.collision.rrt import RrtConnect
from kinlearn.errors import ConfigError, ShapeError


@pytest.fixture(scope="module", params=["iiwa14", "panda"])
def wall_problem(request):
    """A wall across the arm's front between two configurations the straight joint line joins through it."""
    robot = load_robot(request.param)
    body = body_spheres(robot).double()
    start = torch.as_tensor((robot.lower + robot.upper) / 2)
    start[0], start[1] = -0.9, 0.6
    goal = start.clone()
    goal[0] = 0.9
    line = torch.stack([start, goal])
    kin = __import__("kinlearn").kinematics(robot, "fast")
    mid = kin.position(((start + goal) / 2).clone(), validate=False)
    c, s = np.cos(0.4), np.sin(0.4)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    scene = Scene.from_primitives(
        [Box(tuple(mid.tolist()), (0.08, 0.08, 0.08), R), Cylinder((-0.5, -0.6, 0.9), 0.05, 0.2)],
        floor=0.0,
    )
    assert not bool(check_path(body, line, scene).collision_free), "the straight joint line must be blocked"
    assert bool(check_path(body, start[None], scene).collision_free)
    assert bool(check_path(body, goal[None], scene).collision_free)
    return robot, body, scene, start.numpy(), goal.numpy()


def _solve(rrt: RrtConnect, rounds: int = 400, iterations: int = 25):
    """Run ``rrt`` for up to ``rounds`` rounds of ``iterations``: its path, or None."""
    for _ in range(rounds):
        path = rrt.run(iterations)
        if path is not None:
            return path
    return None


def test_finds_a_path_free_by_the_torch_check_and_shortcuts_keep_it_free(wall_problem):
    robot, body, scene, start, goal = wall_problem
    kb, ks = K.KernelBody(body), K.KernelScene(scene)
    rrt = RrtConnect(kb, ks, start, goal, robot.lower, robot.upper, seed=3)
    path = _solve(rrt)
    assert path is not None and rrt.found and rrt.size > 2
    for p in (path, rrt.shortcut(path)):
        assert np.array_equal(p[0], start) and np.array_equal(p[-1], goal)
        assert (p >= robot.lower).all() and (p <= robot.upper).all()
        assert bool(check_path(body, torch.from_numpy(p), scene).collision_free)
    short = rrt.shortcut(path)
    assert short.shape[0] <= path.shape[0]
    assert (
        np.linalg.norm(np.diff(short, axis=0), axis=1).sum()
        <= np.linalg.norm(np.diff(path, axis=0), axis=1).sum()
    )


def _seeded(problem, kb, ks, rounds: int, seed: int, budget: int, **options):
    """RRT-Connect on ``problem`` with ``seed`` and the sampling ``options``, run ``rounds`` iterations at a
    time for up to ``budget``: its path and the iterations it took."""
    robot, _, _, start, goal = problem
    rrt = RrtConnect(kb, ks, start, goal, robot.lower, robot.upper, seed=seed, **options)
    path = _solve(rrt, budget // rounds, rounds)
    assert path is not None, "no path"
    return path, rrt.iterations


def test_same_seed_same_path_whatever_the_rounds(wall_problem):
    kb, ks = K.KernelBody(wall_problem[1]), K.KernelScene(wall_problem[2])

    def solve(rounds, seed):
        return _seeded(wall_problem, kb, ks, rounds, seed, 10_000)

    a, na = solve(1, 5)
    b, nb = solve(1, 5)
    c, _ = solve(7, 5)
    assert np.array_equal(a, b) and np.array_equal(a, c) and na == nb
    assert not np.array_equal(a, solve(1, 6)[0])


def test_colliding_ends_and_bad_input_are_refused(wall_problem):
    robot, body, scene, start, goal = wall_problem
    kb = K.KernelBody(body)
    inside = K.KernelScene(Scene.from_spheres([[0.0, 0.0, 0.3, 0.5]], floor=0.0))  # the base inside a ball
    rrt = RrtConnect(kb, inside, start, goal, robot.lower, robot.upper)
    assert not rrt.valid_ends and rrt.exhausted and rrt.run(100) is None
    same = RrtConnect(kb, K.KernelScene(scene), start, start, robot.lower, robot.upper)
    assert np.array_equal(same.run(1), np.stack([start, start]))
    with pytest.raises(ShapeError, match="start"):
        RrtConnect(kb, K.KernelScene(scene), start[:-1], goal, robot.lower, robot.upper)
    with pytest.raises(ConfigError, match="step"):
        RrtConnect(kb, K.KernelScene(scene), start, goal, robot.lower, robot.upper, step=-1.0)
    with pytest.raises(ConfigError, match="local_step"):
        RrtConnect(kb, K.KernelScene(scene), start, goal, robot.lower, robot.upper, local_step=float("nan"))


def test_the_default_step_is_ompls_range_with_each_joint_counted_at_most_one_turn(wall_problem):
    """The default extension is 0.2 of the joint box's diagonal (OMPL's default range), each joint's
    range counted at most one turn: the panda's and the iiwa14's are OMPL's own, the ur5's ±2π joints
    count 2π each (3.1 rad, not 5.8)."""
    from kinlearn import load_robot
    from kinlearn.collision import body_spheres
    from kinlearn.collision.rrt import TURN

    robot, body, scene, start, goal = wall_problem
    box = 0.2 * float(np.linalg.norm(robot.upper - robot.lower))
    rrt = RrtConnect(K.KernelBody(body), K.KernelScene(scene), start, goal, robot.lower, robot.upper)
    assert (robot.upper - robot.lower < TURN).all() and rrt.step == pytest.approx(box, rel=1e-12)
    ur5 = load_robot("ur5")
    assert 0.2 * float(np.linalg.norm(ur5.upper - ur5.lower)) > 5.5
    q = np.zeros(6)
    rrt = RrtConnect(K.KernelBody(body_spheres(ur5)), K.KernelScene(scene), q, q, ur5.lower, ur5.upper)
    assert rrt.step == pytest.approx(0.2 * TURN * np.sqrt(6)) and rrt.local_step == rrt.step


def test_samples_near_the_root_extend_by_their_own_step(wall_problem):
    """A sample drawn near the extended tree's root moves that tree by at most ``local_step`` (a short
    step finds the way out of a cell that the long one jumps across); the connection still takes long
    steps, and a path found with a short local step is free."""
    robot, body, scene, start, goal = wall_problem
    kb, ks = K.KernelBody(body), K.KernelScene(scene)
    first = {}
    for local_step in (1e-3, None):
        rrt = RrtConnect(
            kb, ks, start, goal, robot.lower, robot.upper, seed=2, local=1.0, local_step=local_step
        )
        rrt.run(1)  # round 0 extends the start's tree towards a sample near the start
        assert int(rrt.state[0]) == 2
        first[local_step] = float(np.linalg.norm(rrt.nodes[0, 1] - start))
    assert first[1e-3] <= 1e-3 + 1e-12 < first[None]
    rrt = RrtConnect(kb, ks, start, goal, robot.lower, robot.upper, seed=3, local_step=0.3)
    path = next(p for p in (rrt.run(25) for _ in range(400)) if p is not None)
    assert bool(check_path(body, torch.from_numpy(path), scene).collision_free)


def test_balanced_search_extends_the_smaller_tree(wall_problem):
    """The balanced search extends the smaller tree, whatever the round's parity; taking turns does not.
    Seen through samples at the extended tree's own root (``local=1, sigma=0``): an extension adds a copy
    of that root (a free motion of length 0), and nothing else adds one. With the goal's tree made the
    larger (copies of the goal), both of the first two rounds grow the start's tree when balanced, and
    only the first when taking turns. Both find the wall problem's path, free by the torch check."""
    robot, body, scene, start, goal = wall_problem
    kb, ks = K.KernelBody(body), K.KernelScene(scene)
    copies = {}
    for balanced in (True, False):
        rrt = RrtConnect(
            kb, ks, start, goal, robot.lower, robot.upper, local=1.0, sigma=0.0, balanced=balanced
        )
        rrt.nodes[1, 1:30], rrt.parent[1, 1:30], rrt.state[1] = goal, 0, 30
        rrt.run(2)
        n0, n1 = int(rrt.state[0]), int(rrt.state[1])
        copies[balanced] = (
            int((rrt.nodes[0, :n0] == start).all(axis=1).sum()),
            int((rrt.nodes[1, :n1] == goal).all(axis=1).sum()),
        )
    assert copies[True] == (3, 30)  # the start's root and two copies; the goal's tree not extended
    assert copies[False] == (2, 31)  # one copy each
    for balanced in (True, False):
        rrt = RrtConnect(kb, ks, start, goal, robot.lower, robot.upper, seed=3, balanced=balanced)
        path = next(p for p in (rrt.run(25) for _ in range(400)) if p is not None)
        assert bool(check_path(body, torch.from_numpy(path), scene).collision_free)


def test_rrt_connect_needs_a_bound_and_refuses_bad_ones(wall_problem):
    from kinlearn.collision.rrt import rrt_connect

    robot, body, scene, start, goal = wall_problem
    kb, ks = K.KernelBody(body), K.KernelScene(scene)
    args = (kb, ks, start, goal, robot.lower, robot.upper)
    for bad in (0.0, -1.0, float("nan"), "1"):
        with pytest.raises(ConfigError, match="time_limit"):
            rrt_connect(*args, time_limit=bad)
    for bad in (0, -3, 2.5, True):
        with pytest.raises(ConfigError, match="max_iterations"):
            rrt_connect(*args, max_iterations=bad)
    with pytest.raises(ConfigError, match="time limit or an iteration budget"):
        rrt_connect(*args, time_limit=float("inf"))
    # An iteration budget alone: the same answer every time, and never more iterations than asked.
    a = rrt_connect(*args, time_limit=float("inf"), max_iterations=3, seed=2)
    b = rrt_connect(*args, time_limit=float("inf"), max_iterations=3, seed=2)
    assert a[2] == b[2] <= 3
    assert (a[0] is None) == (b[0] is None) and (a[0] is None or np.array_equal(a[0], b[0]))
    for bad in (0, -1, 1.5, True):
        with pytest.raises(ConfigError, match="rounds"):
            rrt_connect(*args, rounds=bad)


def test_rounds_sized_to_their_time_find_the_same_path(wall_problem):
    """rrt_connect's default rounds grow with the time they take; the path is that of one iteration per
    round (the same seed, the same iterations to it)."""
    from kinlearn.collision.rrt import rrt_connect

    robot, body, scene, start, goal = wall_problem
    args = (K.KernelBody(body), K.KernelScene(scene), start, goal, robot.lower, robot.upper)
    kw = dict(time_limit=float("inf"), max_iterations=5000, seed=4, shortcut=False, step=0.1)  # short steps
    one = rrt_connect(*args, rounds=1, **kw)
    sized = rrt_connect(*args, **kw)
    assert one[0] is not None and one[2] > 10
    assert np.array_equal(one[0], sized[0]) and one[2] == sized[2]


def test_trees_grown_from_given_branches(wall_problem):
    """Each tree can start with branches (the planner's free retreats): they are the tree's first nodes,
    and a path through them is found at once where their tips see each other; bad branches are refused."""
    robot, body, scene, start, goal = wall_problem
    kb, ks = K.KernelBody(body), K.KernelScene(scene)
    rrt = RrtConnect(kb, ks, start, goal, robot.lower, robot.upper, seed=3)
    path = _solve(rrt)
    assert path is not None and path.shape[0] >= 3
    k = path.shape[0] // 2
    branches = ([path[1:k]], [path[k:-1][::-1]])  # the found path cut in two, each half from its root
    grown = RrtConnect(kb, ks, start, goal, robot.lower, robot.upper, seed=5, branches=branches)
    assert grown.size == path.shape[0]  # both roots and every branch vertex
    assert np.array_equal(grown.nodes[0, 1:k], path[1:k])
    again = _solve(grown, rounds=40, iterations=1)
    assert again is not None
    assert np.array_equal(again[0], start) and np.array_equal(again[-1], goal)
    assert bool(check_path(body, torch.from_numpy(again), scene).collision_free)
    with pytest.raises(ShapeError, match="branch"):
        RrtConnect(kb, ks, start, goal, robot.lower, robot.upper, branches=([path[1:k, :2]], []))
    outside = path[1:k].copy()
    outside[0, 0] = robot.upper[0] + 1.0
    with pytest.raises(ConfigError, match="joint limits"):
        RrtConnect(kb, ks, start, goal, robot.lower, robot.upper, branches=([outside], []))
    with pytest.raises(ConfigError, match="pair"):
        RrtConnect(kb, ks, start, goal, robot.lower, robot.upper, branches=[path[1:k]])
    nan = path[1:k].copy()
    nan[0, 0] = np.nan
    with pytest.raises(ConfigError, match="finite"):
        RrtConnect(kb, ks, start, goal, robot.lower, robot.upper, branches=([nan], []))
    with pytest.raises(ConfigError, match="exceed"):
        RrtConnect(kb, ks, start, goal, robot.lower, robot.upper, max_nodes=2, branches=([path[1:3]], []))


#: The sampling options of the low-discrepancy sequences and the dynamic domain, each alone and together.
SAMPLINGS = [
    {"sampling": "halton"},
    {"sampling": "r2"},
    {"domain": 2.0},
    {"sampling": "halton", "domain": 1.0, "domain_alpha": 0.3},
]


@pytest.mark.parametrize("options", SAMPLINGS, ids=lambda o: "-".join(f"{k}={v}" for k, v in o.items()))
def test_every_sampling_same_path_whatever_the_rounds_and_free_by_the_compiled_check(wall_problem, options):
    """With the sequences and the dynamic domain too, the same seed gives the same path after the same
    iterations whatever the rounds, another seed another path; the path found is free by the compiled
    dense check and by the torch one."""
    robot, body, scene, start, goal = wall_problem
    kb, ks = K.KernelBody(body), K.KernelScene(scene)

    def solve(rounds, seed):
        return _seeded(wall_problem, kb, ks, rounds, seed, 20_000, **options)

    a, na = solve(1, 5)
    b, nb = solve(7, 5)
    assert np.array_equal(a, b) and na == nb
    other, _ = solve(3, 6)
    assert not np.array_equal(a, other)
    for p in (a, other):
        assert np.array_equal(p[0], start) and np.array_equal(p[-1], goal)
        assert (p >= robot.lower).all() and (p <= robot.upper).all()
        assert K.first_free(kb, p[None], ks, max_travel=0.01) == 0
        assert bool(check_path(body, torch.from_numpy(p), scene).collision_free)


def test_dynamic_domain_radii_shrink_on_failure_and_grow_on_success(wall_problem):
    """Iteration by iteration (box samples only, ``local=0``): a node's radius is unbounded until an
    extension from it fails, which sets it to ``domain`` steps; a later failure shrinks it by ``1 − α`` (to
    ``domain_min`` steps at least), a success grows it by ``1 + α``; only the extended tree's nearest
    node changes, and new nodes start unbounded. The roots start bounded (by ``domain``), so that the
    extensions from them show both changes."""
    robot, body, scene, start, goal = wall_problem
    kb, ks = K.KernelBody(body), K.KernelScene(scene)
    alpha = 0.25
    seen = {"set": 0, "shrunk": 0, "grown": 0}
    for seed in range(40):  # short steps: many extensions, some into the wall
        rrt = RrtConnect(
            kb, ks, start, goal, robot.lower, robot.upper, seed=seed, step=0.4, local=0.0, domain=20.0,
            domain_min=0.5, domain_alpha=alpha,
        )  # fmt: skip
        assert rrt.domain == pytest.approx(8.0) and rrt.domain_min == pytest.approx(0.2)
        rrt.radius[:, 0] = rrt.domain  # the roots bounded already: their extensions change them
        for _ in range(2000):
            before, counts = rrt.radius.copy(), rrt.state[:2].copy()
            a = int(rrt.state[6] % 2) if counts[0] == counts[1] else int(np.argmin(counts))
            if rrt.run(1) is not None or rrt.exhausted:
                break
            grew = int(rrt.state[a]) > counts[a]
            changed = np.argwhere(before != rrt.radius)
            assert len(changed) <= 1
            for t in (0, 1):  # the nodes added this iteration (and the slots not yet used) are unbounded
                assert np.isinf(rrt.radius[t, counts[t] :]).all()
            if len(changed) == 0:
                continue
            t, k = changed[0]
            assert t == a and k < counts[a]
            old, new = before[t, k], rrt.radius[t, k]
            if np.isinf(old):
                assert not grew and new == rrt.domain
                seen["set"] += 1
            elif grew:
                assert new == pytest.approx(old * (1 + alpha), rel=1e-12)
                seen["grown"] += 1
            else:
                assert new == pytest.approx(max(old * (1 - alpha), rrt.domain_min), rel=1e-12)
                seen["shrunk"] += 1
        finite = rrt.radius[np.isfinite(rrt.radius)]
        assert (finite >= rrt.domain_min - 1e-12).all()
        if min(seen.values()) > 5:
            break
    assert min(seen.values()) > 5, seen


def test_dynamic_domain_rejects_samples_beyond_the_nearest_nodes_radius(wall_problem):
    """Box samples farther from their nearest node than its radius are rejected: with the roots' radii
    tiny, the trees do not grow from box samples (the iterations still count); unbounded, they grow."""
    robot, body, scene, start, goal = wall_problem
    kb, ks = K.KernelBody(body), K.KernelScene(scene)
    for radius, grows in ((1e-6, False), (np.inf, True)):
        rrt = RrtConnect(kb, ks, start, goal, robot.lower, robot.upper, seed=4, local=0.0, domain=1.0)
        rrt.radius[:, 0] = radius
        rrt.run(20)
        assert rrt.iterations == 20 or rrt.found
        assert (rrt.size > 2) == grows


def test_the_sequences_spread_their_samples_evenly():
    """The Halton and R2 samples of the joint box fill it more evenly than random ones (every joint's
    range cut into 8 bins: 1024 samples put 128 ± a few in each), shifted or not."""
    from kinlearn.collision.rrt import _R2, _UNIFORM, _box_sample, _primes, _r2

    lo, hi = -np.arange(1.0, 8.0), np.arange(1.0, 8.0)
    spread = {}
    for kind, gen in ((_UNIFORM, _r2(7)), (1, _primes(7)), (_R2, _r2(7))):
        for shift in (np.zeros(7), np.full(7, 0.3)):
            state, q = np.zeros(8, dtype=np.int64), np.empty(7)
            state[2] = 12345
            pts = np.empty((1024, 7))
            for i in range(1024):
                _box_sample(state, kind, gen, shift, lo, hi, q)
                pts[i] = q
            assert (pts >= lo).all() and (pts < hi).all()
            bins = np.floor((pts - lo) / (hi - lo) * 8).astype(int)
            spread[kind, shift[0]] = max(np.abs(np.bincount(b, minlength=8) - 128).max() for b in bins.T)
            if kind != _UNIFORM:
                assert int(state[7]) == 1024  # the sequence's index: one per sample
    assert spread[_UNIFORM, 0.0] > 8
    for kind in (1, _R2):
        assert spread[kind, 0.0] <= 4 and spread[kind, 0.3] <= 4
    assert _primes(9).tolist() == [2, 3, 5, 7, 11, 13, 17, 19, 23]
    phi = 1.0 / _r2(1)[0]
    assert phi == pytest.approx((1 + 5**0.5) / 2)


def test_bad_sampling_options_are_refused(wall_problem):
    robot, body, scene, start, goal = wall_problem
    args = (K.KernelBody(body), K.KernelScene(scene), start, goal, robot.lower, robot.upper)
    with pytest.raises(ConfigError, match="sampling"):
        RrtConnect(*args, sampling="sobol")
    for name, bad in (("domain", -1.0), ("domain_min", float("nan")), ("domain_alpha", 1.0)):
        with pytest.raises(ConfigError, match=name):
            RrtConnect(*args, **{name: bad})
