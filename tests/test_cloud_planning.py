"""Planning among point clouds: the compiled kernels see a scene's points as its torch twin does, a point on
the arm at the start is refused unless self-filtered, and a plan among a cloud is free of the true obstacle."""

import warnings

import numpy as np
import pytest
import torch

from kinlearn.collision import Scene, body_obstacle_distance, check_path
from kinlearn.collision.cloud_render import surface_points
from kinlearn.errors import CollidingEndWarning, EndContactWarning
from kinlearn.planning.planner import Planner

START = torch.tensor([-1.2, 0.9, 0.5, -1.6, 0.3, 1.2, -2.0], dtype=torch.float64)
GOAL = torch.tensor([1.5, -0.4, -0.8, 1.1, -1.9, -0.6, 2.4], dtype=torch.float64)
BALL = Scene.from_spheres([[0.58, -0.11, 1.03, 0.12]])  # across the straight joint line (the README's)


@pytest.fixture(scope="module")
def planner():
    return Planner.default("iiwa14")


def test_the_kernels_see_the_points_as_torch_does(planner, robot):
    from kinlearn.collision import kernel

    box = torch.tensor([[0.6, 0.0, 0.3, 0.05, 0.05, 0.05]])
    scene = Scene.from_points(surface_points(BALL, noise=0.0), primitives=Scene(boxes=box), floor=0.0)
    body = planner.body.double()
    q = robot.sample(50, torch.Generator().manual_seed(3), dtype=torch.float64)
    kb, ks = kernel.KernelBody.of(body), kernel.KernelScene.of(scene)
    d, _, per = kernel.clearances(kb, ks, q.numpy(), per_sphere=True)
    ref_d, ref_per = body_obstacle_distance(
        body(q), body.radii, scene, per_sphere=True, floor_mask=body.floor_mask
    )
    np.testing.assert_allclose(per, ref_per.numpy(), rtol=0, atol=1e-12)
    np.testing.assert_allclose(d, ref_d.numpy(), rtol=0, atol=1e-12)
    points = np.random.default_rng(0).random((500, 3)) * 1.5 - 0.5
    np.testing.assert_allclose(
        kernel.point_distances(ks, points),
        np.minimum(kernel.point_distances(kernel.KernelScene.of(Scene(boxes=box, floor=0.0)), points),
                   scene.cloud.distance(points, np.zeros(len(points)))),
        rtol=0, atol=1e-12,
    )  # fmt: skip


def test_a_point_on_the_arm_at_the_start_is_refused_unless_filtered(planner):
    body = planner.body.double()
    centres = body(START[None])[0].numpy()
    wall = np.array([[-0.6, y, z] for y in np.arange(-0.7, -0.5, 0.02) for z in np.arange(0.0, 0.2, 0.02)])
    on_arm = centres[-1]  # the centre of the hand's last sphere
    points = np.vstack([wall, on_arm])
    with pytest.warns(CollidingEndWarning, match="start"):
        refused = planner.plan(START, GOAL, obstacles=Scene.from_points(points), refine_steps=0)
    assert not bool(refused.collision_free) and not bool(refused.success)
    filtered = Scene.from_points(points, self_filter=(planner, START.numpy()))
    assert filtered.cloud.num_points == len(wall)
    with warnings.catch_warnings():
        warnings.simplefilter("error", CollidingEndWarning)
        plan = planner.plan(START, GOAL, obstacles=filtered, refine_steps=0)
    assert bool(plan.collision_free) and bool(plan.success)


def test_a_plan_among_a_cloud_is_free_of_the_true_obstacle(planner):
    cloud = Scene.from_points(surface_points(BALL, spacing=0.01, noise=0.002))
    line = check_path(planner.body.double(), torch.stack((START, GOAL)), cloud)
    assert not bool(line.collision_free)  # the straight joint line crosses the points
    plan = planner.plan(START, GOAL, obstacles=cloud)
    assert bool(plan.collision_free) and bool(plan.success)
    joints = torch.as_tensor(plan.joints).double()
    assert bool(check_path(planner.body.double(), joints, cloud).collision_free)  # torch's twin agrees
    assert bool(check_path(planner.body.double(), joints, BALL).collision_free)  # and the true ball


def test_plan_points_on_the_command_line(tmp_path):
    from kinlearn.cli.main import main

    np.save(tmp_path / "ball.npy", surface_points(BALL, noise=0.0))
    joints = lambda q: ",".join(f"{v:.4f}" for v in q.tolist())  # noqa: E731
    code = main(
        ["plan", "--start", joints(START), "--goal", joints(GOAL), "--points", str(tmp_path / "ball.npy")]
    )
    assert code == 0
    bad = ["plan", "--start", joints(START), "--goal", joints(GOAL), "--camera-pose", "0,0,0,0,0,0,1"]
    assert main(bad) == 2  # a camera pose without points
    # a point on the arm's body at the goal: the goal collides, unless vouched for
    planner = Planner.default("iiwa14")
    with torch.no_grad():
        hand = planner.body(GOAL[None].to(planner.body.radii))[0, -1].numpy()
    np.save(tmp_path / "held.npy", np.vstack([surface_points(BALL, noise=0.0), hand]))
    held = ["plan", "--start", joints(START), "--goal", joints(GOAL), "--points", str(tmp_path / "held.npy")]
    with pytest.warns(CollidingEndWarning, match="goal"):
        assert main([*held, "--refine-steps", "0"]) == 1
    assert main([*held, "--vouch-goal"]) == 0
    assert main([*held[:3], "--goal-position", "0.5,0,0.5", *held[5:], "--vouch-goal"]) == 2
    # a point 8 mm off the hand at the goal: its ball touches the arm, no point lies inside it; taken as
    # the surface the goal touches by default, refused with --contact 0
    r = float(planner.body.radii[-1])
    near_hand = hand + np.array([0.0, 0.0, r + 0.008])
    np.save(tmp_path / "near.npy", np.vstack([surface_points(BALL, noise=0.0), near_hand]))
    near = [*held[:5], "--points", str(tmp_path / "near.npy")]
    with pytest.warns(EndContactWarning, match="goal"):
        assert main(near) == 0
    with pytest.warns(CollidingEndWarning, match="goal"):
        assert main([*near, "--contact", "0", "--refine-steps", "0"]) == 1
    assert main([*held[:5], "--contact", "0.01"]) == 2  # a contact depth without points
    # two clouds fused: the ball's and the point on the hand, each given in its own camera's frame
    T = np.eye(4)
    T[:3, 3] = (0.1, -0.2, 0.3)
    np.save(tmp_path / "hand.npy", hand[None] - T[:3, 3])
    pose = ",".join(map(str, (*T[:3, 3], 0, 0, 0, 1)))
    ball_pose, two = "0,0,0,0,0,0,1", [*held[:5], "--points", str(tmp_path / "ball.npy")]
    two += ["--points", str(tmp_path / "hand.npy"), "--camera-pose", ball_pose, "--camera-pose", pose]
    with pytest.warns(CollidingEndWarning, match="goal"):  # the hand's point, moved back onto the hand
        assert main([*two, "--refine-steps", "0"]) == 1
    assert main([*two, "--vouch-goal"]) == 0
    assert main([*two[:-2]]) == 2  # one pose for two clouds
    with pytest.raises(SystemExit) as refused:  # a negative one: argparse's usage error
        main([*near, "--contact", "-0.01"])
    assert refused.value.code == 2
