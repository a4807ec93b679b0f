"""Obstacle baselines: every path starts and ends at the given joints; the trajectory optimiser gets
round a sphere across the straight line, deterministically; RRT-Connect with simplification returns a
path the success rule accepts."""

from pathlib import Path

import pytest
import torch

from kinlearn import kinematics, load_robot
from kinlearn.collision import Scene, body_spheres, check_path, clearances
from kinlearn.errors import ConfigError, JointLimitError, ShapeError
from kinlearn.evaluation.obstacles import obstacle_outcome
from kinlearn.planning.obstacle_baselines import (
    OptimiserConfig,
    cartesian_line_path,
    default_body,
    joint_line_path,
    scene_rrt_connect,
    trajectory_optimiser,
)

F64 = torch.float64


@pytest.fixture(scope="module")
def body():
    return default_body("iiwa14")


@pytest.fixture(scope="module")
def problem(body):
    """Start and goal 1.6 rad apart about joint 1; an 8 cm sphere on the straight line's midpoint end
    effector; a floor at z = 0."""
    start = torch.tensor([-0.8, 0.6, 0.0, -1.2, 0.0, 0.9, 0.0], dtype=F64)
    goal = start.clone()
    goal[0] = 0.8
    ee = kinematics(body.robot, "fast").position((start + goal) / 2)
    scene = Scene(spheres=torch.cat((ee, torch.tensor([0.08], dtype=F64))).unsqueeze(0), floor=0.0)
    assert not bool(check_path(body, torch.stack((start, goal)), scene).collision_free)  # the line collides
    d, s = clearances(body, torch.stack((start, goal)), scene)
    assert bool((d > 0).all() and (s > 0).all())
    return start, goal, scene


def test_default_body_is_the_12_sphere_body_with_base(body):
    reference = body_spheres(load_robot("iiwa14"))
    assert body.num_spheres == reference.num_spheres and torch.equal(body.radii, reference.radii.double())
    assert default_body("iiwa14") is body


@pytest.mark.parametrize(
    "method",
    [joint_line_path, cartesian_line_path, lambda s, g, sc: trajectory_optimiser(s, g, sc, steps=3)],
    ids=["joint_line_path", "cartesian_line_path", "optimiser"],
)
def test_paths_start_and_end_at_the_given_joints(problem, method):
    start, goal, scene = problem
    path, seconds = method(start.float(), goal.tolist(), scene)  # any real input type
    assert path.dtype == F64 and path.ndim == 2 and path.shape[1] == 7 and path.shape[0] >= 3
    assert torch.equal(path[0], start.float().double()) and torch.equal(path[-1], goal)
    assert seconds > 0


def test_obstacle_unaware_baselines_collide_where_the_line_does(body, problem):
    start, goal, scene = problem
    line, _ = joint_line_path(start, goal, scene)
    assert torch.allclose(line[5], start + 0.5 * (goal - start), atol=1e-12)
    out = obstacle_outcome(body, [line], (start, goal, scene))
    assert not bool(out["collision_free"][0]) and bool(out["goal_reached"][0])


def test_optimiser_gets_round_a_sphere_deterministically(body, problem):
    start, goal, scene = problem
    path, _ = trajectory_optimiser(start, goal, scene, steps=100)
    out = obstacle_outcome(body, [path], (start, goal, scene))
    assert bool(out["success"][0]), {k: v.tolist() for k, v in out.items()}
    assert path.shape == (OptimiserConfig().knots, 7)
    again, _ = trajectory_optimiser(start, goal, scene, steps=100)
    assert torch.equal(path, again)
    # Zero steps is the straight line through the sphere.
    line, _ = trajectory_optimiser(start, goal, scene, steps=0)
    assert not bool(obstacle_outcome(body, [line], (start, goal, scene))["collision_free"][0])


def test_bad_inputs_raise_typed_errors(problem):
    start, goal, scene = problem
    with pytest.raises(ShapeError):
        joint_line_path(start[:6], goal, scene)
    beyond = goal.clone()
    beyond[1] = 2.5
    with pytest.raises(JointLimitError):
        trajectory_optimiser(start, beyond, scene)
    with pytest.raises(ConfigError):
        trajectory_optimiser(start, goal, scene, steps=-1)
    with pytest.raises(ShapeError):
        trajectory_optimiser(start, goal, Scene.stack([scene, scene]))
    with pytest.raises(ConfigError):
        OptimiserConfig(knots=2)
    with pytest.raises(ConfigError):
        OptimiserConfig(lr=0.0)


def test_rrt_connect_with_simplification_returns_a_valid_path(body, problem):
    pytest.importorskip("ompl")
    start, goal, scene = problem
    # A generous limit (the search returns when it has a path): a busy machine must not fail the test.
    path, seconds = scene_rrt_connect(start, goal, scene, time_limit=30.0, simplify=True, seed=0)
    assert path is not None and seconds > 0
    assert torch.equal(path[0], start) and torch.equal(path[-1], goal)
    assert bool(obstacle_outcome(body, [path], (start, goal, scene))["success"][0])


def test_compiled_rrt_connect_plans_around_what_the_line_hits():
    """The compiled RRT-Connect as a registry baseline: a problem the joint line collides on is solved,
    its plan judged collision-free by judge's dense check (torch), the same seed the same path."""
    from kinlearn import Problem, baselines
    from kinlearn.data.problems import ProblemSet

    heldout = Path(__file__).resolve().parents[1] / "benchmarks" / "data" / "obstacle_problems_heldout.npz"
    problems = ProblemSet.load(heldout, robot="iiwa14")
    start, goal, scene = problems[problems.hard].problem(0)
    planner = baselines.make("compiled-rrt-connect", "iiwa14", time_limit=5.0, seed=1)
    assert planner.avoids_obstacles
    problem = Problem.make(load_robot("iiwa14"), start, goal, obstacles=scene)
    a, b = planner.plan(problem), planner.plan(problem)
    assert bool(a.collision_free) and bool(a.success)
    assert torch.equal(a.joints, b.joints)
    line = baselines.make("joint-line", "iiwa14")
    with pytest.warns(UserWarning):
        assert not bool(line.plan(problem).collision_free)


def test_sampling_baselines_search_the_planners_box():
    """The ur5's problems made within its tool model's ±π (the committed set): the compiled and OMPL
    RRT-Connect search within ±π there, as the planner does, and their paths stay within it."""
    import numpy as np

    from kinlearn.collision import planning_body
    from kinlearn.data.problems import ProblemSet
    from kinlearn.planning.obstacle_baselines import compiled_rrt_connect

    data = Path(__file__).resolve().parents[1] / "benchmarks" / "data" / "scene_problems_ur5_within.npz"
    problems = ProblemSet.load(data, robot="ur5")
    tool = planning_body(load_robot("ur5")).double()
    start, goal, scene = problems[problems.hard].problem(0)
    for method in (compiled_rrt_connect, scene_rrt_connect):
        path, _ = method(start, goal, scene, time_limit=30.0, body=tool)  # returns when found
        assert path is not None and float(path.abs().max()) <= np.pi + 1e-9
        assert bool(check_path(tool, path, scene).collision_free)
