"""Signed distances cross-checked against coal (the collision library shipped with pin) on the same
geometry, their gradients, masks and batching."""

import coal
import numpy as np
import pytest
import torch

from kinlearn.collision import (
    Scene,
    body_obstacle_distance,
    body_spheres,
    self_collision_distance,
    sphere_box_distance,
    sphere_plane_distance,
    sphere_sphere_distance,
)

TOL = 1e-3  # metres: the agreement asked of the torch distances (they agree far closer)


def _tf(p) -> coal.Transform3s:
    t = coal.Transform3s()
    t.setTranslation(np.asarray(p, dtype=float))
    return t


def _coal_distance(g1, p1, g2, p2) -> float:
    return coal.distance(g1, _tf(p1), g2, _tf(p2), coal.DistanceRequest(), coal.DistanceResult())


def _random_spheres(n, gen, spread=0.4, rmin=0.02, rmax=0.15):
    c = (torch.rand(n, 3, generator=gen, dtype=torch.float64) - 0.5) * 2 * spread
    r = rmin + (rmax - rmin) * torch.rand(n, 1, generator=gen, dtype=torch.float64)
    return torch.cat([c, r], dim=1)


def _random_boxes(n, gen, spread=0.4, hmax=0.27):
    c = (torch.rand(n, 3, generator=gen, dtype=torch.float64) - 0.5) * 2 * spread
    h = 0.02 + (hmax - 0.02) * torch.rand(n, 3, generator=gen, dtype=torch.float64)
    return torch.cat([c, h], dim=1)


def test_sphere_sphere_matches_coal():
    gen = torch.Generator().manual_seed(0)
    a, b = _random_spheres(300, gen), _random_spheres(300, gen)
    d = sphere_sphere_distance(a, b)
    ref = [
        _coal_distance(coal.Sphere(float(x[3])), x[:3], coal.Sphere(float(y[3])), y[:3])
        for x, y in zip(a, b, strict=True)
    ]
    ref = torch.tensor(ref, dtype=torch.float64)
    assert bool((d < 0).any() and (d > 0).any())  # both sides of contact were drawn
    assert float((d - ref).abs().max()) <= TOL
    assert float((d - ref).abs().max()) <= 1e-9


def test_sphere_box_matches_coal_inside_and_outside():
    gen = torch.Generator().manual_seed(1)
    s, box = _random_spheres(400, gen), _random_boxes(400, gen)
    s[:50, :3] = (
        box[:50, :3] + (torch.rand(50, 3, generator=gen, dtype=torch.float64) - 0.5) * box[:50, 3:]
    )  # centre inside
    d = sphere_box_distance(s, box)
    ref = torch.tensor(
        [
            _coal_distance(coal.Sphere(float(x[3])), x[:3], coal.Box(*(2 * y[3:]).tolist()), y[:3])
            for x, y in zip(s, box, strict=True)
        ],
        dtype=torch.float64,
    )
    assert bool((d[:50] < 0).all()) and bool((d > 0).any())
    assert float((d - ref).abs().max()) <= TOL
    # Known answers: centre of a 0.4 × 0.2 × 0.2 box, sphere r = 0.1 → −(0.1 + 0.1); 0.3 m out along x → 0.
    box1 = torch.tensor([0.0, 0.0, 0.0, 0.2, 0.1, 0.1], dtype=torch.float64)
    assert float(
        sphere_box_distance(torch.tensor([0.0, 0.0, 0.0, 0.1], dtype=torch.float64), box1)
    ) == pytest.approx(-0.2)
    assert float(
        sphere_box_distance(torch.tensor([0.5, 0.0, 0.0, 0.1], dtype=torch.float64), box1)
    ) == pytest.approx(0.2)
    corner = torch.tensor([0.2 + 0.3, 0.1 + 0.4, 0.0, 0.05], dtype=torch.float64)
    assert float(sphere_box_distance(corner, box1)) == pytest.approx(0.5 - 0.05)


def test_sphere_plane_matches_coal_halfspace():
    gen = torch.Generator().manual_seed(2)
    s = _random_spheres(200, gen)
    h = 0.05
    d = sphere_plane_distance(s, h)
    floor = coal.Halfspace(np.array([0.0, 0.0, 1.0]), h)  # solid where z <= h
    ref = torch.tensor(
        [_coal_distance(coal.Sphere(float(x[3])), x[:3], floor, [0, 0, 0]) for x in s], dtype=torch.float64
    )
    assert bool((d < 0).any() and (d > 0).any())
    assert float((d - ref).abs().max()) <= TOL


def _coal_scene(scene: Scene):
    shapes = [(coal.Sphere(float(s[3])), s[:3].tolist()) for s in scene.spheres]
    shapes += [(coal.Box(*(2 * b[3:6]).tolist()), b[:3].tolist()) for b in scene.boxes]
    return shapes


def test_body_scene_distance_matches_coal(robot):
    """Random configurations and obstacles; every body sphere against every obstacle and the floor."""
    body = body_spheres(robot).double()
    gen = torch.Generator().manual_seed(4)
    q = robot.sample(30, gen, dtype=torch.float64)
    sp = _random_spheres(4, gen, spread=0.3, rmax=0.1) + torch.tensor(
        [0.55, 0.0, 0.7, 0.0], dtype=torch.float64
    )
    bx = _random_boxes(4, gen, spread=0.3, hmax=0.1) + torch.tensor(
        [0.55, 0.0, 0.6, 0.0, 0.0, 0.0], dtype=torch.float64
    )
    scene = Scene(sp, bx, floor=0.1)
    c = body(q)
    d, per = body_obstacle_distance(c, body.radii, scene, per_sphere=True, floor_mask=body.floor_mask)
    assert d.shape == (30,) and per.shape == (30, body.num_spheres)
    floor = coal.Halfspace(np.array([0.0, 0.0, 1.0]), 0.1)
    ref = np.empty((30, body.num_spheres))
    for n in range(30):
        for m in range(body.num_spheres):
            me = coal.Sphere(float(body.radii[m]))
            ds = [_coal_distance(me, c[n, m].tolist(), g, p) for g, p in _coal_scene(scene)]
            if bool(body.floor_mask[m]):
                ds.append(_coal_distance(me, c[n, m].tolist(), floor, [0, 0, 0]))
            ref[n, m] = min(ds)
    assert bool((d < 0).any() and (d > 0).any())
    assert np.abs(per.numpy() - ref).max() <= TOL
    assert np.abs(d.numpy() - ref.min(1)).max() <= TOL


def test_self_collision_matches_coal(robot):
    body = body_spheres(robot, dense=True).double()
    gen = torch.Generator().manual_seed(6)
    q = robot.sample(4000, gen, dtype=torch.float64)
    d = self_collision_distance(body(q), body.radii, body.pairs)
    # Some colliding and some free configurations, checked pair by pair with coal.
    pick = torch.cat([torch.nonzero(d < 0).flatten()[:5], torch.nonzero(d > 0).flatten()[:5]])
    assert len(pick) == 10
    c = body(q[pick])
    d2, per = self_collision_distance(c, body.radii, body.pairs, per_pair=True)
    assert per.shape == (10, len(body.pairs))
    r = body.radii
    for n in range(10):
        ref = [
            _coal_distance(
                coal.Sphere(float(r[i])), c[n, i].tolist(), coal.Sphere(float(r[j])), c[n, j].tolist()
            )
            for i, j in body.pairs.tolist()
        ]
        assert np.abs(per[n].numpy() - np.array(ref)).max() <= TOL
    assert bool((d2[:5] < 0).all() and (d2[5:] > 0).all())


def test_gradients_float64():
    gen = torch.Generator().manual_seed(7)
    s = _random_spheres(6, gen).requires_grad_(True)
    o = _random_spheres(6, gen).requires_grad_(True)
    box = _random_boxes(6, gen).requires_grad_(True)
    assert torch.autograd.gradcheck(sphere_sphere_distance, (s, o))
    assert torch.autograd.gradcheck(sphere_box_distance, (s, box))
    assert torch.autograd.gradcheck(lambda x: sphere_plane_distance(x, 0.1), (s,))


def test_body_distance_gradient_through_the_joints(robot):
    body = body_spheres(robot).double()
    gen = torch.Generator().manual_seed(8)
    scene = Scene(
        _random_spheres(3, gen) + torch.tensor([0.4, 0, 0.6, 0], dtype=torch.float64),
        _random_boxes(2, gen) + torch.tensor([0.4, 0, 0.5, 0, 0, 0], dtype=torch.float64),
        floor=0.0,
    )
    q = robot.sample(3, gen, dtype=torch.float64).requires_grad_(True)

    def f(x):
        c = body(x)
        _, per = body_obstacle_distance(c, body.radii, scene, per_sphere=True, floor_mask=body.floor_mask)
        return per, self_collision_distance(c, body.radii, body.pairs, per_pair=True)[1]

    assert torch.autograd.gradcheck(f, (q,))
    # Obstacles are differentiable too (e.g. to learn or adapt a scene).
    sp = scene.spheres.clone().requires_grad_(True)
    d = body_obstacle_distance(body(q.detach()), body.radii, Scene(sp, scene.boxes)).sum()
    d.backward()
    assert torch.isfinite(sp.grad).all() and sp.grad.abs().sum() > 0


def test_gradient_finite_inside_a_box(robot):
    """A centre inside a box (where the outside term is 0) still has a finite, useful gradient."""
    s = torch.tensor([[0.01, 0.02, 0.0, 0.05]], dtype=torch.float64, requires_grad=True)
    box = torch.tensor([[0.0, 0.0, 0.0, 0.2, 0.2, 0.2]], dtype=torch.float64)
    sphere_box_distance(s, box).sum().backward()
    # Nearest face: +y (q = |p − c| − h is largest along y); moving along +y reduces the depth.
    assert torch.equal(s.grad, torch.tensor([[0.0, 1.0, 0.0, -1.0]], dtype=torch.float64))
    body = body_spheres(robot).double()
    q = torch.zeros(7, dtype=torch.float64, requires_grad=True)
    c = body(q)
    on_top = torch.cat([c[10].detach(), torch.tensor([0.05], dtype=torch.float64)]).unsqueeze(
        0
    )  # same centre
    d = body_obstacle_distance(c, body.radii, Scene.from_spheres(on_top))
    assert float(d.detach()) == pytest.approx(-0.05 - float(body.radii[10]))
    d.backward()
    assert torch.isfinite(q.grad).all()


def test_masks_empty_scenes_and_batching(robot):
    body = body_spheres(robot)
    q = robot.sample((5,), torch.Generator().manual_seed(9))
    c = body(q)
    near = torch.tensor([[0.0, 0.0, 0.5, 0.1]])
    far = torch.tensor([[5.0, 5.0, 5.0, 0.1]])
    # An empty scene is +inf; a masked obstacle is ignored.
    assert torch.isinf(body_obstacle_distance(c, body.radii, Scene())).all()
    both = Scene(torch.cat([near, far]), sphere_mask=torch.tensor([False, True]))
    assert torch.allclose(
        body_obstacle_distance(c, body.radii, both), body_obstacle_distance(c, body.radii, Scene(far))
    )
    # One scene per configuration broadcasts like torch: (5,) scenes against (5,) configurations.
    per_cfg = Scene(torch.stack([near if i % 2 else far for i in range(5)]))
    d = body_obstacle_distance(c, body.radii, per_cfg)
    assert torch.allclose(d[1::2], body_obstacle_distance(c[1::2], body.radii, Scene(near)))
    assert torch.allclose(d[0::2], body_obstacle_distance(c[0::2], body.radii, Scene(far)))
    # Large batches go through the chunked path and agree with small ones.
    qq = robot.sample(10_000, torch.Generator().manual_seed(10))
    cc = body(qq)
    scene = Scene(near, torch.tensor([[0.5, 0.0, 0.3, 0.1, 0.2, 0.3]]), floor=0.0)
    big = body_obstacle_distance(cc, body.radii, scene, floor_mask=body.floor_mask)
    small = torch.cat(
        [body_obstacle_distance(x, body.radii, scene, floor_mask=body.floor_mask) for x in cc.split(1000)]
    )
    assert torch.equal(big, small)
    assert torch.equal(
        self_collision_distance(cc, body.radii, body.pairs),
        torch.cat([self_collision_distance(x, body.radii, body.pairs) for x in cc.split(1000)]),
    )
    assert torch.isinf(self_collision_distance(c, body.radii, body.pairs[:0])).all()
