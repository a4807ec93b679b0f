"""The result of planning, shared by the learned planner and the baselines, with its verified outcome."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
import torch

from ..body.kinematics import kinematics
from ..body.robot import Robot
from ..checks import as_real, check_finite, check_last_dim
from ..collision.body import BodySpheres, planning_body
from ..collision.check import check_path
from ..data.problem import LIMIT_TOLERANCE, SMALL_BATCH, Problem
from ..errors import ConfigError, ShapeError

__all__ = ["CHECK_TRAVEL", "DEFAULT_TOLERANCE", "Plan", "PlannerLike", "Tolerance", "judge"]

#: Sphere travel (m) allowed between two configurations the dense collision check looks at.
CHECK_TRAVEL = 0.01
#: The finest check :func:`judge` makes (m of sphere travel): a finer one sees nothing the 1 cm check
#: misses that matters, and costs a check per 0.1 mm of the path (a bound on the work asked for).
MIN_CHECK_TRAVEL = 1e-4
#: How far (rad) a judged path's first configuration may be from its problem's start.
START_TOLERANCE = 1e-6


@dataclass(frozen=True)
class Tolerance:
    """When a plan counts as reaching its goal: the end effector within ``position`` metres of the
    target and, for a goal given as joints, every joint within ``joints`` radians of the goal's."""

    position: float = 0.01
    joints: float = 0.05

    def __post_init__(self) -> None:
        for name in ("position", "joints"):
            unit = "m" if name == "position" else "rad"
            object.__setattr__(
                self, name, as_real(getattr(self, name), f"Tolerance.{name} ({unit})", minimum=0.0)
            )


#: The tolerance plans are judged with unless told otherwise (1 cm, 0.05 rad).
DEFAULT_TOLERANCE = Tolerance()


@dataclass(frozen=True)
class Plan:
    """A batch of planned trajectories with T steps (T + 1 configurations, T − 1 intermediate waypoints).

    Attributes (leading batch dimensions ``...`` as in the planner's input):
        goal: ``(..., dof + 3)`` the goal state s(T). For a goal given as an end-effector position, the
            state the planner chose to reach it.
        waypoints: ``(..., T - 1, 3)`` the planner's end-effector waypoints ŝ(1) … ŝ(T−1).
        joints: ``(..., T + 1, dof)`` the joint path (joints[..., 0, :] = θ(0)). Executing it means
            moving linearly in joint space between consecutive configurations.
        ef: ``(..., T + 1, 3)`` the joint path's true end-effector positions by analytic FK.
        target: ``(..., 3)`` the end-effector position asked for.
        goal_error: ``(...)`` ‖ef at the last configuration − target‖ (m), verified by the FK.
        joint_error: ``(...)`` max over joints of |θ at the last configuration − θ of the goal| (rad);
            NaN where the goal was a position only.
        success: ``(...)`` bool: ``goal_error ≤ tolerance.position`` and (joint goals)
            ``joint_error ≤ tolerance.joints``; every configuration is within the joint limits.
        tolerance: the :class:`Tolerance` used.
        robot: the name of the robot the plan is for (lets :meth:`timed`, :meth:`show` and
            :meth:`animate` find its limits and geometry).
        collision_free: ``(...)`` bool where the plan was made among obstacles: no configuration of the
            joint path, checked densely (at most 1 cm of body-sphere travel between checked
            configurations, :func:`kinlearn.collision.check_path`), touches the scene or itself;
            ``success`` then requires it. ``None`` where no obstacles were given (not checked).
        stage: which stage of the planner made each plan (:data:`kinlearn.planning.stages.STAGES`):
            ``"learned"`` (the learned model's plan or proposals), ``"refine"`` (bounded gradient
            refinement), ``"rrt"`` (RRT-Connect under a deadline), ``"none"`` (no stage cleared the
            obstacles: flagged, ``success`` False). A ``str`` for a single plan, an array of them
            ``(...)`` for a batch; ``None`` for a baseline's plan.

    Derived: ``start`` ``(..., dof + 3)`` the start state [θ(0), ef(0)]; ``actions`` ``(..., T, dof)`` the
    joint changes a(0) … a(T−1).
    """

    goal: torch.Tensor
    waypoints: torch.Tensor
    joints: torch.Tensor
    ef: torch.Tensor
    target: torch.Tensor
    goal_error: torch.Tensor
    joint_error: torch.Tensor
    success: torch.Tensor
    tolerance: Tolerance = DEFAULT_TOLERANCE
    robot: str | None = None
    collision_free: torch.Tensor | None = None
    stage: str | np.ndarray | None = None

    #: Fields holding per-plan tensors, indexed with the batch (``collision_free`` too, where set).
    _BATCHED = (
        "goal",
        "waypoints",
        "joints",
        "ef",
        "target",
        "goal_error",
        "joint_error",
        "success",
        "collision_free",
    )

    @classmethod
    def from_joints(
        cls,
        goal: torch.Tensor,
        joints: torch.Tensor,
        ef: torch.Tensor,
        *,
        waypoints: torch.Tensor | None = None,
        target: torch.Tensor | None = None,
        joint_goal: bool = True,
        within_limits: torch.Tensor | None = None,
        collision_free: torch.Tensor | None = None,
        tolerance: Tolerance = DEFAULT_TOLERANCE,
        robot: str | None = None,
        stage: str | np.ndarray | None = None,
    ) -> Plan:
        """A plan of the joint path ``joints (..., T+1, dof)`` whose true end effector is ``ef (..., T+1, 3)``:
        the one way every planner (learned or baseline) makes its :class:`Plan` from tensors (a few
        float64 paths on the CPU are judged by the same rule in one compiled call instead:
        :func:`verdict_small`).

        ``waypoints`` default to the end effector of the interior configurations; ``target`` to the
        goal state's end effector. ``joint_goal``: whether the goal's joints must be reached too.
        ``within_limits (...)``: where the path is known to stay within the joint limits (default: all).
        ``collision_free (...)``: where the path was checked among obstacles and found free (None: not
        checked); ``success`` requires it.
        """
        dof = joints.shape[-1]
        if target is None:
            target = goal[..., dof:]
        goal_error = torch.linalg.vector_norm(ef[..., -1, :] - target, dim=-1)
        if joint_goal:
            joint_error = (joints[..., -1, :] - goal[..., :dof]).abs().amax(-1)
            ok = (goal_error <= tolerance.position) & (joint_error <= tolerance.joints)
        else:
            joint_error = torch.full_like(goal_error, float("nan"))
            ok = goal_error <= tolerance.position
        if within_limits is not None:
            ok = ok & within_limits
        if collision_free is not None:
            ok = ok & collision_free
        fields = dict(
            goal=goal,
            waypoints=ef[..., 1:-1, :] if waypoints is None else waypoints,
            joints=joints,
            ef=ef,
            target=target,
            goal_error=goal_error,
            joint_error=joint_error,
            success=ok,
            collision_free=collision_free,
        )
        return cls(**fields, tolerance=tolerance, robot=robot, stage=stage)

    @property
    def start(self) -> torch.Tensor:
        """``(..., dof + 3)`` the start state [θ(0), ef(0)]."""
        return torch.cat((self.joints[..., 0, :], self.ef[..., 0, :]), dim=-1)

    @property
    def actions(self) -> torch.Tensor:
        """``(..., T, dof)`` the joint changes a(t) = θ(t + 1) − θ(t)."""
        return self.joints[..., 1:, :] - self.joints[..., :-1, :]

    @property
    def steps(self) -> int:
        """T, the number of steps."""
        return self.joints.shape[-2] - 1

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """The leading batch dimensions (``()`` for a single plan)."""
        return tuple(self.goal.shape[:-1])

    def __len__(self) -> int:
        if not self.batch_shape:
            raise TypeError("a single plan (no batch dimension) has no len()")
        return self.batch_shape[0]

    def __getitem__(self, idx) -> Plan:
        """Index the batch: ``plan[3]``, ``plan[:10]``. A single plan cannot be indexed."""
        if not self.batch_shape:
            raise ShapeError("this is a single plan (no batch dimension): there is nothing to index")
        probe = torch.empty(self.batch_shape, device="meta")
        try:
            probe[idx]
        except (IndexError, TypeError) as exc:
            raise ShapeError(f"index {idx!r} does not fit the plan's batch shape {self.batch_shape}") from exc
        fields = {f: getattr(self, f)[idx] for f in self._BATCHED if getattr(self, f) is not None}
        if isinstance(self.stage, np.ndarray):
            stage = self.stage[idx]
            fields["stage"] = str(stage) if np.ndim(stage) == 0 else stage
        return dataclasses.replace(self, **fields)

    def _robot(self, robot):
        from ..body.robot import Robot, load_robot

        given = robot.name if isinstance(robot, Robot) else robot
        if given is not None and self.robot is not None and given != self.robot:
            raise ConfigError(f"this plan is for {self.robot!r}, not {given!r}: its joints are another arm's")
        if isinstance(robot, Robot):
            return robot
        name = robot or self.robot
        if name is None:
            raise ConfigError("this plan does not name its robot: pass robot= (a name or a kinlearn.Robot)")
        return load_robot(name)

    def _single(self, what: str) -> None:
        if self.batch_shape:
            raise ShapeError(f"{what} takes a single plan; index the batch first, e.g. plan[0]")

    def timed(self, robot=None, **options):
        """A time-parameterised trajectory along this plan's joint path within the robot's velocity and
        acceleration limits (:func:`kinlearn.planning.timing.time_parameterize`, toppra): times, positions,
        velocities, accelerations, ready for a controller (``.to_csv``, ``.to_json``). One plan at a time."""
        from .timing import time_parameterize

        self._single("timed()")
        return time_parameterize(self._robot(robot), self.joints, **options)

    def show(self, robot=None, *, spheres=None, boxes=None, **options):
        """Open an interactive 3-D view of this plan in the browser (viser): the arm along its joint path,
        the waypoints, the executed end-effector path and obstacles (:func:`kinlearn.viz.show_plan`)."""
        from ..viz import show_plan

        self._single("show()")
        return show_plan(
            self._robot(robot), self.joints, waypoints=self.waypoints, spheres=spheres, boxes=boxes, **options
        )

    def animate(self, path, robot=None, *, spheres=None, boxes=None, **options):
        """Write a GIF of the arm moving along this plan (:func:`kinlearn.viz.animate_plan`); returns its path."""
        from ..viz import animate_plan

        self._single("animate()")
        return animate_plan(
            self._robot(robot),
            self.joints,
            path,
            waypoints=self.waypoints,
            spheres=spheres,
            boxes=boxes,
            **options,
        )

    def summary(self) -> str:
        """A short table a person reads: per plan, success, goal errors and end-effector path length."""
        flat = self.ef.reshape(-1, *self.ef.shape[-2:]).double()
        length = (flat[:, 1:] - flat[:, :-1]).norm(dim=-1).sum(-1)
        ge = self.goal_error.reshape(-1)
        je = self.joint_error.reshape(-1)
        ok = self.success.reshape(-1)
        free = None if self.collision_free is None else self.collision_free.reshape(-1)
        stage = None if free is None or self.stage is None else np.asarray(self.stage).reshape(-1)
        tol = self.tolerance
        lines = [
            f"{'plan':>5}  {'success':>7}  {'goal error (mm)':>15}  {'joint error (rad)':>17}  {'ef path (m)':>11}"
            + ("  collision-free" if free is not None else "")
            + ("  stage" if stage is not None else ""),
        ]
        for i in range(ge.numel()):
            jtxt = "—" if bool(torch.isnan(je[i])) else f"{float(je[i]):.4f}"
            lines.append(
                f"{i:>5}  {'yes' if bool(ok[i]) else 'NO':>7}  {1000 * float(ge[i]):>15.2f}  {jtxt:>17}  "
                f"{float(length[i]):>11.3f}"
                + (f"  {'yes' if bool(free[i]) else 'NO':>14}" if free is not None else "")
                + (f"  {stage[i]}" if stage is not None else "")
            )
        lines.append(
            f"success: end effector within {1000 * tol.position:g} mm of the target"
            + (
                f" and every joint within {tol.joints:g} rad of the goal's"
                if not bool(torch.isnan(je).all())
                else ""
            )
            + ("; no collision under the dense check" if free is not None else "")
            + f"; {int(ok.sum())}/{ok.numel()} plans succeeded"
        )
        return "\n".join(lines)


@runtime_checkable
class PlannerLike(Protocol):
    """What every planner is: the learned :class:`~kinlearn.planning.planner.Planner` and each baseline
    (:mod:`kinlearn.planning.baselines`, :mod:`kinlearn.planning.obstacle_baselines`). ``plan`` takes a
    :class:`~kinlearn.data.problem.Problem` for ``robot`` and returns one :class:`Plan` per problem, whose
    outcome (``success``, ``collision_free`` where there are obstacles) is verified, not believed."""

    robot: Robot

    def plan(self, problem: Problem) -> Plan: ...


def judge(
    problem: Problem,
    joints: torch.Tensor,
    *,
    waypoints: torch.Tensor | None = None,
    found: torch.Tensor | None = None,
    tolerance: Tolerance = DEFAULT_TOLERANCE,
    max_travel: float = CHECK_TRAVEL,
    body: BodySpheres | None = None,
    collision_free=None,
    stage: str | np.ndarray | None = None,
) -> Plan:
    """The :class:`Plan` of the joint paths ``joints (..., T+1, dof)`` a planner made for ``problem``,
    judged on the robot itself: the analytic FK gives the end effector, the limits are checked on every
    configuration, the goal (state or position) is checked within ``tolerance``, and among obstacles
    every path is checked densely (:func:`~kinlearn.collision.check_path`, ``max_travel`` m of sphere
    travel between checked configurations). ``waypoints`` default to the interior configurations' FK.
    ``found (...)``: where the planner found a path at all (a search that ran out of time gives a
    stand-in path with ``found`` False): ``success`` requires it, and that the path starts at the
    problem's start (within :data:`START_TOLERANCE`). ``body``: the collision spheres to check with
    (default: :func:`~kinlearn.collision.planning_body` of the robot, the body its planners check with,
    built for this call).
    ``collision_free (...)``: verdicts of this very dense check already computed by the caller (the
    learned planner checks its candidates with it, and passes the chosen ones'), taken instead of
    checking again; it is ignored without obstacles. ``stage``: the plan's :attr:`Plan.stage`.

    Up to :data:`~kinlearn.data.problem.SMALL_BATCH` paths given as a float64 NumPy array ``joints``
    (or as a tensor) are judged on the fast path: FK and the dense check in the compiled kernels
    (:mod:`kinlearn.collision.kernel`, the same verdicts), the rest in NumPy, no per-operation dispatch
    (a batch-1 plan's verdict in microseconds); larger batches in torch. The rule is one.

    Raises :class:`ShapeError` for paths or a ``found`` mask of the wrong shape, :class:`ConfigError`
    for a ``max_travel`` that is not a number ≥ :data:`MIN_CHECK_TRAVEL` or a tolerance that is no
    :class:`Tolerance`."""
    if not isinstance(problem, Problem):
        raise ConfigError(f"judge takes a kinlearn.Problem (Problem.make), got {type(problem).__name__}")
    if not isinstance(tolerance, Tolerance):
        raise ConfigError(f"tolerance must be a kinlearn Tolerance, got {type(tolerance).__name__}")
    if max_travel is not CHECK_TRAVEL:  # the default needs no check (a fifth of a batch-1 verdict's Python)
        max_travel = as_real(max_travel, "max_travel (m of sphere travel)", minimum=MIN_CHECK_TRAVEL)
    robot = problem.robot
    if isinstance(joints, np.ndarray):
        if joints.dtype != np.float64 or joints.ndim < 2 or joints.shape[-1] != robot.dof:
            joints = torch.from_numpy(np.asarray(joints))  # checked (and explained) as a tensor below
        elif math.prod(joints.shape[:-2]) <= SMALL_BATCH:
            return _judge_small(
                problem, joints, waypoints, found, tolerance, max_travel, body, collision_free, stage
            )
        else:
            joints = torch.from_numpy(joints)
    check_last_dim(joints, robot.dof, "joint paths")
    if isinstance(waypoints, np.ndarray):
        waypoints = torch.from_numpy(waypoints)
    if (
        joints.device.type == "cpu"
        and joints.ndim >= 2
        and math.prod(joints.shape[:-2]) <= SMALL_BATCH
        and joints.shape[:-2] == problem.batch_shape
    ):
        return _judge_small(
            problem,
            joints.detach().double().numpy(),
            waypoints,
            found,
            tolerance,
            max_travel,
            body,
            collision_free,
            stage,
        )
    if joints.ndim < 2 or joints.shape[:-2] != problem.batch_shape or joints.shape[-2] < 2:
        raise ShapeError(
            f"joint paths must have shape {(*problem.batch_shape, 'T+1', robot.dof)} with T ≥ 1 for "
            f"problems of batch shape {tuple(problem.batch_shape)}, got {tuple(joints.shape)}"
        )
    check_finite(joints, "joint paths")
    joints = joints.detach().double()
    ef = kinematics(robot, "fast").position(joints, validate=False)
    within = robot.within_limits(joints, LIMIT_TOLERANCE).all(-1)
    if found is not None:
        if (
            not isinstance(found, torch.Tensor)
            or found.dtype != torch.bool
            or found.shape != problem.batch_shape
        ):
            what = (
                f"a {found.dtype} tensor of shape {tuple(found.shape)}"
                if isinstance(found, torch.Tensor)
                else (type(found).__name__)
            )
            raise ShapeError(
                f"found must be a bool tensor of the problems' batch shape {tuple(problem.batch_shape)}, got {what}"
            )
        within = within & found.to(within.device)
    start = problem.start_joints.to(device=joints.device, dtype=torch.float64)
    within = within & ((joints[..., 0, :] - start).abs().amax(-1) <= START_TOLERANCE)
    free = None
    if problem.obstacles is not None:
        if collision_free is not None:
            free = torch.as_tensor(collision_free, dtype=torch.bool).reshape(problem.batch_shape)
        else:
            body = planning_body(robot) if body is None else body
            free = check_path(body, joints, problem.obstacles, max_travel=max_travel).collision_free
    state = problem.goal_kind == "state"
    goal = problem.goal if state else torch.cat((joints[..., -1, :], ef[..., -1, :]), dim=-1)
    return Plan.from_joints(
        goal,
        joints,
        ef,
        waypoints=waypoints,
        target=problem.target,
        joint_goal=state,
        within_limits=within,
        collision_free=free,
        tolerance=tolerance,
        robot=robot.name,
        stage=stage,
    )


def _as_numpy(t: torch.Tensor) -> np.ndarray:
    """A CPU tensor's values as a float64 array (a view where it already is one)."""
    if t.requires_grad or t.dtype != torch.float64 or t.device.type != "cpu":
        t = t.detach().double().cpu()
    return t.numpy()


def _found_array(found, batch: torch.Size) -> np.ndarray | None:
    if found is None:
        return None
    if not isinstance(found, torch.Tensor) or found.dtype != torch.bool or found.shape != batch:
        what = (
            f"a {found.dtype} tensor of shape {tuple(found.shape)}"
            if isinstance(found, torch.Tensor)
            else (type(found).__name__)
        )
        raise ShapeError(
            f"found must be a bool tensor of the problems' batch shape {tuple(batch)}, got {what}"
        )
    return found.cpu().numpy().reshape(-1)


def _judge_small(
    problem, J, waypoints, found, tolerance, max_travel, body, collision_free, stage=None
) -> Plan:
    """:func:`judge` for at most ``SMALL_BATCH`` float64 paths ``J (..., T+1, dof)``: the same rule, in
    NumPy and the compiled kernels (:func:`verdict_small`, given the problem's arrays)."""
    robot, batch = problem.robot, problem.batch_shape
    dof = robot.dof
    if J.shape[:-2] != batch or J.shape[-2] < 2:
        raise ShapeError(
            f"joint paths must have shape {(*batch, 'T+1', dof)} with T ≥ 1 for "
            f"problems of batch shape {tuple(batch)}, got {tuple(J.shape)}"
        )
    K = J.shape[-2]
    flat = np.ascontiguousarray(J.reshape(-1, K, dof))
    n = flat.shape[0]
    free = None
    if problem.obstacles is not None:
        if collision_free is not None:
            free = np.asarray(collision_free, dtype=bool).reshape(n)
        else:
            if not np.isfinite(flat).all():
                check_finite(torch.from_numpy(flat), "joint paths")
            from ..collision import kernel

            kb = kernel.KernelBody.of(planning_body(robot) if body is None else body)
            scene = problem.obstacles
            unbatched = len(scene.batch_shape) == 0
            flat_scene = None if unbatched else scene.reshape(n)
            free = np.empty(n, dtype=bool)
            for i in range(n):
                ks = kernel.KernelScene.of(scene) if unbatched else kernel.KernelScene(flat_scene[i])
                free[i] = kernel.first_free(kb, flat[i : i + 1], ks, max_travel=float(max_travel)) == 0
    wp = None
    if waypoints is not None:
        wp = waypoints.detach().double().cpu().numpy() if isinstance(waypoints, torch.Tensor) else waypoints
        wp = wp.reshape(n, *wp.shape[len(batch) :])
    # The problem's tensors as arrays (views: no torch operation on the fast path).
    return verdict_small(
        robot,
        flat,
        _as_numpy(problem.start).reshape(n, problem.start.shape[-1]),
        _as_numpy(problem.goal).reshape(n, problem.goal.shape[-1]),
        problem.goal_kind == "state",
        tuple(batch),
        free,
        tolerance,
        waypoints=wp,
        found=_found_array(found, batch),
        stage=stage,
    )


#: Every path of a small batch (:func:`verdict_small`'s ``found`` and ``free`` where none is given).
_EVERY = np.ones(SMALL_BATCH, dtype=bool)


def verdict_small(
    robot: Robot,
    flat: np.ndarray,
    start: np.ndarray,
    goal: np.ndarray,
    state_goal: bool,
    batch: tuple,
    free: np.ndarray | None,
    tolerance: Tolerance = DEFAULT_TOLERANCE,
    *,
    waypoints: np.ndarray | None = None,
    found: np.ndarray | None = None,
    stage=None,
) -> Plan:
    """The :class:`Plan` of ``n`` ≤ ``SMALL_BATCH`` float64 paths ``flat (n, T+1, dof)`` (C-contiguous) for
    start states ``start (n, dof + 3)`` and goals ``goal (n, dof + 3)`` (states, ``state_goal``) or
    ``(n, 3)`` (positions), judged by :func:`judge`'s rule (its batch-1 core; the planner's batch-1 entry
    calls it with the arrays it already holds): the analytic FK of every configuration, the limits, the
    path starting at the start and the goal within ``tolerance``, all in one compiled call
    (:meth:`~kinlearn.collision.kernel.KernelChain.judged`, :meth:`Plan.from_joints`' rule);
    ``free (n,)`` the dense check's verdicts among obstacles (None: no obstacles), ``found (n,)`` where
    a path was found at all; every field shaped to ``batch``, a tensor sharing its array's memory. A
    batch-1 plan's few NumPy and torch calls cost microseconds each where other work ran before them
    (the code they run has left the caches): one compiled call replaced a dozen array operations."""
    n, K, dof = flat.shape
    from ..collision.kernel import KernelChain

    tols = (LIMIT_TOLERANCE, START_TOLERANCE, tolerance.position, tolerance.joints)
    every = _EVERY[:n] if n <= SMALL_BATCH else np.ones(n, dtype=bool)  # read only
    ef, scores, ok, finite = KernelChain.of(robot).judged(
        flat.reshape(n * K, dof), K, start, goal, state_goal, tols,
        every if found is None else found, every if free is None else free,
    )  # fmt: skip
    if not finite:
        check_finite(torch.from_numpy(flat), "joint paths")
    ef = ef.reshape(n, K, 3)
    fields = dict(
        goal=goal if state_goal else np.concatenate((flat[:, -1], ef[:, -1]), -1),
        waypoints=ef[:, 1:-1] if waypoints is None else waypoints,
        joints=flat,
        ef=ef,
        target=goal[:, dof:] if state_goal else goal,
        goal_error=scores[0],
        joint_error=scores[1],
        success=ok,
        collision_free=free,
    )
    return Plan(
        **{k: None if v is None else torch.from_numpy(v.reshape((*batch, *v.shape[1:]))) for k, v in fields.items()},
        tolerance=tolerance, robot=robot.name, stage=stage,
    )  # fmt: skip
