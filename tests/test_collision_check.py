"""Collision checks of configurations and dense checks of joint paths: known answers, the 1 cm travel
guarantee, collisions that endpoint checks miss, self-collision and bad inputs."""

import pytest
import torch

from kinlearn.collision import Scene, check_path, clearances, in_collision, segment_steps
from kinlearn.errors import ConfigError, NonFiniteError, ShapeError


def _bent(theta1: float) -> torch.Tensor:
    return torch.tensor([theta1, 0.8, 0.0, -1.0, 0.0, 0.8, 0.0], dtype=torch.float64)


def test_obstacle_on_a_link_sphere_collides_and_far_away_does_not(body):
    q = _bent(0.3)
    c = body(q)
    for m in (7, 12, body.num_spheres - 1):  # an upper-arm, a forearm and the wrist sphere
        on = Scene.from_spheres(torch.cat([c[m], torch.tensor([0.02], dtype=torch.float64)]).unsqueeze(0))
        assert bool(in_collision(body, q, on))
    far = Scene.from_spheres(torch.tensor([[3.0, 3.0, 3.0, 0.2]], dtype=torch.float64))
    assert not bool(in_collision(body, q, far))
    d, s = clearances(body, q, far)
    assert float(d) > 2.0 and float(s) > 0.0
    # A box just touching the wrist sphere from below: the contact counts as a collision.
    w = c[-1]
    r = float(body.radii[-1])
    box = torch.tensor(
        [[float(w[0]), float(w[1]), float(w[2]) - r - 0.1, 0.1, 0.1, 0.1]], dtype=torch.float64
    )
    assert bool(in_collision(body, q, Scene(boxes=box)))
    assert not bool(in_collision(body, q, Scene(boxes=box - torch.tensor([0, 0, 0.001, 0, 0, 0]))))


def test_floor_ignores_the_base_but_not_the_arm(body):
    up = torch.zeros(7, dtype=torch.float64)
    assert not bool(in_collision(body, up, Scene(floor=0.0)))  # base spheres reach below z = 0
    down = torch.tensor([0.0, 1.9, 0.0, 0.3, 0.0, 1.5, 0.0], dtype=torch.float64)  # reaching down
    arm = body.link > 0
    lowest = float((body(down)[arm, 2] - body.radii[arm]).min())  # 0.080 m
    assert bool(in_collision(body, down, Scene(floor=lowest + 1e-3)))
    assert not bool(in_collision(body, down, Scene(floor=lowest - 1e-3)))


def test_dense_check_catches_what_endpoint_checks_miss(body):
    mid = body(_bent(0.0))[-1]  # where the wrist passes half way
    scene = Scene.from_spheres(torch.cat([mid, torch.tensor([0.04], dtype=torch.float64)]).unsqueeze(0))
    path = torch.stack([_bent(-1.0), _bent(1.0)])
    assert not bool(in_collision(body, path, scene).any())  # both endpoints are free
    res = check_path(body, path, scene)
    assert not bool(res.collision_free) and int(res.first_collision) == 0
    assert float(res.clearance) < 0 and int(res.checked) > 50
    # The same obstacle moved out of the way: free, and the clearance is positive.
    away = Scene.from_spheres(torch.tensor([[-0.8, 0.0, 0.4, 0.05]], dtype=torch.float64))
    ok = check_path(body, path, away)
    assert bool(ok.collision_free) and int(ok.first_collision) == -1 and float(ok.clearance) > 0


def test_first_collision_is_the_segment_index(body):
    mid = body(_bent(0.0))[-1]
    scene = Scene.from_spheres(torch.cat([mid, torch.tensor([0.04], dtype=torch.float64)]).unsqueeze(0))
    path = torch.stack([_bent(-2.0), _bent(-1.5), _bent(-1.0), _bent(1.0), _bent(1.5)])
    res = check_path(body, path, scene)
    assert int(res.first_collision) == 2
    assert int(check_path(body, path.flip(0), scene).first_collision) == 1
    # A collision at the last waypoint only reports index T.
    end = torch.stack([_bent(-1.0), _bent(0.0)])
    assert int(check_path(body, end, scene).first_collision) == 0  # reached during the segment already
    single = check_path(body, _bent(0.0).unsqueeze(0), scene)
    assert int(single.first_collision) == 0 and int(single.checked) == 1


def test_sub_steps_keep_every_sphere_within_one_centimetre(robot, body):
    gen = torch.Generator().manual_seed(2)
    a, b = robot.sample(40, gen, dtype=torch.float64), robot.sample(40, gen, dtype=torch.float64)
    path = torch.stack([a, b], dim=1)
    n = segment_steps(body, path, 0.01)[:, 0]
    worst = 0.0
    for i in range(40):
        s = torch.linspace(0, 1, int(n[i]) + 1, dtype=torch.float64).unsqueeze(-1)
        c = body(a[i] + s * (b[i] - a[i]))
        worst = max(worst, float((c[1:] - c[:-1]).norm(dim=-1).max()))
    assert worst <= 0.01
    assert worst > 0.003  # the bound is not absurdly conservative
    res = check_path(body, path, Scene())
    assert torch.equal(res.checked, n + 1)


def test_self_collision_is_found_along_a_path(robot, body):
    q = robot.sample(5000, torch.Generator().manual_seed(3), dtype=torch.float64)
    _, s = clearances(body, q, Scene())
    bad = q[s < 0][0]
    free = q[s > 0.05][0]
    res = check_path(body, torch.stack([free, bad]), Scene())
    assert bool(res.self_collision) and not bool(res.collision_free) and float(res.self_clearance) < 0
    assert torch.isinf(res.clearance)  # nothing in the scene
    assert bool(in_collision(body, bad, Scene()))


def test_batched_paths_and_scenes(body):
    mid = body(_bent(0.0))[-1]
    hit = torch.cat([mid, torch.tensor([0.04], dtype=torch.float64)]).unsqueeze(0)
    miss = torch.tensor([[-0.8, 0.0, 0.4, 0.05]], dtype=torch.float64)
    scenes = Scene(torch.stack([hit, miss, hit]))
    path = torch.stack([_bent(-1.0), _bent(1.0)]).expand(3, 2, 7)
    res = check_path(body, path, scenes)
    assert res.collision_free.tolist() == [False, True, False]
    # Paths of batch (2, 3) against one scene per row of the first dimension: unsqueeze the scene.
    path2 = path.unsqueeze(0).expand(2, 3, 2, 7)
    two = Scene(torch.stack([hit, miss]))
    res2 = check_path(body, path2, two.unsqueeze(-1))
    assert res2.collision_free.tolist() == [[False] * 3, [True] * 3]
    with pytest.raises(ShapeError, match="broadcast"):
        check_path(body, path, two)
    with pytest.raises(ShapeError, match="enlarge"):
        check_path(body, path[0], scenes)


def test_margin_and_bad_inputs(body):
    path = torch.stack([_bent(-1.0), _bent(1.0)])
    scene = Scene(floor=0.0)
    clear = float(check_path(body, path, scene).clearance)
    assert clear > 0
    assert bool(check_path(body, path, scene, margin=clear - 1e-4).collision_free)
    assert not bool(check_path(body, path, scene, margin=clear + 1e-4).collision_free)
    with pytest.raises(ConfigError, match="max_travel"):
        check_path(body, path, scene, max_travel=0.0)
    with pytest.raises(ShapeError):
        check_path(body, path[:, :6], scene)
    with pytest.raises(ShapeError):
        check_path(body, path[0], scene)
    with pytest.raises(NonFiniteError):
        check_path(body, path * float("nan"), scene)


def test_in_collision_agrees_with_single_configuration_checks(robot, body):
    q = robot.sample(300, torch.Generator().manual_seed(4), dtype=torch.float64)
    scene = Scene(
        torch.tensor([[0.5, 0.0, 0.6, 0.15], [0.0, 0.5, 0.4, 0.1]], dtype=torch.float64),
        torch.tensor([[0.5, -0.4, 0.2, 0.2, 0.1, 0.2]], dtype=torch.float64),
        floor=0.0,
    )
    flags = in_collision(body, q, scene)
    res = check_path(body, q.unsqueeze(-2), scene)
    assert torch.equal(~res.collision_free, flags)
    assert 0.1 < float(flags.double().mean()) < 0.9
