"""Retreat and approach: the fixed-time candidates that leave the start's cell before the transfer and
enter the goal's after it.

A start or a goal inside a cell (a bookcase's, a cubby's, a cage's, under a table) is left the way a
hand is taken out of a shelf: straight back out of the opening first, then across, then straight in.
The obstacle network's candidates are smooth bends of the straight joint line; they rarely thread that
(the cell families are where its fixed-time success is lowest). This stage adds the structure, and
keeps the network for what it does well, the transfer between two points in the open:

1. **Retreats.** For each end of a problem, a chain of via configurations per direction
   (:data:`RETREAT_DIRECTIONS`: back toward the base's vertical axis, straight up, and both at once),
   the end effector moved by each of :data:`RETREAT_DISTANCES` (metres for an arm of the iiwa14's
   reach, scaled by the arm's); each via solved from the one before by a fixed number of projected
   damped least-squares steps on the planner's kinematic chain (the identified one where the planner
   has it: :mod:`kinlearn.models.chain`), so that the joint line between neighbours moves the hand
   nearly straight. Each direction has two chains (:data:`RETREAT_HANDS`): one solved for the hand's
   position alone (the smallest joint move, which may turn the hand) and one that also keeps the
   hand's orientation at the end, as a hand holding a grasp is drawn straight back out of a shelf (a
   gripper turned inside a cell hits its boards). How deep each chain is free from its end is found by the compiled dense check, one
   walk along it (a chain is cut at its first colliding segment). An end none of whose retreats in
   those directions is free all the way (a cell that opens sideways or downward, a hand under a board)
   also retreats in the :data:`OPEN_DIRECTIONS` directions along which the scene is most open from its
   end effector (:func:`open_directions`: of the 26 of a cube's faces, edges and corners, those whose
   points out to the farthest retreat keep the most clearance).
2. **Straight transfers.** Every pair of free retreats (one of either end, or none at one end) joined
   by the straight joint line between them; the shortest whole path (joint length) whose joining
   segment is free. Retreats and transfer are checked apart: the dense check of a polyline is that of
   its segments, so the joined path's verdict is theirs.
3. **Learned transfers.** Where no straight transfer is free: between the deepest free retreats (at
   most :data:`RETREAT_TRANSFERS` pairs), the obstacle network's candidates for the transfer, as a
   problem of its own (the straight line first, then its paths both ways), the shortest free.
4. **Transfers through a midpoint.** Where none of those is free: the same pairs' transfers, the
   deepest first, each split in two at vias (:meth:`RetreatVias.midpoints`: the hand halfway between
   the two ends, lifted by each of :data:`MIDPOINT_LIFTS` and pulled toward the base's axis by each of
   :data:`MIDPOINT_PULLS`, solved from the joints halfway), each half a learned transfer of its own, at
   most :data:`MIDPOINT_TRANSFERS` of them. A transfer that turns several joints by a turn or more (the
   ur5's, whose joints span ±2π) is two smaller problems the network clears more often than the whole.
   Only under a deadline: with a budget of sampler iterations the sampler clears what step 3 leaves
   sooner (:data:`MIDPOINT_TRANSFERS`).

Every count is fixed: the solver's steps, the vias (an end's open directions at most once), the path
checks, at most 2 × :data:`RETREAT_TRANSFERS` network passes for step 3 and 2 ×
:data:`MIDPOINT_TRANSFERS` for step 4. The stage runs only for problems the learned proposals left
colliding, so the plans they clear do not change (:mod:`kinlearn.planning.stages`).
"""

from __future__ import annotations

import copy
from collections.abc import Callable

import numpy as np

from ..errors import ConfigError
from ..models.chain import ChainFM

__all__ = [
    "KEEP_WEIGHT",
    "MIDPOINT_LIFTS",
    "MIDPOINT_PULLS",
    "MIDPOINT_TRANSFERS",
    "OPEN_DIRECTIONS",
    "RETREAT_DIRECTIONS",
    "RETREAT_DISTANCES",
    "RETREAT_HANDS",
    "RETREAT_TRANSFERS",
    "WIGGLE",
    "WIGGLE_DEPTH",
    "RetreatVias",
    "free_chains",
    "open_directions",
    "retreat_path",
    "sampler_branches",
]

#: Directions the end effector retreats in (base frame): toward the base's vertical axis (horizontal),
#: straight up, and the two at once (normalised).
RETREAT_DIRECTIONS: tuple[str, ...] = ("in", "up", "in-up")
#: How far it retreats (m, for an arm of the iiwa14's horizontal reach; scaled by the arm's reach):
#: each direction's chain holds one via per distance.
RETREAT_DISTANCES: tuple[float, ...] = (0.1, 0.2, 0.3)
#: Pairs of deepest free retreats the network plans the transfer between (2 passes each). On the
#: tuning problems (seeds 3004–3010, and the grasp-like ones, fixed time) the ur5 with its gripper
#: cleared 83.6 / 83.0% with 5, against 80.7 / 81.0% with 3 (4: 80.7 / 83.0%; 6 and 8 no more than 5);
#: the panda and the iiwa14 the same with either (it adds work only where every transfer collides).
RETREAT_TRANSFERS = 5
#: Directions an end with no retreat in :data:`RETREAT_DIRECTIONS` free all the way also retreats in: the
#: scene's most open ones (:func:`open_directions`). On the tuning problems (seeds 3004–3010 and the
#: grasp-like ones, fixed time) 5 cleared 87.9 / 86.0% (ur5 with its gripper), 97.9 / 100% (panda) and
#: 98.6 / 100% (iiwa14), 3 cleared 86.4 / 86.0, 97.9 / 99.0 and 98.6 / 99.0% (6: as 5; 8: the ur5 two
#: problems fewer).
OPEN_DIRECTIONS = 5
#: Clearance (m, for an arm of the iiwa14's reach; scaled) above which a direction counts as fully open:
#: open directions tie, and keep the grid's order.
OPEN_CLEARANCE = 0.1
#: Where along a direction its clearance is looked at, as shares of the farthest retreat.
_RAY_SHARES = np.linspace(0.3, 1.0, 5)
#: The directions :func:`open_directions` ranks: the 26 of a cube's faces, edges and corners (unit).
_GRID = np.array(
    [(x, y, z) for x in (-1, 0, 1) for y in (-1, 0, 1) for z in (-1, 0, 1) if (x, y, z) != (0, 0, 0)],
    dtype=np.float64,
)
_GRID /= np.linalg.norm(_GRID, axis=1, keepdims=True)
#: Damped least-squares steps per via (from the via before it, or from the end itself).
RETREAT_ITERATIONS = 15
#: Damping of those steps (m): a via moves the joints little where the chain is near a singularity.
RETREAT_DAMPING = 0.05
#: How each direction's chain treats the hand: ``"turning"`` (the position alone is solved for, the
#: smallest joint move, which may turn the hand) and ``"kept"`` (the hand's orientation at the end held
#: too, as a hand is drawn straight back out of a shelf). On the tuning problems (seeds 3004–3010, fixed
#: time) both kinds cleared 97.1 / 80.7 / 98.6% (panda, ur5 with its gripper, iiwa14), the turning
#: chains alone 95.7 / 78.6 / 98.6% and the kept ones alone 96.4 / 80.0% (panda, ur5).
RETREAT_HANDS: tuple[str, ...] = ("turning", "kept")
#: Weight (m/rad) of the orientation error against the position error in a kept chain's steps.
KEEP_WEIGHT = 0.1
#: How far (rad) an end none of whose retreats gets past :data:`WIGGLE_DEPTH` vias turns one joint,
#: either way, before it retreats again (:meth:`RetreatVias.wiggled`). 0.6 rad left both of the ur5's
#: wedged tuning ends wedged.
WIGGLE = 0.3
#: The free depth at or below which every retreat of an end must stop for the end to wiggle. On the tuning
#: problems (seeds 3004–3010 and the grasp-like ones, fixed time, with step 4), wiggling where every
#: retreat stops within its first via cleared 94.3 / 96.2% (ur5 with its gripper), 98.6 / 100% (panda)
#: and 98.6 / 100% (iiwa14); only where none is free at all (0) 94.3 / 93.8, 97.9 / 100 and 98.6 / 100%;
#: wherever none is free all the way (2) 93.6 / 96.2, 98.6 / 100 and 98.6 / 100%; without wiggles 93.6 /
#: 93.8, 97.1 / 100 and 98.6 / 100%.
WIGGLE_DEPTH = 1
#: How far a midpoint via lifts the hand above the midpoint of the two ends' hands (m, for an arm of the
#: iiwa14's reach; scaled), and :data:`MIDPOINT_PULLS`: what share of its horizontal distance from the
#: base's vertical axis it is pulled in by; every pair of the two, in order (lifts outer).
MIDPOINT_LIFTS: tuple[float, ...] = (0.0, 0.2, 0.4)
MIDPOINT_PULLS: tuple[float, ...] = (0.0, 0.5)
#: Damped least-squares steps a midpoint via is solved with (from the joints halfway between the ends).
MIDPOINT_ITERATIONS = 30
#: Learned transfers step 4 runs at most (each half of a split transfer is one). It runs under a deadline
#: only (the planner passes no ``midpoints`` otherwise): with the default budget of sampler iterations,
#: the sampler after the stage clears what step 3 leaves, and step 4's transfers mostly cost time. On the
#: tuning problems (seeds 3004–3010, 140 per arm, default plan(), best of two passes by turns), without
#: step 4 plan()'s p99 fell 21% (iiwa14), 11% (panda) and 28% (ur5 with its gripper), its p50 within
#: 2%, success 100% either way, the joint paths 0.2%, 0% and 1.2% longer in sum.
MIDPOINT_TRANSFERS = 12


class RetreatVias:
    """The retreat vias of a configuration: ``vias(theta (dof,)) -> (H · D, L, dof)``, a chain per kind of
    hand and direction (:data:`RETREAT_HANDS` outer, :data:`RETREAT_DIRECTIONS` inner) and L
    distances (:data:`RETREAT_DISTANCES`), solved on ``chain``
    (compiled; a rigid chain: an identified chain's residual network is left out, the vias being only
    guides, and every path through them is checked by the dense check) within ``lower``/``upper``.
    ``scale``: the arm's horizontal reach over the iiwa14's."""

    def __init__(self, chain: ChainFM, lower: np.ndarray, upper: np.ndarray, scale: float):
        if not isinstance(chain, ChainFM):
            raise ConfigError(f"retreat vias need a ChainFM, got {type(chain).__name__}")
        if not (np.isfinite(scale) and scale > 0):
            raise ConfigError(f"scale must be a finite number > 0, got {scale!r}")
        self.arrays = chain.kernel_arrays()
        self.dof = chain.dof
        self.lower = np.ascontiguousarray(lower, dtype=np.float64)
        self.upper = np.ascontiguousarray(upper, dtype=np.float64)
        self.distances = scale * np.asarray(RETREAT_DISTANCES, dtype=np.float64)
        #: What lengths given for the iiwa14's reach are multiplied by (as the distances were).
        self._scaled = self.distances[-1] / RETREAT_DISTANCES[-1]
        self._no_seeds = np.zeros((0, self.dof))

    def within(self, lower: np.ndarray, upper: np.ndarray) -> RetreatVias:
        """These vias solved within ``lower``/``upper`` instead (a problem's box, inside the limits these
        were made with); this object itself where the limits are the same."""
        lower = np.ascontiguousarray(lower, dtype=np.float64)
        upper = np.ascontiguousarray(upper, dtype=np.float64)
        if np.array_equal(lower, self.lower) and np.array_equal(upper, self.upper):
            return self
        out = copy.copy(self)
        out.lower, out.upper = lower, upper
        return out

    def _position(self, theta: np.ndarray) -> np.ndarray:
        from ..models.chain_kernel import chain_positions

        return chain_positions(*self.arrays, theta)

    def vias(
        self, theta: np.ndarray, distance: Callable[[np.ndarray], np.ndarray] | None = None
    ) -> np.ndarray:
        """``(H · D, L, dof)``: the vias of joints ``theta (dof,)`` in :data:`RETREAT_DIRECTIONS`, the hand
        turning, then with the hand kept (:data:`RETREAT_HANDS`), direction by direction, near to far;
        given the scene's ``distance(points (N, 3)) -> (N,)``, in its most open directions instead
        (:func:`open_directions`)."""
        theta = np.ascontiguousarray(theta, dtype=np.float64).reshape(1, self.dof)
        p = self._position(theta)[0]
        if distance is None:
            directions = _directions(p)
        else:
            directions = open_directions(p, distance, self.distances[-1], OPEN_CLEARANCE * self._scaled)
        starts = np.repeat(theta, len(directions), axis=0)
        return self._solve(starts, self._targets(p, directions)).reshape(
            -1, self.distances.shape[0], self.dof
        )

    def free(
        self,
        theta: np.ndarray,
        depths: Callable[[np.ndarray, np.ndarray], np.ndarray],
        distance: Callable[[np.ndarray], np.ndarray] | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """One end's retreats: ``(vias (C, L, dof), free depths (C,))`` in :data:`RETREAT_DIRECTIONS`;
        ``depths(theta, vias (C, L, dof)) -> (C,)``: how many vias each chain from ``theta`` reaches through
        free segments (the planner's: :func:`~kinlearn.collision.kernel.free_depths`, one compiled call);
        where none of those is free all the way (to the farthest distance) and the scene's ``distance``
        is given, in its most open directions as well (the
        chains of either set, the hand turning first: :meth:`vias`' order). A retreat stopped short is
        often one that leads nowhere (toward the base under a table top): on the tuning problems (seeds
        3004–3010 and the grasp-like ones, fixed time; three open directions then) the open directions
        added there cleared 86.4 / 86.0% (ur5 with its gripper), 97.9 / 99.0% (panda) and 98.6 / 99.0%
        (iiwa14), against 83.6 / 83.0, 97.1 / 99.0 and 98.6 / 98.0% with them only where no fixed
        retreat is free at all, and lost no problem. Given the scene too, an end none of whose retreats
        gets past :data:`WIGGLE_DEPTH` vias (a hand wedged in a cell) also retreats from each of its
        wiggles (:meth:`wiggled`)."""
        vias = self.vias(theta)
        depth = depths(theta, vias)
        if distance is not None and depth.max() < vias.shape[1]:
            more = self.vias(theta, distance)
            extra = depths(theta, more)
            vias, depth = _by_hand(vias, more), _by_hand(depth, extra)
        if distance is not None and depth.max() <= WIGGLE_DEPTH:
            more = self.wiggled(theta)
            if len(more):
                extra = depths(theta, more)
                vias, depth = _by_hand(vias, more), _by_hand(depth, extra)
        return vias, depth

    def wiggled(self, theta: np.ndarray) -> np.ndarray:
        """Chains ``(H · W · D, L, dof)`` that leave ``theta (dof,)`` by a wiggle first: one joint moved by
        :data:`WIGGLE` rad either way (within the limits; W of them), then the first L − 1 vias of the
        wiggled configuration's retreats in :data:`RETREAT_DIRECTIONS` (:meth:`vias`), in
        :data:`RETREAT_HANDS` blocks as :meth:`vias` gives them. A hand wedged in a cell often comes out
        once its wrist has turned a little (a sampler's first steps do as much)."""
        theta = np.asarray(theta, dtype=np.float64)
        H, D, L = len(RETREAT_HANDS), len(RETREAT_DIRECTIONS), self.distances.shape[0]
        wiggles = []
        for j in range(self.dof):
            for sign in (-1.0, 1.0):
                w = theta.copy()
                w[j] = min(max(w[j] + sign * WIGGLE, self.lower[j]), self.upper[j])
                if w[j] != theta[j]:
                    wiggles.append(w)
        if not wiggles:
            return np.zeros((0, L, self.dof))
        w = np.stack(wiggles)  # (W, dof): every wiggle's retreats solved in one batch
        targets = np.stack([self._targets(p, _directions(p)) for p in self._position(w)])  # (W, D, L, 3)
        v = self._solve(np.repeat(w, D, axis=0), targets.reshape(-1, L, 3)).reshape(H, len(w), D, L, self.dof)
        chain = np.empty_like(v)
        chain[..., 0, :], chain[..., 1:, :] = w[None, :, None], v[..., :-1, :]
        return chain.reshape(-1, L, self.dof)  # (H, W, D, L, dof): by hand first

    def midpoints(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """The vias ``(V, dof)`` a transfer from ``a`` to ``b (dof,)`` is split at (step 4 of the module
        docstring): per lift of :data:`MIDPOINT_LIFTS` (outer) and pull of :data:`MIDPOINT_PULLS`, the
        joints solved (:data:`MIDPOINT_ITERATIONS` damped least-squares steps, within the limits) from
        those halfway between ``a`` and ``b`` for the hand halfway between theirs, lifted by the lift and
        pulled toward the base's vertical axis by the pull's share of its horizontal distance."""
        from ..models.chain_kernel import solve_position_numba

        ends = np.ascontiguousarray(np.stack((a, b)), dtype=np.float64)
        hand = self._position(ends).mean(axis=0)
        lifts = self._scaled * np.asarray(MIDPOINT_LIFTS)
        targets = np.array(
            [[hand[0] * (1 - s), hand[1] * (1 - s), hand[2] + h] for h in lifts for s in MIDPOINT_PULLS]
        )
        seed = np.clip(ends.mean(axis=0), self.lower, self.upper)
        q, _ = solve_position_numba(
            *self.arrays, np.repeat(seed[None], len(targets), axis=0), targets, self.lower, self.upper,
            self._no_seeds, iterations=MIDPOINT_ITERATIONS, damping=RETREAT_DAMPING, tolerance=1e-4,
        )  # fmt: skip
        return q

    def _targets(self, p: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """The hand's via positions ``(D, L, 3)`` from ``p (3,)`` along ``directions (D, 3)``, near to far."""
        return p + self.distances[None, :, None] * directions[:, None]

    def _solve(self, starts: np.ndarray, targets: np.ndarray) -> np.ndarray:
        """The vias ``(H, R, L, dof)`` of chains from ``starts (R, dof)`` through the hand positions ``targets
        (R, L, 3)``: the hand turning, then kept (each row solved alone, so a batch of rows gives what each
        would alone)."""
        from ..models.chain_kernel import chain_retreats

        return chain_retreats(  # each via from the one before (continuation)
            *self.arrays, starts, targets, self.lower, self.upper, iterations=RETREAT_ITERATIONS,
            damping=RETREAT_DAMPING, tolerance=1e-4, weight=KEEP_WEIGHT,
        )  # fmt: skip


def _by_hand(first: np.ndarray, then: np.ndarray) -> np.ndarray:
    """Two sets of chains (or their depths), each in :data:`RETREAT_HANDS` blocks, as one: each kind of
    hand's chains of ``first``, then of ``then`` (the turning chains first, as :meth:`RetreatVias.vias`
    gives them)."""
    H = len(RETREAT_HANDS)
    return np.concatenate(
        [np.concatenate(p) for p in zip(np.split(first, H), np.split(then, H), strict=True)]
    )


def _directions(p: np.ndarray) -> np.ndarray:
    """The unit retreat directions ``(D, 3)`` of :data:`RETREAT_DIRECTIONS` from an end effector at ``p``:
    "in" horizontal toward the base's vertical axis (none on the axis itself), "up" +z, and the
    normalised sums of the words of a hyphenated name."""
    radial = np.array([p[0], p[1], 0.0])
    norm = float(np.linalg.norm(radial))
    unit = {
        "in": -radial / norm if norm > 1e-9 else np.zeros(3),
        "out": radial / norm if norm > 1e-9 else np.zeros(3),
        "up": np.array([0.0, 0.0, 1.0]),
        "down": np.array([0.0, 0.0, -1.0]),
    }
    out = []
    for name in RETREAT_DIRECTIONS:
        v = sum(unit[w] for w in name.split("-"))
        n = float(np.linalg.norm(v))
        out.append(v / n if n > 1e-9 else v)
    return np.stack(out)


def open_directions(
    p: np.ndarray, distance: Callable[[np.ndarray], np.ndarray], reach: float, cap: float
) -> np.ndarray:
    """The :data:`OPEN_DIRECTIONS` unit directions ``(k, 3)`` of the grid along which the scene is most
    open from the point ``p (3,)``: ranked by the least signed distance ``distance(points (N, 3))`` of
    the points at 30–100% of ``reach`` along each, capped at ``cap`` (directions open beyond it tie and
    keep the grid's order)."""
    points = p + (_RAY_SHARES[None, :, None] * reach) * _GRID[:, None]  # (26, S, 3)
    least = np.minimum(distance(points.reshape(-1, 3)).reshape(len(_GRID), -1).min(axis=1), cap)
    return _GRID[np.argsort(-least, kind="stable")[:OPEN_DIRECTIONS]]


def free_chains(vias: np.ndarray, depth: np.ndarray) -> list[np.ndarray]:
    """One end's free retreats as polylines from it (the end itself left out): per direction of ``vias
    (D, L, dof)``, its first ``depth[d]`` vias (their free depths: :meth:`RetreatVias.free`), deepest prefixes only."""
    return [vias[d, : int(n)] for d, n in enumerate(depth) if n]


def sampler_branches(vias: np.ndarray, depth: np.ndarray) -> list[np.ndarray]:
    """The free retreats a sampler grows its trees from (:mod:`kinlearn.collision.rrt`'s first branches):
    :func:`free_chains` of the chains with the hand turning only (the first of :data:`RETREAT_HANDS`).
    Handing it the kept chains as well cost it time: on the ur5's tuning problems (seeds 3004–3010)
    under a deadline of 0.05 s, 95.4% cleared against 97.9% (five runs by turns in one process)."""
    D = vias.shape[0] // len(RETREAT_HANDS)
    return free_chains(vias[:D], depth[:D])


def _ends(theta: np.ndarray, vias: np.ndarray, depth: np.ndarray) -> tuple[list[np.ndarray], np.ndarray]:
    """The free retreats of one end as vertex lists from it, ``[theta]`` (none) first, then each
    direction's free prefixes, shallow to deep; and each one's joint length."""
    ends, lengths = [theta[None]], [0.0]
    chains = np.empty((vias.shape[0], vias.shape[1] + 1, vias.shape[2]))  # every chain from theta
    chains[:, 0], chains[:, 1:] = theta, vias
    steps = np.cumsum(np.linalg.norm(np.diff(chains, axis=1), axis=-1), axis=1)  # (the same sums, at once)
    for d, n in enumerate(depth.tolist()):
        for k in range(n):
            ends.append(chains[d, : k + 2])
        lengths.extend(steps[d, :n].tolist())
    return ends, np.array(lengths)


def retreat_path(
    theta0: np.ndarray,
    thetaT: np.ndarray,
    vias0: np.ndarray,
    viasT: np.ndarray,
    depth0: np.ndarray,
    depthT: np.ndarray,
    first_free: Callable[[np.ndarray, np.ndarray], int],
    transfer: Callable[[np.ndarray, np.ndarray], np.ndarray | None] | None,
    stop: Callable[[], bool] | None = None,
    midpoints: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
) -> np.ndarray | None:
    """The retreat stage's path ``(V, dof)`` from ``theta0`` to ``thetaT`` (steps 2 to 4 of the module
    docstring), or None. ``vias*``/``depth*``: each end's vias and free depths (:class:`RetreatVias`,
    :meth:`RetreatVias.free`). ``first_free(paths (P, W, dof), order)``: the dense check's first free path
    in ``order`` (−1: none). ``transfer(a, b)``: a free path from configuration ``a`` to ``b`` by the
    network (None: none free, or no network). ``stop()``: asked before the joins and before each
    transfer; True gives up (a deadline that has run out). ``midpoints(a, b) -> (V, dof)``: the vias a
    transfer is split at (:meth:`RetreatVias.midpoints`; None: no step 4)."""
    (ends0, len0), (endsT, lenT) = _ends(theta0, vias0, depth0), _ends(thetaT, viasT, depthT)
    if len(ends0) == 1 and len(endsT) == 1:  # no free retreat at either end: the straight line again
        return None
    if stop is not None and stop():
        return None
    a_last = np.stack([a[-1] for a in ends0])
    b_last = np.stack([b[-1] for b in endsT])
    joins = np.empty((len(ends0), len(endsT), 2, a_last.shape[1]))
    joins[:, :, 0], joins[:, :, 1] = a_last[:, None], b_last[None]
    gap = np.linalg.norm(joins[:, :, 1] - joins[:, :, 0], axis=-1)
    length = (len0[:, None] + lenT[None] + gap).ravel()
    order = np.argsort(length, kind="stable")
    order = order[order != 0]  # pair (0, 0): no retreat at either end, the straight line
    k = first_free(joins.reshape(-1, 2, a_last.shape[1]), order)
    if k >= 0:
        a, b = ends0[k // len(endsT)], endsT[k % len(endsT)]
        return np.concatenate((a, b[::-1]))
    if transfer is None:
        return None
    depth = np.add.outer([len(a) for a in ends0], [len(b) for b in endsT]).ravel()
    depth[0] = 0
    # the deepest pairs first (the pair without a retreat at either end, depth 0, is stage 1's problem)
    deepest = [k for k in np.argsort(-depth, kind="stable")[:RETREAT_TRANSFERS] if depth[k]]
    for k in deepest:
        if stop is not None and stop():
            return None
        a, b = ends0[k // len(endsT)], endsT[k % len(endsT)]
        middle = transfer(a[-1], b[-1])
        if middle is not None:
            return np.concatenate((a[:-1], middle, b[::-1][1:]))
    if midpoints is None:
        return None
    left = MIDPOINT_TRANSFERS
    for k in deepest:  # the pairs of step 3, the deepest first
        a, b = ends0[k // len(endsT)], endsT[k % len(endsT)]
        for m in midpoints(a[-1], b[-1]):
            if left <= 0 or (stop is not None and stop()):
                return None
            if first_free(np.stack((m, m))[None], np.zeros(1, dtype=np.int64)) < 0:  # the via collides
                continue
            left -= 1
            first = transfer(a[-1], m)
            if first is None:
                continue
            left -= 1
            second = transfer(m, b[-1])
            if second is not None:
                return np.concatenate((a[:-1], first, second[1:], b[::-1][1:]))
    return None
