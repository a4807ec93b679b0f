"""The baseline registry: what iterates it sees a baseline registered there, and no longer after it is
unregistered; the registry refuses what cannot be a baseline; the old baseline names still work, warning."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import pytest
import torch

from kinlearn import baselines
from kinlearn.baselines import Baseline
from kinlearn.body.robot import Robot
from kinlearn.collision import body_spheres
from kinlearn.data.problem import Problem
from kinlearn.errors import ConfigError
from kinlearn.evaluation.model_error import evaluate_believed, planner_labels
from kinlearn.planning.judge import judge
from kinlearn.planning.plan import Plan


@dataclass(frozen=True)
class StandStill(Baseline):
    """A throwaway baseline: it stays at the start (two equal configurations)."""

    robot: Robot | str
    body: object = None

    label: ClassVar[str] = "stand still"
    goals: ClassVar[tuple[str, ...]] = ("state", "position")

    def plan(self, problem: Problem) -> Plan:
        self.check_problem(problem)
        joints = problem.start_joints.unsqueeze(-2).expand(*problem.batch_shape, 2, self.robot.dof)
        return judge(problem, joints)


def test_a_registered_baseline_is_iterated_until_unregistered(robot):
    q0 = torch.tensor([[0.1, 0.3, 0.0, -1.0, 0.0, 0.8, 0.0]], dtype=torch.float64)
    goal = torch.tensor([[0.5, 0.0, 0.5]], dtype=torch.float64)
    baselines.register("stand-still", StandStill)
    try:
        assert baselines.names()[-1] == "stand-still" and "stand-still" in baselines.names(
            avoids_obstacles=False
        )
        assert "stand-still" in baselines.names(goal_kind="position")
        assert isinstance(baselines.planners(robot)["stand-still"], StandStill)
        # the model-error comparison runs every free-space baseline, this one too: standing still misses
        out = evaluate_believed(robot, robot, q0, goal, rrt=False)
        assert "stand-still" in out and float(out["stand-still"]["error"][0]) > 0.1
        assert planner_labels()["stand-still"] == "stand still (believed model)"
        with pytest.raises(ConfigError, match="registered already"):
            baselines.register("stand-still", StandStill)
    finally:
        baselines.unregister("stand-still")
    assert "stand-still" not in baselines.names()
    assert "stand-still" not in evaluate_believed(robot, robot, q0, goal, rrt=False)
    with pytest.raises(ConfigError, match="no baseline named 'stand-still'"):
        baselines.get("stand-still")


def test_the_registry_refuses_what_cannot_be_a_baseline():
    class NoPlan:
        label = "x"

    class NoAttributes:
        def plan(self, problem):
            return None

    with pytest.raises(ConfigError, match="plan"):
        baselines.register("no-plan", NoPlan)
    with pytest.raises(ConfigError, match="avoids_obstacles"):
        baselines.register("no-attributes", NoAttributes)
    with pytest.raises(ConfigError, match="hyphens"):
        baselines.register("My Planner", StandStill)
    with pytest.raises(ConfigError, match="goal_kind"):
        baselines.names(goal_kind="pose")
    assert "no-plan" not in baselines.names() and "no-attributes" not in baselines.names()


def test_every_built_in_baseline_says_what_it_does(robot):
    built_in = ["joint-line", "cartesian-line", "rrt-connect", "scene-rrt-connect", "trajectory-optimiser"]
    assert [n for n in baselines.names() if n in built_in] == built_in  # in table order
    avoiding = baselines.names(avoids_obstacles=True)
    assert {"scene-rrt-connect", "trajectory-optimiser"} <= set(avoiding)
    assert not {"joint-line", "cartesian-line", "rrt-connect"} & set(avoiding)
    for name in baselines.names():
        cls = baselines.get(name)
        assert cls.avoids_obstacles == (name in avoiding) and cls.label and cls.goals, name
        assert (name in baselines.names(goal_kind="position")) == ("position" in cls.goals), name
    assert "cartesian-line" in baselines.names(goal_kind="position")
    assert baselines.get("rrt-connect").requires == ("ompl",) and baselines.get("rrt-connect").one_at_a_time
    # a seed goes to the searches and is ignored by the deterministic baselines
    assert baselines.make("rrt-connect", robot, seed=5).seed == 5
    assert baselines.make("joint-line", "iiwa14", seed=5) == baselines.JointLine(robot)
    assert baselines.subset_label("RRT-Connect (OMPL)", 500) == "RRT-Connect (OMPL, 500 pairs)"


def test_the_old_baseline_names_warn_and_still_work(robot):
    import kinlearn.planning.baselines as free
    import kinlearn.planning.obstacle_baselines as obstacles

    for module, old, new in (
        (free, "joint_interpolation", "joint_line"),
        (free, "cartesian_dls", "cartesian_line"),
        (free, "JointInterpolation", "JointLine"),
        (free, "CartesianDLS", "CartesianLine"),
        (obstacles, "joint_line", "joint_line_path"),
        (obstacles, "cartesian_line", "cartesian_line_path"),
        (obstacles, "rrt_connect", "scene_rrt_connect"),
    ):
        with pytest.warns(DeprecationWarning, match=new):
            assert getattr(module, old) is getattr(module if old.islower() else free, new)
    start = torch.tensor([0.1, 0.3, 0.0, -1.0, 0.0, 0.8, 0.0], dtype=torch.float64)
    goal = start + 0.3
    p = Problem.make(robot, start, goal)
    body = body_spheres(robot).double()
    # The obstacle module's classes keep their old defaults: ten steps; the Cartesian line ends at the goal.
    with pytest.warns(DeprecationWarning, match="kinlearn.baselines.JointLine"):
        line = obstacles.JointLine(body)
    assert line.body is body and line.plan(p).joints.shape == (11, robot.dof)
    with pytest.warns(DeprecationWarning, match="to_goal_joints=True"):
        cart = obstacles.CartesianLine(body).plan(p)
    assert cart.joints.shape == (12, robot.dof) and torch.allclose(cart.joints[-1], goal)
    path, _ = obstacles.cartesian_line_path(start, goal, steps=10, body=body)
    assert torch.allclose(cart.joints, path, atol=1e-9)
