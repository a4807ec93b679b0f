"""The contract every kind of obstacle keeps, kind by kind over the table of kinds
(:data:`kinlearn.collision.kinds.SCENE_KINDS`, so a new kind is held to it without touching this file):
its torch signed distance (the reference), its compiled twin (one primitive, the scene's minimum with
bounding-ball culling, every sphere at once) and coal's distance agree; the dense check of paths among
primitives of that kind gives torch's verdicts; the obstacle network's rows of the packed scene are
those torch makes."""

from __future__ import annotations

import sys

import numpy as np
import pytest
import torch

from kinlearn import load_robot
from kinlearn.collision import Scene, body_obstacle_distance, body_spheres, check_path
from kinlearn.collision import kernel as K
from kinlearn.collision.kinds import SCENE_KINDS, Primitive

KIND_IDS = [k.kind for k in SCENE_KINDS]


def rotations(n: int, rng: np.random.Generator) -> np.ndarray:
    """``(n, 9)`` uniformly random rotations, row-major (from normalised Gaussian quaternions)."""
    q = rng.normal(size=(n, 4))
    x, y, z, w = (q / np.linalg.norm(q, axis=1, keepdims=True)).T
    R = np.stack(
        [
            1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
            2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
            2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y),
        ],
        axis=1,
    )  # fmt: skip
    return R


def rows_of(kind: type[Primitive], n: int, rng: np.random.Generator, lo=(0.3, -0.5, 0.1), hi=(0.7, 0.5, 0.9)):
    """``(n, width)`` valid rows of ``kind``: its padding row with a random centre, sizes of 3–20 cm and
    a random rotation (where the kind has one)."""
    rows = np.tile(np.asarray(kind.pad, dtype=np.float64), (n, 1))
    rows[:, :3] = rng.uniform(lo, hi, (n, 3))
    sizes = rows[:, kind.sizes]
    rows[:, kind.sizes] = rng.uniform(0.03, 0.2, sizes.shape)
    if kind.rotation_columns is not None:
        rows[:, kind.rotation_columns] = rotations(n, rng)
    for r in rows:  # the kind's own checks accept them
        kind.from_row(r)
    return rows


def scene_of(kind: type[Primitive], rows: np.ndarray, floor=None) -> Scene:
    return Scene(**{kind.table: torch.from_numpy(rows)}, floor=floor)


@pytest.mark.parametrize("kind", SCENE_KINDS, ids=KIND_IDS)
def test_torch_and_compiled_distances_agree(kind):
    """One primitive at a time (the kind's compiled ``distance``), and a scene's minimum over many (its
    ``nearest``, culling by bounding balls, and ``nearest_many``, every sphere at once) are torch's."""
    rng = np.random.default_rng(53)
    rows = rows_of(kind, 7, rng)
    pts = rng.uniform((0.0, -0.8, -0.2), (1.0, 0.8, 1.2), (400, 3))
    ref = kind.point_distance(torch.from_numpy(pts)[:, None], torch.from_numpy(rows)[None]).numpy()
    ks = K.KernelScene(scene_of(kind, rows))
    table = ks.tables[[k.kind for k in SCENE_KINDS].index(kind.kind)]
    assert table.shape == (len(rows), kind.packed_width)
    compiled = sys.modules[kind.__module__].distance
    one = np.array([[compiled(*p, table, i) for i in range(len(rows))] for p in pts])
    np.testing.assert_allclose(one, ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(K.point_distances(ks, pts), ref.min(1), rtol=0, atol=1e-12)
    assert (ref.min(1) < 0).any() and (ref.min(1) > 0).any()
    radii, on_floor = rng.uniform(0.0, 0.05, len(pts)), np.ones(len(pts), dtype=bool)
    many = np.empty(len(pts))
    K._spheres_scene(pts, radii, on_floor, *ks.args(), np.empty((3, len(pts))), many)
    alone = [K._sphere_scene(*pts[m], radii[m], True, *ks.args()) for m in range(len(pts))]
    assert np.array_equal(many, alone)
    np.testing.assert_allclose(many, ref.min(1) - radii, rtol=0, atol=1e-12)
    # every row lies within its bounding radius of its centre (the culling is sound)
    module = sys.modules[kind.__module__]
    far = np.array([module.radius(table, i) for i in range(len(rows))])
    direction = rng.normal(size=(len(rows), 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    outside = rows[:, :3] + direction * (far[:, None] + 1e-6)
    d = kind.point_distance(torch.from_numpy(outside), torch.from_numpy(rows)).numpy()
    assert (d > 0).all()


@pytest.mark.parametrize("kind", SCENE_KINDS, ids=KIND_IDS)
def test_coal_agrees(kind):
    """coal (the ``pin`` wheel's collision library) gives the same distance between small balls and each
    primitive where they are apart (to its GJK's precision) and finds them overlapping where they overlap
    (its EPA's depth is an approximation on curved shapes, so only its sign is held)."""
    coal = pytest.importorskip("coal")
    rng = np.random.default_rng(54)
    rows = rows_of(kind, 5, rng)
    req = coal.DistanceRequest()
    apart = overlapping = 0
    for row in rows:
        shape, R, t = kind.coal_shape(row)
        T = coal.Transform3s(R, t)
        for _ in range(40):
            c = row[:3] + rng.normal(scale=0.25, size=3)
            r = float(rng.uniform(0.005, 0.05))
            ref = float(kind.sphere_distance(torch.tensor([*c, r]), torch.from_numpy(row)))
            res = coal.DistanceResult()
            got = coal.distance(coal.Sphere(r), coal.Transform3s(np.eye(3), c), shape, T, req, res)
            if ref > 1e-3:
                apart += 1
                assert got == pytest.approx(ref, abs=1e-5)
            elif ref < -1e-3:
                overlapping += 1
                assert got < 0
    assert apart > 20 and overlapping > 5


@pytest.mark.parametrize("kind", SCENE_KINDS, ids=KIND_IDS)
def test_dense_check_and_network_rows_agree_with_torch(kind):
    """Paths of the iiwa14 among primitives of this kind (and a floor): the compiled dense check's
    verdicts, first colliding segments and clearances, and :func:`~kinlearn.collision.kernel.first_free`,
    are torch's :func:`~kinlearn.collision.check_path`; the network's rows of the packed scene are
    :func:`~kinlearn.models.obstacle_path.scene_primitives`'."""
    from kinlearn.models.obstacle_path import scene_primitives

    robot = load_robot("iiwa14")
    body = body_spheres(robot).double()
    kb = K.KernelBody(body)
    rng = np.random.default_rng(55)
    rows = rows_of(kind, 4, rng)
    scene = scene_of(kind, rows, floor=-0.05)
    ks = K.KernelScene(scene)
    lo, hi = robot.lower * 0.6, robot.upper * 0.6
    paths = rng.uniform(lo, hi, (10, 3, robot.dof))
    ref = check_path(body, torch.from_numpy(paths), scene)
    free, clear, first = K.check_paths(kb, paths, ks)
    assert np.array_equal(free, ref.collision_free.numpy())
    assert np.array_equal(first, ref.first_collision.numpy())
    np.testing.assert_allclose(clear, ref.clearance.numpy(), rtol=0, atol=1e-9)
    assert np.array_equal(K.check_paths(kb, paths, ks, exact=False)[0], free)
    want = int(np.flatnonzero(free)[0]) if free.any() else -1
    assert K.first_free(kb, paths, ks) == want
    assert 0 < free.sum() < len(free)
    q = torch.from_numpy(paths[:, 0])
    d = body_obstacle_distance(body(q), body.radii, scene, floor_mask=body.floor_mask)
    np.testing.assert_allclose(K.clearances(kb, ks, paths[:, 0])[0], d.numpy(), rtol=0, atol=1e-12)
    net, mask, _ = scene_primitives(scene, 1, torch.float64)
    np.testing.assert_allclose(ks.model_rows(), net[0][mask[0]].numpy(), rtol=0, atol=1e-12)
