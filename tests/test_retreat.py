"""The retreat stage: vias along fixed end-effector retreats (or, where none is free, along the scene's
most open directions), chains cut at their first colliding segment, the shortest free join, the network
across between the deepest retreats (whole, or split at a midpoint), and the planner's plans from it
(free by torch's independent dense check, the same alone and in a batch)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from kinlearn.body.robot import load_robot
from kinlearn.collision import Box, Scene, check_path
from kinlearn.collision.kernel import KernelBody, KernelScene, first_free, free_depths, point_distances
from kinlearn.data.problems import ProblemSet
from kinlearn.errors import ConfigError
from kinlearn.models.chain import ChainFM
from kinlearn.models.chain_kernel import chain_positions
from kinlearn.planning import retreat as R
from kinlearn.planning.plan import CHECK_TRAVEL
from kinlearn.planning.planner import DEFAULT_CHECKPOINTS, Planner

SCENES = Path(__file__).resolve().parents[1] / "benchmarks" / "data" / "scene_problems_panda.npz"
#: Held-out panda problems: two cells the network's proposals leave colliding (bookcase; the retreat stage
#: clears the first by a straight join, the second by the network's transfer), one it clears (bin).
CELL_STRAIGHT, CELL_ACROSS, OPEN = 2, 5, 60
#: A held-out cubby problem whose start cannot retreat in any fixed direction (its cell opens elsewhere).
CELL_SIDEWAYS = 33


@pytest.fixture(scope="module")
def problems():
    return ProblemSet.load(SCENES, robot="panda")


@pytest.fixture(scope="module")
def panda():
    return Planner.default("panda")


@pytest.fixture(scope="module")
def alone():
    """The shipped panda planner without the retreat stage: its network's own fixed-time plans."""
    return Planner.load(DEFAULT_CHECKPOINTS / "panda", retreat=False)


def test_vias_move_the_hand_the_fixed_distances_in_the_fixed_directions(problems):
    robot = load_robot("panda")
    chain = ChainFM.from_robot(robot)
    vias = R.RetreatVias(chain, robot.lower, robot.upper, scale=1.0)
    theta = problems.start[1].numpy()  # a bookcase start every retreat distance is within reach of
    out = vias.vias(theta)
    H, D, L = len(R.RETREAT_HANDS), len(R.RETREAT_DIRECTIONS), len(R.RETREAT_DISTANCES)
    assert out.shape == (H * D, L, robot.dof)
    assert (out >= robot.lower).all() and (out <= robot.upper).all()
    arrays = chain.kernel_arrays()
    p = chain_positions(*arrays, theta[None])[0]
    inward = -np.array([p[0], p[1], 0.0]) / np.linalg.norm(p[:2])
    up = np.array([0.0, 0.0, 1.0])
    directions = [inward, up, (inward + up) / np.sqrt(2)]
    for h in range(H):  # the hand turning, then kept: the same targets
        for d, u in enumerate(directions):
            moved = chain_positions(*arrays, out[h * D + d]) - p
            np.testing.assert_allclose(moved, np.outer(R.RETREAT_DISTANCES, u), atol=5e-3)
    # each via solved from the one before: neighbours are close in joint space (no jump to another branch)
    steps = np.linalg.norm(
        np.diff(np.concatenate((np.broadcast_to(theta, (H * D, 1, 7)), out), 1), axis=1), axis=-1
    )
    assert steps.max() < 0.6


def _hand(robot, theta):
    """The end effector's rotation ``(N, 3, 3)`` at joints ``theta (N, dof)`` by Pinocchio's FK of the URDF
    (independent of the chain the vias are solved on)."""
    from kinlearn.body.kinematics import kinematics

    pose = kinematics(robot, "pinocchio").pose(torch.from_numpy(np.atleast_2d(theta)))
    return pose[:, :3, :3].numpy()


@pytest.mark.parametrize("name", ["panda", "ur5"])
def test_kept_chains_hold_the_hands_orientation_and_turning_ones_do_not(name):
    """At configurations across the limits, a kept chain's vias hold the hand's orientation at the end
    (by Pinocchio's FK of the URDF: the median turn under 5 degrees; a retreat out of reach or against a
    limit turns it more), and the turning chains, solved for position alone, turn it tens of degrees."""
    robot = load_robot(name)
    chain = ChainFM.from_robot(robot)
    vias = R.RetreatVias(chain, robot.lower, robot.upper, scale=1.0)
    D = len(R.RETREAT_DIRECTIONS)
    rng = np.random.default_rng(0)
    turns: tuple[list, list] = ([], [])
    for _ in range(20):
        theta = rng.uniform(0.7 * np.asarray(robot.lower), 0.7 * np.asarray(robot.upper))
        out = vias.vias(theta)
        R0 = _hand(robot, theta)[0]
        for h, chains in enumerate((out[:D], out[D:])):
            for Rk in _hand(robot, chains.reshape(-1, robot.dof)):
                turns[h].append(np.degrees(np.arccos(np.clip((np.trace(R0.T @ Rk) - 1) / 2, -1, 1))))
    assert np.median(turns[1]) < 5.0
    assert np.median(turns[0]) > 20.0


def test_the_sampler_gets_the_turning_chains_only():
    vias = np.arange(6 * 3 * 2, dtype=np.float64).reshape(6, 3, 2)
    depth = np.array([2, 0, 3, 3, 3, 3])
    branches = R.sampler_branches(vias, depth)
    assert len(branches) == 2
    assert np.array_equal(branches[0], vias[0, :2]) and np.array_equal(branches[1], vias[2])


def test_vias_within_a_narrower_box_stay_in_it():
    """``within``: the same solver in a problem's box (the ur5's tool model's ±π, say), every via inside
    it; the same limits give the same object."""
    robot = load_robot("ur5")
    vias = R.RetreatVias(ChainFM.from_robot(robot), robot.lower, robot.upper, scale=1.0)
    assert vias.within(robot.lower.copy(), robot.upper.copy()) is vias
    theta = np.array([3.0, -1.2, 1.5, -2.9, -1.6, 3.1])
    lo, hi = theta - 0.2, theta + 0.2  # a box the retreats' moves leave
    wide, box = vias.vias(theta), vias.within(lo, hi).vias(theta)
    assert ((wide < lo) | (wide > hi)).any()
    assert ((box >= lo) & (box <= hi)).all()


def test_bad_vias_settings_are_refused():
    robot = load_robot("panda")
    with pytest.raises(ConfigError):
        R.RetreatVias(object(), robot.lower, robot.upper, 1.0)
    with pytest.raises(ConfigError):
        R.RetreatVias(ChainFM.from_robot(robot), robot.lower, robot.upper, float("nan"))
    with pytest.raises(ConfigError, match="retreat"):
        Planner.load(DEFAULT_CHECKPOINTS / "panda", retreat="yes")


def _depths(body, ks):
    """The planner's free depths of chains from a configuration (one compiled call)."""
    return lambda theta, vias: free_depths(body, theta, vias, ks, max_travel=CHECK_TRAVEL)


def test_free_depths_stop_at_the_first_segment_torch_finds_colliding(panda, problems):
    """Each chain's depth agrees with torch's dense check (an independent implementation): its first
    `depth` segments free, the next one colliding."""
    body = KernelBody(panda.body)
    seen = set()
    for i in (CELL_STRAIGHT, CELL_ACROSS, 20, 41):
        start, _, scene = problems.problem(i)
        theta = start.numpy()
        vias = panda._retreat_vias().vias(theta)
        ks = KernelScene(scene)
        depth = _depths(body, ks)(theta, vias)
        # the same depths as checking every segment apart
        for d in range(vias.shape[0]):
            chain = np.concatenate((theta[None], vias[d]))
            apart = next(
                (
                    k
                    for k in range(vias.shape[1])
                    if first_free(body, chain[None, k : k + 2], ks, max_travel=CHECK_TRAVEL) != 0
                ),
                vias.shape[1],
            )
            assert depth[d] == apart
        for d in range(vias.shape[0]):
            chain = np.concatenate((theta[None], vias[d]))
            for k in range(min(int(depth[d]) + 1, vias.shape[1])):
                free = bool(check_path(panda.body, torch.from_numpy(chain[k : k + 2]), scene).collision_free)
                assert free == (k < depth[d])
            seen.add(int(depth[d]))
    assert min(seen) < len(R.RETREAT_DISTANCES) in seen  # both a cut chain and a whole one were met


def test_open_directions_point_out_of_a_cell_and_keep_the_grid_order_in_the_open():
    """A cell of five boards around a point, open toward −x: the most open direction leaves through the
    opening, and every direction returned is at least as open as any other. In an empty scene every
    direction is fully open: the grid's own order (no preference from rounding)."""
    p = np.array([0.6, 0.1, 0.4])
    boards = [  # centre, half extents: floor, roof, back (+x), and both sides
        ((0.6, 0.1, 0.28), (0.2, 0.2, 0.02)),
        ((0.6, 0.1, 0.52), (0.2, 0.2, 0.02)),
        ((0.82, 0.1, 0.4), (0.02, 0.2, 0.14)),
        ((0.6, -0.12, 0.4), (0.2, 0.02, 0.14)),
        ((0.6, 0.32, 0.4), (0.2, 0.02, 0.14)),
    ]
    ks = KernelScene(Scene.from_primitives([Box(c, h) for c, h in boards]))

    def distance(points):
        return point_distances(ks, points)

    out = R.open_directions(p, distance, reach=0.3, cap=0.1)
    assert out.shape == (R.OPEN_DIRECTIONS, 3)
    np.testing.assert_allclose(np.linalg.norm(out, axis=1), 1.0)
    assert out[0] @ np.array([-1.0, 0.0, 0.0]) > 0.99  # straight out of the opening

    def least(d):
        return min(distance(p + np.outer(R._RAY_SHARES * 0.3, d)).min(), 0.1)

    kept = min(least(d) for d in out)
    assert all(least(d) <= kept + 1e-12 for d in R._GRID if not any(np.allclose(d, o) for o in out))
    empty = KernelScene(Scene.from_spheres(np.zeros((0, 4))))
    np.testing.assert_array_equal(
        R.open_directions(p, lambda x: point_distances(empty, x), 0.3, 0.1), R._GRID[: R.OPEN_DIRECTIONS]
    )


def test_an_end_with_no_free_fixed_retreat_retreats_where_its_scene_is_open(panda, problems):
    """The start of a cubby problem cannot retreat toward the base or up (every fixed chain's first
    segment collides); given the scene, its retreats go where the scene is open, and torch's dense
    check (independent) finds them free as deep as the stage says. The planner's plan is the retreat
    stage's, free."""
    start, goal, scene = problems.problem(CELL_SIDEWAYS)
    theta = start.numpy()
    ks = KernelScene(scene)
    body = KernelBody(panda.body)

    vias = panda._retreat_vias()
    fixed, depth = vias.free(theta, _depths(body, ks))
    assert not depth.any() and np.array_equal(fixed, vias.vias(theta))
    opened, depth = vias.free(theta, _depths(body, ks), lambda x: point_distances(ks, x))
    # the fixed chains (none free), then the open ones, of either kind of hand, the turning ones first
    D, O = len(R.RETREAT_DIRECTIONS), R.OPEN_DIRECTIONS
    assert opened.shape == (2 * (D + O), *fixed.shape[1:])
    assert np.array_equal(opened[:D], fixed[:D]) and np.array_equal(opened[D + O : 2 * D + O], fixed[D:])
    assert not depth[:D].any() and not depth[D + O : 2 * D + O].any()
    assert depth.max() == len(R.RETREAT_DISTANCES)
    for d in np.flatnonzero(depth):
        chain = torch.from_numpy(np.concatenate((theta[None], opened[d, : depth[d]])))
        assert bool(check_path(panda.body, chain, scene).collision_free)
    plan = panda.plan(start, goal, obstacles=scene, refine_steps=0)
    assert plan.stage == "retreat" and bool(plan.success)
    assert bool(check_path(panda.body, plan.joints, scene).collision_free)


def test_open_directions_join_the_fixed_ones_where_none_is_free_all_the_way(panda):
    """An end whose fixed retreats all stop short (here: every chain's third segment collides) also
    retreats in the scene's most open directions; one with a fixed retreat free to its farthest via does
    not. The open ones follow the fixed ones of each kind of hand, the turning chains first, so the
    sampler's branches are still the turning ones."""
    vias = panda._retreat_vias()
    theta = (panda._lo_np + panda._hi_np) / 2
    L, D = len(R.RETREAT_DISTANCES), len(R.RETREAT_DIRECTIONS)
    fixed = vias.vias(theta)

    def far(points):  # an empty scene: every direction open, the grid's order kept
        return np.full(len(points), 10.0)

    def short(theta, chains):  # every chain collides in its third segment
        return np.full(len(chains), 2)

    opened, depth = vias.free(theta, short, far)
    O = R.OPEN_DIRECTIONS
    assert opened.shape == (2 * (D + O), L, theta.shape[0]) and depth.tolist() == [2] * (2 * (D + O))
    assert np.array_equal(opened[:D], fixed[:D]) and np.array_equal(opened[D + O : 2 * D + O], fixed[D:])
    assert np.array_equal(opened[D : D + O], vias.vias(theta, far)[:O])  # the turning open chains
    assert len(R.sampler_branches(opened, depth)) == D + O  # turning: fixed and open

    kept, depth = vias.free(theta, lambda t, chains: np.full(len(chains), L), far)  # free all the way
    assert np.array_equal(kept, fixed) and depth.tolist() == [L] * (2 * D)


def _chains(L=2, D=1, dof=2):
    """Vias of two ends on a plane: the start's go up in y, the goal's too."""
    v0 = np.array([[[0.0, 1.0 + k] for k in range(L)]] * D)
    vT = np.array([[[4.0, 1.0 + k] for k in range(L)]] * D)
    return np.zeros(dof), np.array([4.0, 0.0]), v0, vT


def test_the_shortest_free_join_is_taken_and_never_the_straight_line():
    theta0, thetaT, v0, vT = _chains()
    asked = []

    def first_free(paths, order):  # free: a join at height ≥ 2 (a wall below)
        asked.append(order.copy())
        for k in order:
            if paths[k][:, 1].min() >= 2.0:
                return int(k)
        return -1

    path = R.retreat_path(theta0, thetaT, v0, vT, np.array([2]), np.array([2]), first_free, None)
    np.testing.assert_array_equal(path, [[0, 0], [0, 1], [0, 2], [4, 2], [4, 1], [4, 0]])
    assert 0 not in asked[0]  # the pair without a retreat at either end: the straight line, not asked again
    # The same with both chains cut at depth 1: no join clears the wall, and no network: nothing.
    assert R.retreat_path(theta0, thetaT, v0, vT, np.array([1]), np.array([1]), first_free, None) is None
    # No free retreat at either end: nothing asked.
    asked.clear()
    assert R.retreat_path(theta0, thetaT, v0, vT, np.array([0]), np.array([0]), first_free, None) is None
    assert not asked


def test_the_network_goes_across_between_the_deepest_retreats_a_bounded_number_of_times():
    theta0, thetaT, v0, vT = _chains(L=3, D=2)
    calls = []

    def transfer(a, b):
        calls.append((a.copy(), b.copy()))
        return np.stack((a, (a + b) / 2, b)) if len(calls) == 2 else None

    path = R.retreat_path(
        theta0, thetaT, v0, vT, np.array([3, 2]), np.array([1, 3]), lambda p, o: -1, transfer
    )
    assert len(calls) == 2 <= R.RETREAT_TRANSFERS
    np.testing.assert_array_equal(calls[0][0], v0[0, 2])  # the deepest pair first: 3 vias + 3 vias
    np.testing.assert_array_equal(calls[0][1], vT[1, 2])
    a, b = calls[1]
    np.testing.assert_array_equal(path[0], theta0)
    np.testing.assert_array_equal(path[-1], thetaT)
    assert any((path == (a + b) / 2).all(-1))  # the transfer's own knot is in the path
    none = []
    R.retreat_path(
        theta0,
        thetaT,
        v0,
        vT,
        np.array([3, 3]),
        np.array([3, 3]),
        lambda p, o: -1,
        lambda a, b: none.append(1),
    )
    assert len(none) == R.RETREAT_TRANSFERS


def test_cells_the_network_leaves_colliding_are_cleared_by_the_retreat_stage(panda, alone, problems):
    for i in (CELL_STRAIGHT, CELL_ACROSS):
        start, goal, scene = problems.problem(i)
        before = alone.plan(start, goal, obstacles=scene, refine_steps=0)
        assert before.stage == "none" and not bool(before.collision_free)
        plan = panda.plan(start, goal, obstacles=scene, refine_steps=0)
        assert plan.stage == "retreat" and bool(plan.collision_free) and bool(plan.success)
        assert bool(check_path(panda.body, plan.joints, scene).collision_free)  # torch agrees
        assert torch.equal(plan.joints[0], start) and torch.equal(plan.joints[-1], goal)
        again = panda.plan(start, goal, obstacles=scene, refine_steps=0)
        assert torch.equal(again.joints, plan.joints)  # fixed work: deterministic
    # The network's own plans are not touched.
    start, goal, scene = problems.problem(OPEN)
    a = alone.plan(start, goal, obstacles=scene, refine_steps=0)
    b = panda.plan(start, goal, obstacles=scene, refine_steps=0)
    assert a.stage == b.stage == "learned" and torch.equal(a.joints, b.joints)


@pytest.mark.parametrize("n", [3, 17])  # a few plans and more than SMALL_BATCH
def test_a_batch_plans_each_problem_as_alone(panda, problems, n):
    idx = [CELL_STRAIGHT, CELL_ACROSS, OPEN, *range(61, 61 + n - 3)]
    sub = problems[torch.tensor(idx)]
    batch = panda.plan(sub.start, sub.goal, obstacles=sub.scene, refine_steps=0)
    assert list(batch.stage[:3]) == ["retreat", "retreat", "learned"]
    for j in range(3):
        one = panda.plan(*sub.problem(j)[:2], obstacles=sub.problem(j)[2], refine_steps=0)
        # the same polyline (the batch's knots are its longest plan's count: segments split more finely)
        assert _off(batch.joints[j], one.joints) < 1e-12 and _off(one.joints, batch.joints[j]) < 1e-12
        assert bool(batch.collision_free[j]) == bool(one.collision_free)
        assert bool(check_path(panda.body, batch.joints[j], sub.scene[j]).collision_free) == bool(
            one.collision_free
        )


def _off(points: torch.Tensor, polyline: torch.Tensor) -> float:
    """The largest distance (rad) from a knot of ``points`` to the polyline ``polyline``."""
    a, b = polyline[:-1].numpy(), polyline[1:].numpy()
    d = b - a
    worst = 0.0
    for p in points.numpy():
        t = np.clip(((p - a) * d).sum(-1) / np.maximum((d * d).sum(-1), 1e-300), 0.0, 1.0)
        worst = max(worst, float(np.linalg.norm(a + t[:, None] * d - p, axis=-1).min()))
    return worst


def test_the_plan_command_has_the_stage_and_leaves_it_out_when_asked(problems, tmp_path, capsys):
    from kinlearn.cli.main import main

    start, goal, scene = problems.problem(CELL_STRAIGHT)
    scene.save(tmp_path / "scene.npz")
    joints = [",".join(f"{v:.17g}" for v in q.tolist()) for q in (start, goal)]
    args = ["plan", "--robot", "panda", "--start", joints[0], "--goal", joints[1], "--refine-steps", "0"]
    assert main([*args, "--obstacles", str(tmp_path / "scene.npz")]) == 0
    assert "retreat" in capsys.readouterr().out
    assert main([*args, "--obstacles", str(tmp_path / "scene.npz"), "--no-retreat"]) == 1
    assert "none" in capsys.readouterr().out
    assert main([*args, "--no-retreat"]) == 2
    assert "--no-retreat leaves out a stage of planning around obstacles" in capsys.readouterr().err


def test_a_deadline_that_runs_out_stops_the_stage_between_transfers(panda, problems, monkeypatch):
    """Every clock reading 20 ms later: with a deadline of 50 ms the joins are tried, then the deadline
    has run out before the first network transfer, so the cell the network crosses stays flagged."""
    from kinlearn.planning import stages

    start, goal, scene = problems.problem(CELL_ACROSS)
    assert panda.plan(start, goal, obstacles=scene, deadline=30.0).stage == "retreat"  # time enough: cleared
    now = [0.0]

    def slow():
        now[0] += 0.02
        return now[0]

    monkeypatch.setattr(stages.time, "perf_counter", slow)
    plan = panda.plan(start, goal, obstacles=scene, deadline=0.05)
    assert plan.stage == "none" and not bool(plan.collision_free)
    assert now[0] <= 0.2  # a handful of readings: the stage asked the deadline and stopped
    calls = []
    theta0, thetaT, v0, vT = _chains(L=3, D=2)
    out = R.retreat_path(
        theta0, thetaT, v0, vT, np.array([3, 3]), np.array([3, 3]), lambda p, o: -1,
        lambda a, b: calls.append(1), stop=lambda: True,
    )  # fmt: skip
    assert out is None and not calls


def test_free_chains_are_each_directions_free_prefix():
    vias = np.arange(3 * 3 * 2, dtype=np.float64).reshape(3, 3, 2)
    chains = R.free_chains(vias, np.array([2, 0, 3]))
    assert len(chains) == 2  # the direction with no free via gives none
    assert np.array_equal(chains[0], vias[0, :2]) and np.array_equal(chains[1], vias[2])


@pytest.mark.filterwarnings("ignore::kinlearn.errors.NoObstacleModelWarning")
def test_the_sampler_grows_from_the_retreats_the_stage_found_free(panda, problems, monkeypatch):
    """Where the retreat stage leaves a problem colliding, the sampler's trees start from its free
    retreats: every branch handed over is free by torch's dense check from its end."""
    from kinlearn.collision import rrt

    seen = []
    real = rrt.rrt_connect

    def spy(*args, **kw):
        seen.append(kw.get("branches"))
        return real(*args, **kw)

    monkeypatch.setattr(rrt, "rrt_connect", spy)
    start, goal, scene = problems.problem(CELL_SIDEWAYS)
    alone = Planner(panda.robot, panda.tm, panda.fm, panda.im)  # no network: the transfers are lines
    plan = alone.plan(start, goal, obstacles=scene)
    assert plan.stage == "rrt" and bool(plan.collision_free)  # no deadline: the same every run
    (branches,) = seen
    assert sum(len(b) for b in branches) > 0
    for end, chains in zip((start, goal), branches, strict=True):
        for chain in chains:
            poly = torch.cat([end.double()[None], torch.from_numpy(chain)])
            assert bool(check_path(alone.body, poly, scene).collision_free)


def test_midpoint_vias_put_the_hand_halfway_lifted_and_pulled_in(problems):
    robot = load_robot("panda")
    chain = ChainFM.from_robot(robot)
    vias = R.RetreatVias(chain, robot.lower, robot.upper, scale=1.0)
    a, b = problems.start[1].numpy(), problems.goal[1].numpy()
    out = vias.midpoints(a, b)
    assert out.shape == (len(R.MIDPOINT_LIFTS) * len(R.MIDPOINT_PULLS), robot.dof)
    assert (out >= robot.lower).all() and (out <= robot.upper).all()
    arrays = chain.kernel_arrays()
    hand = chain_positions(*arrays, np.stack((a, b))).mean(axis=0)
    reached = chain_positions(*arrays, out)
    for (lift, pull), p in zip(
        [(h, s) for h in R.MIDPOINT_LIFTS for s in R.MIDPOINT_PULLS], reached, strict=True
    ):
        target = np.array([hand[0] * (1 - pull), hand[1] * (1 - pull), hand[2] + lift])
        assert np.linalg.norm(p - target) < 1e-3, (lift, pull)  # every target of this pair is reachable


def test_a_transfer_is_split_at_a_midpoint_where_no_whole_one_is_free_a_bounded_number_of_times():
    theta0, thetaT, v0, vT = _chains(L=3, D=2)
    vias = np.array([[9.0, 9.0], [2.0, 5.0], [2.0, 6.0]])  # the first collides (below)
    whole, halves = [], []

    def first_free(paths, order):  # every join collides; of the vias (checked alone) the one at (9, 9)
        p = paths[order[0]]
        return int(order[0]) if (p[0] == p[-1]).all() and not (p == 9.0).all() else -1

    def transfer(a, b):  # whole transfers (end to end) all collide; halves through (2, 6) are free
        if a[0] == 0.0 and b[0] == 4.0:
            whole.append(1)
            return None
        halves.append((a.copy(), b.copy()))
        return np.stack((a, b)) if 6.0 in (a[1], b[1]) else None

    path = R.retreat_path(
        theta0, thetaT, v0, vT, np.array([3, 2]), np.array([1, 3]), first_free, transfer,
        midpoints=lambda a, b: vias,
    )  # fmt: skip
    assert len(whole) == R.RETREAT_TRANSFERS  # step 3 first, all of it
    # Step 4: the colliding via skipped unasked, the second's first half refused, the third's two halves.
    assert len(halves) == 3
    np.testing.assert_array_equal(halves[1][1], [2.0, 6.0])
    np.testing.assert_array_equal(path[0], theta0)
    np.testing.assert_array_equal(path[-1], thetaT)
    assert any((path == [2.0, 6.0]).all(-1)) and not any((path == [2.0, 5.0]).all(-1))
    asked = []
    none = R.retreat_path(
        theta0, thetaT, v0, vT, np.array([3, 3]), np.array([3, 3]), first_free,
        lambda a, b: asked.append(1), midpoints=lambda a, b: np.array([[2.0, 5.0]] * 50),
    )  # fmt: skip
    assert none is None and len(asked) == R.RETREAT_TRANSFERS + R.MIDPOINT_TRANSFERS  # bounded
    # One free retreat in all (the goal has none): one pair, its whole transfer, then its split ones.
    whole.clear(), halves.clear()
    path = R.retreat_path(
        theta0, thetaT, v0, vT, np.array([1, 0]), np.array([0, 0]), first_free, transfer,
        midpoints=lambda a, b: vias,
    )  # fmt: skip
    assert len(whole) == 1 and len(halves) == 3  # the retreat's end to the goal whole, then split
    assert any((path == [2.0, 6.0]).all(-1)) and (path[-1] == thetaT).all()


#: Held-out ur5 problems (its gripper carried) whose transfer the network clears only split at a midpoint.
UR5_SPLIT = (82, 100)


def test_the_ur5s_long_turns_are_cleared_through_a_midpoint_where_no_sampler_follows(monkeypatch):
    ur5 = Planner.default("ur5")
    problems = ProblemSet.load(SCENES.with_name("scene_problems_ur5.npz"), robot="ur5")
    for i in UR5_SPLIT:
        start, goal, scene = problems.problem(i)
        plan = ur5.plan(start, goal, obstacles=scene, refine_steps=0)
        assert plan.stage == "retreat" and bool(plan.success)
        assert bool(check_path(ur5.body, plan.joints, scene).collision_free)  # torch agrees
    # With the default budget of sampler iterations next, step 4 is left to the sampler, which clears them.
    split = []
    real = R.RetreatVias.midpoints
    monkeypatch.setattr(R.RetreatVias, "midpoints", lambda self, a, b: split.append(1) or real(self, a, b))
    for i in UR5_SPLIT:
        start, goal, scene = problems.problem(i)
        plan = ur5.plan(start, goal, obstacles=scene)
        assert plan.stage == "rrt" and bool(plan.success) and not split
    assert ur5.plan(start, goal, obstacles=scene, refine_steps=0).stage == "retreat" and split  # it runs
    monkeypatch.setattr(R, "MIDPOINT_TRANSFERS", 0)  # no step 4: the same problems stay colliding
    for i in UR5_SPLIT:
        start, goal, scene = problems.problem(i)
        assert ur5.plan(start, goal, obstacles=scene, refine_steps=0).stage == "none"


def test_wiggles_turn_one_joint_then_retreat(problems):
    robot = load_robot("panda")
    vias = R.RetreatVias(ChainFM.from_robot(robot), robot.lower, robot.upper, scale=1.0)
    theta = problems.start[1].numpy()
    out = vias.wiggled(theta)
    H, D, L = len(R.RETREAT_HANDS), len(R.RETREAT_DIRECTIONS), len(R.RETREAT_DISTANCES)
    W = out.shape[0] // (H * D)
    assert out.shape == (H * W * D, L, robot.dof) and W <= 2 * robot.dof
    moved = out[:, 0] - theta
    assert ((np.abs(moved) > 1e-12).sum(-1) == 1).all()  # one joint each
    size = np.abs(moved).max(-1)
    at_limit = np.isclose(out[:, 0], robot.lower).any(-1) | np.isclose(out[:, 0], robot.upper).any(-1)
    assert (np.isclose(size, R.WIGGLE) | at_limit).all()  # WIGGLE rad, or as far as the limit allows
    assert (out[:, 0] >= robot.lower).all() and (out[:, 0] <= robot.upper).all()
    turning = out.reshape(H, W, D, L, robot.dof)[0]
    for w in range(W):  # each wiggle's chains are that configuration's retreats, the farthest via left out
        np.testing.assert_allclose(turning[w, :, 1:], vias.vias(turning[w, 0, 0])[:D, :-1])


#: A held-out ur5 problem whose start is wedged in a bookcase's cell: no retreat free at all, until a wiggle.
UR5_WEDGED = 11


def test_a_wedged_end_retreats_after_a_wiggle(monkeypatch):
    ur5 = Planner.default("ur5")
    start, goal, scene = ProblemSet.load(SCENES.with_name("scene_problems_ur5.npz"), robot="ur5").problem(
        UR5_WEDGED
    )
    plan = ur5.plan(start, goal, obstacles=scene, refine_steps=0)
    assert plan.stage == "retreat" and bool(plan.success)
    assert bool(check_path(ur5.body, plan.joints, scene).collision_free)
    wiggled = R.RetreatVias.wiggled
    monkeypatch.setattr(R.RetreatVias, "wiggled", lambda self, theta: wiggled(self, theta)[:0])
    assert ur5.plan(start, goal, obstacles=scene, refine_steps=0).stage == "none"


@pytest.mark.parametrize("index", [CELL_STRAIGHT, CELL_ACROSS])
def test_sample_first_runs_the_sampler_before_the_retreat_stage(problems, index):
    """Default plan() (a sampler budget, no deadline) on cells the learned stage leaves colliding: the
    retreat stage clears them; with sample_first=True the sampler does, before the retreat stage runs,
    deterministically, except under a deadline (the retreat stage first). Every plan is judged alike."""
    later = Planner.load(DEFAULT_CHECKPOINTS / "panda")
    first = Planner.load(DEFAULT_CHECKPOINTS / "panda", sample_first=True)
    start, goal, scene = problems.problem(index)
    a, b = first.plan(start, goal, obstacles=scene), later.plan(start, goal, obstacles=scene)
    assert a.stage == "rrt" and b.stage == "retreat"
    assert bool(a.success) and bool(b.success) and bool(a.collision_free)
    assert torch.equal(a.joints, first.plan(start, goal, obstacles=scene).joints)
    assert first.plan(start, goal, obstacles=scene, deadline=30.0).stage == "retreat"


def test_sample_first_is_a_bool():
    from kinlearn.errors import ConfigError

    with pytest.raises(ConfigError, match="sample_first"):
        Planner.load(DEFAULT_CHECKPOINTS / "panda", sample_first="yes")
