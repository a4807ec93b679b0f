"""Many configurations at once (:func:`kinlearn.collision.kernel.free_configurations`) give the dense
check's verdicts: those of :func:`~kinlearn.collision.kernel.clearances`' numbers and of one-configuration
paths through :func:`~kinlearn.collision.kernel.check_paths`, on every arm, scenes of every kind, a
margin, configurations beyond the joint box (every self-collision pair then) and the typed errors."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from kinlearn import load_robot
from kinlearn.collision import Scene, body_spheres
from kinlearn.collision import kernel as K
from kinlearn.errors import NonFiniteError, ShapeError


def scene(rng: np.random.Generator) -> Scene:
    """Balls, boxes and cylinders of random orientation in front of the arm, and a floor."""
    R = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    R = R * np.sign(np.linalg.det(R))
    boxes = [[*rng.uniform((0.3, -0.4, 0.1), (0.7, 0.4, 0.8)), 0.1, 0.05, 0.2, *R.ravel()]]
    cylinders = [[*rng.uniform((0.3, -0.4, 0.1), (0.7, 0.4, 0.8)), 0.05, 0.15, *R.T.ravel()]]
    spheres = np.concatenate(
        [rng.uniform((0.2, -0.5, 0.1), (0.8, 0.5, 0.9), (3, 3)), np.full((3, 1), 0.08)], 1
    )
    return Scene(spheres=spheres, boxes=boxes, cylinders=cylinders, floor=0.0)


@pytest.mark.parametrize("name", ["iiwa14", "panda", "ur5"])
def test_free_configurations_are_the_dense_check_s_verdicts(name):
    robot = load_robot(name)
    kb = K.KernelBody(body_spheres(robot).double())
    rng = np.random.default_rng(60)
    frees = []
    for s, margin in enumerate((0.0, 0.02)):
        ks = K.KernelScene(scene(rng))
        q = robot.sample(400, torch.Generator().manual_seed(s), dtype=torch.float64).numpy()
        q[:20] = q[:20] * 1.3  # beyond the joint box: every self-collision pair is checked
        free = K.free_configurations(kb, ks, q, margin=margin)
        d, sc = K.clearances(kb, ks, q)
        assert np.array_equal(free, (d > margin) & (sc > 0))
        paths = q[:60, None, :]
        assert np.array_equal(free[:60], K.check_paths(kb, paths, ks, margin=margin, exact=False)[0])
        frees += free.tolist()
        assert np.array_equal(K.free_configurations(kb, ks, q[::-1]), K.free_configurations(kb, ks, q)[::-1])
    assert 0.05 < np.mean(frees) < 0.95  # both verdicts, often
    assert K.free_configurations(kb, ks, np.empty((0, robot.dof))).shape == (0,)


def test_free_configurations_refuse_bad_input():
    robot = load_robot("panda")
    kb = K.KernelBody(body_spheres(robot))
    ks = K.KernelScene(Scene.from_spheres([[0.5, 0.0, 0.5, 0.1]]))
    q = np.zeros((3, robot.dof))
    q[1, 2] = np.nan
    with pytest.raises(NonFiniteError):
        K.free_configurations(kb, ks, q)
    with pytest.raises(ShapeError):
        K.free_configurations(kb, ks, np.zeros((3, robot.dof - 1)))
