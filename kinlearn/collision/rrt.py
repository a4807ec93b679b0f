"""RRT-Connect compiled with its collision checker: the sampling stage of a plan under a deadline.

The algorithm is RRT-Connect (Kuffner and LaValle, ICRA 2000): two trees, rooted at the start and the
goal; the smaller one (balanced bidirectional search, LaValle, *Planning Algorithms*, 2006, §5.5.3)
extends a step of at most ``step`` radians towards a random configuration
(uniform in the limits, or near its root), the other then greedily connects towards the new node,
until they meet. The joined
path is shortened by the shortcut pass every plan goes through (:mod:`kinlearn.collision.shortcut`).
The joint box is sampled uniformly by default; :class:`RrtConnect` also offers low-discrepancy sequences
(Halton, R2) and dynamic-domain sampling (Yershova et al., ICRA 2005) in their place (``sampling``,
``domain``). Every state and motion is checked by the compiled dense check of :mod:`kinlearn.collision.kernel`
(≤ ``max_travel`` of sphere travel between checked configurations, self-collision and the floor
included), so a path found is free by the same rule every plan is judged by.

Why compiled here and not OMPL's RRT-Connect: OMPL's Python bindings call back into Python for every
state and motion check, which dominates on these problems (measured on one core, the same checker,
``benchmarks/rrt_checker_speed.py``); here the planner's loop, its random numbers and the checks run
in one compiled call. OMPL stays kinlearn's reference sampling baseline and the verifier of generated
problems (:mod:`kinlearn.data.problems`).

Work is done in rounds of ``iterations`` (:class:`RrtConnect` keeps the trees between rounds), so a
caller can stop at a deadline between rounds; the same seed and the same total number of iterations
give the same path, whatever the rounds (random numbers come from a counter-based generator kept in
the state, not from a global one). :func:`rrt_connect` sizes its rounds to the time they take
(:data:`ROUND_SECONDS`): a round of one iteration costs a call from Python, a few microseconds, next to
an iteration's 10–100.
"""

from __future__ import annotations

import functools
import math
import time

import numpy as np

from ..body.jit import jit
from ..checks import as_int, as_real
from ..errors import ConfigError, ShapeError
from . import kernel
from .shortcut import DEFAULT_ATTEMPTS, shorten_packed

__all__ = ["DOMAIN_TRIES", "ROUND_SECONDS", "SAMPLINGS", "TURN", "RrtConnect", "rrt_connect", "warm_up"]

_jit = jit(error_model="numpy")

#: The most of a joint's range the default step counts, rad: one turn. The default step is OMPL's default
#: range, 0.2 of the joint box's diagonal, with every joint's range counted at most once round: a range
#: beyond a turn adds no pose to sample, only ways to reach one. The panda's and the iiwa14's (ranges
#: under a turn) stay OMPL's, 2.6–2.8 rad; the ur5's ±2π joints would give 5.8 rad, a step that sweeps
#: metres of the arm per motion check and is mostly trapped, and give 3.1 rad instead. On the ur5's
#: tuning problems (seeds 3004–3010) the capped step solved more within a budget than OMPL's; a flat cap
#: in radians cost the panda and the iiwa14 time, so the cap is by turns, not rad.
TURN = 2.0 * math.pi

#: The longest a round of :func:`rrt_connect` is meant to take, s (and at most a quarter of the time left):
#: rounds start at one iteration and double while the iterations so far say the next stays within it,
#: so a deadline is overrun by about a round at most. One iteration per round instead spent a fifth of
#: the sampler's time calling it from Python (the ur5 with its gripper, 280 searches of its tuning
#: problems, seeds 3004–3010: 1.57 s in all against 1.22 s for rounds of 8 or 64 iterations; the
#: same paths).
ROUND_SECONDS = 5e-4

_TRAPPED, _ADVANCED, _REACHED = 0, 1, 2
#: State slots: the sizes of the two trees (0 rooted at the start, 1 at the goal), the generator's
#: counter, the connection (its node in tree 0, in tree 1), status (0 growing, 1 found, −1 a tree full),
#: rounds done (the tree extended alternates with it), the index of the low-discrepancy sequence.
_N0, _N1, _RNG, _CA, _CB, _STATUS, _ROUND, _SEQ = range(8)

#: The samples of the joint box: ``"uniform"`` (counter-based random numbers), ``"halton"`` (the Halton
#: sequence, prime bases 2, 3, 5, …, one per joint) or ``"r2"`` (the Kronecker sequence of the generalised
#: golden ratio, Roberts' R_d), the two sequences shifted modulo 1 by a random vector drawn from the seed
#: (a Cranley–Patterson rotation) so that different seeds give different samples.
SAMPLINGS = ("uniform", "halton", "r2")
_UNIFORM, _HALTON, _R2 = range(3)

#: The most box samples one iteration draws while the dynamic domain rejects them; an iteration whose
#: samples are all rejected extends nothing.
DOMAIN_TRIES = 64


@_jit
def _uniform(state) -> float:
    """A number in [0, 1) from a splitmix64 step of the counter in ``state[_RNG]``."""
    state[_RNG] += 1
    z = np.uint64(state[_RNG]) * np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    z = z ^ (z >> np.uint64(31))
    return float(z >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@_jit
def _radical_inverse(i: int, base: int) -> float:
    """The van der Corput radical inverse of ``i`` in ``base``: its digits mirrored about the point."""
    inv = 1.0 / base
    f, r = inv, 0.0
    while i > 0:
        r += (i % base) * f
        i //= base
        f *= inv
    return r


@_jit
def _box_sample(state, kind, gen, shift, lo, hi, q):
    """A sample of the joint box ``[lo, hi]`` into ``q``: uniform random numbers (``kind`` 0), or the
    next point of the Halton (1: ``gen`` its bases) or R2 (2: ``gen`` its increments) sequence, its index
    in ``state[_SEQ]``, shifted modulo 1 by ``shift``."""
    dof = lo.shape[0]
    if kind == _UNIFORM:
        for j in range(dof):
            q[j] = lo[j] + _uniform(state) * (hi[j] - lo[j])
        return
    state[_SEQ] += 1
    i = state[_SEQ]
    for j in range(dof):
        if kind == _HALTON:
            u = _radical_inverse(i, int(gen[j]))
        else:
            u = i * gen[j]
            u -= math.floor(u)
        u += shift[j]
        if u >= 1.0:
            u -= 1.0
        q[j] = lo[j] + u * (hi[j] - lo[j])


@_jit
def _free(a, b, seg, max_travel, f, n, s) -> bool:
    for j in range(a.shape[0]):
        seg[0, j], seg[1, j] = a[j], b[j]
    return kernel._free_packed(seg, max_travel, 0.0, f, n, s)


@_jit
def _nearest(nodes, t, m, q):
    """The node of tree ``t`` (its first ``m``) nearest to ``q`` and its squared distance (a linear scan:
    the motion checks, not this, take an iteration's time)."""
    dof = q.shape[0]
    best, near = np.inf, 0
    for i in range(m):
        d = 0.0
        for j in range(dof):
            e = nodes[t, i, j] - q[j]
            d += e * e
        if d < best:
            best, near = d, i
    return near, best


@_jit
def _extend(nodes, parent, count, t, q, step, seg, max_travel, f, n, s, out, near=-1, best=0.0):
    """Extend tree ``t`` (nodes ``nodes[t, :count[t]]``) towards ``q`` from its nearest node (``near``
    with squared distance ``best`` where the caller found it): (status, new node or −1, nearest or −1)."""
    m = count[t]
    if m >= nodes.shape[1]:
        return _TRAPPED, -1, -1
    dof = q.shape[0]
    if near < 0:
        near, best = _nearest(nodes, t, m, q)
    dist = math.sqrt(best)
    reached = dist <= step
    scale = 1.0 if reached else step / dist
    for j in range(dof):
        out[j] = nodes[t, near, j] + scale * (q[j] - nodes[t, near, j])
    if not _free(nodes[t, near], out, seg, max_travel, f, n, s):
        return _TRAPPED, -1, near
    nodes[t, m] = out
    parent[t, m] = near
    count[t] = m + 1
    return (_REACHED if reached else _ADVANCED), m, near


@_jit
def _grow(
    nodes, parent, state, lo, hi, step, local, sigma, local_step, iterations, max_travel, f, n, s, balanced,
    kind, gen, shift, radius, domain, domain_min, domain_alpha, tries,
):  # fmt: skip
    """Up to ``iterations`` rounds of RRT-Connect on the trees in ``nodes``/``parent``; a share
    ``local`` of the samples is drawn near the extended tree's root (Gaussian, ``sigma`` rad per joint),
    the others in the joint box (:func:`_box_sample`: ``kind``, ``gen``, ``shift``).
    ``balanced``: the smaller tree is extended (in turn when they are equal), else each in turn.

    Dynamic domain (Yershova, Jaillet, Siméon and LaValle, ICRA 2005; the radius adapted as by Jaillet
    et al., IROS 2005) where ``domain`` > 0: a box sample farther from its nearest node than that node's
    ``radius`` is rejected and another drawn (at most ``tries``, within the same iteration);
    an extension that fails sets its nearest node's radius to ``domain`` the first time, then shrinks it
    by a factor ``1 − domain_alpha`` down to ``domain_min``; one that succeeds grows a finite radius by
    ``1 + domain_alpha``. New nodes have no bound (an infinite radius)."""
    dof = lo.shape[0]
    count = state[_N0 : _N1 + 1]
    seg, q, new, conn = np.empty((2, dof)), np.empty(dof), np.empty(dof), np.empty(dof)
    dd = domain > 0.0
    for _ in range(iterations):
        if state[_STATUS] != 0:
            return
        a = int(state[_ROUND] % 2)
        if balanced and count[0] != count[1]:
            a = 0 if count[0] < count[1] else 1
        state[_ROUND] += 1
        near = _uniform(state) < local
        k, best = -1, 0.0
        if near:  # near the root: out of the cell, from under the table
            for j in range(dof):
                u1, u2 = max(_uniform(state), 1e-300), _uniform(state)
                g = math.sqrt(-2.0 * math.log(u1)) * math.cos(2.0 * math.pi * u2)
                q[j] = min(max(nodes[a, 0, j] + sigma * g, lo[j]), hi[j])
        else:
            accepted = not dd
            for _try in range(tries if dd else 1):
                _box_sample(state, kind, gen, shift, lo, hi, q)
                if not dd:
                    break
                k, best = _nearest(nodes, a, count[a], q)
                r = radius[a, k]
                if best <= r * r:
                    accepted = True
                    break
            if not accepted:
                continue
        st, i, k = _extend(
            nodes, parent, count, a, q, local_step if near else step, seg, max_travel, f, n, s, new, k, best
        )
        if dd and k >= 0:
            r = radius[a, k]
            if st == _TRAPPED:
                radius[a, k] = domain if r == np.inf else max(r * (1.0 - domain_alpha), domain_min)
            elif r != np.inf:
                radius[a, k] = r * (1.0 + domain_alpha)
        if st == _TRAPPED:
            if count[a] >= nodes.shape[1]:
                state[_STATUS] = -1
            continue
        b = 1 - a
        while True:
            st2, kb, _near = _extend(nodes, parent, count, b, new, step, seg, max_travel, f, n, s, conn)
            if st2 != _ADVANCED:
                break
        if st2 == _REACHED:
            state[_CA], state[_CB] = (i, kb) if a == 0 else (kb, i)
            state[_STATUS] = 1
            return
        if count[b] >= nodes.shape[1]:
            state[_STATUS] = -1
            return


_NONE = np.empty(0)


@_jit
def _shift_of(counter: int, dof: int) -> np.ndarray:
    """``dof`` numbers in [0, 1) of the splitmix64 generator from ``counter``."""
    state = np.zeros(8, dtype=np.int64)
    state[_RNG] = counter
    out = np.empty(dof)
    for j in range(dof):
        out[j] = _uniform(state)
    return out


@functools.cache
def _primes(n: int) -> np.ndarray:
    """The first ``n`` primes (the Halton sequence's bases, one per joint)."""
    out: list[int] = []
    k = 2
    while len(out) < n:
        if all(k % p for p in out if p * p <= k):
            out.append(k)
        k += 1
    return np.array(out, dtype=np.float64)


@functools.cache
def _r2(n: int) -> np.ndarray:
    """The increments of Roberts' R_d sequence in ``n`` dimensions: powers of 1/φ_n, φ_n the root > 1 of
    x^(n+1) = x + 1 (the golden ratio for n = 1)."""
    phi = 2.0
    for _ in range(64):
        phi = (1.0 + phi) ** (1.0 / (n + 1))
    return np.array([(1.0 / phi) ** (j + 1) % 1.0 for j in range(n)])


class RrtConnect:
    """One RRT-Connect query on a compiled body and scene (:class:`~kinlearn.collision.kernel.KernelBody`,
    :class:`~kinlearn.collision.kernel.KernelScene`), from ``start`` to ``goal`` (joints ``(dof,)``
    inside ``[lower, upper]``). ``step``: the largest extension, rad (default: 0.2 of the joint box's
    diagonal, OMPL's default range, each joint's range counted at most one :data:`TURN`); ``max_nodes``: each tree's capacity;
    ``seed`` fixes the samples.
    ``local``: the share of samples drawn near the extended tree's root, Gaussian with ``sigma`` rad
    per joint (the rest uniform in the limits): starts and goals inside shelves, cubbies and cages sit
    in narrow cells whose way out uniform samples rarely find: on generated problems of the seven
    families the defaults solve many more within a budget than uniform samples alone.
    ``local_step``: the largest extension towards a sample near the root (default: ``step``). A short one
    lets a tree creep out of a deep cell that long steps jump across: on the panda's tuning problems
    (seeds 3004–3010) a short one helped the hardest cubby and cage problems; on the iiwa14's it cost
    time and on the ur5's it changed nothing, so it is not the default.

    ``balanced``: extend the smaller tree each round (the trees take turns when equal), not the two in
    turn: a tree stuck in a cell gets the samples until it is out. On the tuning problems (seeds
    3004–3010) it solved more within a budget on every arm and shortened the mean time to a path.

    ``sampling``: how the joint box is sampled (:data:`SAMPLINGS`): ``"uniform"`` random numbers, or the
    ``"halton"`` or ``"r2"`` low-discrepancy sequence shifted by the seed. ``domain``: dynamic-domain
    sampling (Yershova, Jaillet, Siméon and LaValle, ICRA 2005) where > 0: a box sample farther from its
    nearest node than that node's radius (``radius``, rad) is rejected; an extension that fails bounds its
    node by ``domain`` steps the first time, later ones shrink the bound by ``1 − domain_alpha`` to
    ``domain_min`` steps, and one that succeeds widens it by ``1 + domain_alpha`` (the adaptive radius of
    Jaillet, Yershova, LaValle and Siméon, IROS 2005). Both change the samples only: every motion is
    checked as before, and a seed still fixes the path. Neither is the default: on the tuning problems
    (seeds 3004–3010, those uniform samples needed over 200 iterations for) and on the held-out ones,
    neither solved more within the plan's budget nor took less time on every arm (the dynamic domain
    shortened one arm's searches and lengthened another's, the arms trading places between the two sets;
    ``benchmarks/sampler_speed.py --compare sampling``).

    ``branches``: polylines each tree starts with, ``(start tree's, goal tree's)``, each ``(V, dof)`` from
    its root (the root left out), its segments already found free by the same check: the planner gives
    the retreat stage's free retreats, so the trees start out of their cells: on the tuning problems the
    fixed-time stages left colliding it took fewer iterations to a path.

    ``run(iterations)`` grows the trees for up to that many more iterations (fewer where they meet) and
    returns the path ``(V, dof)`` once found (``None`` while not); ``iterations`` counts those run;
    ``valid_ends`` says whether start and goal are free at all.
    """

    def __init__(
        self,
        body,
        scene,
        start,
        goal,
        lower,
        upper,
        step: float | None = None,
        max_nodes: int = 4096,
        seed: int = 0,
        max_travel: float = 0.01,
        local: float = 0.5,
        sigma: float = 0.8,
        local_step: float | None = None,
        balanced: bool = True,
        branches: tuple = ((), ()),
        sampling: str = "uniform",
        domain: float = 0.0,
        domain_min: float = 0.5,
        domain_alpha: float = 0.1,
    ):
        self.balanced = bool(balanced)
        if sampling not in SAMPLINGS:
            raise ConfigError(f"sampling must be one of {SAMPLINGS}, got {sampling!r}")
        for name, v in (("domain", domain), ("domain_min", domain_min), ("domain_alpha", domain_alpha)):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v >= 0):
                raise ConfigError(f"{name} must be a number >= 0, got {v!r}")
        if domain_alpha >= 1:
            raise ConfigError(f"domain_alpha must be below 1, got {domain_alpha!r}")
        self.sampling = sampling
        lo, hi = np.ascontiguousarray(lower, np.float64), np.ascontiguousarray(upper, np.float64)
        q0, q1 = np.ascontiguousarray(start, np.float64), np.ascontiguousarray(goal, np.float64)
        dof = body.dof
        for name, v in (("start", q0), ("goal", q1), ("lower", lo), ("upper", hi)):
            if v.shape != (dof,):
                raise ShapeError(f"RRT-Connect's {name} must have shape ({dof},), got {v.shape}")
        max_nodes = as_int(max_nodes, "max_nodes", minimum=2)
        self.step = 0.2 * float(np.linalg.norm(np.minimum(hi - lo, TURN))) if step is None else float(step)
        if not (math.isfinite(self.step) and self.step > 0):
            raise ConfigError(f"step must be a number of radians > 0, got {step!r}")
        self.local_step = self.step if local_step is None else float(local_step)
        if not (math.isfinite(self.local_step) and self.local_step > 0):
            raise ConfigError(f"local_step must be a number of radians > 0, got {local_step!r}")
        self.lo, self.hi, self.max_travel = lo, hi, float(max_travel)
        self.local, self.sigma = float(local), float(sigma)
        # the dynamic domain's radii, rad: a failed extension's node gets ``domain`` steps, shrinking to
        # ``domain_min`` steps (never above the first)
        self.domain = float(domain) * self.step
        self.domain_min = min(float(domain_min) * self.step, self.domain)
        self.domain_alpha = float(domain_alpha)
        # every node lies between the limits, the ends and the branches (checked within the limits)
        self._f, self._n = body.packing_of(np.stack([lo, hi, q0, q1]))
        self._s = scene.packed
        self.nodes = np.empty((2, max_nodes, dof))
        self.parent = np.full((2, max_nodes), -1, dtype=np.int64)
        self.nodes[0, 0], self.nodes[1, 0] = q0, q1
        # each node's dynamic-domain radius, rad (infinite: unbounded; none without a dynamic domain)
        self.radius = np.full((2, max_nodes if self.domain > 0 else 0), np.inf)
        self.state = np.zeros(8, dtype=np.int64)
        self.state[_N0] = self.state[_N1] = 1
        self._graft(branches, dof, lo, hi)
        self.state[_RNG] = (int(seed) * 0x632BE59BD9B4E019) % (1 << 62)
        self._kind = SAMPLINGS.index(sampling)
        self._gen = self._shift = _NONE
        if self._kind != _UNIFORM:
            self._gen = _primes(dof) if self._kind == _HALTON else _r2(dof)
            # the sequence's shift: numbers of the seed's generator from a counter of their own (the
            # search's random numbers stay those of the uniform sampling)
            self._shift = _shift_of(int(self.state[_RNG]) ^ 0x5DEECE66D, dof)
        self.iterations = 0
        self.valid_ends = all(
            kernel._verdict_packed(q[None], self.max_travel, 0.0, self._f, self._n, self._s)[0] < 0
            for q in (q0, q1)
        )
        self._path = None
        if self.valid_ends and np.array_equal(q0, q1):  # nothing to search
            self._path = np.stack([q0, q1])

    def _graft(self, branches, dof: int, lo: np.ndarray, hi: np.ndarray) -> None:
        """Each tree starts with its ``branches``: polylines ``(V, dof)`` from its root (the root left
        out) whose segments the caller has found free by the same check (the retreat stage's free
        retreats). A path through them is checked again as every plan is."""
        if not (isinstance(branches, (tuple, list)) and len(branches) == 2):
            raise ConfigError("branches must be a pair (the start tree's, the goal tree's) of polyline lists")
        for t, chains in enumerate(branches):
            for chain in chains:
                v = np.asarray(chain, dtype=np.float64)
                if v.ndim != 2 or v.shape[1] != dof:
                    raise ShapeError(f"a branch must have shape (V, {dof}), got {v.shape}")
                if not (np.isfinite(v).all() and (v >= lo).all() and (v <= hi).all()):
                    raise ConfigError("a branch must be finite and within the joint limits")
                prev = 0
                for q in v:
                    m = int(self.state[_N0 + t])
                    if m >= self.nodes.shape[1]:
                        raise ConfigError(f"branches exceed the trees' {self.nodes.shape[1]} nodes")
                    self.nodes[t, m], self.parent[t, m] = q, prev
                    self.state[_N0 + t] = m + 1
                    prev = m

    @property
    def found(self) -> bool:
        return self._path is not None or int(self.state[_STATUS]) == 1

    @property
    def exhausted(self) -> bool:
        """No path can come from more rounds: an end collides, or a tree is full."""
        return not self.valid_ends or int(self.state[_STATUS]) == -1

    @property
    def size(self) -> int:
        """Nodes in both trees."""
        return int(self.state[_N0] + self.state[_N1])

    def run(self, iterations: int) -> np.ndarray | None:
        if self._path is not None:
            return self._path
        if self.exhausted:
            return None
        _grow(
            self.nodes, self.parent, self.state, self.lo, self.hi, self.step, self.local, self.sigma, self.local_step, int(iterations),
            self.max_travel, self._f, self._n, self._s, self.balanced, self._kind, self._gen, self._shift,
            self.radius, self.domain, self.domain_min, self.domain_alpha, DOMAIN_TRIES,
        )  # fmt: skip
        self.iterations = int(self.state[_ROUND])  # those run: a round stops where the trees meet
        if int(self.state[_STATUS]) != 1:
            return None
        half = []
        for t, i in ((0, int(self.state[_CA])), (1, int(self.state[_CB]))):
            chain = []
            while i >= 0:
                chain.append(self.nodes[t, i])
                i = int(self.parent[t, i])
            half.append(chain)
        # start … meeting node … goal (the goal tree's copy of the meeting node left out)
        self._path = np.array([*half[0][::-1], *half[1][1:]])
        return self._path

    def shortcut(self, path: np.ndarray, attempts: int = DEFAULT_ATTEMPTS) -> np.ndarray:
        """``path`` (one this search found) shortened by the shortcut pass every plan goes through
        (:func:`~kinlearn.collision.shortcut.shorten`: vertex skipping, then ``attempts`` partial
        shortcuts), on this search's body and scene."""
        p = np.ascontiguousarray(path, np.float64)
        return shorten_packed(
            p, self._f, self._n, self._s, p.shape[0], int(attempts), 0, self.max_travel, 0.0
        )


def rrt_connect(
    body,
    scene,
    start,
    goal,
    lower,
    upper,
    time_limit: float = 1.0,
    seed: int = 0,
    rounds: int | None = None,
    shortcut: bool = True,
    shortcut_attempts: int = DEFAULT_ATTEMPTS,
    clock=None,
    max_iterations: int | None = None,
    **options,
) -> tuple[np.ndarray | None, float, int]:
    """Solve one query with :class:`RrtConnect` for at most ``time_limit`` seconds (checked between
    rounds; ``math.inf`` for no limit) and at most ``max_iterations`` iterations (default: no limit),
    shortening the path found by the shortcut pass (:mod:`kinlearn.collision.shortcut`, with
    ``shortcut_attempts`` partial shortcuts after its vertex skipping). ``rounds``:
    iterations per round; by default they are sized to take at most :data:`ROUND_SECONDS` and a quarter
    of the time left. The rounds change when the search stops, never the path it finds.

    With an iteration budget and no time limit the answer is the machine's speed's no more: the same
    seed and budget give the same path, or the same failure, everywhere.

    Returns ``(path (V, dof) or None, seconds taken, iterations)``. ``clock``: the time source
    (default ``time.perf_counter``). ``options`` go to :class:`RrtConnect`.
    """
    time_limit = as_real(
        time_limit, "time_limit", minimum=0.0, open_minimum=True, finite=False,
        expected="a number of seconds > 0 (or inf)",
    )  # fmt: skip
    if rounds is not None:
        rounds = as_int(rounds, "rounds (or None: sized to their time)", minimum=1)
    if max_iterations is not None and (
        isinstance(max_iterations, bool) or not isinstance(max_iterations, int) or max_iterations < 1
    ):
        raise ConfigError(f"max_iterations must be an integer >= 1 (or None), got {max_iterations!r}")
    if math.isinf(time_limit) and max_iterations is None:
        raise ConfigError(
            "give rrt_connect a time limit or an iteration budget: without either it may not stop"
        )
    clock = time.perf_counter if clock is None else clock
    t0 = clock()
    rrt = RrtConnect(body, scene, start, goal, lower, upper, seed=seed, **options)
    budget = math.inf if max_iterations is None else max_iterations
    path, size, now = None, 1 if rounds is None else rounds, clock()
    t_grow = now
    while path is None and not rrt.exhausted and rrt.iterations < budget and now - t0 < time_limit:
        path = rrt.run(int(min(size, budget - rrt.iterations)))
        now = clock()
        if rounds is None:  # the next round: twice this one, if the time per iteration so far allows
            per = (now - t_grow) / rrt.iterations
            room = min(ROUND_SECONDS, 0.25 * (time_limit - (now - t0)))
            size = max(1, min(2 * size, int(room / per) if per > 0 else 2 * size))
    if path is not None and shortcut:  # the shortcut pass, a fixed budget
        path = rrt.shortcut(path, shortcut_attempts)
    return path, clock() - t0, rrt.iterations


def warm_up() -> None:
    """Compile (or load from numba's cache) the sampler's kernels now, on a tiny problem: a first
    sampling stage otherwise spends its deadline loading them."""
    from ..body.robot import load_robot
    from .body import body_spheres
    from .scene import Scene

    robot = load_robot("iiwa14")
    body = kernel.KernelBody(body_spheres(robot).double())
    scene = kernel.KernelScene(Scene.from_spheres([[0.5, 0.0, 0.5, 0.1]], floor=0.0))
    start = np.zeros(robot.dof)
    goal = start.copy()
    goal[0] = 0.5
    rrt = RrtConnect(body, scene, start, goal, robot.lower, robot.upper)
    path = rrt.run(5)
    if path is not None:
        rrt.shortcut(path, 1)
