"""The result of planning, shared by the learned planner and the baselines, with its verified outcome."""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Protocol, cast, runtime_checkable

import numpy as np
import torch

from ..body.robot import Robot
from ..checks import as_real
from ..collision.body import BodySpheres
from ..collision.scene import Scene
from ..data.problem import Problem
from ..errors import ConfigError, ShapeError

__all__ = [
    "CHECK_TRAVEL",
    "DEFAULT_TOLERANCE",
    "LazyArrays",
    "Plan",
    "PlannerLike",
    "Tolerance",
    "executed_check",
]

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


class LazyArrays(Mapping):
    """A plan's arrays by field name (:meth:`Plan.deferred`), made by ``make()`` when one is first asked
    for: views of one buffer a compiled call filled cost more to make than most callers read."""

    __slots__ = ("_arrays", "_make", "_names")

    def __init__(self, names: frozenset[str], make: Callable[[], dict[str, np.ndarray]]):
        self._names, self._make, self._arrays = names, make, None

    def __contains__(self, name: object) -> bool:
        return name in self._names

    def __getitem__(self, name: str) -> np.ndarray:
        if self._arrays is None:
            self._arrays = self._make()
        return self._arrays[name]

    def __iter__(self):
        return iter(self._names)

    def __len__(self) -> int:
        return len(self._names)


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
        scene: the obstacles the plan was made and checked among (a :class:`~kinlearn.collision.Scene`,
            batched like the plan or shared), ``None`` in free space; ``body``: the collision spheres it
            was checked with. :meth:`timed` verifies the executed motion against both.

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
    scene: Scene | None = None
    body: BodySpheres | None = None

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
    def deferred(cls, arrays: Mapping[str, np.ndarray], narrow: bool, **fields) -> Plan:
        """A plan whose tensor fields ``arrays`` (float64 or bool NumPy arrays, by field name: a dict, or
        :class:`LazyArrays` that makes them when first asked for) become tensors when first read (each a
        :func:`torch.from_numpy` of its array, rounded to float32 where ``narrow``), its other ``fields``
        as given: a batch-1 plan handed back without making the tensors its caller may never read
        (:meth:`~kinlearn.planning.planner.Planner.plan`'s free-space entry). It reads, compares, copies
        and pickles as the plan of those tensors."""
        plan = object.__new__(cls)
        state = plan.__dict__  # (a frozen dataclass's fields are its instance dict's, as __init__ sets them)
        state.update(_defaults(cls))
        state.update(fields)
        state["_arrays"] = (arrays, narrow)
        for name in _hidden(cls):  # given as an array, made now: its class default would hide it
            if name in arrays:
                plan.__getattr__(name)
        return plan

    def __getattr__(self, name: str):
        # only for attributes not set: a deferred plan's tensor fields, on first read
        arrays = self.__dict__.get("_arrays")
        if arrays is None or name not in arrays[0]:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        a = arrays[0][name]
        t = torch.from_numpy(a.astype(np.float32) if arrays[1] and a.dtype != np.bool_ else a)
        object.__setattr__(self, name, t)
        return t

    def __getstate__(self) -> dict:
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}

    def __setstate__(self, state: dict) -> None:
        for k, v in state.items():
            object.__setattr__(self, k, v)

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
        return cls(
            goal=goal,
            waypoints=ef[..., 1:-1, :] if waypoints is None else waypoints,
            joints=joints,
            ef=ef,
            target=target,
            goal_error=goal_error,
            joint_error=joint_error,
            success=ok,
            collision_free=collision_free,
            tolerance=tolerance,
            robot=robot,
            stage=stage,
        )

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
        if self.scene is not None and self.scene.batch_shape:
            fields["scene"] = self.scene[idx]
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
        """The motion a controller executes: a time-optimal trajectory along this plan's joint path within
        the robot's position, velocity and acceleration limits
        (:func:`kinlearn.planning.timing.time_parameterize`, toppra): times, positions, velocities,
        accelerations, at rest at both ends (``.to_csv``, ``.to_json``). One plan at a time.

        A plan made among obstacles keeps its scene and body, and the executed motion is verified
        against them: its samples, and the motion between consecutive samples, pass the same dense check
        as the plan (:data:`CHECK_TRAVEL` of sphere travel between checked configurations, the scene,
        the floor and self-collision). Where the smooth interpolant leaves the checked corridor the path
        gets more knots on its own segments there, then rests at the corners there, then follows its
        straight segments there, until the samples pass (``traj.verified`` is True). A plan whose own
        path collides raises :class:`~kinlearn.errors.UnsafeTrajectoryError`."""
        from .timing import time_parameterize

        self._single("timed()")
        verify = None if self.scene is None else executed_check(self.body, self.scene)
        return time_parameterize(self._robot(robot), self.joints, verify=verify, **options)

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


def executed_check(body: BodySpheres | None, scene: Scene, max_travel: float = CHECK_TRAVEL):
    """The check :meth:`Plan.timed` verifies an executed motion with, for one scene (batch shape ``()``)
    and the body it was planned with: a function of the sampled positions ``q (K, dof)`` giving, per
    sample interval ``(K − 1,)``, whether it collides — either sample touches the scene, the floor or
    the body itself (the compiled clearances), or the dense check of the polyline through the samples
    (``max_travel`` m of sphere travel between checked configurations) finds a collision in it (its
    first one; the next round of repairs finds any later one)."""
    from ..collision import kernel

    if body is None:
        raise ConfigError("a plan among obstacles needs the body it was checked with to verify its motion")
    if scene.batch_shape:
        raise ShapeError(f"executed_check takes one scene (batch shape ()), got {tuple(scene.batch_shape)}")
    kb = kernel.KernelBody.of(body)
    ks = kernel.KernelScene.of(scene if scene.dtype == torch.float64 else scene.to(torch.float64))

    def verify(q: np.ndarray) -> np.ndarray:
        # without per_sphere, clearances returns (scene clearance, self clearance) alone
        d, s = cast("tuple[np.ndarray, np.ndarray]", kernel.clearances(kb, ks, q))
        hit = (d <= 0.0) | (s <= 0.0)
        bad = hit[:-1] | hit[1:]
        free, _, first = kernel.check_paths(kb, q[None], ks, max_travel=max_travel, exact=False)
        if not free[0] and len(bad):
            bad[min(int(first[0]), len(bad) - 1)] = True
        return bad

    return verify


@functools.cache
def _defaults(cls: type) -> dict:
    """The defaults of a dataclass's fields that have one (a deferred :class:`Plan`'s starting state)."""
    return {f.name: f.default for f in dataclasses.fields(cls) if f.default is not dataclasses.MISSING}


@functools.cache
def _hidden(cls: type) -> tuple[str, ...]:
    """The tensor fields of a :class:`Plan` class that have a default (``collision_free``): the class
    holds the default, so a read of one never reaches :meth:`Plan.__getattr__`, and a deferred plan
    makes it at once."""
    return tuple(name for name in cls._BATCHED if name in _defaults(cls))
