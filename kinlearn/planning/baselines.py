"""Planners that learn nothing, for comparison with the learned trajectory model.

Each function takes a batch of start and goal states ``(..., dof + 3)`` (s = [θ, ef], see
:class:`~kinlearn.body.state.StateLayout`) and returns a :class:`~kinlearn.planning.plan.Plan` of ``steps`` steps,
so the same metrics (:mod:`kinlearn.evaluation.metrics`) apply to all of them:

- :func:`joint_line`: θ moves on a straight line in joint space (joint interpolation). Fixed time,
  always within the limits, ends exactly at θ(T); the end effector follows a curve.
- :func:`cartesian_line`: the end effector is sent along the straight line from ef(s(0)) to ef(s(T))
  by damped-least-squares IK on the robot's exact kinematics. Perfect on the paper's geometric
  metrics by construction (its waypoints *are* the line); what it reveals is whether the joints can
  follow, through the executed path and the goal error. It ends at *an* IK solution for the goal
  position, not necessarily at θ(T).
- :func:`rrt_connect`: OMPL's RRT-Connect in joint space (optional dependency ``ompl``).

None of them knows about obstacles (for those see :mod:`kinlearn.planning.obstacle_baselines`). Each also
comes as a planner of the planner protocol (:class:`~kinlearn.planning.plan.PlannerLike`), listed in the
baseline registry (:mod:`kinlearn.baselines`): :class:`JointLine`, :class:`CartesianLine` and
:class:`RRTConnect` take a :class:`~kinlearn.data.problem.Problem` and return a
:class:`~kinlearn.planning.plan.Plan` judged by :func:`~kinlearn.planning.plan.judge`; given obstacles,
they say so (``avoids_obstacles = False`` and an :class:`~kinlearn.errors.ObstaclesIgnoredWarning`) and
their plan says whether it collides.

Old names, kept for one release with a :class:`DeprecationWarning`: ``joint_interpolation``
(:func:`joint_line`), ``cartesian_dls`` (:func:`cartesian_line`), ``JointInterpolation``
(:class:`JointLine`), ``CartesianDLS`` (:class:`CartesianLine`).
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import torch

from ..body.kinematics import dls_step, kinematics
from ..body.robot import Robot, load_robot
from ..body.state import StateLayout, straight_line
from ..checks import as_int, as_real, check_finite, check_last_dim
from ..collision.body import BodySpheres
from ..collision.ompl import OmplRrtConnect
from ..data.problem import LIMIT_TOLERANCE, Problem
from ..errors import (
    ConfigError,
    KinlearnDeprecationWarning,
    ObstaclesIgnoredWarning,
    PlanningError,
    ShapeError,
)
from ..polyline import resample
from .judge import judge
from .plan import Plan

__all__ = [
    "Baseline",
    "CartesianLine",
    "JointLine",
    "PlanningError",
    "RRTConnect",
    "cartesian_line",
    "joint_line",
    "rrt_connect",
    "rrt_connect_timed",
]

#: Old names → new ones, kept for one release (module ``__getattr__`` warns).
_RENAMED = {
    "joint_interpolation": "joint_line",
    "cartesian_dls": "cartesian_line",
    "JointInterpolation": "JointLine",
    "CartesianDLS": "CartesianLine",
}


def __getattr__(name: str):
    if name in _RENAMED:
        new = _RENAMED[name]
        warnings.warn(
            f"kinlearn.planning.baselines.{name} is now {new} (kinlearn.baselines.{new}); the old name goes "
            "in the next release",
            KinlearnDeprecationWarning,
            stacklevel=2,
        )
        return globals()[new]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _check_steps(steps) -> None:
    as_int(steps, "steps (at least one intermediate waypoint)", minimum=2, maximum=MAX_STEPS)


#: The most steps a baseline's path (or its DLS iterations) may have: a bound on its work and memory.
MAX_STEPS = 10_000
#: The longest search an RRT-Connect query may be given (s).
MAX_TIME_LIMIT = 3600.0


def as_robot(robot) -> Robot:
    """``robot`` as a :class:`Robot`: one already, or the name of a bundled or registered arm (as the
    planner takes it); :class:`ConfigError` for anything else, ``UnknownRobotError`` for an unknown name."""
    if isinstance(robot, Robot):
        return robot
    if isinstance(robot, str):
        return load_robot(robot)
    raise ConfigError(f"robot must be a kinlearn.Robot or a robot's name, got {type(robot).__name__}")


class Baseline:
    """What every baseline of the registry (:mod:`kinlearn.baselines`) is: a frozen dataclass planner of
    the protocol (:class:`~kinlearn.planning.plan.PlannerLike`) whose first field ``robot`` is a
    :class:`Robot` or a robot's name (or a :class:`~kinlearn.collision.BodySpheres`: its robot, and the
    spheres its plans are checked with), whose last field ``body`` (``None``: the robot's default
    spheres) checks its plans among obstacles, and which says, in class attributes, what it does:

    - ``label``: its name in tables and messages;
    - ``avoids_obstacles``: True where it plans around a problem's obstacles; False where it plans as in
      free space: given obstacles, it warns (:class:`~kinlearn.errors.ObstaclesIgnoredWarning`) and its plan
      is still checked among them (``collision_free`` says which collide, and ``success`` requires it);
    - ``goals``: the goal kinds it plans for (``"state"``, ``"position"``);
    - ``requires``: the optional modules it needs (``("ompl",)``): without them it is not available;
    - ``one_at_a_time``: it solves one problem after another (a search), so evaluations may give it a
      subset.
    """

    label: ClassVar[str] = "baseline"
    avoids_obstacles: ClassVar[bool] = False
    goals: ClassVar[tuple[str, ...]] = ("state",)
    requires: ClassVar[tuple[str, ...]] = ()
    one_at_a_time: ClassVar[bool] = False

    def __post_init__(self) -> None:
        robot = self.robot
        if isinstance(robot, BodySpheres):
            if self.body is None:
                object.__setattr__(self, "body", robot)
            robot = robot.robot
        object.__setattr__(self, "robot", as_robot(robot))
        if self.body is not None and not isinstance(self.body, BodySpheres):
            raise ConfigError(f"body must be a kinlearn BodySpheres or None, got {type(self.body).__name__}")

    def check_problem(self, problem: Problem) -> None:
        """Refuse a problem this baseline cannot plan (:class:`ConfigError`: not a :class:`Problem`, of
        another robot, of a goal kind not in ``goals``); warn where it would ignore the problem's
        obstacles. A baseline's ``plan`` calls it first."""
        _check_problem(self, problem, self.label)
        if problem.goal_kind not in self.goals:
            problem.require(self.goals[0], self.label)
        if problem.obstacles is not None and not self.avoids_obstacles:
            warnings.warn(
                f"{self.label} ignores obstacles: it plans as in free space, and its plan is checked among "
                "them (plan.collision_free says which collide); for a baseline that avoids them see "
                "kinlearn.baselines.names(avoids_obstacles=True)",
                ObstaclesIgnoredWarning,
                stacklevel=3,
            )

    _check = check_problem


def _check_dls(iterations, damping) -> None:
    as_int(iterations, "iterations", minimum=1, maximum=MAX_STEPS)
    as_real(damping, "damping (m)", minimum=0.0, open_minimum=True)


def _endpoints(robot: Robot, start: torch.Tensor, goal: torch.Tensor, steps: int) -> StateLayout:
    layout = StateLayout(robot.dof)
    check_last_dim(start, layout.size, "start states")
    check_last_dim(goal, layout.size, "goal states")
    if start.shape != goal.shape:
        raise ShapeError(
            f"start and goal states must have the same shape, got {tuple(start.shape)} and {tuple(goal.shape)}"
        )
    check_finite(start, "start states")
    check_finite(goal, "goal states")
    _check_steps(steps)
    return layout


def _plan_from_joints(robot: Robot, start, goal, joints: torch.Tensor, waypoints=None) -> Plan:
    """A Plan whose joint path is ``joints (..., T+1, dof)``, judged against the goal state (joints and
    end effector); waypoints default to its interior FK points."""
    ef = kinematics(robot, "fast").position(joints, validate=False)
    within = robot.within_limits(joints, LIMIT_TOLERANCE).all(-1)
    return Plan.from_joints(goal, joints, ef, waypoints=waypoints, within_limits=within, robot=robot.name)


@torch.no_grad()
def joint_line(robot: Robot, start: torch.Tensor, goal: torch.Tensor, steps: int = 11) -> Plan:
    """Joint-space linear interpolation: θ(k) = θ(0) + (k/T)(θ(T) − θ(0)), k = 0 … T.

    Waypoints are the end-effector positions (exact FK) of the interior configurations, so the
    executed path passes exactly through them and ends at FK(θ(T)).
    """
    layout = _endpoints(robot, start, goal, steps)
    theta0, _ = layout.split(start)
    thetaT, _ = layout.split(goal)
    joints = straight_line(theta0, thetaT, steps)
    return _plan_from_joints(robot, start, goal, joints)


@torch.no_grad()
def cartesian_line(
    robot: Robot,
    start: torch.Tensor,
    goal: torch.Tensor,
    steps: int = 11,
    iterations: int = 20,
    damping: float = 1e-2,
) -> Plan:
    """A straight Cartesian line of the end effector, followed by damped-least-squares IK.

    The waypoints are the line's interior points x(k) = ef(0) + (k/T)(ef(T) − ef(0)), with ef(0), ef(T)
    the end-effector parts of the start and goal states. θ(0) is the start's joints; each later
    θ(k) is ``iterations`` DLS steps (:func:`~kinlearn.body.kinematics.dls_step`, damping λ in metres,
    clamped to the joint limits) towards x(k), warm-started from θ(k−1). ``plan.joints`` is that IK
    path and ``plan.ef`` its true FK.

    Caveats: the line may leave the workspace or pass where the arm cannot follow it within its
    joint limits, and DLS gets stuck near singularities: then the executed path leaves the line
    and the goal error (see :func:`~kinlearn.evaluation.metrics.plan_metrics`) shows by how much. θ(T) of the
    goal state is not used: the path ends at whatever IK solution the warm start leads to.
    """
    layout = _endpoints(robot, start, goal, steps)
    _check_dls(iterations, damping)
    theta, ef0 = layout.split(start)
    _, efT = layout.split(goal)
    joints, line = _dls_path(robot, theta, ef0, efT, steps, iterations, damping)
    return _plan_from_joints(robot, start, goal, joints, waypoints=line[..., 1:-1, :])


def _dls_path(robot: Robot, theta, ef0, efT, steps: int, iterations: int, damping: float):
    """The DLS IK path along the straight end-effector line ef0 → efT: joints ``(..., T+1, dof)`` and the
    line ``(..., T+1, 3)``."""
    kin = kinematics(robot, "fast")
    line = straight_line(ef0, efT, steps)  # (..., T+1, 3)
    path = [theta]
    for k in range(1, steps + 1):
        theta = dls_step(kin, theta, line[..., k, :], iterations=iterations, damping=damping, clamp=True)
        path.append(theta)
    return torch.stack(path, dim=-2), line


# --------------------------------------------------------------------------------------------------
# OMPL RRT-Connect
# --------------------------------------------------------------------------------------------------


def rrt_connect_timed(
    robot: Robot,
    start: torch.Tensor,
    goal: torch.Tensor,
    steps: int = 11,
    time_limit: float = 1.0,
    seed: int | None = 0,
    simplify: bool = False,
) -> tuple[Plan, torch.Tensor]:
    """:func:`rrt_connect`, also returning each query's planning time in seconds ``(...)`` (float64, CPU).

    A query's time is the wall time of everything done for it: setting the start and goal, OMPL's
    ``solve``, the optional simplification, reading the path back and resampling it.
    """
    layout = _endpoints(robot, start, goal, steps)
    as_real(time_limit, "time_limit (s)", minimum=0.0, open_minimum=True, maximum=MAX_TIME_LIMIT)
    rrt = OmplRrtConnect(robot, why="rrt_connect")  # free space: every state valid
    theta0, _ = layout.split(start)
    thetaT, _ = layout.split(goal)
    robot.check_joints(theta0, what="start joints")
    robot.check_joints(thetaT, what="goal joints")
    batch = start.shape[:-1]
    lo, hi = robot.lower, robot.upper
    q0 = np.clip(theta0.detach().reshape(-1, robot.dof).double().cpu().numpy(), lo, hi)
    qT = np.clip(thetaT.detach().reshape(-1, robot.dof).double().cpu().numpy(), lo, hi)
    paths = np.empty((q0.shape[0], steps + 1, robot.dof))
    times = np.empty(q0.shape[0])
    for i in range(q0.shape[0]):
        t0 = time.perf_counter()
        vertices, _ = rrt.solve(
            q0[i],
            qT[i],
            time_limit=time_limit,
            seed=seed if i == 0 else None,  # seeded once: the queries draw from one stream
            simplify=simplify,
            simplify_time=math.inf,
        )
        if vertices is None:
            raise PlanningError(
                f"RRT-Connect found no exact path for query {i} within time_limit={time_limit} s; "
                "raise time_limit"
            )
        vertices[0], vertices[-1] = q0[i], qT[i]
        paths[i] = resample(vertices, steps + 1)
        times[i] = time.perf_counter() - t0

    joints = torch.as_tensor(paths, dtype=start.dtype, device=start.device).reshape(
        *batch, steps + 1, robot.dof
    )
    # Pin the endpoints to the given joints exactly (resampling in float64 keeps them; the cast may not).
    joints = torch.cat((theta0.unsqueeze(-2), joints[..., 1:-1, :], thetaT.unsqueeze(-2)), dim=-2)
    plan = _plan_from_joints(robot, start, goal, joints.detach())
    return plan, torch.as_tensor(times, dtype=torch.float64).reshape(batch)


def rrt_connect(
    robot: Robot,
    start: torch.Tensor,
    goal: torch.Tensor,
    steps: int = 11,
    time_limit: float = 1.0,
    seed: int | None = 0,
    simplify: bool = False,
) -> Plan:
    """OMPL RRT-Connect in joint space from θ(0) to θ(T), one query at a time, resampled to ``steps`` steps.

    The planner searches the box of the joint limits with every state valid (no obstacles, no self
    collision). Its path (a few straight joint-space segments through random tree vertices) is
    resampled to ``steps + 1`` configurations evenly spaced by joint-space arc length, so the corners
    at the tree vertices may be cut; it starts at θ(0) and ends at θ(T) exactly. With ``simplify`` OMPL
    shortens the path first, which without obstacles gives the straight segment, i.e.
    :func:`joint_line`. Waypoints are the FK of the interior configurations.

    Honest caveat: **without obstacles RRT-Connect is trivial**: the two trees connect after one or two
    extensions, a query takes tens of microseconds, and its path is a random detour of joint
    interpolation. It is a fair baseline for planning *time* (and its tail) only alongside this
    statement; its time grows with obstacles (among them: :class:`kinlearn.planning.obstacle_baselines.SceneRRTConnect`).

    ``seed`` seeds OMPL's process-wide random generator before planning, which makes a call
    reproducible (``None`` leaves it alone). Raises :class:`MissingDependencyError` without ``ompl``
    and :class:`PlanningError` if a query finds no path within ``time_limit`` seconds. Use
    :func:`rrt_connect_timed` to get the per-query planning times as well.
    """
    return rrt_connect_timed(robot, start, goal, steps, time_limit, seed, simplify)[0]


# --------------------------------------------------------------------------------------------------
# The planner protocol: plan(problem) -> Plan
# --------------------------------------------------------------------------------------------------


def _check_problem(planner, problem: Problem, who: str) -> None:
    if not isinstance(problem, Problem):
        raise ConfigError(
            f"{who} plans a kinlearn Problem (Problem.make(robot, start, goal)), got {type(problem).__name__}"
        )
    if problem.robot.name != planner.robot.name:
        raise ConfigError(
            f"{who} plans for {planner.robot.name!r}; the problems are for {problem.robot.name!r}"
        )


@dataclass(frozen=True)
class JointLine(Baseline):
    """:func:`joint_line` (joint interpolation) as a planner (:class:`~kinlearn.planning.plan.PlannerLike`):
    goal states only; obstacles are not avoided (a plan among them is checked and says whether it
    collides)."""

    robot: Robot | str
    steps: int = 11
    body: BodySpheres | None = None

    label: ClassVar[str] = "joint interpolation"

    def __post_init__(self) -> None:
        super().__post_init__()
        _check_steps(self.steps)

    def plan(self, problem: Problem) -> Plan:
        self._check(problem)
        with torch.no_grad():
            joints = straight_line(problem.start_joints, problem.goal_joints, self.steps)
            return judge(problem, joints, body=self.body)


@dataclass(frozen=True)
class CartesianLine(Baseline):
    """:func:`cartesian_line` as a planner: the end effector on a straight line to the goal (a state's end
    effector or a position), followed by DLS IK; ignores obstacles (a plan among them is checked). With
    ``to_goal_joints`` (state goals) a last straight joint-space segment goes from the IK's last
    configuration to the goal's joints, so the path ends there (long where the IK's redundancy
    resolution differs from the goal's)."""

    robot: Robot | str
    steps: int = 11
    iterations: int = 20
    damping: float = 1e-2
    to_goal_joints: bool = False
    body: BodySpheres | None = None

    label: ClassVar[str] = "Cartesian line + DLS IK"
    goals: ClassVar[tuple[str, ...]] = ("state", "position")

    def __post_init__(self) -> None:
        super().__post_init__()
        _check_steps(self.steps)
        _check_dls(self.iterations, self.damping)

    def plan(self, problem: Problem) -> Plan:
        self._check(problem)
        if self.to_goal_joints:
            problem.require("state", f"{self.label} with to_goal_joints")
        ef0 = problem.start[..., self.robot.dof :]
        with torch.no_grad():
            joints, line = _dls_path(
                self.robot,
                problem.start_joints,
                ef0,
                problem.target,
                self.steps,
                self.iterations,
                self.damping,
            )
            waypoints = line[..., 1:-1, :]
            if self.to_goal_joints:
                joints = torch.cat((joints, problem.goal_joints.unsqueeze(-2).to(joints.dtype)), dim=-2)
                waypoints = None
            return judge(problem, joints, waypoints=waypoints, body=self.body)


@dataclass(frozen=True)
class RRTConnect(Baseline):
    """:func:`rrt_connect` (free space: every state valid) as a planner; goal states only. For planning
    around obstacles use :class:`kinlearn.planning.obstacle_baselines.SceneRRTConnect`."""

    robot: Robot | str
    steps: int = 11
    time_limit: float = 1.0
    seed: int | None = 0
    simplify: bool = False
    body: BodySpheres | None = None

    label: ClassVar[str] = "RRT-Connect (OMPL)"
    requires: ClassVar[tuple[str, ...]] = ("ompl",)
    one_at_a_time: ClassVar[bool] = True

    def plan(self, problem: Problem) -> Plan:
        self._check(problem)
        joints = rrt_connect(
            self.robot, problem.start, problem.goal, self.steps, self.time_limit, self.seed, self.simplify
        ).joints
        return judge(problem, joints, body=self.body)
