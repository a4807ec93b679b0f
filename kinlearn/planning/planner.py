"""Planning with a trained trajectory model: ``plan(start, goal)`` and :class:`Planner`.

Two kinds of trajectory model plan here:

- the **joint-path TM** (:class:`~kinlearn.models.joint_path.JointPathModel`, the shipped planners): it
  predicts every waypoint's joints and end effector in one pass; the plan is its joint path from the
  start's joints to the goal's, clamped to the limits, then checked by the analytic FK. A few problems
  run compiled (:mod:`kinlearn.planning.inference`); one problem given as two joint vectors is one
  compiled call from the input to the verdict, tens of microseconds; many problems run in torch;
- the paper's **waypoint TM** (:class:`~kinlearn.models.trajectory.TrajectoryModel`): it predicts the end
  effector of each waypoint, and the IM and FM roll out from the start through them to the goal
  (Algorithm 1; one model-based correction per action, joints kept exact), so its plan ends near the
  goal's end effector but not at the goal's joints.

A goal given as an end-effector position (``goal_position=`` or a goal of shape ``(..., 3)``) is
first turned into goal joints on the identified chain, or by the learned IM and FM stepping the end
effector along the straight line to it; the joint path is then planned to those joints. Among
obstacles the stages of :mod:`kinlearn.planning.around` make the joint path (the planner derives from
its :class:`~kinlearn.planning.around.ObstacleStages`).

Every plan says how it went (:class:`~kinlearn.planning.plan.Plan`: ``goal_error``, ``joint_error``,
``success``), measured by the analytic FK of its own joint path. Inputs outside the domain the TM was
trained on give a :class:`~kinlearn.errors.DomainWarning`, or a :class:`~kinlearn.errors.DomainError`
with ``strict=True``.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from functools import lru_cache
from pathlib import Path
from typing import cast

import numpy as np
import torch

from ..body.fk import KernelChain
from ..body.kinematics import kinematics
from ..body.robot import BUILTIN_ROBOTS, ROBOTS, Robot, load_robot
from ..body.state import StateLayout
from ..checks import as_int, as_real
from ..collision.body import BodySpheres
from ..collision.cloud_contact import CONTACT_MARGIN, ends_in_contact
from ..collision.scene import Scene, as_scene
from ..data.babbling import MAX_STEP
from ..data.problem import LIMIT_TOLERANCE, SMALL_BATCH, Problem, positions
from ..errors import (
    ConfigError,
    DomainError,
    DomainWarning,
    EndContactWarning,
    KinlearnError,
    NoObstacleModelWarning,
)
from ..io import load_checkpoint, resolve_dependency
from ..models.chain import ChainFM, solve_position, solve_position_arrays
from ..models.forward_inverse import ForwardModel, InverseModel, load_fm, load_im
from ..models.joint_path import JointPathModel, load_path_model
from ..models.obstacle_path import ObstaclePathModel, load_obstacle_model
from ..models.rollout import rectify
from ..models.trajectory import TrajectoryModel, load_trajectory_model
from .around import ObstacleStages, _kernel, _load_kernels, _retreat_over
from .inference import CompiledPathModel
from .judge import judge, verdict_small
from .plan import CHECK_TRAVEL, DEFAULT_TOLERANCE, START_TOLERANCE, LazyArrays, Plan, Tolerance
from .retreat import RetreatVias
from .stages import Deadline
from .stages import retreat_share as _retreat_share

__all__ = ["DEFAULT_CHECKPOINTS", "Planner", "plan", "step_to_position"]

#: Planners shipped inside the package, one folder per robot (see ``kinlearn/checkpoints/README.md``).
DEFAULT_CHECKPOINTS = Path(__file__).resolve().parents[1] / "checkpoints"

#: RRT-Connect iterations a plan gets by default (no deadline, no ``refine_steps``) where its learned
#: proposals (or, without an obstacle network, its straight line) and the retreat stage cleared nothing:
#: a fixed budget of work, so the same path on every machine. It only binds on the hardest cells (a cage
#: whose way out a few thousand samples miss, a passage a cloud's balls narrow); problems the earlier
#: stages clear never reach it, and a problem that fails pays it all (about 0.5 s on the ur5). 20,000 left
#: two of the ur5's tuning problems among surface clouds (seeds 3004–3010) unsolved that 30,000 solve.
DEFAULT_RRT_ITERATIONS = 50_000


#: A joint goal this close to the start (rad, every joint) is no move: its plan stays at the start.
ZERO_MOVE = 1e-9
#: The most refinement steps a plan may take (each costs milliseconds: a bound on a plan's time).
MAX_REFINE_STEPS = 10_000
#: An identified chain's file in a planner folder (position goals are solved on it).
CHAIN = "chain.pt"
#: Position goals farther than this many of the chain's reaches from the base are refused.
REACH_BOUND = 10.0
#: The position solver's budget: damped least-squares steps from the start and from each restart.
POSITION_ITERATIONS = 40
POSITION_RESTARTS = 16
#: The model error at which a position solution is taken as reaching its goal (m).
POSITION_TOLERANCE = 2e-4
#: The obstacle-aware TM's file in a planner folder.
OBSTACLE_TM = "tm_obstacles.pt"


def _out_dtype(x) -> tuple[torch.dtype, torch.device]:
    """The dtype and device a plan of input ``x`` (already checked) is handed back in: a floating tensor's
    own, float64 for a float64 array, else torch's default dtype; the CPU unless a tensor says otherwise."""
    if isinstance(x, torch.Tensor):
        return (x.dtype if x.is_floating_point() else torch.get_default_dtype()), x.device
    kind = x.dtype if isinstance(x, np.ndarray) else np.asarray(x).dtype
    return (torch.float64 if kind == np.float64 else torch.get_default_dtype()), torch.device("cpu")


class Planner(ObstacleStages):
    """A trajectory model with the frozen models it plans through, for one robot."""

    def __init__(
        self,
        robot: Robot,
        tm: JointPathModel | TrajectoryModel,
        fm: ForwardModel | None = None,
        im: InverseModel | None = None,
        *,
        refine: int = 1,
        exact_joints: bool = True,
        tolerance: Tolerance = DEFAULT_TOLERANCE,
        max_step: float | None = None,
        obstacle_tm: ObstaclePathModel | None = None,
        body: BodySpheres | None = None,
        refine_steps: int = 0,
        chain: ChainFM | None = None,
        retreat: bool = True,
        retreat_share: float | None = None,
        shortcut: bool = True,
        sample_first: bool = False,
    ):
        """``fm``/``im``: needed by a waypoint TM, and by a planner without ``chain`` for end-effector
        position goals.

        ``chain``: an identified chain FM (``kinlearn identify``): position goals are then solved on it
        (:func:`~kinlearn.models.chain.solve_position`: projected damped least squares with fixed
        restarts, within the joint limits, a fixed budget), instead of stepping the IM through the FM.

        ``obstacle_tm``: the obstacle-aware TM that plans when obstacles are given; ``body``: the arm's
        collision spheres its plans are checked with (default: the robot's planning body,
        :func:`~kinlearn.collision.planning_body`: its analytic sphere model, the ur5's carrying the
        standard benchmarks' gripper; ``body_spheres(robot)`` for the arm alone).
        ``retreat``: where no proposed path is collision-free, the retreat stage
        (:mod:`kinlearn.planning.retreat`: out of the start's cell and into the goal's along fixed
        end-effector retreats, the straight line or the network across; fixed time) before anything
        else; False leaves the proposals alone (the network's own fixed-time success).
        ``retreat_share``: under a deadline, the share of it after which the retreat stage starts no
        more work, so that the sampler keeps the rest (0: it does not run under a deadline; default the
        arm's measured one, :func:`~kinlearn.planning.stages.retreat_share`: 0.3, the ur5's 0).
        ``refine_steps``: where no proposed path is collision-free, this many steps of the gradient
        trajectory optimiser (:func:`kinlearn.planning.obstacle_baselines.trajectory_optimiser`) from the least
        colliding one, kept if the dense check then finds it free (0: none; the plan's time stays
        bounded either way).

        ``sample_first``: with the default sampling budget (no deadline, no ``refine_steps`` given), send a
        problem the learned proposals leave colliding to the compiled RRT-Connect next and to the retreat
        stage only where the sampler's budget runs out. Measured against the default (retreat first) by
        ``benchmarks/stage_order.py``: about the same median and success; a lower p99 where the retreat
        stage often fails and a higher one where it rarely does, by arm; longer paths where the orders
        differ (the retreat stage's are shorter).

        ``shortcut``: every plan a stage cleared among obstacles is shortened by the shortcut stage
        (:mod:`kinlearn.collision.shortcut`: deterministic, a fixed budget, checked densely; the path
        never grows longer); False hands over the stages' paths as they are.

        ``refine`` and ``exact_joints`` set the IM/FM rollout (see :func:`~kinlearn.models.rollout.rectify`):
        by default one model-based correction of each action and the joints kept at θ(0) + Σ â.
        ``refine=0, exact_joints=False`` is the paper's Algorithm 1 as published. ``tolerance``: when a
        plan counts as a success. ``max_step``: the largest joint change per IM action (rad; default: the
        FM's babbling step bound, :attr:`~kinlearn.models.interface.ForwardModel.max_step`).
        """
        if not isinstance(robot, Robot):
            raise ConfigError(f"robot must be a kinlearn.Robot (see load_robot), got {type(robot).__name__}")
        if refine < 0:
            raise ConfigError(f"refine must be ≥ 0, got {refine}")
        if not isinstance(tm, (JointPathModel, TrajectoryModel)):
            raise ConfigError(f"tm must be a JointPathModel or TrajectoryModel, got {type(tm).__name__}")
        if isinstance(tm, TrajectoryModel) and (fm is None or im is None):
            raise ConfigError("a waypoint TrajectoryModel plans through an FM and an IM: pass both")
        for what, m in (("TM", tm), ("FM", fm), ("IM", im)):
            if m is not None and m.robot_name != robot.name:
                raise ConfigError(
                    f"the {what} was trained for {m.robot_name!r}, the planner is for {robot.name!r}"
                )
        self.refine, self.exact_joints = int(refine), bool(exact_joints)
        self.shortcut = bool(shortcut)
        if max_step is None:  # the FM is valid for the steps of the data it learned from
            max_step = fm.max_step if fm is not None else MAX_STEP
        self.tolerance, self.max_step = tolerance, float(max_step)
        self.robot = robot
        self.layout = StateLayout(robot.dof)
        self.tm = tm.eval().requires_grad_(False)
        self.fm = fm.eval().requires_grad_(False) if fm is not None else None
        self.im = im.eval().requires_grad_(False) if im is not None else None
        for m in (self.fm, self.im):  # the planner checks its inputs once; no per-call re-checks
            if m is not None:
                m.validate_inputs = False
        self.kin = kinematics(robot)
        self._path_kernel = CompiledPathModel(tm) if isinstance(tm, JointPathModel) else None
        if obstacle_tm is not None:
            if not isinstance(obstacle_tm, ObstaclePathModel):
                raise ConfigError(
                    f"obstacle_tm must be an ObstaclePathModel, got {type(obstacle_tm).__name__}"
                )
            if obstacle_tm.robot_name != robot.name:
                raise ConfigError(
                    f"the obstacle TM was trained for {obstacle_tm.robot_name!r}, the planner is for {robot.name!r}"
                )
            obstacle_tm = obstacle_tm.eval().requires_grad_(False)
        self.obstacle_tm = obstacle_tm
        if chain is not None:
            if not isinstance(chain, ChainFM):
                raise ConfigError(
                    f"chain must be a ChainFM (see kinlearn identify), got {type(chain).__name__}"
                )
            if chain.robot_name != robot.name or chain.dof != robot.dof:
                raise ConfigError(
                    f"the chain was identified for {chain.robot_name!r} ({chain.dof} joints), the planner is "
                    f"for {robot.name!r} ({robot.dof})"
                )
            chain = chain.eval().requires_grad_(False)
            with torch.no_grad():  # how far the chain reaches, for refusing goals far beyond it
                q = robot.sample(4096, torch.Generator().manual_seed(0), dtype=torch.float64)
                self._chain_reach = float(chain.position(q).norm(dim=-1).max())
        self.chain = chain
        self._compiled_cache = None  # the obstacle network packed for the compiled proposals (first use)
        self._body, self._body64 = body, None
        self.refine_steps = _check_steps(refine_steps)
        if not isinstance(retreat, bool):
            raise ConfigError(f"retreat must be True or False, got {retreat!r}")
        self.retreat = retreat
        if not isinstance(sample_first, bool):
            raise ConfigError(f"sample_first must be True or False, got {sample_first!r}")
        self.sample_first = sample_first
        if retreat_share is None:
            retreat_share = _retreat_share(robot.name)
        self.retreat_share = as_real(
            retreat_share, "retreat_share", minimum=0.0, maximum=1.0, expected="a number in [0, 1] (or None)"
        )
        self._vias: RetreatVias | bool | None = None  # made on the first retreat (False: not possible)
        self._np_body_cache = None
        self._wide_robot = None  # the robot obstacle problems are checked with (first use)
        self._warm = False
        self._small, self._large = _Compiled, _Torch
        self._core = self._rollout
        self._lo, self._hi = robot.limits(torch.float64)
        self._lo_np, self._hi_np = self._lo.numpy(), self._hi.numpy()
        self._lo_tol, self._hi_tol = self._lo_np - LIMIT_TOLERANCE, self._hi_np + LIMIT_TOLERANCE
        # registered buffers (nn.Module's __getattr__ is typed Tensor | Module)
        dom_lo = cast(torch.Tensor, tm.domain_lo).double().numpy()
        dom_hi = cast(torch.Tensor, tm.domain_hi).double().numpy()
        # Inputs are already held within the joint limits: a domain that covers them checks nothing.
        S, J = self.layout.size, self.layout.joints
        covers = all(
            (dom_lo[k : k + S][J] <= self._lo_np + LIMIT_TOLERANCE).all()
            and (dom_hi[k : k + S][J] >= self._hi_np - LIMIT_TOLERANCE).all()
            and np.isinf(dom_lo[k : k + S][self.layout.ef]).all()
            and np.isinf(dom_hi[k : k + S][self.layout.ef]).all()
            for k in (0, S)
        )
        self._domain = None if covers else (dom_lo, dom_hi)

    # ----------------------------------------------------------------------------------------------
    # Loading
    # ----------------------------------------------------------------------------------------------

    @classmethod
    def load(cls, run_dir: str | Path, robot: str | Robot | None = None, **options) -> Planner:
        """Load a planner from a folder holding ``tm.pt`` and, where present, ``fm.pt``/``im.pt``.

        A waypoint TM run trained through models elsewhere finds them through its run configuration.
        ``options``: as for :meth:`__init__`.
        """
        run_dir = Path(run_dir)
        name = robot.name if isinstance(robot, Robot) else robot
        if not (run_dir / "tm.pt").is_file():
            raise ConfigError(
                f"{run_dir} holds no tm.pt; train one with `kinlearn train-tm --run-dir {run_dir}`"
            )
        # One verified read says which kind of TM the folder holds and what it records.
        payload = load_checkpoint(run_dir / "tm.pt", kind=None, robot=name)
        if payload["kind"] == JointPathModel.kind:
            # with_dependencies: the TM and the paths of the models it records
            tm, sources = cast(
                "tuple[JointPathModel, dict[str, Path]]",
                load_path_model(run_dir / "tm.pt", robot=name, with_dependencies=True, payload=payload),
            )
            fm = load_fm(sources["fm"], robot=tm.robot_name) if "fm" in sources else None
            im = load_im(sources["im"], robot=tm.robot_name) if "im" in sources else None
            if "chain" not in options and (run_dir / CHAIN).is_file():
                options["chain"] = load_fm(run_dir / CHAIN, robot=tm.robot_name)
            if "obstacle_tm" not in options:
                # A folder whose tm.pt records its obstacle TM (an export) must hold that very file.
                recorded = "obstacle_tm" in payload.get("depends", {})
                source = resolve_dependency(run_dir / "tm.pt", payload, "obstacle_tm") if recorded else None
                if source is None and (run_dir / OBSTACLE_TM).is_file():
                    source = run_dir / OBSTACLE_TM
                if source is not None:
                    options["obstacle_tm"] = load_obstacle_model(source, robot=tm.robot_name)
            return cls(_robot(robot, tm.robot_name), tm, fm, im, **options)
        tm, fm, im = load_trajectory_model(run_dir / "tm.pt", robot=name)
        if "chain" not in options and (run_dir / CHAIN).is_file():
            options["chain"] = load_fm(run_dir / CHAIN, robot=tm.robot_name)
        return cls(_robot(robot, tm.robot_name), tm, fm, im, **options)

    @classmethod
    def default(cls, robot: str | Robot = "iiwa14", **options) -> Planner:
        """The planner shipped with kinlearn for ``robot`` (one per process, shared); with ``options``
        (as for :meth:`__init__`, e.g. ``retreat=False``) a new one of the same models."""
        if isinstance(robot, Robot):
            robot = robot.name
        if options:
            return Planner.load(_shipped_folder(robot), robot=robot, **options)
        return _default_planner(robot)

    # ----------------------------------------------------------------------------------------------
    # Input checks: one Problem, made and checked once
    # ----------------------------------------------------------------------------------------------

    def _problem(self, start, goal, goal_position, obstacles) -> tuple[Problem, torch.dtype, torch.device]:
        """The problem :meth:`plan` was given (a :class:`Problem`, trusted as made) or the one its arguments
        make (:meth:`Problem.make` checks them, once), with the dtype and device the plan is handed back
        in: the inputs' (float64 on the CPU for a Problem)."""
        if isinstance(start, Problem):
            if goal is not None or goal_position is not None or obstacles is not None:
                raise ConfigError("a Problem carries its goal and obstacles: pass plan(problem) alone")
            if start.robot.name != self.robot.name:
                raise ConfigError(
                    f"this planner is for {self.robot.name!r}; the problems are for {start.robot.name!r}"
                )
            return start, torch.float64, torch.device("cpu")
        # Among obstacles, within the limits of the planning body's model where they allow more.
        robot = self.robot if obstacles is None else self._obstacle_robot
        problem = Problem.make(robot, start, goal, goal_position=goal_position, obstacles=obstacles)
        if robot is not self.robot:  # one warning for the starts and goal joints beyond the robot's own
            ends = [problem.start_joints.numpy().reshape(-1, robot.dof)]
            if problem.goal_kind == "state":
                ends.append(problem.goal_joints.numpy().reshape(-1, robot.dof))
            self._warn_beyond(np.concatenate(ends), stacklevel=4)
        dtype, device = _out_dtype(start)
        other, _ = _out_dtype(goal_position if goal_position is not None else goal)
        return problem, torch.promote_types(dtype, other), device

    def _check_domain(self, s0: np.ndarray, sT: np.ndarray | None, strict: bool) -> None:
        if self._domain is None:
            return
        lo, hi = self._domain
        S = self.layout.size
        parts = [("start", s0, lo[:S], hi[:S])]
        if sT is not None:
            parts.append(("goal", sT, lo[S:], hi[S:]))
        for what, s, a, b in parts:
            out = (s < a - LIMIT_TOLERANCE) | (s > b + LIMIT_TOLERANCE)
            if out.any():
                n = int(out.any(-1).sum())
                msg = (
                    f"{n} {what}(s) lie outside the domain this planner was trained on (its training "
                    f"problems' range of [θ, ef]); the plan may be poor"
                )
                if strict:
                    raise DomainError(msg + "; pass strict=False to plan anyway")
                warnings.warn(msg, DomainWarning, stacklevel=5)

    # ----------------------------------------------------------------------------------------------
    # Planning
    # ----------------------------------------------------------------------------------------------

    def plan(
        self,
        start,
        goal=None,
        *,
        goal_position=None,
        obstacles=None,
        refine_steps: int | None = None,
        deadline: float | None = None,
        strict: bool = False,
    ) -> Plan:
        """Plan from ``start`` to ``goal``, around ``obstacles`` if given; or plan a
        :class:`~kinlearn.data.problem.Problem` given as ``start`` (the planner protocol,
        :class:`~kinlearn.planning.plan.PlannerLike`: ``planner.plan(problem)``). The convenience form
        makes one :class:`Problem` of its arguments (:meth:`Problem.make`: every check, the start's and
        goal's FK, the obstacles as a float64 scene) and plans it; one problem given as joint vectors
        and a :class:`~kinlearn.collision.Scene` (or spheres ``(K, 4)``) is first tried without one (the
        start and goal checked and FK'd in one compiled call, then stage 1), and made into a Problem only
        where stage 1 leaves it colliding: the same plan, to the bit, for less Python.

        ``start``: joint values ``(..., dof)`` or a state ``(..., dof + 3)``. ``goal``: likewise — the plan
        ends at its joints — or an end-effector position ``(..., 3)`` (also as ``goal_position=``), reached
        in whatever configuration the learned models find. Tensors, arrays or sequences of numbers;
        leading batch dimensions broadcast. Deterministic: the same input gives the same plan bit for
        bit. Outputs have the input's floating dtype and device (a Problem's plan: float64).

        ``obstacles``: spheres ``[x, y, z, radius]`` (m, the robot's base frame) as ``(K, 4)`` (one scene
        for every plan) or ``(..., K, 4)`` (a scene per plan), or a :class:`~kinlearn.collision.Scene`
        (spheres, boxes, cylinders, a floor) of batch shape ``()`` or the plans'. The obstacle-aware TM
        proposes several joint paths, the straight joint line joins them, and the shortest (in joint
        space) that the dense check finds collision-free is the plan; where none is, the retreat stage
        (:mod:`kinlearn.planning.retreat`, unless the planner was made with ``retreat=False``) backs the
        hand out of the start's cell and into the goal's and crosses between them, in fixed time. The
        plan's ``collision_free`` says whether a stage cleared it (``success`` requires it); if none did,
        the shortest proposal, flagged. A start or goal that
        already collides gives a plan with ``collision_free`` False. Bad obstacles raise
        :class:`~kinlearn.errors.ObstacleError`. ``refine_steps``: overrides the planner's (see
        :meth:`__init__`) for this call: where no proposal is free, this many gradient steps refine the
        least colliding one (bounded time; 25 lifts the held-out success from 80% to 92%).

        ``deadline`` (seconds, from the call; the first plan among obstacles in a process first loads the
        compiled kernels and this planner's sphere body, about a second, before its clock starts:
        :meth:`warm_up`): among obstacles, where the learned proposals, the retreat stage and the
        refinement cleared nothing, RRT-Connect with shortcutting on the compiled checker
        (:mod:`kinlearn.collision.rrt`) gets what is left of it; the plan comes back by the deadline,
        flagged (``collision_free`` False) where nothing was cleared in time. Without a deadline (the
        default) plans are bit-reproducible; with one, whether the sampling stage finds a path in time
        depends on the machine (its path, once found, on the seed alone).

        By default (``refine_steps`` not given) a plan the fixed-time stages did not clear (the learned
        proposals, without an obstacle network the straight joint line alone, and the retreat stage) is
        sampled for: RRT-Connect runs for at most
        :data:`DEFAULT_RRT_ITERATIONS` iterations — a budget of work, not of time, so the plan is the
        same on every machine — or, with a deadline, for the time left. ``refine_steps=k`` (0 too) asks
        for fixed-time planning instead: the proposals, the retreat stage and k refinement steps, no
        sampling.
        ``plan.stage`` names the stage that made each plan (:mod:`kinlearn.planning.stages`). Free-space plans ignore the deadline (they are fixed-time).

        Every plan's verdict is :func:`~kinlearn.planning.plan.judge`'s (the analytic FK of its joint
        path, the limits, the goal within tolerance, the dense check among obstacles).

        Raises :class:`ShapeError`, :class:`DTypeError`, :class:`NonFiniteError`,
        :class:`JointLimitError` or :class:`StateError` for bad input; warns with
        :class:`DomainWarning` (or raises :class:`DomainError` when ``strict``) for input outside
        the training domain. A plan that misses its goal is returned with ``success`` False; one among
        obstacles that failed because its start or goal itself collides also warns with
        :class:`~kinlearn.errors.CollidingEndWarning`, which names the problems and says where the scene
        overlaps the robot's fixed base. Among a point cloud, one problem's start or goal that touches the
        points within the cloud's contact depth is taken to touch the surface they sample
        (:mod:`~kinlearn.collision.cloud_contact`), with an :class:`~kinlearn.errors.EndContactWarning`.
        """
        if (  # one free-space problem as two joint vectors: one compiled call
            obstacles is None
            and goal_position is None
            and refine_steps is None
            and deadline is None
            and self._domain is None
            and self._path_kernel is not None
        ):
            lean = self._batch1_free(start, goal)
            if lean is not None:
                return lean
        if obstacles is not None or getattr(start, "obstacles", None) is not None:
            self.warm_up()  # once, before the clock starts: no deadline is spent loading kernels
        timer = Deadline(deadline)  # started before the input is checked: the caller's time
        if obstacles is not None and goal_position is None and getattr(obstacles, "cloud", None) is not None:
            obstacles = self._in_contact(start, goal, obstacles)
        steps = self.refine_steps if refine_steps is None else _check_steps(refine_steps)
        stage1 = retreated = None  # what the batch-1 entry ran of a batch-1 problem's stages
        if obstacles is not None and goal_position is None:
            first = self._batch1(start, goal, obstacles, steps)
            if first is not None:
                q, ef, stage1, packed, dtype, scene = first
                paths, pick, free = stage1
                if free[0]:  # stage 1 cleared it: no Problem made
                    return self._batch1_plan(q, ef, paths[0, pick[0]], "learned", dtype, packed, scene)
                sampling = refine_steps is None and deadline is None  # the default budget of iterations
                retreat_now = not (sampling and self.sample_first)  # else after the sampler (_plan_around)
                if (
                    retreat_now
                    and self._retreat_vias() is not None
                    and not _retreat_over(timer, self.retreat_share)
                ):
                    path, branches = self._retreat(q[0], q[1], packed, steps, timer, sampling)
                    if path is not None:  # the retreat stage cleared it: no Problem made either
                        return self._batch1_plan(q, ef, path, "retreat", dtype, packed, scene)
                    retreated = branches  # the later stages start from its free retreats
                if refine_steps is not None and steps == 0 and deadline is None:  # no later stage runs
                    self._explain(q[:1], q[1:], _NOT_FREE, [packed], stacklevel=3)
                    return self._batch1_plan(
                        q, ef, paths[0, pick[0]], "none", dtype, packed, scene, free=False
                    )
        problem, dtype, device = self._problem(start, goal, goal_position, obstacles)
        return self._plan(
            problem, steps, refine_steps is None, strict, dtype, device, timer, stage1, retreated
        )

    __call__ = plan

    def _batch1_free(self, start, goal) -> Plan | None:
        """The batch-1 entry of a free-space plan, for the most common call: one problem given as joint
        vectors ``(dof,)`` (float tensors on the CPU or float arrays, as :meth:`_batch1` reads them), planned
        by a joint-path TM whose domain covers the limits: the ends checked and FK'd, the network, the
        knots and the verdict in one compiled call
        (:meth:`~kinlearn.planning.inference.CompiledPathModel.free_plan`), the same arithmetic as the
        general path's, so the same plan to the bit. None for any other input, or ends outside the limits
        or not apart: the general path checks (and explains) or plans them."""
        dof = self.robot.dof
        a, b = _joint_vector(start, dof), _joint_vector(goal, dof)
        if a is None or b is None:
            return None
        (a, da), (b, db) = a, b
        path_kernel = self._path_kernel
        assert path_kernel is not None  # the caller's condition
        tolerance = self.tolerance
        tols = (LIMIT_TOLERANCE, START_TOLERANCE, tolerance.position, tolerance.joints)
        out = path_kernel.free_plan(a, b, self._chain_kernel, ZERO_MOVE, tols)
        if out is None:
            return None
        buffer, ef = out
        dtype = da if da is db else torch.promote_types(da, db)
        # float32 rounded as torch's .to() rounds, without its per-tensor dispatch; the tensors (and the
        # views of the buffer) made when first read (a plan's caller often reads one or two of its eight)
        arrays = LazyArrays(_FREE_FIELDS, lambda: path_kernel.views(buffer, ef))
        plan = Plan.deferred(
            arrays, dtype == torch.float32, tolerance=tolerance, robot=self.robot.name, stage="learned"
        )
        if dtype in (torch.float64, torch.float32):
            return plan
        return _as_output(plan, dtype, _CPU, self._lo_np, self._hi_np)

    @property
    def _chain_kernel(self) -> KernelChain:
        """The robot's FK packed for the kernels (:meth:`KernelChain.of`: made once per robot)."""
        return KernelChain.of(self.robot)

    def _in_contact(self, start, goal, scene: Scene) -> Scene:
        """The scene a plan of one problem among a point cloud, given as finite joint vectors ``(dof,)``,
        plans in: where an end touches the points within the cloud's contact depth, without the points it
        touches there (:func:`~kinlearn.collision.cloud_contact.ends_in_contact`), with an
        :class:`~kinlearn.errors.EndContactWarning`. Other input as it is (a batch shares its cloud, and
        its problems' ends differ; the plan's checks explain bad joints)."""
        dof = self.robot.dof
        a, b = _joint_vector(start, dof), _joint_vector(goal, dof)
        if a is None or b is None or not isinstance(scene, Scene) or scene.batch_shape or scene.cloud is None:
            return scene
        q = np.stack((a[0], b[0]))
        if not np.isfinite(q).all():
            return scene
        contact = scene.cloud.contact
        scene, found = ends_in_contact(self._np_body, scene, q)
        if found:
            ends = " and ".join(
                f"the {c.end} (deepest point {c.depth * 1e3:.1f} mm inside the arm)" if c.depth > 0
                else f"the {c.end} (no point inside the arm, the points' balls reach it)"
                for c in found
            )  # fmt: skip
            warnings.warn(
                f"{ends} touches the point cloud within its contact depth ({contact * 1e3:g} mm): taken to "
                f"touch the surface the points sample, the points within {CONTACT_MARGIN * 1e3:g} mm of the "
                "arm there are dropped for this plan (a cloud of contact=0 refuses such an end)",
                EndContactWarning,
                stacklevel=3,
            )
        return scene

    def _batch1(self, start, goal, obstacles, steps: int) -> tuple | None:
        """The batch-1 entry of a plan among obstacles, for the most common call, one problem given as
        joint vectors ``(dof,)`` (float tensors on the CPU or float arrays) and an unbatched
        :class:`Scene` or spheres ``(K, 4)`` (read by :func:`~kinlearn.collision.scene.as_scene`), with an
        obstacle network: its joints ``(2, dof)`` (start, goal), their end effectors ``(2, 3)`` and its
        stage 1 ``(paths, pick, free)`` (:meth:`_learned`'s: the same candidates and verdicts as the
        general path's), the ends checked (finite, within the limits, apart), FK'd and planned in one
        compiled call (:meth:`~kinlearn.planning.proposals.CompiledObstacleModel.stage_one`). None for
        any other input, or one that fails a check or does not move: :meth:`Problem.make` then checks it
        (and explains what is wrong, the joints before the scene) and :meth:`_plan` plans it. The
        general path takes 0.2 ms more per plan in the Python around the compiled calls (making a
        Problem, judging it); each NumPy or torch call costs microseconds where other work ran before
        the plan (its code has left the caches), so this entry makes few."""
        if self.obstacle_tm is None or self._domain is not None:
            return None
        dof = self.robot.dof
        a, b = _joint_vector(start, dof), _joint_vector(goal, dof)
        if a is None or b is None:
            return None
        (a, da), (b, db) = a, b
        q = np.concatenate((a, b)).reshape(2, dof)  # (np.stack's Python costs more than the copy)
        try:  # a scene the general path refuses: it explains (after the joints, as it checks them first)
            obstacles = as_scene(obstacles)
            if obstacles.batch_shape:
                return None
            kernel = _kernel()
            packed = kernel.KernelScene.of(obstacles)  # the general path finds it packed (a float64 scene)
        except KinlearnError:
            return None
        first = self._compiled_tm.stage_one(
            q, kernel.KernelChain.of(self._obstacle_robot), self.body.limits, bool(steps), self._np_body, packed,
            CHECK_TRAVEL, LIMIT_TOLERANCE, ZERO_MOVE,
        )  # fmt: skip
        if first is None:  # an end outside the limits, or no move: the general path explains or plans it
            return None
        ef, paths, pick, free = first
        self._warn_beyond(q, stacklevel=4)
        return q, ef, (paths[None], pick, free), packed, torch.promote_types(da, db), obstacles

    def _batch1_plan(
        self, q, ef, path: np.ndarray, stage: str, dtype: torch.dtype, packed, scene: Scene, free: bool = True
    ) -> Plan:
        """The plan of a batch-1 problem whose joint path ``path (K, dof)`` a fixed-time stage cleared
        (:meth:`_batch1`'s stage 1, or the retreat stage run on its arrays), or, ``free`` False, that no
        stage cleared and no later stage is asked for (stage 1's shortest proposal, flagged): judged by
        :func:`judge`'s rule (:func:`~kinlearn.planning.plan.verdict_small`) on the arrays at hand, in the
        output's ``dtype`` (on the CPU, as the batch-1 entry's input)."""
        states = np.concatenate((q, ef), axis=1)
        if free and self.shortcut:
            path = self._shortened(path, packed)
        plan = verdict_small(
            self._obstacle_robot, np.ascontiguousarray(path[None]), states[:1], states[1:], True, (),
            (_FREE if free else _NOT_FREE).copy(), self.tolerance, stage=stage,
            deferred={"scene": scene, "body": self.body},
        )  # fmt: skip
        if dtype == torch.float64:  # its tensors made when first read (a caller often reads one or two)
            return plan
        return _as_output(plan, dtype, _CPU, self._obstacle_robot.lower, self._obstacle_robot.upper)

    def warm_up(self) -> None:
        """Load now what the first plan among obstacles would load (once per planner): the compiled
        check and sampler (:func:`_load_kernels`), the retreat stage's solver, this planner's sphere
        body and its self-collision pairs proven apart (:func:`~kinlearn.collision.kernel.proven_apart`,
        0.1–0.4 s), the obstacle network packed for its compiled call, and one small plan's code paths.
        :meth:`plan` calls it before its deadline's clock starts; call it ahead to keep the first plan's
        call short too."""
        if self._warm:
            return
        self._warm = True
        _load_kernels()
        vias = self._retreat_vias()
        if vias is not None:  # the chain's compiled solver
            vias.vias((self._lo_np + self._hi_np) / 2)
        _ = self._np_body.boxed  # the proof of the pairs apart: here, not in a plan
        if self.obstacle_tm is not None:
            _ = self._compiled_tm  # the network packed (the plan below compiles its one call)
        mid = torch.as_tensor((self._lo_np + self._hi_np) / 2)
        far = Scene.from_spheres([[10.0, 10.0, 10.0, 0.1]], floor=None)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            self.plan(mid, mid + 0.01, obstacles=far, refine_steps=0)

    def _plan(
        self,
        problem: Problem,
        steps: int,
        default_steps: bool,
        strict: bool,
        dtype,
        device,
        deadline: Deadline,
        first: tuple | None = None,
        retreated: tuple | None = None,
    ) -> Plan:
        """Plan a checked problem: its goal joints (solved first for a position goal), the joint paths
        (free space: the TM's; among obstacles the stages of :meth:`_plan_around`; ``first``: the batch-1
        entry's stage 1 of it, already run; ``retreated``: the free retreats of its retreat stage, run
        by the entry too and clearing nothing), one verdict (:func:`judge`), and the plan in the output's
        dtype and device."""
        batch = problem.batch_shape
        dof, S = self.robot.dof, self.layout.size
        n = math.prod(batch)
        s0 = problem.start.numpy().reshape(n, S)
        theta0, ef0 = s0[:, :dof], s0[:, dof:]
        position = problem.goal_kind == "position"
        if position:
            self._check_domain(s0, None, strict)
            target = problem.goal.numpy().reshape(n, 3)
            thetaT = self._reach_position(theta0, ef0, target)
            efT = positions(self.robot, thetaT)
        else:
            sT = problem.goal.numpy().reshape(n, S)
            self._check_domain(s0, sT, strict)
            thetaT, efT = sT[:, :dof], sT[:, dof:]
        free = waypoints = None
        iterations = 0  # the sampling stage's iteration budget without a deadline (0: no sampling)
        stage = np.full(n, "learned", dtype=object)
        timed = deadline.seconds is not None
        if problem.obstacles is not None:
            scene = problem.obstacles
            scene = scene.reshape(n) if len(scene.batch_shape) > 1 else scene
            if default_steps and not timed:  # a budget of work; a deadline bounds the sampling instead
                iterations = DEFAULT_RRT_ITERATIONS
            if self.obstacle_tm is None:
                if default_steps:
                    how = "then RRT-Connect on the compiled checker " + (
                        "within the deadline"
                        if timed
                        else f"for up to {iterations} iterations (deterministic)"
                    )
                else:
                    how = f"and {steps} steps of gradient refinement" if steps else "alone (refine_steps=0)"
                    if timed:
                        how += ", then RRT-Connect within the deadline"
                warnings.warn(
                    f"{self.robot.name} has no obstacle-trained network in this planner ({OBSTACLE_TM}): "
                    f"planning with the straight joint line {how}, checked densely; plan.collision_free says "
                    "whether it cleared the obstacles",
                    NoObstacleModelWarning,
                    stacklevel=4,
                )
            joints, free, stage = self._plan_around(
                theta0, ef0, thetaT, efT, scene, steps, deadline, iterations, first, retreated
            )
        elif self._path_kernel is not None:
            joints, waypoints = self._joint_path(theta0, ef0, thetaT, efT)
        else:
            joints, waypoints = self._waypoint_rollout(theta0, ef0, thetaT, efT)
        # A move of zero plans as no motion, whatever the TM proposes (a position goal the start
        # already reaches keeps the start's joints).
        still = (np.abs(thetaT - theta0) <= ZERO_MOVE).all(-1)
        if still.any():
            joints[still] = theta0[still, None]
            if waypoints is not None:
                waypoints[still] = ef0[still, None]
        lead = tuple(batch)
        paths = joints.reshape(*lead, *joints.shape[1:])  # arrays: judge's fast path
        wps = None if waypoints is None else waypoints.reshape(*lead, *waypoints.shape[1:])
        plan = judge(
            problem,
            paths,
            waypoints=wps,
            tolerance=self.tolerance,
            body=self.body if free is not None else None,
            collision_free=free,
            stage=str(stage[0]) if lead == () else stage.astype(str).reshape(lead),
        )
        if position:  # the state the planner chose to reach the target (the waypoint TM may end beside it)
            goal = np.concatenate((thetaT, efT), -1)
            plan = dataclasses.replace(
                plan, goal=torch.from_numpy(goal[0] if lead == () else goal.reshape(*lead, S))
            )
        if problem.obstacles is not None:  # what the plan was checked against, for its timed motion
            plan = dataclasses.replace(plan, scene=problem.obstacles, body=self.body)
        limits = problem.robot.lower, problem.robot.upper  # the obstacle robot's among obstacles
        return _as_output(plan, dtype, device, *limits)

    # ----------------------------------------------------------------------------------------------
    # Free space
    # ----------------------------------------------------------------------------------------------

    def _backend(self, n: int) -> type[_Backend]:
        """Where the free-space TM runs for a batch of ``n`` plans: NumPy for a few (no per-operation
        dispatch), torch for many (its batched products are faster there). The one place the batch
        size decides anything (obstacle plans are checked by the compiled kernels at every size)."""
        return self._small if n <= SMALL_BATCH else self._large

    def _joint_path(self, theta0, ef0, thetaT, efT) -> tuple[np.ndarray, np.ndarray]:
        """The joint-path TM's plan: knots ``(N, T + 1, dof)`` (clamped to the limits) and its ef
        waypoints ``(N, T − 1, 3)``."""
        n, dof = theta0.shape
        mid, waypoints = self._backend(n).tm(self, theta0, ef0, thetaT, efT)
        np.clip(mid, self._lo_np, self._hi_np, out=mid)
        joints = np.empty((n, mid.shape[1] + 2, dof))
        joints[:, 0], joints[:, 1:-1], joints[:, -1] = theta0, mid, thetaT
        return joints, waypoints

    @torch.no_grad()
    def _waypoint_rollout(self, theta0, ef0, thetaT, efT) -> tuple[np.ndarray, np.ndarray]:
        """The waypoint TM's plan (TM waypoints, IM/FM rollout): joints and waypoints."""
        net_dtype = cast(torch.Tensor, self.tm.in_mean).dtype  # a registered buffer
        s0 = torch.from_numpy(np.concatenate((theta0, ef0), -1)).to(net_dtype)
        sT = torch.from_numpy(np.concatenate((thetaT, efT), -1)).to(net_dtype)
        waypoints, actions = self._core(s0, sT)
        joints = theta0[:, None] + np.concatenate(
            (np.zeros_like(theta0[:, None]), np.cumsum(actions.double().numpy(), axis=1)), axis=1
        )
        return joints, waypoints.double().numpy()

    def _rollout(self, s0: torch.Tensor, sT: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """TM waypoints and the IM/FM rollout's actions for flat ``(N, S)`` states (network dtype)."""
        waypoints = self.tm(s0, sT)
        # a waypoint TM's planner holds both (__init__ refuses one without them)
        assert self.fm is not None and self.im is not None
        _, actions = rectify(
            waypoints,
            s0,
            sT,
            self.fm,
            self.im,
            self.layout,
            refine=self.refine,
            exact_joints=self.exact_joints,
        )
        return waypoints, actions

    def compile(self, **options) -> Planner:
        """Compile a waypoint TM's rollout with ``torch.compile`` (first calls per input shape are slow).

        Plans stay the same up to floating-point rounding; returns ``self``. The joint-path TM needs no
        compiling: it plans in a handful of NumPy operations.
        """
        if self._path_kernel is None:
            self._core = torch.compile(self._rollout, dynamic=False, **options)
        return self

    @torch.no_grad()
    def _solve_on_chain(self, theta0: np.ndarray, target: np.ndarray) -> np.ndarray:
        """Goal joints for end-effector positions on the identified chain (the analytic FK only judges).

        A start whose end effector the chain already puts on the goal keeps its joints (a move of zero);
        goals farther than :data:`REACH_BOUND` reaches are a :class:`DomainError`.
        """
        chain = self.chain
        assert chain is not None  # called for a planner with a chain alone (_reach_position)
        far = np.linalg.norm(target, axis=-1) > REACH_BOUND * self._chain_reach
        if far.any():
            k = int(np.argmax(far))
            raise DomainError(
                f"goal_position {target[k].tolist()} lies {np.linalg.norm(target[k]):.4g} m from the base; "
                f"{self.robot.name} reaches about {self._chain_reach:.3g} m, and goals beyond "
                f"{REACH_BOUND:g}× that are refused (they cannot be reached)"
            )
        if chain.residual is None:
            thetaT, _ = solve_position_arrays(
                chain,
                theta0,
                target,
                self._lo_np,
                self._hi_np,
                iterations=POSITION_ITERATIONS,
                restarts=POSITION_RESTARTS,
                tolerance=POSITION_TOLERANCE,
            )
        else:
            th, _ = solve_position(
                chain,
                torch.from_numpy(theta0),
                torch.from_numpy(target),
                self._lo,
                self._hi,
                iterations=POSITION_ITERATIONS,
                restarts=POSITION_RESTARTS,
                tolerance=POSITION_TOLERANCE,
            )
            thetaT = th.numpy()
        return thetaT

    def _reach_position(self, theta0: np.ndarray, ef0: np.ndarray, target: np.ndarray) -> np.ndarray:
        """Goal joints for end-effector positions: on the identified chain when the planner has one
        (:meth:`_solve_on_chain`), else found with the learned IM and FM alone.

        Without a chain: :func:`step_to_position`. The analytic FK is not used: it only judges the
        result (``plan.goal_error``).
        """
        if self.chain is not None:
            return self._solve_on_chain(theta0, target)
        if self.fm is None or self.im is None:
            raise ConfigError(
                "this planner has no chain and no FM and IM, which an end-effector position goal needs; give "
                "joint goals or load a planner folder holding chain.pt (kinlearn identify) or fm.pt and im.pt"
            )
        return step_to_position(
            self.fm,
            self.im,
            theta0,
            ef0,
            target,
            self._lo,
            self._hi,
            refine=self.refine,
            max_step=self.max_step,
        )


class _Backend:
    """Where the free-space TM's forward pass runs for a batch size (:meth:`Planner._backend`): a class
    whose static :meth:`tm` gives the knots ``(N, T − 1, dof)`` and ef waypoints ``(N, T − 1, 3)``."""

    @staticmethod
    def tm(planner: Planner, theta0, ef0, thetaT, efT) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError


class _Compiled(_Backend):
    """A few plans: the TM compiled (:class:`~kinlearn.planning.inference.CompiledPathModel`: no
    per-operation dispatch)."""

    @staticmethod
    def tm(planner: Planner, theta0, ef0, thetaT, efT) -> tuple[np.ndarray, np.ndarray]:
        path_kernel = planner._path_kernel
        assert path_kernel is not None  # the free-space TM of a joint-path TM's planner alone (_joint_path)
        return path_kernel(theta0, ef0, thetaT, efT)


class _Torch(_Backend):
    """Many plans: the TM in torch (in its dtype), one batched pass."""

    @staticmethod
    def tm(planner: Planner, theta0, ef0, thetaT, efT) -> tuple[np.ndarray, np.ndarray]:
        dtype = cast(torch.Tensor, planner.tm.in_mean).dtype  # a registered buffer
        s0 = torch.from_numpy(np.concatenate((theta0, ef0), -1)).to(dtype)
        sT = torch.from_numpy(np.concatenate((thetaT, efT), -1)).to(dtype)
        with torch.no_grad():
            out = planner.tm(s0, sT)
        return out.joints.double().numpy(), out.ef.double().numpy()


@torch.no_grad()
def step_to_position(
    fm: ForwardModel,
    im: InverseModel,
    theta0: np.ndarray,
    ef0: np.ndarray,
    target: np.ndarray,
    lower: torch.Tensor,
    upper: torch.Tensor,
    *,
    refine: int = 1,
    max_step: float = MAX_STEP,
) -> np.ndarray:
    """Goal joints ``(N, dof)`` for end-effector positions ``target (N, 3)`` from ``theta0`` (whose end
    effector is ``ef0``), with an IM and an FM alone: the end effector is stepped along the straight line
    in steps of at most 2 cm, then held at the target for 10 more steps; each action is the IM's,
    corrected ``refine`` times through the FM (â ← â + IM[FM[s, â], target]), bounded by ``max_step``
    and kept within the limits; the end effector of each new state is the FM's."""
    layout = fm.layout
    dtype = next(im.parameters(), torch.empty(0)).dtype
    theta, e0, p = (torch.tensor(a, dtype=dtype) for a in (theta0, ef0, target))
    lo, hi = lower.to(dtype), upper.to(dtype)
    # Each plan's own number of line steps (at most 2 cm each), so a plan does not depend on its batch.
    K = torch.ceil((p - e0).norm(dim=-1, keepdim=True) / 0.02).clamp_min(1)
    e = e0
    for k in range(1, int(K.max()) + 11 if K.numel() else 0):
        aim = e0 + torch.clamp(k / K, max=1.0) * (p - e0)
        s = layout.join(theta, e)
        a = im(s, aim)
        for _ in range(refine):
            a = a + im(fm(s, a), aim)
        a = a.clamp(-max_step, max_step)
        nxt = torch.minimum(torch.maximum(theta + a, lo), hi)
        e = fm(s, nxt - theta)[..., layout.ef]
        theta = nxt
    return theta.double().numpy()


def _joint_vector(x, dof: int) -> tuple[np.ndarray, torch.dtype] | None:
    """``x`` as float64 joints ``(dof,)`` (a view where it already is float64) and the dtype a plan of it is
    handed back in (:func:`_out_dtype`'s), where it is a float tensor on the CPU without a gradient and
    whose values NumPy reads, or a float array, of that shape; else None (for :meth:`Problem.make` to
    check). The tensor is read as an array first: NumPy's attributes cost less than torch's."""
    if isinstance(x, torch.Tensor):
        try:
            a = x.numpy()  # refused for a tensor on another device, with a gradient or in bfloat16
        except (TypeError, RuntimeError):
            return None
        dtype = _TORCH_FLOATS.get(a.dtype.type)
    elif isinstance(x, np.ndarray):
        a, dtype = x, torch.float64 if x.dtype == np.float64 else torch.get_default_dtype()
    else:
        return None
    if a.shape != (dof,) or a.dtype.kind != "f" or dtype is None:
        return None
    return a.astype(np.float64, copy=False), dtype


#: The torch dtype of a tensor whose values NumPy reads as a float array of each type.
_TORCH_FLOATS = {np.float64: torch.float64, np.float32: torch.float32, np.float16: torch.float16}
#: A batch-1 plan's collision verdict (:meth:`Planner._batch1_plan`: a copy of one, as its plan holds
#: it), and its device.
_FREE, _NOT_FREE, _CPU = np.ones(1, dtype=bool), np.zeros(1, dtype=bool), torch.device("cpu")
#: The tensor fields of a free-space batch-1 plan (:meth:`Planner._batch1_free`): all but the verdict
#: among obstacles.
_FREE_FIELDS = frozenset(Plan._BATCHED) - {"collision_free"}


def _as_output(plan: Plan, dtype: torch.dtype, device, lo: np.ndarray, hi: np.ndarray) -> Plan:
    """``plan`` (float64 on the CPU) in the output's ``dtype`` and ``device``; its joints kept within the
    limits ``lo``/``hi`` where half precision rounds them across."""
    if dtype != torch.float64 or device.type != "cpu":
        plan = dataclasses.replace(
            plan,
            **{
                f: v.to(device=device, dtype=dtype if v.is_floating_point() else v.dtype)
                for f in Plan._BATCHED
                if (v := getattr(plan, f)) is not None
            },
        )
    if plan.joints.dtype in (torch.float16, torch.bfloat16):  # rounding may cross a limit by 2e-3 rad
        plan = dataclasses.replace(plan, joints=_inside(plan.joints, lo, hi))
    return plan


def _inside(joints: torch.Tensor, lo: np.ndarray, hi: np.ndarray) -> torch.Tensor:
    """``joints (..., K, dof)`` of a half-precision plan with its interior configurations clamped to the
    limits rounded inward in that precision (the plan was judged within the limits in float64; its start
    and goal are the caller's own values, kept)."""
    lo_t, hi_t = (torch.from_numpy(b).to(device=joints.device, dtype=joints.dtype) for b in (lo, hi))
    lo64, hi64 = (torch.from_numpy(b).to(joints.device) for b in (lo, hi))
    lo_t = torch.where(lo_t.double() < lo64, torch.nextafter(lo_t, hi_t), lo_t)
    hi_t = torch.where(hi_t.double() > hi64, torch.nextafter(hi_t, lo_t), hi_t)
    out = joints.clone()
    out[..., 1:-1, :] = torch.minimum(torch.maximum(out[..., 1:-1, :], lo_t), hi_t)
    return out


def _check_steps(steps) -> int:
    return as_int(steps, "refine_steps", minimum=0, maximum=MAX_REFINE_STEPS)


def _robot(robot: str | Robot | None, name: str) -> Robot:
    if isinstance(robot, Robot):
        return robot
    return load_robot(name)


def _shipped_folder(robot: str) -> Path:
    """The folder of the planner kinlearn ships for ``robot`` (a ConfigError for any other arm)."""
    path = DEFAULT_CHECKPOINTS / robot
    own = (
        getattr(load_robot(robot), "planner_dir", None)
        if robot in ROBOTS and robot not in BUILTIN_ROBOTS
        else None
    )
    if own is not None:  # an onboarded arm (kinlearn.training.onboard.load_onboarded): its own planner folder
        return Path(own)
    # Only kinlearn's own arms ship planners: a registered arm never gets another arm's.
    if robot not in BUILTIN_ROBOTS or not (path / "tm.pt").is_file():
        shipped = sorted(p.name for p in DEFAULT_CHECKPOINTS.iterdir() if (p / "tm.pt").is_file())
        raise ConfigError(
            f"kinlearn ships no planner for {robot!r} (shipped: {', '.join(shipped)}); train one with "
            "`kinlearn train-planner` and load it with Planner.load(run_dir)"
        )
    return path


@lru_cache(maxsize=8)
def _default_planner(robot: str) -> Planner:
    return Planner.load(_shipped_folder(robot), robot=robot)


def plan(
    start,
    goal=None,
    *,
    goal_position=None,
    obstacles=None,
    refine_steps: int | None = None,
    deadline: float | None = None,
    robot: str | Robot = "iiwa14",
    strict: bool = False,
) -> Plan:
    """Plan with the planner shipped for ``robot`` (see :meth:`Planner.plan`)."""
    return Planner.default(robot).plan(
        start,
        goal,
        goal_position=goal_position,
        obstacles=obstacles,
        refine_steps=refine_steps,
        deadline=deadline,
        strict=strict,
    )
