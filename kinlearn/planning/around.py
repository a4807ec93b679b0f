"""Planning around obstacles: the stages a checked problem goes through once obstacles are given.

:class:`ObstacleStages` is the part of :class:`~kinlearn.planning.planner.Planner` that plans among
obstacles (the planner derives from it and holds the state it reads: the robot, the limits, the
obstacle network, the body, the chain): the learned proposals checked by the compiled dense check, the
retreat stage (:mod:`kinlearn.planning.retreat`), bounded refinement and the compiled RRT-Connect, each
for the problems the one before left colliding (:mod:`kinlearn.planning.stages`). The planner module
keeps what every plan goes through (the inputs checked once, the free-space TM, the verdict).

Every problem's scene is packed once for the compiled kernels (:mod:`kinlearn.collision.kernel`), which
also give the obstacle network its rows, and every batch size is checked by them.
"""

from __future__ import annotations

import copy
import warnings

import numpy as np
import torch

from ..collision.body import BodySpheres, planning_body
from ..collision.scene import Scene
from ..data.problem import LIMIT_TOLERANCE
from ..errors import BeyondLimitsWarning, CollidingEndWarning, NonFiniteError
from ..models.chain import ChainFM
from .plan import CHECK_TRAVEL
from .retreat import RetreatVias, retreat_path, sampler_branches
from .stages import DEADLINE_RESERVE, Deadline, densify

__all__ = ["NO_MODEL_KNOTS", "ObstacleStages"]

#: Without an obstacle-trained network: the straight joint line's segments.
NO_MODEL_KNOTS = 11


def _kernel():
    """The compiled collision kernels, imported on first use (numba takes about a second to load)."""
    if "kernel" not in _LAZY:
        from ..collision import kernel

        _LAZY["kernel"] = kernel
    return _LAZY["kernel"]


_LAZY: dict = {}


def _load_kernels() -> None:
    """Load the compiled collision check and sampler now (once per process; about a second from
    numba's cache), so that no plan's deadline is spent loading them."""
    if not _LAZY.get("warm"):
        from ..collision import rrt

        _kernel().warm_up()
        rrt.warm_up()
        _LAZY["warm"] = True


class ObstacleStages:
    """The obstacle stages of a :class:`~kinlearn.planning.planner.Planner` (see the module docstring).

    It reads what the planner holds: ``robot``, the limits ``_lo_np``/``_hi_np``, the obstacle network
    (``obstacle_tm``, packed for the compiled proposals on first use), the identified ``chain``, the given body
    (``_body``), ``retreat``, ``sample_first``, and the caches ``_body64``, ``_np_body_cache``, ``_compiled_cache``, ``_vias`` and
    ``_wide_robot`` its ``__init__`` sets to None.
    """

    @property
    def body(self) -> BodySpheres:
        """The collision spheres plans are checked with (float64; made once, the given body untouched): the
        given one, else the robot's planning body (:func:`~kinlearn.collision.planning_body`: the ur5's
        carries the standard benchmarks' gripper)."""
        if self._body64 is None:
            body = planning_body(self.robot) if self._body is None else self._body
            self._body64 = body if body.radii.dtype == torch.float64 else copy.deepcopy(body).double()
        return self._body64

    @property
    def _obstacle_robot(self):
        """The robot problems among obstacles are checked and judged with: the planner's, or, where its
        planning body's model allows more (:attr:`~kinlearn.collision.BodySpheres.outer_limits`: the
        benchmarks' MoveIt panda), the same robot with those limits (:meth:`~kinlearn.body.robot.Robot.with_limits`;
        made once)."""
        if self._wide_robot is None:
            self._wide_robot = self.robot.with_limits(*self.body.outer_limits)
        return self._wide_robot

    def _warn_beyond(self, q: np.ndarray, stacklevel: int) -> None:
        """Warn (:class:`~kinlearn.errors.BeyondLimitsWarning`) where starts or goals ``q (..., dof)`` of
        problems among obstacles (already checked within :attr:`_obstacle_robot`'s limits) leave the
        robot's own: they are planned within the limits of the model the planning body was read from."""
        if self._obstacle_robot is self.robot:
            return
        r = self.robot
        out = (q < r.lower - LIMIT_TOLERANCE) | (q > r.upper + LIMIT_TOLERANCE)
        if out.any():
            j = int(np.flatnonzero(out.reshape(-1, r.dof).any(0))[0])
            lo, hi = self._obstacle_robot.lower[j], self._obstacle_robot.upper[j]
            warnings.warn(
                f"a start or goal lies outside {r.name}'s joint limits (joint {r.joint_names[j]}: "
                f"[{r.lower[j]:.6g}, {r.upper[j]:.6g}] rad) but within those of its planning body's model "
                f"([{lo:.6g}, {hi:.6g}] rad, as the standard benchmarks' {r.name} allows): planned within the "
                "model's limits, where the robot itself may not go",
                BeyondLimitsWarning,
                stacklevel=stacklevel,
            )

    @property
    def _np_body(self):
        """The body packed for the compiled checks (:class:`~kinlearn.collision.kernel.KernelBody`)."""
        if self._np_body_cache is None:
            self._np_body_cache = _kernel().KernelBody(self.body)
        return self._np_body_cache

    def _fractions(self) -> np.ndarray:
        """Where the inner knots of every proposal sit along it ``(T − 1, 1)``: the obstacle network's, or
        without one the straight line's :data:`NO_MODEL_KNOTS` segments."""
        if self.obstacle_tm is None:
            return np.linspace(0.0, 1.0, NO_MODEL_KNOTS + 1)[1:-1, None]
        return self._compiled_tm.fractions[:, None]

    @property
    def _compiled_tm(self):
        """The obstacle network packed for the compiled proposals
        (:class:`~kinlearn.planning.proposals.CompiledObstacleModel`, made on first use: numba is
        imported with it)."""
        if self._compiled_cache is None:
            from .proposals import CompiledObstacleModel

            self._compiled_cache = CompiledObstacleModel(self.obstacle_tm)
        return self._compiled_cache

    def _boxes(self, theta0: np.ndarray, thetaT: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each problem's joint box (:meth:`~kinlearn.collision.BodySpheres.joint_box` of the planning body):
        every stage keeps its paths inside."""
        return self.body.joint_box(theta0, thetaT)

    def _line(self, theta0, thetaT, steps: int) -> np.ndarray:
        """The straight joint line ``(N, 1, K, dof)`` with the knots the proposals give it (the first
        candidate of :meth:`_proposals`, to the bit)."""
        f = self._fractions()
        return _knotted(theta0, (theta0[:, None] + f * (thetaT - theta0)[:, None])[:, None], thetaT, steps)

    def _proposals(self, theta0, ef0, thetaT, efT, scenes, steps: int) -> tuple[np.ndarray, np.ndarray]:
        """The candidate joint paths ``(N, C + 1, K, dof)`` (the straight joint line first, then the
        obstacle-aware TM's for the problem, then its paths for the problem the other way round, walked
        backwards: C twice the network's candidates; segments halved when refining) and each problem's
        order of them, shortest first (the straight line leads among equals).

        ``scenes``: per problem its scene's model rows ``(P, 7)`` and floor ``(2,)``, without padding. The
        TM runs on each problem alone, as a batch-1 plan runs it: float32 products of another batch size
        round differently (up to 3e-5 rad on the held-out set), and a plan must not depend on its
        batch-mates. Every candidate of every problem (a plan's stage 1, :meth:`_learned`, runs the
        network only where the line collides)."""
        n = theta0.shape[0]
        if self.obstacle_tm is None:  # the straight joint line alone
            return self._line(theta0, thetaT, steps), np.zeros((n, 1), dtype=np.int64)
        net = self._compiled_tm
        lo, hi = self._boxes(theta0, thetaT)
        paths = np.empty((n, *net.candidates_shape(bool(steps))))
        order = np.empty(paths.shape[:2], dtype=np.int64)
        for i in range(n):
            rows, floor = scenes[i]
            paths[i], order[i] = net.proposals(
                theta0[i], ef0[i], thetaT[i], efT[i], rows, floor, lo[i], hi[i], bool(steps)
            )
        return paths, order

    def _learned(self, theta0, ef0, thetaT, efT, packed: list, steps: int) -> tuple[np.ndarray, ...]:
        """Stage 1 for every problem: its candidate paths ``(N, 2C + 1, K, dof)`` (:meth:`_proposals`'),
        the one picked ``(N,)`` — the first collision-free in their order, else the shortest — and whether
        it is free ``(N,)``. The straight joint line, the shortest path, is checked first: where it is
        free it is the plan and the network does not run. One compiled call per problem
        (:meth:`~kinlearn.planning.proposals.CompiledObstacleModel.first_free`); without a network the
        line alone."""
        n = theta0.shape[0]
        if self.obstacle_tm is None:
            line = self._line(theta0, thetaT, steps)
            return line, np.zeros(n, dtype=np.int64), _lines_free(self, line, packed)
        net, body = self._compiled_tm, self._np_body
        lo, hi = self._boxes(theta0, thetaT)
        paths = None if n == 1 else np.empty((n, *net.candidates_shape(bool(steps))))
        pick, free = np.empty(n, dtype=np.int64), np.empty(n, dtype=bool)
        for i in range(n):
            p, order, k = net.first_free(
                theta0[i], ef0[i], thetaT[i], efT[i], lo[i], hi[i], bool(steps), body, packed[i], CHECK_TRAVEL
            )
            if paths is None:  # a batch-1 plan: its candidates as they are (no copy)
                paths = p[None]
            else:
                paths[i] = p
            pick[i], free[i] = k if k >= 0 else order[0], k >= 0
        return paths, pick, free

    def _plan_around(
        self,
        theta0,
        ef0,
        thetaT,
        efT,
        scene: Scene,
        steps: int,
        deadline: Deadline,
        iterations: int = 0,
        first: tuple | None = None,
        retreated: tuple | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Joint paths ``(N, K, dof)`` around ``scene``, whether each is collision-free ``(N,)`` and the
        stage that made it ``(N,)`` (:data:`~kinlearn.planning.stages.STAGES`).

        Stage 1 (:meth:`_learned`): the straight joint line, where it collides the learned proposals,
        each problem's first collision-free one in their order (exact verdicts), else its shortest, flagged. Stage 2 (the planner's ``retreat``),
        for the problems stage 1 left colliding: :meth:`_retreat`. Stage 3 (``steps`` > 0), for those
        still colliding: the optimiser from the least colliding proposal (:meth:`_refine`), kept if the
        dense check finds it free. Stage 4 (a ``deadline``, or an iteration budget ``iterations``), for
        those still colliding, one after the other while time is left: the compiled RRT-Connect
        (:meth:`_sample`). With a budget and no deadline the retreat stage runs after the sampler instead,
        on what its budget left (:meth:`_samples_first`). Each plan is its problem's alone: proposals are made as at batch 1, the
        optimiser starts from the very path a batch-1 plan starts from, and paths of other lengths (the
        retreat stage's, the sampler's) are brought to the batch's longest by splitting segments (the
        same polylines, checked again). ``first``: stage 1's ``(paths, pick, free)`` for these very
        problems where the caller already ran it (the planner's batch-1 entry); ``retreated``: where the
        entry ran the retreat stage on its one problem too and it cleared nothing, its free retreats (the
        sampler's first branches; the stage is not run again).
        """
        n = theta0.shape[0]
        packed = _packed_scenes(scene, n)  # the scene converted once, for the TM and the check
        if first is None:
            paths, pick, free = self._learned(theta0, ef0, thetaT, efT, packed, steps)
        else:  # stage 1 already run (the planner's batch-1 entry), on this very problem
            paths, pick, free = first
        out = paths[np.arange(n), pick]
        if free.all():  # every plan cleared by stage 1 (a batch-1 plan most often): no later stage runs
            return self._shorten_free(out, free, packed), free, np.full(n, "learned", dtype=object)
        stage = np.where(free, "learned", "none").astype(object)
        batched = len(scene.batch_shape) > 0

        found: dict[int, tuple[np.ndarray, str]] = {}  # paths of other lengths, joined at the end
        branches: dict[int, tuple] = {}  # each problem's free retreats, the sampler's first branches
        open_ = ~free  # the problems no stage has cleared yet
        first_sampled = self._samples_first(deadline, iterations)
        if not first_sampled:  # a budget of sampler iterations (no deadline) next, or not
            sampler_next = deadline.seconds is None and iterations > 0
            self._retreat_open(
                theta0, thetaT, packed, open_, steps, deadline, found, branches, retreated, sampler_next
            )
        if steps:
            for i in np.flatnonzero(open_):
                if deadline.expired(DEADLINE_RESERVE):
                    break
                nscene = packed[i]
                _, clear, _ = _kernel().check_paths(self._np_body, paths[i], nscene, max_travel=CHECK_TRAVEL)
                best = paths[i, int(np.argmax(clear))]  # from the least colliding one
                out[i], free[i] = self._refine(best, scene[int(i)] if batched else scene, nscene, steps)
                stage[i] = "refine" if free[i] else "none"
                open_[i] = not free[i]
        if deadline.seconds is not None or iterations:
            for i in np.flatnonzero(open_):
                if deadline.expired(DEADLINE_RESERVE):  # never, without a deadline
                    break
                path = self._sample(
                    theta0[i],
                    thetaT[i],
                    packed[i],
                    deadline,
                    int(i),
                    iterations,
                    branches.get(int(i), ((), ())),
                )
                if path is not None:
                    found[int(i)] = (path, "rrt")
                    open_[i] = False
        if first_sampled:  # what the sampler's budget left: the retreat stage, last
            self._retreat_open(
                theta0, thetaT, packed, open_, steps, deadline, found, branches, retreated, False
            )
        if found:
            # Every plan at the knots of the longest: a later stage's path as it is where later stages
            # replaced every proposal (a batch-1 plan), else at least at the proposals' knots.
            longest = max(p.shape[0] for p, _ in found.values())
            K = longest if len(found) == n else max(longest, out.shape[1])
            cleared = self._cleared(found, K, packed)
            if len(cleared) < n and K < out.shape[1]:  # a proposal stays after all: at its knots
                K = out.shape[1]
                cleared = self._cleared(found, K, packed)
            if K > out.shape[1]:  # the same polylines, at K knots
                out = np.stack([densify(p, K) for p in out])
            elif K < out.shape[1]:  # every row is a later stage's path (below)
                out = np.empty((n, K, out.shape[2]))
            for i, dense in cleared.items():
                out[i], free[i], stage[i] = dense, True, found[i][1]
        if not free.all():  # the user's plan() is four calls up
            self._explain(theta0, thetaT, free, packed, stacklevel=5)
        return self._shorten_free(out, free, packed), free, stage

    def _samples_first(self, deadline: Deadline, iterations: int) -> bool:
        """Whether the sampler runs before the retreat stage: with a budget of iterations and no deadline,
        where the planner asks for it (``Planner(sample_first=True)``; ``benchmarks/stage_order.py``
        measures both orders)."""
        return self.sample_first and iterations > 0 and deadline.seconds is None

    def _retreat_open(
        self, theta0, thetaT, packed: list, open_: np.ndarray, steps: int, deadline: Deadline, found: dict,
        branches: dict, retreated: tuple | None, sampler_next: bool,
    ) -> None:  # fmt: skip
        """The retreat stage on the problems still ``open_`` (cleared ones added to ``found`` and closed;
        each problem's free retreats kept in ``branches``, the sampler's first branches); ``retreated``:
        the batch-1 entry ran it on its one problem already, clearing nothing (not run again);
        ``sampler_next``: :meth:`_retreat`'s."""
        if self._retreat_vias() is None:
            return
        for i in np.flatnonzero(open_):
            if retreated is not None:
                branches[int(i)] = retreated
                continue
            if _retreat_over(deadline, self.retreat_share):
                break
            path, branches[int(i)] = self._retreat(
                theta0[i], thetaT[i], packed[i], steps, deadline, sampler_next
            )
            if path is not None:
                found[int(i)] = (path, "retreat")
                open_[i] = False

    def _shorten_free(self, paths: np.ndarray, free: np.ndarray, packed: list) -> np.ndarray:
        """The shortcut stage on every cleared plan of ``paths (N, K, dof)`` (:meth:`_shortened`)."""
        for i in np.flatnonzero(free if self.shortcut else ()):
            paths[i] = self._shortened(paths[i], packed[i])
        return paths

    def _shortened(self, path: np.ndarray, nscene) -> np.ndarray:
        """The shortcut stage (:func:`~kinlearn.collision.shortcut.shorten`: vertex skipping, then
        :data:`~kinlearn.collision.shortcut.DEFAULT_ATTEMPTS` partial shortcuts, deterministic) on a cleared
        path ``(K, dof)``, kept at ``K`` knots by repeating its last one (the goal): every segment of the
        result is one the pass checked, or none (a repeated knot), so its verdict is the pass's. A path
        the pass does not shorten is handed back as it was."""
        from ..collision.shortcut import shorten

        K = path.shape[0]
        short = shorten(self._np_body, nscene, path, cap=K, max_travel=CHECK_TRAVEL)
        before, after = (float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum()) for p in (path, short))
        if after >= before * (1.0 - 1e-9):  # nothing shortened (a straight line stays at its knots)
            return path
        if short.shape[0] < K:
            short = np.concatenate((short, np.repeat(short[-1:], K - short.shape[0], axis=0)))
        return short

    def _cleared(self, found: dict, K: int, packed: list) -> dict[int, np.ndarray]:
        """The later stages' paths ``found`` ({problem: (path, stage)}) at ``K`` knots each (:func:`densify`),
        those the dense check of their own knots finds free: the plan's knots are checked as the plan
        will be judged (sub-steps of its own segments), not only the sampler's motions, so no plan is
        called free that the dense check of its joints would not call free. A retreat path's segments
        were checked as they are (the verdict of a polyline is its segments'): again only when split."""
        out = {}
        for i, (path, name) in found.items():
            dense = densify(path, K)
            if (name == "retreat" and dense.shape[0] == path.shape[0]) or _kernel().first_free(
                self._np_body, dense[None], packed[i], max_travel=CHECK_TRAVEL
            ) == 0:
                out[i] = dense
        return out

    def _retreat_vias(self) -> RetreatVias | None:
        """The retreat stage's via solver (made once): on the planner's identified chain, else on the
        chain its robot's model describes; None where the stage is skipped: a planner made with
        ``retreat=False``, or an arm that is not all revolute joints."""
        if not self.retreat:
            return None
        if self._vias is None:
            from ..data.scenes import scene_scale

            if self.chain is None and any(j.kind != "revolute" for j in self.robot.joints):
                self._vias = False
            else:
                chain = self.chain if self.chain is not None else ChainFM.from_robot(self.robot)
                self._vias = RetreatVias(chain, self._lo_np, self._hi_np, scene_scale(self.robot))
        return self._vias or None

    def _retreat(
        self,
        theta0: np.ndarray,
        thetaT: np.ndarray,
        nscene,
        steps: int,
        deadline: Deadline,
        sampler_next: bool,
    ) -> tuple[np.ndarray | None, tuple]:
        """The retreat stage (:mod:`kinlearn.planning.retreat`) for one problem: its path ``(V, dof)`` or
        None, and the free retreats of either end (:func:`~kinlearn.planning.retreat.sampler_branches`: the
        sampler grows its trees from them). Its transfers are stage 1's (:meth:`_learned`) between two
        configurations. ``sampler_next``: a budget of sampler iterations follows (no deadline), which
        clears what the learned transfers leave sooner than transfers through midpoints do (step 4 of
        :mod:`~kinlearn.planning.retreat`, run otherwise; see
        :data:`~kinlearn.planning.retreat.MIDPOINT_TRANSFERS`)."""
        k, body = _kernel(), self._np_body
        lo, hi = self._boxes(theta0[None], thetaT[None])
        vias = self._retreat_vias().within(lo[0], hi[0])  # the vias kept in the problem's box

        # The kernels' compiled cores on the stage's own float64 arrays (C-contiguous; orders of distinct
        # indices): the public wrappers' checks and conversions cost more than the joins' check itself.
        def first_free(paths, order):
            found = k.first_free_boxed(paths, order, CHECK_TRAVEL, 0.0, *body.boxed, nscene.packed)
            if found == -2:
                raise NonFiniteError("a retreat path holds NaN or infinity")
            return found

        def depths(theta, chains):  # each chain walked to its first collision, all in one compiled call
            depth = np.empty(chains.shape[0], dtype=np.int64)
            if not k.free_depths_boxed(theta, chains, CHECK_TRAVEL, 0.0, *body.boxed, nscene.packed, depth):
                raise NonFiniteError("a retreat via holds NaN or infinity")
            return depth

        transfer = None
        if self.obstacle_tm is not None:
            net, chain, limits = self._compiled_tm, k.KernelChain.of(self._obstacle_robot), self.body.limits

            def transfer(a, b):  # stage 1 between two configurations (:meth:`_learned`'s, in one call)
                # (a zero move of −1: no pair of vias is refused for lying close, as _learned refuses none)
                first = net.stage_one(
                    np.stack((a, b)), chain, limits, bool(steps), body, nscene, CHECK_TRAVEL, LIMIT_TOLERANCE, -1.0
                )  # fmt: skip
                if first is None:  # a via outside the limits (they are solved within them)
                    return None
                _, paths, pick, free = first
                return paths[pick[0]] if free[0] else None

        def distance(points):
            return k.point_distances(nscene, points)

        (v0, d0), (vT, dT) = (
            vias.free(theta0, depths, distance),
            vias.free(thetaT, depths, distance),
        )
        path = retreat_path(
            theta0,
            thetaT,
            v0,
            vT,
            d0,
            dT,
            first_free,
            transfer,
            stop=lambda: _retreat_over(deadline, self.retreat_share),
            midpoints=None if transfer is None or sampler_next else vias.midpoints,
        )
        return path, (sampler_branches(v0, d0), sampler_branches(vT, dT))

    def _explain(self, theta0, thetaT, free: np.ndarray, packed: list, stacklevel: int) -> None:
        """Warn (:class:`~kinlearn.errors.CollidingEndWarning`) where plans that are not ``free (N,)`` failed
        because their start ``theta0`` or goal ``thetaT (N, dof)`` itself collides with its scene ``packed``
        (:class:`~kinlearn.collision.kernel.KernelScene` each) or with the arm, naming the problems, and
        saying where the scene overlaps the robot's fixed base. Nothing where their ends are free (a plan no
        stage found). Run only for plans that failed."""
        k, body = _kernel(), self._np_body
        base = body.link == 0  # the spheres no joint moves
        starts, goals, overlap = [], [], False
        for i in np.flatnonzero(~free):
            ends = np.ascontiguousarray(np.stack((theta0[i], thetaT[i])), dtype=np.float64)
            d, s, per = k.clearances(body, packed[i], ends, per_sphere=True)
            hit = (d <= 0.0) | (s <= 0.0)  # touching counts, as in the dense check
            if hit[0]:
                starts.append(int(i))
            if hit[1]:
                goals.append(int(i))
            overlap |= bool((per[:, base] <= 0.0).any())
        if not starts and not goals:
            return
        named = lambda idx: ", ".join(map(str, idx[:8])) + (", …" if len(idx) > 8 else "")  # noqa: E731
        parts = [f"the start of problem(s) {named(starts)}"] if starts else []
        parts += [f"the goal of problem(s) {named(goals)}"] if goals else []
        msg = (
            f"{' and '.join(parts)} collide(s) with the scene or with the arm itself before any motion: no "
            "collision-free plan can start or end there (plan.collision_free is False)"
        )
        if overlap:
            msg += (
                "; the scene overlaps the robot's fixed base (its spheres on link 0, which no joint moves), as a "
                "surface the robot stands on given as a box does: leave that surface out of the scene or give "
                "it as the floor (Scene(..., floor=height)), which the base stands on"
            )
        warnings.warn(msg, CollidingEndWarning, stacklevel=stacklevel)

    def _sample(
        self,
        start: np.ndarray,
        goal: np.ndarray,
        nscene,
        deadline: Deadline,
        seed: int,
        iterations: int,
        branches: tuple = ((), ()),
    ):
        """Stage 4: the compiled RRT-Connect from ``start`` to ``goal`` for what ``deadline`` leaves (less
        :data:`~kinlearn.planning.stages.DEADLINE_RESERVE`) and at most ``iterations`` iterations (0: no
        budget but the deadline); its path ``(V, dof)`` or None (the shortcut stage shortens it with the
        other stages' plans). ``branches``: the free
        retreats of the start and of the goal, its trees' first branches (out of a cell already)."""
        from ..collision.rrt import rrt_connect

        left = deadline.left() - DEADLINE_RESERVE  # inf without a deadline
        if left <= 0:
            return None
        lo, hi = self._boxes(start[None], goal[None])
        path, _, _ = rrt_connect(
            self._np_body, nscene, start, goal, lo[0], hi[0], time_limit=left, seed=seed,
            max_travel=CHECK_TRAVEL, clock=deadline.clock,
            max_iterations=iterations or None, branches=branches, shortcut=False,
        )  # fmt: skip
        return path

    def _refine(self, path: np.ndarray, scene: Scene, nscene, steps: int) -> tuple[np.ndarray, bool]:
        """``steps`` steps of the gradient trajectory optimiser from ``path`` (if any); the refined path
        and whether the dense check finds it free. Without steps: ``(path, False)``."""
        if not steps:
            return path, False
        from .obstacle_baselines import OptimiserConfig, trajectory_optimiser

        p = torch.from_numpy(path)
        config = OptimiserConfig(knots=p.shape[0])  # the plan's own length: every plan of a batch has it
        refined, _ = trajectory_optimiser(
            p[0], p[-1], scene, steps=steps, config=config, body=self.body, init=p
        )
        refined = np.ascontiguousarray(refined.numpy())
        lo, hi = self._boxes(path[:1], path[-1:])
        if (refined < lo).any() or (refined > hi).any():  # out of the problem's box: not a plan
            return path, False
        free = _kernel().first_free(self._np_body, refined[None], nscene, max_travel=CHECK_TRAVEL) == 0
        return (refined, True) if free else (path, False)


# Obstacle plans are checked by the compiled kernels at every batch size: a problem's candidates in
# the order of their length, each walked with the skipping bounds and stopped at its first collision
# (:mod:`kinlearn.collision.kernel`), where torch's dense check evaluates every sub-step of every
# candidate (on the CPU, 0.2 s for 200 held-out iiwa14 problems against a ConfigError for too many
# configurations; 88 s for 17 of the panda's scene-family problems).


def _retreat_over(deadline: Deadline, share: float) -> bool:
    """Whether the retreat stage may start no more work: the deadline is (nearly) over, or its
    ``share`` of it is spent (the planner's ``retreat_share``)."""
    return deadline.expired(DEADLINE_RESERVE) or deadline.spent(share)


def _packed_scenes(scene: Scene, n: int) -> list:
    """Each problem's scene packed once for the kernels (which also give the obstacle TM its rows)."""
    K = _kernel().KernelScene
    if len(scene.batch_shape) == 0:
        return [K.of(scene)] * n
    return [K(scene[i]) for i in range(n)]


def _lines_free(planner: ObstacleStages, line: np.ndarray, packed: list) -> np.ndarray:
    """Whether each problem's straight joint line ``(N, 1, K, dof)`` is free (the exact verdict)."""
    check = _kernel().first_free
    return np.array(
        [
            check(planner._np_body, line[i], packed[i], max_travel=CHECK_TRAVEL) == 0
            for i in range(len(packed))
        ],
        dtype=bool,
    )


def _knotted(theta0: np.ndarray, inner: np.ndarray, thetaT: np.ndarray, steps: int) -> np.ndarray:
    """Paths ``(N, C, T + 1, dof)`` from their inner knots ``(N, C, T − 1, dof)`` between each problem's
    start and goal ``(N, dof)``, each segment halved when refining (``steps`` > 0)."""
    n, C, inside, dof = inner.shape
    paths = np.empty((n, C, inside + 2, dof))
    paths[:, :, 0] = theta0[:, None]
    paths[:, :, 1:-1] = inner
    paths[:, :, -1] = thetaT[:, None]
    return _halve_segments(paths) if steps else paths


def _halve_segments(paths: np.ndarray) -> np.ndarray:
    """Joint paths ``(..., K, dof)`` with a knot inserted halfway along each segment: ``(..., 2K − 1, dof)``,
    the same piecewise-linear paths."""
    out = np.empty((*paths.shape[:-2], 2 * paths.shape[-2] - 1, paths.shape[-1]))
    out[..., 0::2, :] = paths
    out[..., 1::2, :] = 0.5 * (paths[..., :-1, :] + paths[..., 1:, :])
    return out
