"""The travel bound at a configuration (kinlearn.body.travel) held to the motion itself: along random
segments of every bundled arm with obstacles, each body sphere's centre (placed by torch's FK, not the
compiled chain the bound reads) and each link's ball centre travel no farther from a configuration of the
segment than D(u) says, either way; the window a budget gives is never shorter than the global bound's,
and within it the travel stays within the budget."""

import math

import numpy as np
import pytest
import torch

from kinlearn import load_robot
from kinlearn.body.fk import KernelChain, _chain, _point
from kinlearn.body.travel import axis_speed, growth, window
from kinlearn.collision import body_spheres
from kinlearn.collision import kernel as K
from kinlearn.collision.kernel_body import _unpack_body
from kinlearn.collision.probe import _link_levers


def travel(u, a, g, c):
    """D(u) of kinlearn.body.travel's docstring: the most a point travels over a share u of a segment."""
    return min(a * u + 0.5 * g * u * u, c * u)


@pytest.mark.parametrize("name", ["iiwa14", "panda", "ur5"])
def test_no_point_of_a_link_travels_farther_than_its_bound(name):
    robot = load_robot(name)
    body = body_spheres(robot).double()
    kb = K.KernelBody(body)
    chain = KernelChain.of(robot)
    lever = body.lever.numpy()
    link = np.asarray(kb.link)
    balls = np.asarray(kb.l_folded)
    ball_lever = np.empty((len(balls), robot.dof))  # the probe's: per link, its spheres' largest levers
    _link_levers(_unpack_body(*kb.packed), ball_lever)
    rng = np.random.default_rng(3)
    s = np.linspace(0.0, 1.0, 401)
    tighter, checked = [], 0
    for t in range(12):
        a, b = rng.uniform(robot.lower, robot.upper, (2, robot.dof))
        b = a + (b - a) * rng.uniform(0.05, 1.0)  # long and short segments
        path = np.stack([a, b])
        qs = a + s[:, None] * (b - a)
        centres = body(torch.from_numpy(qs)).numpy()  # (401, M, 3), torch's FK
        frames = np.empty((robot.dof + 1, 3, 4))
        for i0 in (0, 137, 400):  # a configuration of the segment, the bound taken there
            _chain(qs[i0], chain.F, chain.prismatic, frames)
            u = np.abs(s - s[i0])
            for m, lk in enumerate(link):
                if lk == 0:
                    continue
                c = float(np.abs(b - a) @ lever[m])
                x, y, z = centres[i0, m]
                speed = axis_speed(frames, x, y, z, int(lk), path, 0, chain.prismatic)
                g = growth(path, 0, int(lk), lever, m)
                moved = np.linalg.norm(centres[:, m] - centres[i0, m], axis=1)
                bound = np.array([travel(v, speed, g, c) for v in u])
                assert (moved <= bound + 1e-9).all(), (name, t, m)
                checked += 1
                if c == 0.0:  # on the axis of the one joint that moves it: it stays put (asserted above)
                    continue
                budget = 0.05
                w = window(budget, speed, g, c)
                assert w >= budget / c * (1 - 1e-12)
                assert travel(w, speed, g, c) <= budget * (1 + 1e-9)
                tighter.append(w * c / budget)
            for lk in range(1, len(balls)):  # the links' ball centres, moving rigidly with them
                if not (link == lk).any():
                    continue
                centre = np.array(_point(frames, lk, balls[lk]))
                cs = []
                for q in qs[::40]:
                    f = np.empty_like(frames)
                    _chain(q, chain.F, chain.prismatic, f)
                    cs.append(_point(f, lk, balls[lk]))
                speed = axis_speed(frames, *centre, lk, path, 0, chain.prismatic)
                g = growth(path, 0, lk, ball_lever, lk)
                c = float(np.abs(b - a) @ ball_lever[lk])
                moved = np.linalg.norm(np.array(cs) - centre, axis=1)
                assert (moved <= np.array([travel(v, speed, g, c) for v in u[::40]]) + 1e-9).all()
    assert checked > 300
    # the point of the bound: a window at a configuration is longer than the global one, often by much
    assert np.median(tighter) > 1.1


def test_window_edges():
    assert window(0.0, 1.0, 1.0, 1.0) == 0.0 and window(-1.0, 1.0, 1.0, 1.0) == 0.0
    assert window(0.1, 0.0, 0.0, 0.0) == math.inf  # nothing moves the point
    assert window(0.1, 0.5, 0.0, 1.0) == pytest.approx(0.2)  # no growth: b / A
    assert window(0.1, 2.0, 0.0, 1.0) == pytest.approx(0.1)  # never shorter than the global b / C
    u = window(0.1, 0.5, 4.0, 1.0)
    assert 0.1 < u < 0.2 and travel(u, 0.5, 4.0, 1.0) == pytest.approx(0.1)
