"""The stage bookkeeping of an obstacle plan: the deadline's clock and the densified sampling path."""

import itertools
import math

import numpy as np
import pytest

from kinlearn.errors import ConfigError
from kinlearn.planning.stages import STAGES, Deadline, densify


class _Clock:
    """A clock that moves only when told to."""

    def __init__(self):
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_deadline_counts_down_on_its_clock_and_never_below_zero():
    clock = _Clock()
    d = Deadline(0.05, clock=clock)
    assert d.left() == pytest.approx(0.05) and not d.expired()
    clock.now += 0.03
    assert d.left() == pytest.approx(0.02) and d.elapsed() == pytest.approx(0.03)
    assert d.expired(reserve=0.025) and not d.expired(reserve=0.01)
    clock.now += 1.0
    assert d.left() == 0.0 and d.expired()
    assert Deadline(None, clock=clock).left() == math.inf
    assert not Deadline(None, clock=clock).spent(0.0)  # no deadline: no share of it ever goes


def test_a_share_of_the_deadline_is_spent_once_that_much_time_has_gone():
    clock = _Clock()
    d = Deadline(0.05, clock=clock)
    assert d.spent(0.0) and not d.spent(0.3)
    clock.now += 0.014
    assert not d.spent(0.3) and d.spent(0.2)
    clock.now += 0.002
    assert d.spent(0.3) and not d.spent(1.0)
    for bad in (0, -1.0, math.nan, math.inf, True, "1"):
        with pytest.raises(ConfigError, match="deadline"):
            Deadline(bad)


def test_densify_keeps_every_vertex_and_the_path():
    rng = np.random.default_rng(0)
    v = rng.normal(size=(5, 7))
    out = densify(v, 23)
    assert out.shape == (23, 7)
    for vertex in v:  # every vertex is a knot
        assert np.abs(out - vertex).max(axis=1).min() == 0.0
    # the same polyline: every knot lies on one of the original segments
    for q in out:
        on = []
        for a, b in itertools.pairwise(v):
            t = np.clip(np.dot(q - a, b - a) / np.dot(b - a, b - a), 0, 1)
            on.append(np.linalg.norm(a + t * (b - a) - q))
        assert min(on) < 1e-12
    assert np.allclose(
        np.linalg.norm(np.diff(out, axis=0), axis=1).sum(), np.linalg.norm(np.diff(v, axis=0), axis=1).sum()
    )
    assert np.array_equal(densify(v, 5), v)
    with pytest.raises(ConfigError, match="keeps them all"):
        densify(v, 4)
    assert STAGES[-1] == "none"
