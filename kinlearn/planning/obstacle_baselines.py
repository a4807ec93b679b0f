"""Baselines for planning around obstacles, one problem at a time: ``(start, goal, scene) → joint path``.

Every function takes the start and goal joints ``(dof,)`` and a :class:`~kinlearn.collision.Scene`
(unbatched) and returns ``(path, seconds)``: the joint path ``(K, dof)`` (float64, CPU; executing it
means moving linearly in joint space between consecutive rows; ``path[0]`` is the start and
``path[-1]`` the goal exactly) or ``None`` when the method found none, and the wall time of the call.
The body is the iiwa14's 12-sphere model with the base, or for another robot the body its planner checks
with (:func:`default_body`, :func:`~kinlearn.collision.planning_body`), unless one is passed; its robot
is the robot planned for.

===============================  =================================================================
:func:`joint_line_path`          the straight joint-space line (:func:`kinlearn.planning.baselines.joint_line`
                                 for one problem); obstacle-unaware.
:func:`cartesian_line_path`      the end effector along a straight line by damped-least-squares IK
                                 (:func:`kinlearn.planning.baselines.cartesian_line`), then a straight
                                 joint-space move from the IK's last configuration to the goal joints;
                                 obstacle-unaware.
:func:`scene_rrt_connect`        OMPL's RRT-Connect on :class:`~kinlearn.collision.ompl.RrtChecker`
                                 (the dense 1 cm check), optionally with OMPL's path simplification,
                                 within a time limit that covers both.
:func:`compiled_rrt_connect`     RRT-Connect compiled with the dense check (:mod:`kinlearn.collision.rrt`),
                                 random vertex shortcuts, within a time limit.
:func:`trajectory_optimiser`     a fixed number of Adam steps on a knot path initialised on the straight
                                 joint line: smoothness + hinge penalties on the body's clearance to the
                                 scene and to itself at the knots and points between them, joint limits
                                 by clamping.
===============================  =================================================================

None of them is a guarantee: judge their paths with :func:`kinlearn.evaluation.obstacles.obstacle_outcome`.

The planners of the protocol (:class:`~kinlearn.planning.plan.PlannerLike`) that avoid obstacles,
:class:`SceneRRTConnect` and :class:`TrajectoryOptimiser`, take a :class:`~kinlearn.data.problem.Problem`
batch (goal states; its obstacles, or free space) and return one :class:`~kinlearn.planning.plan.Plan`,
judged by :func:`~kinlearn.planning.plan.judge`. Paths of different lengths are padded by repeating
their last configuration (zero-length segments: the same motion); a search that found nothing gives
the straight line with ``success`` False. The obstacle-unaware lines as planners are
:class:`kinlearn.planning.baselines.JointLine` and :class:`~kinlearn.planning.baselines.CartesianLine`
(``to_goal_joints=True``); every one is listed in the baseline registry (:mod:`kinlearn.baselines`).

Old names, kept for one release with a :class:`DeprecationWarning`: ``joint_line`` (:func:`joint_line_path`),
``cartesian_line`` (:func:`cartesian_line_path`), ``rrt_connect`` (:func:`scene_rrt_connect`), and the
classes ``JointLine(body, steps=10)`` and ``CartesianLine(body, steps=10, ...)``, which now make
:class:`kinlearn.planning.baselines.JointLine` and :class:`~kinlearn.planning.baselines.CartesianLine`
(``to_goal_joints=True``) with those defaults.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import asdict, dataclass
from functools import cache
from typing import ClassVar

import numpy as np
import torch

from ..body.kinematics import kinematics
from ..body.robot import Robot, load_robot
from ..checks import as_int, as_real
from ..collision import (
    BodySpheres,
    Scene,
    body_obstacle_distance,
    planning_body,
    self_collision_distance,
)
from ..collision.ompl import OmplRrtConnect
from ..data.problem import Problem
from ..errors import ConfigError, KinlearnDeprecationWarning, ShapeError, UnknownRobotError
from . import baselines as _free
from .baselines import MAX_STEPS, Baseline
from .judge import judge
from .plan import Plan

__all__ = [
    "CompiledRRTConnect",
    "OptimiserConfig",
    "SceneRRTConnect",
    "TrajectoryOptimiser",
    "cartesian_line_path",
    "compiled_rrt_connect",
    "default_body",
    "joint_line_path",
    "scene_rrt_connect",
    "trajectory_optimiser",
]


def _old_joint_line(body, steps: int = 10):
    return _free.JointLine(body, steps=steps)


def _old_cartesian_line(body, steps: int = 10, iterations: int = 20, damping: float = 1e-2):
    return _free.CartesianLine(body, steps, iterations, damping, to_goal_joints=True)


#: Old names → (their new home, what they are now), kept for one release (module ``__getattr__`` warns).
_RENAMED = {
    "joint_line": ("kinlearn.planning.obstacle_baselines.joint_line_path", "joint_line_path"),
    "cartesian_line": ("kinlearn.planning.obstacle_baselines.cartesian_line_path", "cartesian_line_path"),
    "rrt_connect": ("kinlearn.planning.obstacle_baselines.scene_rrt_connect", "scene_rrt_connect"),
    "JointLine": ("kinlearn.baselines.JointLine (steps=11 by default)", _old_joint_line),
    "CartesianLine": (
        "kinlearn.baselines.CartesianLine(..., to_goal_joints=True) (steps=11 by default)",
        _old_cartesian_line,
    ),
}


def __getattr__(name: str):
    if name in _RENAMED:
        home, value = _RENAMED[name]
        warnings.warn(
            f"kinlearn.planning.obstacle_baselines.{name} is now {home}; the old name goes in the next release",
            KinlearnDeprecationWarning,
            stacklevel=2,
        )
        return globals()[value] if isinstance(value, str) else value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


_F64 = torch.float64


@cache
def _body_for(robot_name: str) -> BodySpheres:
    return planning_body(load_robot(robot_name)).double()


def default_body(robot: str = "iiwa14") -> BodySpheres:
    """The body a bundled robot's planners check with (float64, built once per process): its
    :func:`~kinlearn.collision.planning_body` (the iiwa14's 12 spheres with the base; the ur5's arm with
    the standard benchmarks' gripper), the body kinlearn's own planner uses."""
    return _body_for(robot)


def _inputs(start, goal, body: BodySpheres | None) -> tuple[torch.Tensor, torch.Tensor, BodySpheres]:
    body = default_body() if body is None else body
    robot = body.robot
    out = []
    for what, q in (("start", start), ("goal", goal)):
        if isinstance(q, torch.Tensor):
            q = q.detach().to(device="cpu", dtype=_F64)
        else:  # a list of Python floats would otherwise become float32 on the way
            q = torch.from_numpy(np.array(q, dtype=np.float64))
        if q.shape != (robot.dof,):
            raise ShapeError(
                f"{what} must be one configuration ({robot.dof},) of {robot.name}, got {tuple(q.shape)}"
            )
        robot.check_joints(q, what=f"{what} joints")
        out.append(q)
    return out[0], out[1], body


def _one_scene(scene) -> Scene:
    if not isinstance(scene, Scene):
        raise ConfigError(f"scene must be a kinlearn Scene, got {type(scene).__name__}")
    if len(scene.batch_shape):
        raise ShapeError(
            f"plan one problem at a time: the scene must be unbatched, got batch {tuple(scene.batch_shape)} "
            "(ProblemSet.problem(i) gives one)"
        )
    return scene.to(_F64)


def _states(body: BodySpheres, start: torch.Tensor, goal: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(dof,)`` joints → states ``[θ, ef]`` by the fast FK (the layout :mod:`kinlearn.planning.baselines` takes)."""
    ef = kinematics(body.robot, "fast").position(torch.stack([start, goal]), validate=False)
    return torch.cat((start, ef[0])), torch.cat((goal, ef[1]))


def _pin(path: torch.Tensor, start: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
    """The path with its first and last rows set to the given joints exactly."""
    path = path.detach().to(_F64).clone()
    path[0], path[-1] = start, goal
    return path


def joint_line_path(
    start, goal, scene: Scene | None = None, *, steps: int = 10, body: BodySpheres | None = None
) -> tuple[torch.Tensor, float]:
    """The straight joint-space line from ``start`` to ``goal`` in ``steps`` equal steps; ignores ``scene``."""
    t0 = time.perf_counter()
    start, goal, body = _inputs(start, goal, body)
    s0, sT = _states(body, start, goal)
    path = _free.joint_line(body.robot, s0, sT, steps=steps).joints
    return _pin(path, start, goal), time.perf_counter() - t0


def cartesian_line_path(
    start,
    goal,
    scene: Scene | None = None,
    *,
    steps: int = 10,
    iterations: int = 20,
    damping: float = 1e-2,
    body: BodySpheres | None = None,
) -> tuple[torch.Tensor, float]:
    """The end effector on a straight line from the start's to the goal's, followed by DLS IK; ignores ``scene``.

    :func:`kinlearn.planning.baselines.cartesian_line` gives ``steps + 1`` configurations ending at an IK solution
    for the goal's end-effector position, not at the goal's joints; a last straight joint-space segment
    to the goal joints is appended (long where the IK's redundancy resolution differs from the goal's).
    """
    t0 = time.perf_counter()
    start, goal, body = _inputs(start, goal, body)
    s0, sT = _states(body, start, goal)
    ik = _free.cartesian_line(body.robot, s0, sT, steps=steps, iterations=iterations, damping=damping).joints
    path = torch.cat((ik, goal.unsqueeze(0)))
    return _pin(path, start, goal), time.perf_counter() - t0


def _box(body: BodySpheres, start: torch.Tensor, goal: torch.Tensor) -> tuple[np.ndarray, np.ndarray]:
    """The joint box a sampling baseline searches: the planner's (:meth:`BodySpheres.joint_box`)."""
    lo, hi = body.joint_box(start.double().numpy()[None], goal.double().numpy()[None])
    return lo[0], hi[0]


def scene_rrt_connect(
    start,
    goal,
    scene: Scene,
    *,
    time_limit: float = 1.0,
    simplify: bool = True,
    seed: int | None = 0,
    max_travel: float = 0.01,
    body: BodySpheres | None = None,
) -> tuple[torch.Tensor | None, float]:
    """OMPL RRT-Connect around ``scene`` on the dense checker (:class:`~kinlearn.collision.ompl.OmplRrtConnect`),
    in the planner's joint box (the body's limits where start and goal lie within them).

    With ``simplify`` OMPL's path simplifier shortens the path in whatever the search left of
    ``time_limit`` seconds; it checks that limit only between its steps and does at least one round,
    so a query may take longer (the returned time is what it took). ``seed`` seeds OMPL's random
    generator (``None`` leaves it alone). Returns ``(None, seconds)`` where no path was found in time.
    Needs the optional dependency ``ompl`` (:class:`~kinlearn.errors.MissingDependencyError`).
    """
    t0 = time.perf_counter()
    start, goal, body = _inputs(start, goal, body)
    scene = _one_scene(scene)
    rrt = OmplRrtConnect(body.robot, body, scene, max_travel=max_travel, bounds=_box(body, start, goal))
    path, _ = rrt.solve(start, goal, time_limit=time_limit, seed=seed, simplify=simplify)
    if path is None:
        return None, time.perf_counter() - t0
    return _pin(torch.from_numpy(np.ascontiguousarray(path)), start, goal), time.perf_counter() - t0


def compiled_rrt_connect(
    start,
    goal,
    scene: Scene,
    *,
    time_limit: float = 1.0,
    seed: int = 0,
    max_travel: float = 0.01,
    body: BodySpheres | None = None,
) -> tuple[torch.Tensor | None, float]:
    """RRT-Connect compiled with the dense check (:func:`kinlearn.collision.rrt.rrt_connect`: local and
    uniform samples, random vertex shortcuts), for at most ``time_limit`` seconds (checked every few
    iterations). Returns ``(path (V, dof) or None, seconds)``; the same seed gives the same path
    whenever it is found within the limit."""
    from ..collision import kernel
    from ..collision.rrt import rrt_connect

    t0 = time.perf_counter()
    start, goal, body = _inputs(start, goal, body)
    scene = _one_scene(scene)
    lo, hi = _box(body, start, goal)
    path, _, _ = rrt_connect(
        kernel.KernelBody.of(body),
        kernel.KernelScene.of(scene.to(_F64)),
        start.numpy(),
        goal.numpy(),
        lo,
        hi,
        time_limit=time_limit,
        seed=seed,
        max_travel=max_travel,
    )
    if path is None:
        return None, time.perf_counter() - t0
    return _pin(torch.from_numpy(np.ascontiguousarray(path)), start, goal), time.perf_counter() - t0


# --------------------------------------------------------------------------------------------------
# Gradient trajectory optimiser
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class OptimiserConfig:
    """The trajectory optimiser's settings.

    The defaults were chosen on 48 problems outside the held-out set (``make_problems`` with seeds
    3001–3003, 16 per family, unverified), by success of the dense check at 100 steps: 10–32 knots,
    4 or 8 samples, margins 2.5–4 cm, learning rates 0.01–0.1 and collision weights 10²–10⁵ solved
    between 5 and 19 of the 33 hard ones; these settings solved 19 (and all 15 easy ones), 32 knots
    no more at a higher cost per step. Adam is invariant to the scale of the loss, so only the ratios
    of the weights matter.

    The path is ``knots`` configurations (both endpoints included, fixed); the collision terms are
    evaluated at ``samples`` equally spaced points of every segment, its start included (the fixed
    start and goal configurations left out: nothing to move there). With d a body sphere's signed
    distance to the scene and s a self-collision pair's:

        loss = smooth · (knots − 1) · Σ_k ‖θ_{k+1} − θ_k‖²
             + collision · Σ_points Σ_spheres relu(margin − d)² / samples
             + self_collision · Σ_points Σ_pairs relu(self_margin − s)² / samples

    (the first term equals smooth · L² for a path of length L with equal steps). Each step is one Adam
    step (β₁ = 0.9, β₂ = 0.999) of learning rate ``lr`` (rad), followed by clamping the knots to the
    joint limits.
    """

    knots: int = 24
    samples: int = 4
    margin: float = 0.025
    self_margin: float = 0.01
    lr: float = 0.05
    smooth: float = 1.0
    collision: float = 1e4
    self_collision: float = 1e4

    def __post_init__(self):
        for name in ("knots", "samples"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < (3 if name == "knots" else 1):
                raise ConfigError(
                    f"OptimiserConfig.{name} must be an integer >= {3 if name == 'knots' else 1}, got {value!r}"
                )
        for name in ("margin", "self_margin", "lr", "smooth", "collision", "self_collision"):
            value = getattr(self, name)
            value = as_real(value, f"OptimiserConfig.{name}", minimum=0.0, expected="a finite number >= 0")
            object.__setattr__(self, name, value)
        if self.lr <= 0:
            raise ConfigError(f"OptimiserConfig.lr must be > 0, got {self.lr!r}")

    def to_dict(self) -> dict:
        return asdict(self)


class _Objective:
    """The optimiser's loss for one problem: fixed endpoints, a scene, a body."""

    def __init__(self, body: BodySpheres, scene: Scene, start, goal, cfg: OptimiserConfig):
        self.body, self.cfg = body, cfg
        self.scene = _one_scene(scene)
        self.start, self.goal = start.unsqueeze(0), goal.unsqueeze(0)
        frac = torch.arange(cfg.samples, dtype=_F64) / cfg.samples
        self.frac = frac.view(1, -1, 1)  # (1, S, 1)
        self.radii = body.radii.to(_F64)
        self.floor_mask = body.floor_mask
        self.pairs = body.pairs

    def path(self, inner: torch.Tensor) -> torch.Tensor:
        return torch.cat((self.start, inner, self.goal))

    def __call__(self, inner: torch.Tensor) -> torch.Tensor:
        cfg = self.cfg
        path = self.path(inner)
        delta = path[1:] - path[:-1]  # (K-1, dof)
        smooth = (delta * delta).sum() * (path.shape[0] - 1)
        points = (path[:-1].unsqueeze(1) + self.frac * delta.unsqueeze(1)).reshape(-1, path.shape[1])
        points = points[1:]  # the start (and the goal, not included) are fixed: no gradient there
        centres = self.body(points, validate=False)
        _, per = body_obstacle_distance(
            centres, self.radii, self.scene, per_sphere=True, floor_mask=self.floor_mask
        )
        loss = cfg.smooth * smooth
        if cfg.collision:
            loss = loss + cfg.collision / cfg.samples * torch.relu(cfg.margin - per).square().sum()
        if cfg.self_collision:
            _, pp = self_collision_distance(centres, self.radii, self.pairs, per_pair=True)
            loss = loss + cfg.self_collision / cfg.samples * torch.relu(cfg.self_margin - pp).square().sum()
        return loss


def trajectory_optimiser(
    start,
    goal,
    scene: Scene,
    *,
    steps: int = 100,
    config: OptimiserConfig | None = None,
    body: BodySpheres | None = None,
    init: torch.Tensor | None = None,
) -> tuple[torch.Tensor, float]:
    """``steps`` Adam steps on a knot path from ``start`` to ``goal`` around ``scene`` (:class:`OptimiserConfig`).

    The interior knots start evenly spaced on the straight joint-space line, or, given ``init`` (a joint
    path ``(K, dof)`` from ``start`` to ``goal``), on that path at evenly spaced fractions of its knots
    (a learned planner's proposal to refine); the endpoints stay fixed;
    after every step the knots are clamped to the joint limits. Deterministic (no random draws; one
    thread gives the same result bit for bit). Always returns a path, ``(config.knots, dof)``: it is
    not checked here, so it may still collide (between the evaluated points, or where the optimiser
    got stuck).
    """
    t0 = time.perf_counter()
    steps = as_int(steps, "steps", minimum=0, maximum=MAX_STEPS)
    cfg = config or OptimiserConfig()
    start, goal, body = _inputs(start, goal, body)
    lo, hi = body.robot.limits(_F64)
    objective = _Objective(body, scene, start, goal, cfg)
    frac = torch.linspace(0.0, 1.0, cfg.knots, dtype=_F64)[1:-1].unsqueeze(-1)
    if init is None:
        inner = (start + frac * (goal - start)).requires_grad_(True)
    else:
        init = torch.as_tensor(init, dtype=_F64)
        if init.ndim != 2 or init.shape[-1] != start.shape[-1] or init.shape[0] < 2:
            raise ShapeError(f"init must be a joint path (K ≥ 2, {start.shape[-1]}), got {tuple(init.shape)}")
        x = frac[:, 0] * (init.shape[0] - 1)  # position along the init path's knots
        k = x.floor().long().clamp(max=init.shape[0] - 2)
        w = (x - k).unsqueeze(-1)
        inner = (init[k] + w * (init[k + 1] - init[k])).clone().requires_grad_(True)
    # Adam (β = 0.9, 0.999, ε = 1e-8) written out: torch.optim's per-step bookkeeping costs more than
    # this problem's arithmetic at batch 1.
    m, v = torch.zeros_like(inner), torch.zeros_like(inner)
    b1, b2 = 0.9, 0.999
    for k in range(1, steps + 1):
        (grad,) = torch.autograd.grad(objective(inner), inner)
        with torch.no_grad():
            m.mul_(b1).add_(grad, alpha=1 - b1)
            v.mul_(b2).addcmul_(grad, grad, value=1 - b2)
            denom = (v / (1 - b2**k)).sqrt_().add_(1e-8)
            inner.addcdiv_(m, denom, value=-cfg.lr / (1 - b1**k))
            inner.clamp_(lo, hi)
    path = objective.path(inner.detach())
    return _pin(path, start, goal), time.perf_counter() - t0


# --------------------------------------------------------------------------------------------------
# The planner protocol: plan(problem) -> Plan
# --------------------------------------------------------------------------------------------------


class _PathPlanner(Baseline):
    """A one-problem-at-a-time path function as a planner of problem batches (see the module docstring).
    ``robot``: a :class:`~kinlearn.body.robot.Robot`, its name or its :class:`~kinlearn.collision.BodySpheres`
    (the spheres it plans around; by default the body kinlearn's planner checks with, float64:
    :func:`default_body`)."""

    avoids_obstacles: ClassVar[bool] = True
    one_at_a_time: ClassVar[bool] = True
    body: BodySpheres | None

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.body is None:  # the robot's default sphere body, built once per bundled robot
            try:
                bundled = load_robot(self.robot.name) is self.robot
            except UnknownRobotError:  # a Robot made from a URDF, under no registered name
                bundled = False
            body = default_body(self.robot.name) if bundled else planning_body(self.robot).double()
            object.__setattr__(self, "body", body)

    def _path(self, start: torch.Tensor, goal: torch.Tensor, scene: Scene) -> torch.Tensor | None:
        raise NotImplementedError

    def plan(self, problem: Problem) -> Plan:
        self._check(problem)
        flat_shape = (-1, self.robot.dof)
        starts = problem.start_joints.reshape(flat_shape)
        goals = problem.goal_joints.reshape(flat_shape)
        scene = problem.obstacles if problem.obstacles is not None else Scene()
        scenes = scene.reshape(starts.shape[0]) if len(scene.batch_shape) else None
        paths, found = [], []
        for i in range(starts.shape[0]):
            path = self._path(starts[i], goals[i], scene if scenes is None else scenes[i])
            found.append(path is not None)
            paths.append(torch.stack((starts[i], goals[i])) if path is None else path)
        longest = max(p.shape[0] for p in paths)
        joints = torch.stack([torch.cat((p, p[-1:].expand(longest - p.shape[0], -1))) for p in paths])
        shape = (*problem.batch_shape, longest, self.robot.dof)
        found_at = torch.tensor(found).reshape(problem.batch_shape)
        return judge(problem, joints.reshape(shape), found=found_at, body=self.body)


@dataclass(frozen=True)
class SceneRRTConnect(_PathPlanner):
    """:func:`scene_rrt_connect` (around the problem's obstacles, on the dense checker) as a planner."""

    robot: Robot | str | BodySpheres
    time_limit: float = 1.0
    simplify: bool = True
    seed: int | None = 0
    max_travel: float = 0.01
    body: BodySpheres | None = None

    label: ClassVar[str] = "RRT-Connect around obstacles (OMPL)"
    requires: ClassVar[tuple[str, ...]] = ("ompl",)

    def _path(self, start, goal, scene):
        return scene_rrt_connect(
            start,
            goal,
            scene,
            time_limit=self.time_limit,
            simplify=self.simplify,
            seed=self.seed,
            max_travel=self.max_travel,
            body=self.body,
        )[0]


@dataclass(frozen=True)
class CompiledRRTConnect(_PathPlanner):
    """:func:`compiled_rrt_connect` (around the problem's obstacles, on the compiled dense check) as a planner."""

    robot: Robot | str | BodySpheres
    time_limit: float = 1.0
    seed: int = 0
    max_travel: float = 0.01
    body: BodySpheres | None = None

    label: ClassVar[str] = "RRT-Connect around obstacles (compiled)"

    def _path(self, start, goal, scene):
        return compiled_rrt_connect(
            start,
            goal,
            scene,
            time_limit=self.time_limit,
            seed=self.seed,
            max_travel=self.max_travel,
            body=self.body,
        )[0]


@dataclass(frozen=True)
class TrajectoryOptimiser(_PathPlanner):
    """:func:`trajectory_optimiser` as a planner."""

    robot: Robot | str | BodySpheres
    steps: int = 100
    config: OptimiserConfig | None = None
    body: BodySpheres | None = None

    label: ClassVar[str] = "trajectory optimiser"

    def _path(self, start, goal, scene):
        return trajectory_optimiser(start, goal, scene, steps=self.steps, config=self.config, body=self.body)[
            0
        ]
