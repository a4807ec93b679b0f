"""The obstacle success rule on hand-made paths that must fail (through a box, 2 cm short of the goal,
outside the limits, self-colliding, from the wrong start) and pass, and the table and figure writers."""

import math
from pathlib import Path

import pytest
import torch

from kinlearn import kinematics
from kinlearn.collision import Scene, check_path, clearances
from kinlearn.data.problems import FAMILIES, ProblemSet
from kinlearn.errors import ShapeError
from kinlearn.evaluation.obstacles import (
    OUTCOME_KEYS,
    format_table,
    obstacle_outcome,
    plot_obstacle_plans,
    plot_success_latency,
    summarize_outcome,
)

F64 = torch.float64
#: A configuration within the limits whose 12-sphere body collides with itself (checked below).
SELF_COLLIDING = [1.1406, 2.0034, 2.9417, 2.0850, 0.2484, 1.5315, 1.3671]


@pytest.fixture(scope="module")
def case(robot, body):
    """Start and goal turned 1.6 rad apart about joint 1, a box on the straight line's midpoint end
    effector (10 cm cube), a floor at z = 0."""
    start = torch.tensor([-0.8, 0.6, 0.0, -1.2, 0.0, 0.9, 0.0], dtype=F64)
    goal = start.clone()
    goal[0] = 0.8
    mid = (start + goal) / 2
    ee = kinematics(robot, "fast").position(mid)
    scene = Scene(boxes=torch.cat((ee, torch.full((3,), 0.05, dtype=F64))).unsqueeze(0), floor=0.0)
    d, s = clearances(body, torch.stack((start, goal)), scene)
    assert bool((d > 0.05).all() and (s > 0).all())  # the endpoints are free
    return start, goal, scene


def _line(start, goal, k=12):
    f = torch.linspace(0, 1, k, dtype=F64).unsqueeze(-1)
    return start + f * (goal - start)


def _around(start, goal, lift=0.9):
    """start → (start with the shoulder raised) → (goal raised) → goal: over the box."""
    up = torch.zeros_like(start)
    up[1], up[3] = -lift, 0.6
    return torch.stack((start, start + up, goal + up, goal))


def test_a_path_through_a_box_fails_and_one_around_it_passes(body, case):
    start, goal, scene = case
    out = obstacle_outcome(
        body, [_line(start, goal), _around(start, goal)], (start.repeat(2, 1), goal.repeat(2, 1), scene)
    )
    assert set(out) == set(OUTCOME_KEYS) and all(v.shape == (2,) for v in out.values())
    assert out["success"].tolist() == [False, True]
    assert out["collision_free"].tolist() == [False, True]
    assert out["goal_reached"].tolist() == [True, True] and out["within_limits"].all()
    assert out["starts_at_start"].all() and not out["self_collision"].any()
    assert float(out["clearance"][0]) < 0 < float(out["clearance"][1])
    assert math.isclose(float(out["joint_length"][0]), float((goal - start).norm()), rel_tol=1e-9)
    assert float(out["joint_length"][1]) > float(out["joint_length"][0])
    assert float(out["ee_length"][1]) > 0


def test_the_goal_needs_both_end_effector_and_joints(robot, body, case):
    start, goal, _ = case
    free = Scene()  # nothing to collide with
    kin = kinematics(robot, "fast")
    # Joint 1 turned by δ moves the end effector by r·δ (r its distance from the axis): pick 2 cm.
    r = float(kin.position(goal)[:2].norm())
    short = goal.clone()
    short[0] -= 0.02 / r  # < 0.05 rad: only the end-effector criterion can catch it
    assert 0.02 / r < 0.05
    # The last joint turns the flange about its own axis: 0.06 rad moves the end effector < 1 cm.
    twisted = goal.clone()
    twisted[6] += 0.06
    assert float((kin.position(twisted) - kin.position(goal)).norm()) < 0.01
    paths = [_line(start, short), _line(start, twisted), _line(start, goal)]
    out = obstacle_outcome(body, paths, (start.repeat(3, 1), goal.repeat(3, 1), free))
    assert out["goal_reached"].tolist() == [False, False, True]
    assert out["success"].tolist() == [False, False, True]
    assert abs(float(out["goal_error"][0]) - 0.02) < 1e-3
    assert abs(float(out["joint_error"][1]) - 0.06) < 1e-12
    assert out["collision_free"].all()


def test_leaving_the_limits_self_collision_and_a_wrong_start_fail(robot, body, case):
    start, goal, _ = case
    free = Scene()
    beyond = _line(start, goal, 5)
    beyond[2, 3] = robot.lower[3] - 0.01  # joint 4 past its limit in the middle of the path
    q_self = torch.tensor(SELF_COLLIDING, dtype=F64)
    assert float(clearances(body, q_self, free)[1]) < 0  # the configuration does collide with itself
    folded = torch.stack((start, q_self, goal))
    wrong = _line(start + 0.01, goal)
    paths = [beyond, folded, wrong, None, _line(start, goal)]
    out = obstacle_outcome(body, paths, (start.repeat(5, 1), goal.repeat(5, 1), free))
    assert out["success"].tolist() == [False, False, False, False, True]
    assert out["within_limits"].tolist() == [False, True, True, False, True]
    assert out["self_collision"].tolist() == [False, True, False, False, False]
    assert out["starts_at_start"].tolist() == [True, True, False, False, True]
    assert out["planned"].tolist() == [True, True, True, False, True]
    assert math.isnan(float(out["joint_length"][3])) and math.isnan(float(out["goal_error"][3]))


def test_a_path_is_judged_within_the_limits_given(robot, body, case):
    """``limits``: a path within the robot's limits that leaves narrower ones given (a set made within its
    body's limits) is not within them, and not a success."""
    start, goal, _ = case
    path = _line(start, goal, 5)
    lo, hi = robot.lower.copy(), robot.upper.copy()
    lo[0] = -0.5  # joint 1 turns from -0.8: the start itself lies beyond
    one = (start.unsqueeze(0), goal.unsqueeze(0), Scene())
    assert obstacle_outcome(body, [path], one)["success"].tolist() == [True]
    out = obstacle_outcome(body, [path], one, limits=(lo, hi))
    assert out["within_limits"].tolist() == [False] and out["success"].tolist() == [False]
    lo[0] = -0.9
    assert obstacle_outcome(body, [path], one, limits=(lo, hi))["success"].tolist() == [True]


def test_a_set_made_within_its_bodys_limits_is_judged_within_them():
    """A ProblemSet made within the body's limits (the ur5's ±π) is judged within them by default: a
    path through ±2π's room is not within them, and is within the robot's when those are given."""
    import numpy as np

    from kinlearn import load_robot
    from kinlearn.data.problems import ProblemSet

    ur5 = load_robot("ur5")
    data = Path(__file__).resolve().parents[1] / "benchmarks" / "data"
    one = ProblemSet.load(data / "scene_problems_ur5_within.npz", robot="ur5")[:1]
    body = one.body(ur5).double()
    start, goal = one.start[0], one.goal[0]
    via = start.clone()
    via[0] = np.pi + 0.3  # within the robot's ±2π, beyond the tool model's ±π
    path = torch.stack((start, via, goal))
    assert obstacle_outcome(body, [path], one)["within_limits"].tolist() == [False]
    wide = (ur5.lower.astype(np.float64), ur5.upper.astype(np.float64))
    assert obstacle_outcome(body, [path], one, limits=wide)["within_limits"].tolist() == [True]


def test_paths_of_different_lengths_are_judged_as_one_at_a_time(body, case):
    start, goal, scene = case
    paths = [_line(start, goal, 3), _around(start, goal), _line(start, goal, 40), start.unsqueeze(0)]
    problems = (start.repeat(4, 1), goal.repeat(4, 1), scene)
    together = obstacle_outcome(body, paths, problems)
    for i, p in enumerate(paths):
        alone = obstacle_outcome(body, p.unsqueeze(0), (start, goal, scene))
        for key in OUTCOME_KEYS:
            assert torch.equal(together[key][i : i + 1], alone[key]), key
    # Padding by repeating the last configuration checks the same configurations as check_path alone.
    direct = check_path(body, paths[1], scene)
    assert float(together["clearance"][1]) == float(direct.clearance)
    # A single configuration is a path that goes nowhere.
    assert float(together["joint_length"][3]) == 0.0 == float(together["ee_length"][3])
    assert together["starts_at_start"][3] and not together["goal_reached"][3]
    with pytest.raises(ShapeError):
        obstacle_outcome(body, [paths[0]], problems)


def _tiny_set(case) -> ProblemSet:
    start, goal, scene = case
    n = 3
    return ProblemSet(
        "iiwa14",
        start.repeat(n, 1),
        goal.repeat(n, 1),
        Scene.stack([scene] * n),
        torch.tensor([0, 1, 2]),
        torch.tensor([True, True, False]),
        torch.arange(n),
        torch.full((n,), math.nan, dtype=F64),
    )


def test_summary_table_and_figures_are_written(body, case, tmp_path):
    pytest.importorskip("matplotlib")
    start, goal, _ = case
    problems = _tiny_set(case)
    line, around = _line(start, goal), _around(start, goal)
    methods = {
        "line": [line] * 3,
        "around": [around, around, None],
        "opt 10": [around] * 3,
        "opt 20": [line] * 3,
    }
    summaries = {}
    for name, paths in methods.items():
        out = obstacle_outcome(body, paths, problems)
        summaries[name] = summarize_outcome(out, torch.tensor([0.001, 0.002, 0.004]), problems)
    s = summaries["around"]
    assert s["success"] == pytest.approx(2 / 3) and s["success_hard"] == 1.0
    assert s["success_by_family"] == {FAMILIES[0]: 1.0, FAMILIES[1]: 1.0, FAMILIES[2]: 0.0}
    assert s["latency_ms"]["p50"] == pytest.approx(2.0) and summaries["line"]["joint_length_ratio"] is None
    table = format_table(summaries)
    assert table.count("\n") == 1 + len(methods) and "| around | 66.7 | 100.0 |" in table
    png = plot_success_latency(summaries, tmp_path / "sl.png", curves={"opt": ["opt 10", "opt 20"]}, dpi=30)
    assert png.stat().st_size > 1000
    figure = plot_obstacle_plans(
        problems,
        [0, 2],
        {"line": [line, line], "around": [around, None]},
        body,
        tmp_path / "plans.png",
        success={"line": [False, False], "around": [True, False]},
        dpi=30,
    )
    assert figure.stat().st_size > 1000
