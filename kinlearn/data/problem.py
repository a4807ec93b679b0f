"""A batch of planning problems: where each plan starts, where it must end, and what it must avoid.

:class:`Problem` is what every planner takes (:class:`~kinlearn.planning.plan.PlannerLike`: the learned
:class:`~kinlearn.planning.planner.Planner` and every baseline), what the trajectory models read
(:meth:`Problem.features`) and what evaluation runs planners on. Made once by :meth:`Problem.make`,
which checks everything a planner would otherwise check (shapes, dtypes, NaN/inf, joint limits, a
state's end effector against FK of its joints, obstacles) and fills in what was left out (a start or
goal given as joints gets its end effector by the analytic FK); after that a problem is trusted.

Goal kinds:

- ``"state"``: ``goal`` is a full state [θ(T), ef(T)]; the plan must end at its joints (and so at its
  end effector);
- ``"position"``: ``goal`` is an end-effector position ``(..., 3)``; any configuration reaching it will do.

``obstacles`` is a :class:`~kinlearn.collision.scene.Scene` of batch shape ``()`` (one scene for every
problem) or the problems' batch shape, or ``None`` (free space).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np
import torch
from numpy.typing import ArrayLike

from ..body.kinematics import kinematics
from ..body.robot import Robot, load_robot
from ..body.state import StateLayout
from ..checks import check_finite, check_real_dtype, real_array
from ..collision.scene import Scene, as_scene
from ..errors import BatchIndexError, ConfigError, ShapeError, StateError

if TYPE_CHECKING:
    from .endpoints import EndpointPairs
    from .problems import ProblemSet

__all__ = ["GOAL_KINDS", "STATE_EF_TOLERANCE", "Problem"]

#: What a goal can be: a full state (joints and end effector) or an end-effector position.
GOAL_KINDS = ("state", "position")
#: A given state's end effector may differ from FK of its joints by at most this much (m).
STATE_EF_TOLERANCE = 1e-3
#: Joint values may exceed the limits by this much (rad) before they count as outside.
LIMIT_TOLERANCE = 1e-6


#: Up to this many configurations, FK runs in the compiled kernel (microseconds); more go to torch.
SMALL_BATCH = 16


def _array(x, what: str) -> np.ndarray:
    """``x`` (a tensor, array or nested sequence of real numbers) as a float64 array (a view where it
    already is one)."""
    if isinstance(x, torch.Tensor):
        check_real_dtype(x, what)
        x = x.detach()
        if x.dtype == torch.float64 and x.device.type == "cpu":
            return x.numpy()
        return x.cpu().double().numpy()
    return real_array(x, what).astype(np.float64, copy=False)


def positions(robot: Robot, q: np.ndarray) -> np.ndarray:
    """End-effector positions ``(N, 3)`` of float64 joints ``q (N, dof)`` by the analytic FK: the compiled
    kernel for a few configurations (:class:`~kinlearn.collision.kernel.KernelChain`, no per-operation
    dispatch), torch's fast kinematics for many. The two agree to rounding (≈ 1e-16 m)."""
    if q.shape[0] <= SMALL_BATCH:
        from ..collision.kernel import KernelChain  # numba loads on first use, not at import

        return KernelChain.of(robot).position(q)
    return kinematics(robot, "fast").position(torch.from_numpy(q), validate=False).numpy()


@dataclass(frozen=True, eq=False)
class Problem:
    """A batch of planning problems for one robot (see the module docstring).

    Attributes (float64, batch shape ``...``):
        robot: the :class:`~kinlearn.body.robot.Robot` the problems are for.
        start: ``(..., dof + 3)`` start states [θ(0), ef(0)].
        goal: ``(..., dof + 3)`` goal states, or ``(..., 3)`` end-effector positions (``goal_kind``).
        goal_kind: ``"state"`` or ``"position"``.
        obstacles: a :class:`~kinlearn.collision.scene.Scene` of batch shape ``()`` or ``...``, or None.

    Build it with :meth:`make` (checked) rather than the constructor.
    """

    robot: Robot
    start: torch.Tensor
    goal: torch.Tensor
    goal_kind: Literal["state", "position"] = "state"
    obstacles: Scene | None = None

    @classmethod
    def make(
        cls,
        robot: Robot,
        start: ArrayLike,
        goal: ArrayLike | None = None,
        *,
        goal_position: ArrayLike | None = None,
        obstacles: Scene | ArrayLike | None = None,
    ) -> Problem:
        """Checked problems from ``start`` (joints ``(..., dof)`` or states ``(..., dof + 3)``) to ``goal``
        (joints, states, or an end-effector position ``(..., 3)``, also as ``goal_position=``), around
        ``obstacles`` (a Scene, or spheres ``(K, 4)`` / ``(..., K, 4)`` [x, y, z, radius]).

        Leading batch dimensions broadcast. Raises :class:`ShapeError`, :class:`DTypeError`,
        :class:`NonFiniteError`, :class:`JointLimitError`, :class:`StateError` (a state whose end
        effector is not FK of its joints), :class:`ObstacleError` or :class:`ConfigError`.
        """
        if not isinstance(robot, Robot):
            raise ConfigError(
                f"robot must be a kinlearn Robot (load_robot(name)), got {type(robot).__name__}"
            )
        if (goal is None) == (goal_position is None):
            raise ConfigError("give exactly one of goal (joints or a state) and goal_position (end effector)")
        dof, S = robot.dof, StateLayout(robot.dof).size
        x0 = _array(start, "start")
        position = goal_position is not None
        xT = _array(goal_position if position else goal, "goal_position" if position else "goal")
        if not position and xT.ndim > 0 and xT.shape[-1] == 3 and dof != 3:
            position = True
        if x0.ndim == 0 or x0.shape[-1] not in (dof, S):
            raise ShapeError(
                f"start must have shape (..., {S}) (a state [θ, ef]) or (..., {dof}) (joint values) for "
                f"{robot.name}; got {tuple(x0.shape)}"
            )
        if position and (xT.ndim == 0 or xT.shape[-1] != 3):
            raise ShapeError(f"goal_position must have shape (..., 3) (metres), got {tuple(xT.shape)}")
        if not position and (xT.ndim == 0 or xT.shape[-1] not in (dof, S)):
            raise ShapeError(
                f"goal must have shape (..., {S}) (a state), (..., {dof}) (joint values) or (..., 3) (an "
                f"end-effector position) for {robot.name}; got {tuple(xT.shape)}"
            )
        if x0.shape[:-1] == xT.shape[:-1]:
            batch = x0.shape[:-1]
        else:
            try:
                batch = np.broadcast_shapes(x0.shape[:-1], xT.shape[:-1])
            except ValueError as exc:
                raise ShapeError(
                    f"start {tuple(x0.shape)} and goal {tuple(xT.shape)} do not broadcast"
                ) from exc
            x0 = np.broadcast_to(x0, (*batch, x0.shape[-1]))
            xT = np.broadcast_to(xT, (*batch, xT.shape[-1]))
        if position:
            (start_state,) = _states(robot, (x0, "start"))
            if not np.isfinite(xT).all():
                check_finite(torch.from_numpy(np.ascontiguousarray(xT)), "goal_position")
            goal_state = np.array(xT)  # its own copy
        else:
            start_state, goal_state = _states(robot, (x0, "start"), (xT, "goal"))
        scene = None
        if obstacles is not None:
            scene = as_scene(obstacles, torch.Size(batch)).to(dtype=torch.float64, device="cpu")
        return cls(
            robot,
            torch.from_numpy(start_state),
            torch.from_numpy(goal_state),
            "position" if position else "state",
            scene,
        )

    def __post_init__(self) -> None:
        if self.goal_kind not in GOAL_KINDS:
            raise ConfigError(f"goal_kind must be one of {GOAL_KINDS}, got {self.goal_kind!r}")

    @property
    def layout(self) -> StateLayout:
        return StateLayout(self.robot.dof)

    @property
    def batch_shape(self) -> torch.Size:
        return self.start.shape[:-1]

    def __len__(self) -> int:
        if not self.batch_shape:
            raise BatchIndexError(
                "a single problem (batch shape ()) has no len(); Problem.make with inputs of shape (N, dof) "
                "gives a batch of N"
            )
        return self.batch_shape[0]

    def __getitem__(self, index) -> Problem:
        """The problems at ``index`` of the leading batch dimensions (the scene too, where it has them);
        :class:`BatchIndexError` for an index out of range or past the batch dimensions."""
        batch = tuple(self.batch_shape)
        if not batch:
            raise BatchIndexError("a single problem (batch shape ()) cannot be indexed")
        if isinstance(index, (str, bytes, float)):
            raise BatchIndexError(f"problems are indexed by integers, slices or masks, got {index!r}")
        try:  # the index applies to the batch dimensions only, never to a state's entries
            picked = torch.arange(self.start[..., 0].numel()).reshape(batch)[index]
        except (IndexError, TypeError, ValueError, RuntimeError) as exc:
            raise BatchIndexError(
                f"index {index!r} does not fit problems of batch shape {batch}: {exc}"
            ) from exc
        scene = self.obstacles
        if scene is not None and tuple(scene.batch_shape) != ():
            scene = scene.reshape(int(math.prod(batch)))[picked]
        start = self.start.reshape(-1, self.start.shape[-1])[picked]
        goal = self.goal.reshape(-1, self.goal.shape[-1])[picked]
        return Problem(self.robot, start, goal, self.goal_kind, scene)

    @property
    def start_joints(self) -> torch.Tensor:
        """``(..., dof)`` θ(0)."""
        return self.start[..., : self.robot.dof]

    @property
    def goal_joints(self) -> torch.Tensor:
        """``(..., dof)`` θ(T); :class:`ConfigError` for a position goal (it has no joints)."""
        self.require("state", "goal joints")
        return self.goal[..., : self.robot.dof]

    @property
    def target(self) -> torch.Tensor:
        """``(..., 3)`` the end-effector position the plan must end at."""
        return self.goal if self.goal_kind == "position" else self.goal[..., self.robot.dof :]

    def require(self, goal_kind: str, who: str) -> None:
        """Raise :class:`ConfigError` unless the goals are of ``goal_kind`` (for planners that take one)."""
        if self.goal_kind != goal_kind:
            raise ConfigError(f"{who} needs {goal_kind} goals; these problems have {self.goal_kind} goals")

    def position_goals(self) -> Problem:
        """The same problems with their goals reduced to the end-effector position (any configuration)."""
        return Problem(self.robot, self.start, self.target, "position", self.obstacles)

    def features(self) -> torch.Tensor:
        """What a trajectory model reads of the problems: ``[s(0), s(T)]`` ``(..., 2 (dof + 3))``."""
        self.require("state", "a trajectory model's input")
        return torch.cat((self.start, self.goal), dim=-1)

    @classmethod
    def from_pairs(cls, pairs: EndpointPairs) -> Problem:
        """The problems of endpoint pairs (:class:`~kinlearn.data.endpoints.EndpointPairs`: goal states)."""
        return cls.from_states(load_robot(pairs.config.robot), pairs.start, pairs.goal)

    @classmethod
    def from_problem_set(cls, problems: ProblemSet) -> Problem:
        """The problems of an obstacle benchmark set (:class:`~kinlearn.data.problems.ProblemSet`:
        start and goal joints, one scene each), checked like :meth:`make`."""
        return cls.make(load_robot(problems.robot), problems.start, problems.goal, obstacles=problems.scene)

    @classmethod
    def from_states(
        cls, robot: Robot, start: torch.Tensor, goal: torch.Tensor, obstacles: Scene | ArrayLike | None = None
    ) -> Problem:
        """Problems from start and goal states known to be consistent (e.g. drawn by
        :func:`~kinlearn.data.endpoints.make_endpoints`): shapes are checked, FK is not recomputed."""
        lay = StateLayout(robot.dof)
        for x, what in ((start, "start"), (goal, "goal")):
            if not isinstance(x, torch.Tensor) or x.ndim == 0 or x.shape[-1] != lay.size:
                raise ShapeError(
                    f"{what} states must have shape (..., {lay.size}), got {getattr(x, 'shape', x)}"
                )
        if start.shape != goal.shape:
            raise ShapeError(
                f"start and goal states differ in shape: {tuple(start.shape)}, {tuple(goal.shape)}"
            )
        scene = None if obstacles is None else as_scene(obstacles).to(dtype=torch.float64, device="cpu")
        return cls(robot, start.double(), goal.double(), "state", scene)


def state_error(what: str, worst: float) -> StateError:
    """The error for a state whose end-effector part is ``worst`` m from FK of its joints."""
    return StateError(
        f"{what}: its end-effector part differs from FK of its joints by up to {worst:.4g} m "
        f"(allowed {STATE_EF_TOLERANCE} m); pass joint values alone to have ef computed"
    )


def _states(robot: Robot, *parts: tuple[np.ndarray, str]) -> list[np.ndarray]:
    """Joints or states ``(..., dof [+ 3])`` (float64), each given with its name, as checked states: joints
    within the limits, ef = FK (computed once, here; for a few configurations the limits, finiteness and
    FK of all of them in one compiled call)."""
    dof = robot.dof
    flats = [x.reshape(-1, x.shape[-1]) for x, _ in parts]
    q = np.concatenate([f[:, :dof] for f in flats])  # contiguous
    ef = None
    if q.shape[0] <= SMALL_BATCH:
        from ..collision.kernel import KernelChain  # numba loads on first use, not at import

        ef, ok = KernelChain.of(robot).checked(q, LIMIT_TOLERANCE)
        good = bool(ok.all())
    else:  # one pass checks finiteness and the limits (a comparison with NaN is false)
        good = bool(((q >= robot.lower - LIMIT_TOLERANCE) & (q <= robot.upper + LIMIT_TOLERANCE)).all())
    if not good or any(f.shape[-1] > dof and not np.isfinite(f).all() for f in flats):  # explain
        for (x, what), f in zip(parts, flats, strict=True):
            check_finite(torch.from_numpy(np.ascontiguousarray(x)), what)
            robot.check_joints(
                torch.from_numpy(np.ascontiguousarray(f[:, :dof])), tol=LIMIT_TOLERANCE, what=f"{what} joints"
            )
    if ef is None:
        ef = positions(robot, q)
    out, o = [], 0
    for (x, what), f in zip(parts, flats, strict=True):
        m = f.shape[0]
        if f.shape[-1] > dof:
            err = np.linalg.norm(f[:, dof:] - ef[o : o + m], axis=-1)
            if (err > STATE_EF_TOLERANCE).any():
                raise state_error(what, float(err.max()))
        out.append(np.concatenate((q[o : o + m], ef[o : o + m]), axis=-1).reshape(*x.shape[:-1], dof + 3))
        o += m
    return out
