"""The typed primitives: every sphere–primitive signed distance against coal within 1e-6 m (rotated
boxes, cylinders approached from every side, inside and outside), the dispatch table, gradients, and
scenes of typed primitives (masks, stacking, round trips)."""

import coal
import numpy as np
import pytest
import torch

from kinlearn import load_robot
from kinlearn.collision import Scene, body_obstacle_distance, body_spheres
from kinlearn.collision.distance import sphere_distance
from kinlearn.collision.geometry import (
    KINDS,
    SCENE_KINDS,
    Box,
    Cylinder,
    Plane,
    Sphere,
    aabb_half_extents,
    quaternion_from_rotation,
    rotation_from_quaternion,
)
from kinlearn.errors import ObstacleError

TOL = 1e-6  # metres


def random_rotations(n: int, rng: np.random.Generator) -> np.ndarray:
    """``(n, 3, 3)`` uniformly random rotations (from normalised Gaussian quaternions)."""
    return np.stack([rotation_from_quaternion(q) for q in rng.normal(size=(n, 4))])


def _tf(R, p) -> coal.Transform3s:
    t = coal.Transform3s()
    t.setRotation(np.asarray(R, dtype=float))
    t.setTranslation(np.asarray(p, dtype=float))
    return t


def _request() -> coal.DistanceRequest:
    req = coal.DistanceRequest()
    req.gjk_tolerance = req.epa_tolerance = 1e-12
    req.gjk_max_iterations = req.epa_max_iterations = 1000
    return req


def coal_distance(sphere, primitive) -> float:
    """Signed distance between a sphere [x, y, z, r] and a typed primitive, computed by coal.

    For a cylinder coal has two routes, each exact where it applies and neither everywhere: its
    dedicated sphere–cylinder routine measures penetration radially only (a ball inside near a cap gets
    the depth to the side), and a ball given as a capsule of length 0 goes through GJK/EPA, which near
    the side sometimes stops at a deeper separating direction. Each returns the length of a translation
    that separates the shapes, so the penetration depth is at most the smaller one: the signed distance
    is the larger of the two (outside, both are the exact distance).
    """
    x, r = np.asarray(sphere[:3], dtype=float), float(sphere[3])
    me = coal.Sphere(r)
    eye = np.eye(3)
    if isinstance(primitive, Sphere):
        other, R, p = coal.Sphere(primitive.radius), eye, primitive.centre
    elif isinstance(primitive, Box):
        other = coal.Box(*(2 * np.asarray(primitive.half_extents)).tolist())
        R, p = np.reshape(primitive.rotation, (3, 3)), primitive.centre
    elif isinstance(primitive, Cylinder):
        other = coal.Cylinder(primitive.radius, 2 * primitive.half_length)
        R, p = np.reshape(primitive.rotation, (3, 3)), primitive.centre
        return max(
            coal.distance(g, _tf(eye, x), other, _tf(R, p), _request(), coal.DistanceResult())
            for g in (me, coal.Capsule(r, 0.0))
        )
    elif isinstance(primitive, Plane):
        other, R, p = coal.Halfspace(np.asarray(primitive.normal), primitive.offset), eye, (0, 0, 0)
    else:
        raise TypeError(type(primitive))
    return coal.distance(me, _tf(eye, x), other, _tf(R, p), _request(), coal.DistanceResult())


def _ours(sphere, primitive) -> float:
    s = torch.tensor(sphere, dtype=torch.float64)
    row = torch.tensor(primitive.row(), dtype=torch.float64)
    return float(sphere_distance(s, primitive.kind, row))


def _local_to_world(prim, local: np.ndarray) -> np.ndarray:
    return np.asarray(prim.centre) + np.reshape(prim.rotation, (3, 3)) @ local


def test_dispatch_table_holds_every_kind():
    assert set(KINDS) == {"sphere", "box", "cylinder", "capsule", "plane"}
    for name, kind in KINDS.items():
        assert kind.kind == name and len(kind.pad) == kind.width
    assert {k.table for k in SCENE_KINDS} == {"spheres", "boxes", "cylinders", "capsules"}


def test_sphere_sphere_and_plane_match_coal():
    rng = np.random.default_rng(0)
    errs, signs = [], []
    for _ in range(200):
        s = [*rng.uniform(-0.5, 0.5, 3), rng.uniform(0.02, 0.2)]
        o = Sphere(rng.uniform(-0.5, 0.5, 3), rng.uniform(0.02, 0.3))
        n = rng.normal(size=3)
        pl = Plane(n, rng.uniform(-0.3, 0.3))
        for prim in (o, pl):
            ref = coal_distance(s, prim)
            errs.append(abs(_ours(s, prim) - ref))
            signs.append(ref < 0)
    assert max(errs) <= TOL and 0 < sum(signs) < len(signs)


def test_rotated_box_matches_coal_inside_and_outside():
    rng = np.random.default_rng(1)
    R = random_rotations(300, rng)
    errs, inside, outside = [], 0, 0
    for i in range(300):
        box = Box(rng.uniform(-0.5, 0.5, 3), rng.uniform(0.02, 0.3, 3), R[i])
        h = np.asarray(box.half_extents)
        # Centres inside, near faces, edges and corners, and far outside, in the box's own frame.
        local = rng.uniform(-1.0, 1.0, 3) * h * rng.choice([0.5, 0.95, 1.05, 1.5, 3.0])
        r = rng.uniform(0.01, 0.15)
        s = [*_local_to_world(box, local), r]
        ref = coal_distance(s, box)
        errs.append(abs(_ours(s, box) - ref))
        inside += bool(np.all(np.abs(local) < h))
        outside += bool(ref > 0)
    assert max(errs) <= TOL
    assert inside >= 30 and outside >= 30


@pytest.mark.parametrize(
    "side", ["axis_beyond_cap", "beside", "rim", "inside_near_cap", "inside_near_side", "random"]
)
def test_cylinder_matches_coal_from_every_side(side):
    rng = np.random.default_rng(hash(side) % 2**32)
    R = random_rotations(120, rng)
    errs, ds = [], []
    for i in range(120):
        cyl = Cylinder(rng.uniform(-0.5, 0.5, 3), rng.uniform(0.03, 0.25), rng.uniform(0.03, 0.3), R[i])
        a, h = cyl.radius, cyl.half_length
        phi = rng.uniform(0, 2 * np.pi)
        u = np.array([np.cos(phi), np.sin(phi), 0.0])
        sign = rng.choice([-1.0, 1.0])
        if side == "axis_beyond_cap":
            local = u * rng.uniform(0, 0.9) * a + [0, 0, sign * (h + rng.uniform(0.0, 0.3))]
        elif side == "beside":
            local = u * (a + rng.uniform(0.0, 0.3)) + [0, 0, rng.uniform(-0.9, 0.9) * h]
        elif side == "rim":
            local = u * (a + rng.uniform(0.001, 0.2)) + [0, 0, sign * (h + rng.uniform(0.001, 0.2))]
        elif side == "inside_near_cap":
            local = u * rng.uniform(0, 0.5) * a + [0, 0, sign * h * rng.uniform(0.8, 0.99)]
        elif side == "inside_near_side":
            local = u * a * rng.uniform(0.8, 0.99) + [0, 0, rng.uniform(-0.3, 0.3) * h]
        else:
            local = rng.uniform(-2, 2, 3) * [a, a, h]
        s = [*_local_to_world(cyl, local), rng.uniform(0.01, 0.1)]
        ref = coal_distance(s, cyl)
        errs.append(abs(_ours(s, cyl) - ref))
        ds.append(ref)
    assert max(errs) <= TOL
    if side.startswith("inside"):
        assert max(ds) < 0


def test_distances_are_differentiable_everywhere():
    rng = np.random.default_rng(3)
    prims = [
        Sphere((0.1, 0.0, 0.2), 0.1),
        Box((0.0, 0.3, 0.1), (0.1, 0.2, 0.05), random_rotations(1, rng)[0]),
        Cylinder((0.2, -0.1, 0.0), 0.08, 0.15, random_rotations(1, rng)[0]),
        Plane((0.0, 0.0, 1.0), -0.1),
    ]
    for prim in prims:
        row = torch.tensor(prim.row(), dtype=torch.float64, requires_grad=True)
        s = torch.tensor(rng.uniform(-0.4, 0.4, (50, 4)), dtype=torch.float64)
        s[:, 3] = s[:, 3].abs() + 0.01
        s[0, :3] = torch.tensor(prim.row()[:3]) if not isinstance(prim, Plane) else s[0, :3]  # at the centre
        s.requires_grad_(True)
        d = sphere_distance(s, prim.kind, row)
        d.sum().backward()
        assert torch.isfinite(s.grad).all() and torch.isfinite(row.grad).all()
    # Away from the medial axis the gradient is the analytic one (finite differences).
    cyl = prims[2]
    s = torch.tensor([[0.45, 0.2, 0.3, 0.05]], dtype=torch.float64, requires_grad=True)
    row = torch.tensor(cyl.row(), dtype=torch.float64)
    assert torch.autograd.gradcheck(lambda x: sphere_distance(x, "cylinder", row), (s,))


def test_typed_scene_round_trip_and_stacking(tmp_path):
    rng = np.random.default_rng(4)
    prims = [
        Sphere((0.5, 0.0, 0.6), 0.1),
        Box((0.6, 0.3, 0.2), (0.1, 0.1, 0.2), random_rotations(1, rng)[0]),
        Cylinder((0.4, -0.3, 0.3), 0.05, 0.2, random_rotations(1, rng)[0]),
        Plane((0, 0, 1), 0.0),
    ]
    scene = Scene.from_primitives(prims)
    assert (scene.num_spheres, scene.num_boxes, scene.num_cylinders) == (1, 1, 1)
    assert float(scene.floor) == 0.0 and not scene.axis_aligned
    back = scene.primitives()
    for a, b in zip(prims, back, strict=True):
        assert type(a) is type(b) and np.allclose(a.row(), b.row(), atol=1e-15)
    loaded = Scene.load(scene.save(tmp_path / "s.npz"))
    assert torch.equal(loaded.cylinders, scene.cylinders) and torch.equal(loaded.boxes, scene.boxes)
    small = Scene.from_primitives([Cylinder((0, 0, 1), 0.1, 0.1)], floor=0.0)
    st = Scene.stack([scene, small])
    assert st.cylinders.shape == (2, 1, 14) and st.boxes.shape == (2, 1, 15)
    assert st.box_mask.tolist() == [[True], [False]]
    parts = st.unstack()
    assert parts[1].num_boxes == 0 and torch.equal(parts[1].cylinders, small.cylinders)
    # Axis-aligned boxes in the old (B, 6) layout read as identity rotations.
    old = Scene(boxes=[[0.1, 0.2, 0.3, 0.1, 0.2, 0.3]])
    assert old.boxes.shape == (1, 15) and old.axis_aligned


def test_scene_distance_matches_coal_on_mixed_scenes():
    robot = load_robot("iiwa14")
    body = body_spheres(robot).double()
    rng = np.random.default_rng(5)
    R = random_rotations(6, rng)
    prims = [Sphere(rng.uniform([0.3, -0.4, 0.3], [0.8, 0.4, 1.0]), rng.uniform(0.03, 0.1)) for _ in range(2)]
    prims += [
        Box(rng.uniform([0.3, -0.4, 0.3], [0.8, 0.4, 1.0]), rng.uniform(0.03, 0.15, 3), R[i])
        for i in range(3)
    ]
    prims += [
        Cylinder(
            rng.uniform([0.3, -0.4, 0.3], [0.8, 0.4, 1.0]),
            rng.uniform(0.03, 0.1),
            rng.uniform(0.05, 0.2),
            R[3 + i],
        )
        for i in range(3)
    ]
    scene = Scene.from_primitives(prims, floor=0.05)
    q = robot.sample(20, torch.Generator().manual_seed(5), dtype=torch.float64)
    c = body(q)
    _, per = body_obstacle_distance(c, body.radii, scene, per_sphere=True, floor_mask=body.floor_mask)
    floor = Plane((0, 0, 1), 0.05)
    ref = np.empty(per.shape)
    for n in range(c.shape[0]):
        for m in range(c.shape[1]):
            s = [*c[n, m].tolist(), float(body.radii[m])]
            ds = [coal_distance(s, p) for p in prims]
            if bool(body.floor_mask[m]):
                ds.append(coal_distance(s, floor))
            ref[n, m] = min(ds)
    assert np.abs(per.numpy() - ref).max() <= TOL
    assert (ref < 0).any() and (ref > 0).any()


def test_bounding_boxes_reduce_to_the_axis_aligned_layout():
    box = torch.tensor([Box((0, 0, 0), (0.1, 0.2, 0.3)).row()], dtype=torch.float64)
    assert torch.equal(aabb_half_extents(Box, box), box[:, 3:6])
    R = rotation_from_quaternion([0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)])  # 90° about z
    turned = torch.tensor([Box((0, 0, 0), (0.1, 0.2, 0.3), R).row()], dtype=torch.float64)
    assert torch.allclose(
        aabb_half_extents(Box, turned), torch.tensor([[0.2, 0.1, 0.3]], dtype=torch.float64)
    )
    cyl = torch.tensor([Cylinder((0, 0, 0), 0.1, 0.3).row()], dtype=torch.float64)
    assert torch.allclose(
        aabb_half_extents(Cylinder, cyl), torch.tensor([[0.1, 0.1, 0.3]], dtype=torch.float64)
    )


def test_quaternions_round_trip():
    rng = np.random.default_rng(6)
    for R in random_rotations(50, rng):
        assert np.allclose(rotation_from_quaternion(quaternion_from_rotation(R)), R, atol=1e-12)


@pytest.mark.parametrize(
    "make, match",
    [
        (lambda: Box((0, 0, 0), (0.1, 0.0, 0.1)), "half extent"),
        (lambda: Box((0, 0, 0), (0.1, 0.1, 0.1), np.diag([1.0, 1.0, -1.0])), "determinant"),
        (lambda: Cylinder((0, 0, 0), -0.1, 0.1), "radius"),
        (lambda: Sphere((0, np.nan, 0), 0.1), "finite"),
        (lambda: Plane((0, 0, 0), 0.0), "zero"),
        (lambda: Scene(boxes=torch.tensor([[0, 0, 0, 0.1, 0.1, 0.1, *([2.0] * 9)]])), "orthonormal"),
        (lambda: Scene(cylinders=torch.zeros(1, 5)), "shape"),
        (lambda: Scene.from_primitives([Plane((1, 0, 0), 0.0)]), "floor"),
    ],
)
def test_bad_primitives_raise_typed_errors(make, match):
    with pytest.raises(ObstacleError, match=match):
        make()
