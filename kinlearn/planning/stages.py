"""A plan's stages around obstacles, and the deadline that bounds them.

An obstacle plan is made in up to four stages, each run only when the earlier ones cleared nothing:

=============  ====================================================================================
``learned``    the learned proposals (the obstacle-aware network's paths and the straight joint
               line), the shortest free one by the compiled dense check. Fixed time.
``retreat``    out of the start's cell and into the goal's along fixed end-effector retreats, the
               straight joint line or the network's candidates across (:mod:`kinlearn.planning.retreat`;
               ``Planner(retreat=False)`` leaves it out). Fixed time.
``refine``     bounded gradient refinement of the least colliding proposal (``refine_steps``).
``rrt``        the compiled RRT-Connect with shortcutting (:mod:`kinlearn.collision.rrt`): for what a
               deadline leaves, or, by default (no ``refine_steps`` given), for a fixed budget of
               iterations (:data:`~kinlearn.planning.planner.DEFAULT_RRT_ITERATIONS`).
=============  ====================================================================================

``Planner(sample_first=True)`` runs the sampler right after the learned stage where a budget of iterations is
set (no deadline), and the retreat stage only on what the sampler's budget left: a shorter tail where the
retreat stage often fails, longer paths where the two orders differ (``benchmarks/stage_order.py``).

``plan.stage`` names the stage a plan came from; ``"none"`` marks a plan none of them cleared (it is
flagged: ``collision_free`` False, ``success`` False). ``refine_steps=k`` without a deadline asks for fixed time: the
first two stages and k refinement steps, no sampling. Without a deadline every stage is a fixed amount
of work and a plan is deterministic; with ``deadline=seconds`` each stage starts only while time is
left (the retreat stage only within its first share, :func:`retreat_share`) and the sampling stage stops by
the deadline (:class:`Deadline`), so whether it finds a path in time depends on the machine.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np

from ..checks import as_real
from ..errors import ConfigError

__all__ = ["RETREAT_SHARE", "RETREAT_SHARES", "STAGES", "Deadline", "densify", "retreat_share"]

#: The stages a plan can come from, in the order they run (``Planner(sample_first=True)`` swaps the retreat
#: stage and the sampler); "none" when none cleared the obstacles.
STAGES: tuple[str, ...] = ("learned", "retreat", "refine", "rrt", "none")
#: Time (s) kept back from a deadline for the work after a stage: judging, packing the plan.
DEADLINE_RESERVE = 0.002
#: Share of a deadline after which the retreat stage starts no more work (a problem's retreat, a
#: transfer), so that the sampling stage, which clears what the fixed-time stages cannot, keeps the
#: rest: the default of every arm but those in :data:`RETREAT_SHARES`. The panda's tuning problems made
#: with the hand pointing into the cells (see :data:`RETREAT_SHARES`) cleared 100% under a deadline of
#: 0.05 s with it and 99.0% with none (three runs by turns); its scene families and the iiwa14's
#: problems did not change (99.3% and 100%).
RETREAT_SHARE = 0.3
#: Arms whose retreat stage does not run under a deadline (share 0), measured on their planning bodies.
#: The ur5 with its 40-sphere gripper: its retreat stage takes 5–25 ms where it runs, time the sampler
#: turns into more plans. On its tuning problems (seeds 3004–3010, 20 per family) under a deadline of
#: 0.05 s, 98.6–98.8% cleared with a share of 0 against 97.9–98.3% with 0.3, and on 100 tuning problems
#: with the hand pointing into a bookcase's, a cubby's or a cage's cell or down into a bin 93.7–95.7%
#: against 89.7–90.3% (three runs each, the variants by turns in one process).
RETREAT_SHARES: dict[str, float] = {"ur5": 0.0}


def retreat_share(robot_name: str) -> float:
    """The share of a deadline within which an arm's retreat stage may start work (:data:`RETREAT_SHARES`,
    else :data:`RETREAT_SHARE`)."""
    return RETREAT_SHARES.get(robot_name, RETREAT_SHARE)


class Deadline:
    """A time budget that started when it was made: ``left()`` seconds remain (never below 0),
    ``expired()`` when none do. ``seconds=None`` never expires. ``clock`` (default
    ``time.perf_counter``, looked up when the deadline is made) is read for every answer; the stages
    that run under the deadline read the same clock."""

    def __init__(self, seconds: float | None, clock: Callable[[], float] | None = None):
        # a Python, NumPy or 0-d torch number: np.float32(0.05) and torch.tensor(0.05) are deadlines too
        what = "deadline (a number of seconds, or None)"
        self.seconds = None if seconds is None else as_real(seconds, what, minimum=0.0, open_minimum=True)
        self.clock = time.perf_counter if clock is None else clock
        self._start = self.clock()

    def elapsed(self) -> float:
        return self.clock() - self._start

    def left(self) -> float:
        """Seconds left (``inf`` without a deadline)."""
        if self.seconds is None:
            return math.inf
        return max(0.0, self.seconds - self.elapsed())

    def expired(self, reserve: float = 0.0) -> bool:
        """Whether no more than ``reserve`` seconds are left."""
        return self.left() <= reserve

    def spent(self, share: float) -> bool:
        """Whether at least ``share`` of the deadline has gone (never, without a deadline)."""
        return self.seconds is not None and self.elapsed() >= share * self.seconds

    def __repr__(self) -> str:
        return f"Deadline({self.seconds!r}, left={self.left():.4g} s)"


def densify(vertices: np.ndarray, count: int) -> np.ndarray:
    """The polyline ``vertices (V, dof)`` as ``count >= V`` knots: every vertex kept, the longest
    segments split evenly (the path traced is the same, so its collision verdict is too)."""
    v = np.asarray(vertices, dtype=np.float64)
    if v.ndim != 2 or v.shape[0] < 2:
        raise ConfigError(f"densify needs a polyline of at least 2 vertices (V, dof), got shape {v.shape}")
    if count < v.shape[0]:
        raise ConfigError(f"densify cannot make {count} knots from {v.shape[0]} vertices (it keeps them all)")
    length = np.linalg.norm(np.diff(v, axis=0), axis=1)
    pieces = np.ones(len(length), dtype=np.int64)
    for _ in range(count - v.shape[0]):  # one more piece for the segment whose pieces are longest
        pieces[int(np.argmax(length / pieces))] += 1
    out = [v[:1]]
    for a, b, k in zip(v[:-1], v[1:], pieces, strict=True):
        f = np.arange(1, k, dtype=np.float64)[:, None] / k
        out.append(a + f * (b - a))
        out.append(b[None])  # the vertex itself, not a rounded a + 1 · (b − a)
    return np.concatenate(out)
