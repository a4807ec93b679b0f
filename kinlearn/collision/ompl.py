"""The one OMPL adapter: RRT-Connect in joint space, with OMPL's path simplifier (shortcutting), its
validity answered by kinlearn's checker.

Every use of OMPL in kinlearn goes through :class:`OmplRrtConnect`: the free-space RRT-Connect baseline
(:func:`kinlearn.planning.baselines.rrt_connect_timed`), the obstacle baseline
(:func:`kinlearn.planning.obstacle_baselines.scene_rrt_connect`) and the verification of generated problems
(:func:`kinlearn.data.problems.make_problems`). The state space (the joint-limit box), the
``SimpleSetup`` and the planner are built once per adapter, so a stream of queries on one scene pays
for them once.

Validity: without a scene every state is valid (free space, no self-collision: OMPL's
``AllValidStateValidityChecker``, no callback into Python). With a scene, :class:`RrtChecker`: a state
is valid when its body–scene clearance and self-clearance are > 0; a motion is valid when the dense check
finds the straight joint segment free (≤ ``max_travel`` m of sphere travel between checked
configurations), answered by the compiled kernels (:mod:`kinlearn.collision.kernel`) or, with
``compiled=False``, by torch as before them (kept to measure one against the other:
``benchmarks/rrt_checker_speed.py``).

OMPL is an optional dependency (``pip install kinlearn[ompl]``): without it the adapter raises
:class:`~kinlearn.errors.MissingDependencyError`.
"""

from __future__ import annotations

import math
import time

import numpy as np
import torch

from ..body.state import straight_line
from ..errors import ConfigError, MissingDependencyError
from .body import BodySpheres
from .check import clearances, segment_steps
from .scene import Scene

__all__ = ["OmplRrtConnect", "RrtChecker", "import_ompl"]

_F64 = torch.float64


def import_ompl(why: str = "RRT-Connect"):
    """OMPL's ``base``, ``geometric`` and ``util`` modules; :class:`MissingDependencyError` naming ``why``
    it was needed when the bindings are not installed."""
    try:
        from ompl import base as ob
        from ompl import geometric as og
        from ompl import util as ou
    except ImportError as exc:
        raise MissingDependencyError(
            f"{why} needs OMPL's Python bindings, which are not installed: `pip install ompl` "
            "(or `pip install kinlearn[ompl]`)"
        ) from exc
    return ob, og, ou


class RrtChecker:
    """State and motion validity for OMPL on kinlearn's checker: one body, one unbatched scene.

    A state is valid when its body–scene clearance and self-clearance are both > 0; a motion is valid
    when :func:`~kinlearn.collision.check_path` finds the straight joint-space segment free
    (``max_travel`` metres of sphere travel at most between checked configurations). ``compiled``
    (default): answered by the compiled kernels (:mod:`kinlearn.collision.kernel`, the same verdicts);
    ``False``: by torch, as before them (kept to measure one against the other).
    """

    def __init__(self, body: BodySpheres, scene: Scene, max_travel: float = 0.01, compiled: bool = True):
        self.body, self.scene, self.max_travel = body, scene.to(_F64), max_travel
        self.dof = body.robot.dof
        self.states = 0
        self.motions = 0
        self.compiled = bool(compiled)
        if self.compiled:
            from . import kernel

            kb, ks = kernel.KernelBody.of(body), kernel.KernelScene.of(self.scene)
            # The kernels themselves, their arguments bound once: OMPL calls these thousands of times.
            self._clear, self._free = kernel._clearances, kernel._free_packed
            self._clear_args = (*kb.args(), *ks.args())
            self._kb, self._scene_packed = kb, ks.packed
            self._per = np.empty((1, kb.num_spheres))
            self._travel = float(max_travel)

    def state_valid(self, q: np.ndarray) -> bool:
        self.states += 1
        if self.compiled:
            d, s = self._clear(np.ascontiguousarray(q, dtype=np.float64)[None], *self._clear_args, self._per)
            return bool(d[0] > 0) and bool(s[0] > 0)
        d, s = clearances(self.body, torch.as_tensor(q, dtype=_F64), self.scene, validate=False)
        return bool(d > 0) and bool(s > 0)

    def motion_valid(self, a: np.ndarray, b: np.ndarray) -> bool:
        """The configurations :func:`check_path` checks on segment a → b (in torch: every 8th one first,
        so that a colliding motion is usually rejected without computing the rest)."""
        self.motions += 1
        if self.compiled:
            path = np.stack([a, b]).astype(np.float64)
            return bool(self._free(path, self._travel, 0.0, *self._kb.packing_of(path), self._scene_packed))
        path = torch.as_tensor(np.stack([a, b]), dtype=_F64)
        n = int(segment_steps(self.body, path, self.max_travel)[0])
        q = straight_line(path[0], path[1], n)
        coarse = torch.zeros(n + 1, dtype=torch.bool)
        coarse[::8] = True
        coarse[-1] = True
        for part in (q[coarse], q[~coarse]):
            if part.shape[0]:
                d, s = clearances(self.body, part, self.scene, validate=False)
                if not (bool((d > 0).all()) and bool((s > 0).all())):
                    return False
        return True


class OmplRrtConnect:
    """OMPL's RRT-Connect for one robot in its joint-limit box, optionally around one scene.

    ``body`` and ``scene``: the collision spheres and the unbatched scene the states and motions are
    checked against (:class:`RrtChecker`, ``max_travel`` and ``compiled`` as there); ``scene=None``:
    free space, every state valid (``body`` unused). Built once; :meth:`solve` answers one query at a
    time. ``why``: what the error without OMPL names as needing it. ``bounds``: ``(lower, upper)`` joint
    limits to search within instead of the robot's (inside them).
    """

    def __init__(
        self,
        robot,
        body: BodySpheres | None = None,
        scene: Scene | None = None,
        *,
        max_travel: float = 0.01,
        compiled: bool = True,
        why: str = "RRT-Connect",
        bounds: tuple | None = None,
    ):
        ob, og, ou = import_ompl(why)
        self._ob, self._ou = ob, ou
        self.robot, self.dof = robot, robot.dof
        dof = self.dof
        self.checker = None
        lo, hi = (robot.lower, robot.upper) if bounds is None else bounds
        with _quiet(ou):
            space = ob.RealVectorStateSpace(dof)
            box = ob.RealVectorBounds(dof)
            for j in range(dof):
                box.setLow(j, float(lo[j]))
                box.setHigh(j, float(hi[j]))
            space.setBounds(box)
            setup = og.SimpleSetup(space)
            info = setup.getSpaceInformation()
            if scene is None:
                setup.setStateValidityChecker(ob.AllValidStateValidityChecker(info))
            else:
                if body is None:
                    raise ConfigError("OmplRrtConnect around a scene needs the body's collision spheres")
                checker = self.checker = RrtChecker(body, scene, max_travel, compiled=compiled)

                def as_array(state) -> np.ndarray:
                    return np.fromiter((state[j] for j in range(dof)), dtype=np.float64, count=dof)

                class _Valid(ob.StateValidityChecker):
                    def isValid(self, state) -> bool:  # OMPL's method name
                        return checker.state_valid(as_array(state))

                class _Motion(ob.MotionValidator):
                    def checkMotion(self, s1, s2, *rest) -> bool:  # OMPL's method name
                        return checker.motion_valid(as_array(s1), as_array(s2))

                # OMPL keeps only C++ references: the Python objects must live as long as the setup.
                self._validity = (_Valid(info), _Motion(info))
                setup.setStateValidityChecker(self._validity[0])
                info.setMotionValidator(self._validity[1])
            setup.setPlanner(og.RRTConnect(info))
        self._space, self._setup = space, setup
        self._s, self._g = space.allocState(), space.allocState()
        self._queries = 0

    def solve(
        self,
        start,
        goal,
        *,
        time_limit: float = 1.0,
        seed: int | None = None,
        simplify: bool = False,
        simplify_time: float | None = None,
    ) -> tuple[np.ndarray | None, float]:
        """RRT-Connect from ``start`` to ``goal`` (joints ``(dof,)``, within the limits).

        Returns ``(vertices (K, dof) or None if no exact path within time_limit, wall time in seconds)``;
        the vertices are joined by motions the checker found free. ``seed`` seeds OMPL's process-wide
        random generator first (``None`` leaves it alone).

        ``simplify``: shorten a found path with OMPL's simplifier (``SimpleSetup.simplifySolution``: vertex
        reduction, shortcutting and B-spline smoothing, every new segment accepted only if the same
        motion check finds it free), for at most ``simplify_time`` seconds: ``None`` gives it what the
        search left of ``time_limit`` (nothing if the search used it all), so that search and
        simplification together take ``time_limit``; ``math.inf`` lets it run until it stops on its own.
        OMPL checks that limit only between its steps and does at least one round, so a query may
        overrun it. The wall time returned covers setting the query, the search, the simplification
        and reading the path back.
        """
        if simplify_time is not None and not (simplify_time > 0):
            raise ConfigError(
                f"simplify_time must be a number of seconds > 0 (or inf, or None), got {simplify_time!r}"
            )
        ob, setup, dof = self._ob, self._setup, self.dof
        q0 = _joints(start, dof)
        q1 = _joints(goal, dof)
        with _quiet(self._ou):
            if seed is not None:
                self._ou.RNG.setSeed(int(seed) % (1 << 31) or 1)
            t0 = time.perf_counter()
            s, g = self._s, self._g
            for j in range(dof):
                s[j], g[j] = float(q0[j]), float(q1[j])
            if self._queries:
                setup.clear()  # the trees of the query before go; the setup and planner stay
            self._queries += 1
            setup.setStartAndGoalStates(s, g)
            # A termination condition without a checking interval is tested inline by the planner;
            # ``solve(seconds)`` would start a watchdog thread per query, whose scheduling under load
            # adds milliseconds to a query that takes microseconds.
            setup.solve(ob.timedPlannerTerminationCondition(float(time_limit)))
            if not setup.haveExactSolutionPath():
                return None, time.perf_counter() - t0
            if simplify:
                budget = time_limit - (time.perf_counter() - t0) if simplify_time is None else simplify_time
                if math.isinf(budget):
                    setup.simplifySolution()
                elif budget > 0:
                    setup.simplifySolution(ob.timedPlannerTerminationCondition(float(budget)))
            path = setup.getSolutionPath()
            vertices = np.array(
                [[path.getState(k)[j] for j in range(dof)] for k in range(path.getStateCount())],
                dtype=np.float64,
            )
            return vertices, time.perf_counter() - t0


def _joints(q, dof: int) -> np.ndarray:
    a = q.detach().double().cpu().numpy() if isinstance(q, torch.Tensor) else np.asarray(q, dtype=np.float64)
    return a.reshape(dof)


class _quiet:
    """OMPL's logging off for a block (it logs every query at INFO and warns on re-seeding)."""

    def __init__(self, ou):
        self.ou = ou

    def __enter__(self):
        self.previous = self.ou.getLogLevel()
        self.ou.setLogLevel(self.ou.LOG_NONE)

    def __exit__(self, *exc):
        self.ou.setLogLevel(self.previous)
