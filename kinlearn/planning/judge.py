"""The success rule of a plan, in its two backends: :func:`judge` (any batch; torch, and the dense check
:func:`~kinlearn.collision.check_path`) and :func:`verdict_small` (a few float64 paths: the compiled
:func:`judged`, the same rule in one call, and the compiled dense check). A :class:`~kinlearn.planning.plan.Plan`
succeeds when every configuration is finite and within the joint limits, the path was found, starts at
the problem's start, its end reaches the goal within the tolerance and, among obstacles, it is
collision-free under the dense check."""

from __future__ import annotations

import math

import numpy as np
import torch

from ..body.fk import KernelChain, checked_tips
from ..body.jit import jit
from ..body.kinematics import kinematics
from ..body.robot import Robot
from ..checks import as_real, check_finite, check_last_dim
from ..collision.body import BodySpheres, planning_body
from ..collision.check import check_path
from ..data.problem import LIMIT_TOLERANCE, SMALL_BATCH, Problem
from ..errors import ConfigError, ShapeError
from .plan import CHECK_TRAVEL, DEFAULT_TOLERANCE, MIN_CHECK_TRAVEL, START_TOLERANCE, Plan, Tolerance

__all__ = ["judge", "judged", "verdict_small"]


def judge(
    problem: Problem,
    joints: torch.Tensor | np.ndarray,
    *,
    waypoints: torch.Tensor | np.ndarray | None = None,
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
            if len(scene.batch_shape) == 0:
                scenes = [scene] * n
            else:
                flat_scene = scene.reshape(n)
                scenes = [flat_scene[i] for i in range(n)]
            free = np.empty(n, dtype=bool)
            for i in range(n):
                ks = kernel.KernelScene.of(scenes[i]) if scenes[i] is scene else kernel.KernelScene(scenes[i])
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
    deferred: dict | None = None,
) -> Plan:
    """The :class:`Plan` of ``n`` ≤ ``SMALL_BATCH`` float64 paths ``flat (n, T+1, dof)`` (C-contiguous) for
    start states ``start (n, dof + 3)`` and goals ``goal (n, dof + 3)`` (states, ``state_goal``) or
    ``(n, 3)`` (positions), judged by :func:`judge`'s rule (its batch-1 core; the planner's batch-1 entry
    calls it with the arrays it already holds): the analytic FK of every configuration, the limits, the
    path starting at the start and the goal within ``tolerance``, all in one compiled call
    (:func:`judged`, :meth:`Plan.from_joints`' rule);
    ``free (n,)`` the dense check's verdicts among obstacles (None: no obstacles), ``found (n,)`` where
    a path was found at all; every field shaped to ``batch``, a tensor sharing its array's memory. A
    batch-1 plan's few NumPy and torch calls cost microseconds each where other work ran before them
    (the code they run has left the caches): one compiled call replaced a dozen array operations.
    ``deferred``: the plan's other fields (a scene, a body), given to a plan whose tensors are made when
    first read (:meth:`Plan.deferred`), for a caller handing one plan back as is."""
    n, K, dof = flat.shape
    tols = (LIMIT_TOLERANCE, START_TOLERANCE, tolerance.position, tolerance.joints)
    every = _EVERY[:n] if n <= SMALL_BATCH else np.ones(n, dtype=bool)  # read only
    ef, scores, ok, finite = judged(
        KernelChain.of(robot), flat.reshape(n * K, dof), K, start, goal, state_goal, tols,
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
    if deferred is not None:
        arrays = {k: v.reshape((*batch, *v.shape[1:])) for k, v in fields.items() if v is not None}
        return Plan.deferred(arrays, False, tolerance=tolerance, robot=robot.name, stage=stage, **deferred)
    t = {k: torch.from_numpy(v.reshape((*batch, *v.shape[1:]))) for k, v in fields.items() if v is not None}
    return Plan(
        goal=t["goal"], waypoints=t["waypoints"], joints=t["joints"], ef=t["ef"], target=t["target"],
        goal_error=t["goal_error"], joint_error=t["joint_error"], success=t["success"],
        collision_free=t.get("collision_free"), tolerance=tolerance, robot=robot.name, stage=stage,
    )  # fmt: skip


def judged(
    chain: KernelChain,
    flat,
    K: int,
    start,
    goal,
    state_goal: bool,
    tols: tuple[float, float, float, float],
    found,
    free,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """The arithmetic of a plan's verdict in one compiled call (:func:`verdict_small` holds the rule):
    ``flat (n · K, dof)`` float64 joint paths of K configurations of ``chain``'s robot, start states
    ``start (n, dof + 3)``, goal states ``goal (n, dof + 3)`` (``state_goal``) or target positions
    ``(n, 3)``, ``tols`` (limit, start, position, joint tolerance), ``found``, ``free (n,)`` bool
    (C-contiguous, as every array: one compiled version) → end effectors ``(n · K, 3)``, ``scores (2, n)``
    (goal error, joint error: NaN unless ``state_goal``), ``ok (n,)`` (success) and whether every joint
    value is finite."""
    n = flat.shape[0] // K
    scores, ok = np.empty((2, n)), np.empty(n, dtype=np.bool_)
    ef, finite = _judged(
        flat, K, start, goal, state_goal, chain.F, chain.prismatic, chain.lower, chain.upper, *tols, found,
        free, scores, ok,
    )  # fmt: skip
    return ef, scores, ok, finite


@jit
def _judged(
    flat, K, start, goal, state_goal, F, prismatic, lower, upper, limit_tol, start_tol, position_tol, joint_tol,
    found, free, scores, ok,
):  # fmt: skip
    """The verdict of ``n`` joint paths of ``K`` configurations, ``flat (n · K, dof)`` (:func:`judged`):
    their end effectors ``(n · K, 3)`` (:func:`checked_tips`) returned, and per path ``scores (2, n)`` its
    goal error (m) and joint error (rad; NaN for a position goal) and ``ok (n,)`` whether it succeeds:
    it stays within the limits (widened by ``limit_tol``), was ``found``, starts within ``start_tol`` of
    ``start (n, dof + 3)``'s joints, is ``free``, its last end effector lies within ``position_tol`` of the
    target, and, for ``state_goal``, its last joints within ``joint_tol`` of the goal's: ``goal (n, dof +
    3)`` the goal states (``state_goal``) or ``(n, 3)`` the target positions. Also whether every value of
    ``flat`` is finite."""
    nK, dof = flat.shape
    knots = np.empty(nK, dtype=np.bool_)
    ef = checked_tips(flat, F, prismatic, lower, upper, limit_tol, knots)
    finite = True
    for i in range(nK // K):
        good = found[i] and free[i]
        for k in range(i * K, (i + 1) * K):
            if not knots[k]:
                good = False
                for j in range(dof):
                    if not math.isfinite(flat[k, j]):
                        finite = False
        far = 0.0
        for j in range(dof):
            far = max(far, abs(flat[i * K, j] - start[i, j]))
        last = (i + 1) * K - 1
        t = dof if state_goal else 0  # the target's first column
        e0, e1, e2 = ef[last, 0] - goal[i, t], ef[last, 1] - goal[i, t + 1], ef[last, 2] - goal[i, t + 2]
        scores[0, i] = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
        good = good and far <= start_tol and scores[0, i] <= position_tol
        if state_goal:
            off = 0.0
            for j in range(dof):
                off = max(off, abs(flat[last, j] - goal[i, j]))
            scores[1, i] = off
            good = good and off <= joint_tol
        else:
            scores[1, i] = np.nan
        ok[i] = good
    return ef, finite
