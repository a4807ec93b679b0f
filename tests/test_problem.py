"""Problem batches and the planner protocol: every planner takes a Problem and returns a judged Plan."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from kinlearn import baselines
from kinlearn.baselines import CartesianLine, JointLine, TrajectoryOptimiser
from kinlearn.body.kinematics import kinematics
from kinlearn.body.robot import load_robot
from kinlearn.collision.body import body_spheres
from kinlearn.collision.scene import Scene
from kinlearn.data.problem import Problem
from kinlearn.errors import (
    ConfigError,
    DTypeError,
    JointLimitError,
    NonFiniteError,
    ObstacleError,
    ObstaclesIgnoredWarning,
    ShapeError,
    StateError,
)
from kinlearn.planning.judge import judge
from kinlearn.planning.plan import Plan, PlannerLike
from kinlearn.planning.planner import Planner


@pytest.fixture(scope="module")
def joints(robot):
    g = torch.Generator().manual_seed(0)
    lo, hi = robot.limits(torch.float64)
    u = torch.rand(2, 4, robot.dof, generator=g, dtype=torch.float64)
    return lo + 0.8 * (hi - lo) * (u + 0.125)


def test_make_fills_the_end_effector_and_broadcasts(robot, joints):
    start, goal = joints[0], joints[1]
    p = Problem.make(robot, start, goal)
    assert p.goal_kind == "state" and p.batch_shape == (4,) and len(p) == 4
    ef = kinematics(robot).position(start)
    assert torch.allclose(p.start[:, robot.dof :], ef, atol=1e-9)
    assert torch.equal(p.start_joints, start) and torch.equal(p.goal_joints, goal)
    assert torch.equal(p.features(), torch.cat((p.start, p.goal), -1))
    # A single start broadcasts against a batch of goals; a state's own ef is accepted when it is FK's.
    one = Problem.make(robot, p.start[0], goal)
    assert one.batch_shape == (4,) and torch.equal(one.start[3], p.start[0])
    assert p[1:3].batch_shape == (2,) and torch.equal(p[2].goal, p.goal[2])


def test_position_goals(robot, joints):
    target = torch.tensor([0.5, 0.1, 0.6], dtype=torch.float64)
    p = Problem.make(robot, joints[0], goal_position=target)
    assert p.goal_kind == "position" and p.goal.shape == (4, 3)
    assert torch.equal(p.target[0], target)
    with pytest.raises(ConfigError, match="state goals"):
        _ = p.goal_joints
    with pytest.raises(ConfigError, match="state goals"):
        p.features()
    q = Problem.make(robot, joints[0], joints[1]).position_goals()
    assert q.goal_kind == "position" and q.goal.shape == (4, 3)


def test_bad_problems_raise_typed_errors(robot, joints):
    start, goal = joints[0, 0], joints[1, 0]
    with pytest.raises(ConfigError, match="exactly one"):
        Problem.make(robot, start)
    with pytest.raises(ConfigError, match="Robot"):
        Problem.make("iiwa14", start, goal)
    with pytest.raises(ShapeError, match="start must have shape"):
        Problem.make(robot, start[:5], goal)
    with pytest.raises(ShapeError, match="do not broadcast"):
        Problem.make(robot, joints[0, :3], joints[1])
    with pytest.raises(DTypeError):
        Problem.make(robot, torch.ones(robot.dof, dtype=torch.bool), goal)
    with pytest.raises(DTypeError, match="real numbers"):
        Problem.make(robot, [True] * robot.dof, goal)
    with pytest.raises(DTypeError, match="array of numbers"):
        Problem.make(robot, start, [[0.0] * robot.dof, [0.0]])
    bad = start.clone()
    bad[2] = float("nan")
    with pytest.raises(NonFiniteError):
        Problem.make(robot, bad, goal)
    far = start.clone()
    far[0] = 10.0
    with pytest.raises(JointLimitError, match="goal joints"):  # start and goal are checked in one call
        Problem.make(robot, start, far)
    with pytest.raises(JointLimitError, match="start joints"):
        Problem.make(robot, far, start)
    state = torch.cat((start, torch.tensor([9.0, 9.0, 9.0], dtype=torch.float64)))
    with pytest.raises(StateError, match="end-effector part"):
        Problem.make(robot, state, goal)
    with pytest.raises(StateError, match=r"^goal"):
        Problem.make(robot, goal, state)
    with pytest.raises(ObstacleError):
        Problem.make(robot, start, goal, obstacles=torch.ones(3, 3))
    with pytest.raises(ShapeError, match="batch shape"):
        Problem.make(robot, joints[0], joints[1], obstacles=torch.tensor([[[0.5, 0, 0.5, 0.1]]] * 3))
    with pytest.raises(ConfigError, match="goal_kind"):
        Problem(robot, start, goal, "pose")


#: Small settings for the registered baselines that search or optimise (the rest take their defaults).
TINY = {"trajectory-optimiser": {"steps": 2}, "scene-rrt-connect": {"time_limit": 0.5}}


def test_every_planner_plans_a_problem_by_the_protocol(robot):
    """Each registered baseline (and the learned planner) takes a Problem and returns a judged Plan of
    its batch that starts at the problem's start, and says whether it avoids obstacles."""
    start = torch.tensor([[0.1, 0.3, 0.0, -1.0, 0.0, 0.8, 0.0], [-0.2, 0.5, 0.1, -1.2, 0.1, 0.6, 0.2]])
    goal = start + torch.tensor([0.3, -0.1, 0.2, 0.2, -0.1, 0.1, 0.3])
    p = Problem.make(robot, start.double(), goal.double())
    planners = {"learned": Planner.default("iiwa14")}
    for name in baselines.names(only_available=True):
        planners[name] = baselines.make(name, robot, **TINY.get(name, {}))
        assert isinstance(type(planners[name]).avoids_obstacles, bool), name
    assert {"joint-line", "cartesian-line", "trajectory-optimiser"} <= set(planners)
    for name, planner in planners.items():
        assert isinstance(planner, PlannerLike), name
        assert planner.robot is robot or planner.robot.name == robot.name, name
        plan = planner.plan(p)
        assert isinstance(plan, Plan) and plan.joints.shape[:-2] == (2,), name
        assert torch.allclose(plan.joints[:, 0].double(), p.start_joints, atol=1e-6), name
        assert plan.success.shape == (2,) and plan.collision_free is None, name  # free space: not checked
        assert bool((plan.goal_error >= 0).all()), name
        # The verdict is judge's: its paths judged afresh succeed wherever the plan says they do, with
        # the same goal errors.
        again = judge(p, plan.joints.double())
        assert bool((plan.success <= again.success).all()), name
        assert torch.allclose(again.goal_error, plan.goal_error.double(), atol=1e-4), name


def test_a_baseline_that_ignores_obstacles_says_so(robot, joints):
    start, goal = joints[0, :1], joints[1, :1]
    mid = kinematics(robot).position((start + goal) / 2)
    scene = Scene(spheres=torch.cat((mid, torch.full((1, 1), 0.12, dtype=torch.float64)), -1).unsqueeze(1))
    p = Problem.make(robot, start, goal, obstacles=scene)
    for name in baselines.names(avoids_obstacles=False, only_available=True):
        with pytest.warns(ObstaclesIgnoredWarning, match="ignores obstacles"):
            plan = baselines.make(name, robot).plan(p)
        assert plan.collision_free is not None, name  # still checked among them
        assert bool((plan.success <= plan.collision_free).all()), name
    assert "trajectory-optimiser" in baselines.names(avoids_obstacles=True)


def test_baselines_plan_problems_and_say_how_it_went(robot, joints):
    p = Problem.make(robot, joints[0], joints[1])
    plan = JointLine(robot).plan(p)
    assert plan.joints.shape == (4, 12, robot.dof)
    assert bool(plan.success.all()) and plan.collision_free is None
    assert torch.allclose(plan.joints[:, -1], p.goal_joints)
    # The Cartesian line reaches the position but not the goal's joints: judged against the state...
    dls = CartesianLine(robot).plan(p)
    assert bool((dls.joint_error > 0.05).any()) and not bool(dls.success.all())
    # ...and against the position alone it may succeed.
    pos = CartesianLine(robot).plan(p.position_goals())
    assert torch.isnan(pos.joint_error).all()
    assert bool((pos.success == (pos.goal_error <= 0.01) & ~torch.isnan(pos.goal_error)).all())
    with pytest.raises(ConfigError, match="state goals"):
        JointLine(robot).plan(p.position_goals())
    with pytest.raises(ConfigError, match="panda"):
        JointLine(load_robot("panda")).plan(p)
    with pytest.raises(ConfigError, match="Problem"):
        JointLine(robot).plan((joints[0], joints[1]))
    with pytest.raises(ConfigError, match="steps"):
        JointLine(robot, steps=1)


def test_the_learned_planner_plans_a_problem_as_its_arguments(robot, joints):
    planner = Planner.default("iiwa14")
    p = Problem.make(robot, joints[0], joints[1])
    a, b = planner.plan(p), planner.plan(joints[0], joints[1])
    assert torch.equal(a.joints.double(), b.joints.double()) and torch.equal(a.success, b.success)
    pos = planner.plan(p.position_goals())
    assert torch.isnan(pos.joint_error).all()
    with pytest.raises(ConfigError, match="alone"):
        planner.plan(p, joints[1])
    with pytest.raises(ConfigError, match="panda"):
        Planner.default("panda").plan(p)


def test_obstacles_are_checked_for_every_planner(robot, joints):
    start, goal = joints[0, :2], joints[1, :2]
    mid = kinematics(robot).position((start + goal) / 2)  # a sphere on the straight line's middle
    scene = Scene(spheres=torch.cat((mid, torch.full((2, 1), 0.12, dtype=torch.float64)), -1).unsqueeze(1))
    p = Problem.make(robot, start, goal, obstacles=scene)
    with pytest.warns(ObstaclesIgnoredWarning):
        line = JointLine(robot).plan(p)
    assert line.collision_free is not None and not bool(line.collision_free.any())
    assert not bool(line.success.any())
    opt = TrajectoryOptimiser(body_spheres(robot).double(), steps=3).plan(p)
    assert opt.collision_free.shape == (2,) and torch.allclose(opt.joints[:, -1], goal)
    assert bool((opt.success <= opt.collision_free).all())
    free = JointLine(body_spheres(robot).double()).plan(Problem.make(robot, start, goal))
    assert free.collision_free is None and bool(free.success.all())  # free space: not checked


def test_judge_refuses_paths_that_do_not_fit(robot, joints):
    p = Problem.make(robot, joints[0], joints[1])
    with pytest.raises(ShapeError, match="joint paths"):
        judge(p, torch.zeros(3, 5, robot.dof, dtype=torch.float64))
    found = torch.tensor([True, False, True, True])
    plan = judge(p, torch.stack((p.start_joints, p.goal_joints), -2), found=found)
    assert plan.success.tolist() == [True, False, True, True]


def test_problems_from_endpoint_pairs_and_obstacle_sets(robot):
    from kinlearn.data.endpoints import EndpointConfig, make_endpoints
    from kinlearn.data.problems import ProblemSet

    pairs = make_endpoints(EndpointConfig(robot="iiwa14", n=8, seed=3))
    p = Problem.from_pairs(pairs)
    assert p.goal_kind == "state" and p.batch_shape == (8,) and p.robot.name == "iiwa14"
    assert torch.equal(p.start, pairs.start.double())
    path = Path(__file__).resolve().parents[1] / "benchmarks" / "data" / "obstacle_problems_heldout.npz"
    sets = ProblemSet.load(path)[:4]
    q = Problem.from_problem_set(sets)
    assert q.batch_shape == (4,) and tuple(q.obstacles.batch_shape) == (4,)
    assert torch.equal(q.start_joints, sets.start)
    # The learned planner and a baseline plan the same obstacle problems; both say whether they collide.
    a = Planner.default("iiwa14").plan(q)
    b = JointLine(robot).plan(q)
    assert a.collision_free.shape == b.collision_free.shape == (4,)
    assert bool((b.collision_free == ~sets.hard).all())  # "hard": the straight joint line collides


def test_evaluate_workspace_takes_planners_and_says_what_it_wants(robot):
    from kinlearn.data.endpoints import EndpointConfig, make_endpoints
    from kinlearn.evaluation.workspace import evaluate_workspace

    pairs = make_endpoints(EndpointConfig(robot="iiwa14", n=16, seed=4, preset="workspace"))
    res = evaluate_workspace(robot, pairs, {"line": JointLine(robot), "dls": CartesianLine(robot)})
    assert res["line"]["state_success"] == 1.0
    # The Cartesian line ends at an IK solution: it misses the goal joints, but with position goals
    # only the end effector counts.
    pos = evaluate_workspace(robot, pairs, {"dls": CartesianLine(robot)}, goal_kind="position")
    assert res["dls"]["state_success"] < pos["dls"]["state_success"] == pos["dls"]["ef_success"]
    with pytest.raises(ConfigError, match="plan\\(problem\\)"):
        evaluate_workspace(robot, pairs, {"lambda": lambda a, b: None})
    with pytest.raises(ConfigError, match="goal_kind"):
        evaluate_workspace(robot, pairs, {"line": JointLine(robot)}, goal_kind="pose")


@pytest.mark.parametrize("name", ["iiwa14", "ur5"])
def test_a_few_paths_and_many_get_one_verdict(name):
    """Up to SMALL_BATCH float64 paths are judged in one compiled call
    (:meth:`~kinlearn.collision.kernel.KernelChain.judged`), more in torch: the same verdict on paths
    that pass and that fail each part of it (a knot past a limit, a first knot off the start, the goal
    missed in joints or in position, not found), for joint goals and position goals; NaN refused by both."""
    from kinlearn.data.problem import SMALL_BATCH

    robot = load_robot(name)
    g = torch.Generator().manual_seed(3)
    n, K = SMALL_BATCH + 4, 6
    lo, hi = torch.as_tensor(robot.lower), torch.as_tensor(robot.upper)
    u = lambda *s: torch.rand(*s, generator=g, dtype=torch.float64)  # noqa: E731
    start, goal = lo + 0.1 + (hi - lo - 0.2) * u(n, robot.dof), lo + 0.1 + (hi - lo - 0.2) * u(n, robot.dof)
    paths = start[:, None] + torch.linspace(0, 1, K, dtype=torch.float64)[:, None] * (goal - start)[:, None]
    paths[1::5, 2, 0] = hi[0] + 0.01  # past a limit
    paths[2::5, 0, 1] += 1e-5  # off the start
    paths[3::5, -1, 2] += 0.04  # the goal's joints missed (and its position by a few cm or not)
    paths[4::5, -1, 3] += 0.2
    found = u(n) > 0.2
    for p in (Problem.make(robot, start, goal), Problem.make(robot, start, goal).position_goals()):
        many = judge(p, paths, found=found)  # torch
        assert 0 < int(many.success.sum()) < n
        for part in (slice(0, 8), slice(8, n)):  # compiled
            few = judge(p[part], paths[part].numpy(), found=found[part])
            assert torch.equal(few.success, many.success[part])
            for f in ("goal_error", "joint_error", "ef", "goal", "target", "waypoints"):
                assert torch.allclose(getattr(few, f), getattr(many, f)[part], atol=1e-12, equal_nan=True), f
        bad = paths[:4].clone()
        bad[0, 3, 0] = float("nan")
        for batch in (bad, bad.numpy()):
            with pytest.raises(NonFiniteError):
                judge(p[:4], batch)
