"""Forward kinematics and Jacobians: three backends against each other and against known answers."""

import math

import pytest
import torch
from conftest import ALL_ROBOTS

from kinlearn import NonFiniteError, ShapeError, kinematics, load_robot
from kinlearn.body import dls_step
from kinlearn.body.kinematics import FastKinematics, PkKinematics
from kinlearn.errors import ConfigError


@pytest.fixture(scope="module", params=ALL_ROBOTS)
def robot(request):
    return load_robot(request.param)


@pytest.fixture(scope="module")
def q1000(robot):
    return robot.sample(1000, torch.Generator().manual_seed(7), dtype=torch.float64)


def test_three_backends_agree_float64(robot, q1000):
    ref = kinematics(robot, "pinocchio").position(q1000)
    fast = kinematics(robot, "fast").position(q1000)
    pk = kinematics(robot, "pk").position(q1000)
    assert fast.dtype == pk.dtype == torch.float64
    assert (fast - ref).abs().max() <= 1e-12
    assert (pk - ref).abs().max() <= 1e-12


def test_poses_agree(robot, q1000):
    q = q1000[:100]
    ref = kinematics(robot, "pinocchio").pose(q)
    assert (kinematics(robot, "fast").pose(q) - ref).abs().max() <= 1e-12
    assert (kinematics(robot, "pk").pose(q) - ref).abs().max() <= 1e-12
    R = ref[:, :3, :3]
    assert torch.allclose(
        R @ R.transpose(1, 2), torch.eye(3, dtype=torch.float64).expand(100, 3, 3), atol=1e-12
    )


def test_pk_float64_is_exact_not_float32_rounded(robot, q1000):
    """pytorch-kinematics alone keeps float32-rounded constants; ours must not (pytorch-kinematics 0.10 parses URDF origins in float32)."""
    err = (
        (kinematics(robot, "pk").position(q1000) - kinematics(robot, "pinocchio").position(q1000)).abs().max()
    )
    assert err < 1e-13


def test_iiwa14_zero_configuration():
    robot = load_robot("iiwa14")
    for backend in ("fast", "pk", "pinocchio"):
        p = kinematics(robot, backend).position(torch.zeros(7, dtype=torch.float64))
        assert torch.allclose(p, torch.tensor([0.0, 0.0, 1.306], dtype=torch.float64), atol=1e-12), backend


def test_iiwa14_known_configuration():
    """Joint 2 at +90° lays the arm along the base x or y axis: the shoulder stays at 0.36 m height."""
    robot = load_robot("iiwa14")
    q = torch.zeros(7, dtype=torch.float64)
    q[1] = math.pi / 2
    p = kinematics(robot, "fast").position(q)
    assert abs(float(p[2]) - 0.36) < 1e-12
    assert abs(float(torch.linalg.norm(p[:2])) - (1.306 - 0.36)) < 1e-12


def test_float32_close_to_float64(robot, q1000):
    fast = kinematics(robot, "fast")
    p64 = fast.position(q1000)
    p32 = fast.position(q1000.float())
    assert p32.dtype == torch.float32
    assert (p32.double() - p64).abs().max() <= 1e-5
    pk32 = kinematics(robot, "pk").position(q1000.float())
    assert (pk32.double() - p64).abs().max() <= 1e-5


def test_jacobian_matches_pinocchio_autograd_and_finite_differences(robot, q1000):
    q = q1000[:50]
    fast = kinematics(robot, "fast")
    J = fast.jacobian(q)
    assert J.shape == (50, 3, robot.dof)
    J_pin = kinematics(robot, "pinocchio").jacobian(q)
    assert (J - J_pin).abs().max() <= 1e-12
    J_pk = kinematics(robot, "pk").jacobian(q)
    assert (J_pk - J_pin).abs().max() <= 1e-12
    # autograd through the fast position path
    J_auto = torch.func.vmap(torch.func.jacrev(lambda x: fast.position(x, validate=False)))(q)
    assert (J_auto - J_pin).abs().max() <= 1e-12
    # central finite differences
    h = 1e-6
    eye = torch.eye(robot.dof, dtype=torch.float64)
    cols = [
        (fast.position(q + h * eye[j]) - fast.position(q - h * eye[j])) / (2 * h) for j in range(robot.dof)
    ]
    J_fd = torch.stack(cols, dim=-1)
    assert (J_fd - J_pin).abs().max() <= 1e-8


def test_batched_equals_per_sample(robot, q1000):
    fast = kinematics(robot, "fast")
    q = q1000[:20]
    batched = fast.position(q)
    single = torch.stack([fast.position(qi) for qi in q])
    assert torch.equal(batched, single) or (batched - single).abs().max() <= 1e-15
    # arbitrary leading dimensions
    q3 = q1000[:24].reshape(2, 3, 4, robot.dof)
    assert fast.position(q3).shape == (2, 3, 4, 3)
    assert fast.jacobian(q3).shape == (2, 3, 4, 3, robot.dof)
    assert fast.pose(q3).shape == (2, 3, 4, 4, 4)
    assert torch.allclose(fast.position(q3).reshape(-1, 3), fast.position(q1000[:24]), atol=0)


def test_chunked_large_batch_equals_unchunked():
    robot = load_robot("iiwa14")
    fast = kinematics(robot, "fast")
    q = robot.sample(FastKinematics.chunk + 123, torch.Generator().manual_seed(3), dtype=torch.float64)
    assert torch.equal(fast.position(q), torch.cat([fast._position_chunk(q[:1000]), fast.position(q[1000:])]))


def test_gradcheck_float64(robot):
    q = robot.sample(3, torch.Generator().manual_seed(1), dtype=torch.float64).requires_grad_(True)
    fast = kinematics(robot, "fast")
    assert torch.autograd.gradcheck(lambda x: fast.position(x), (q,))
    assert torch.autograd.gradcheck(lambda x: fast.jacobian(x), (q,))


def test_device_and_dtype_follow_input():
    robot = load_robot("iiwa14")
    q = torch.zeros(2, 7, dtype=torch.float32)
    for backend in ("fast", "pk", "pinocchio"):
        out = kinematics(robot, backend).position(q)
        assert out.dtype == torch.float32 and out.device == q.device


def test_dls_step_reaches_nearby_target(gen):
    robot = load_robot("iiwa14")
    kin = kinematics(robot)
    q = robot.sample(64, gen, dtype=torch.float64, margin=0.3)
    # Reachable by construction: the end effector of a nearby configuration (≈1 cm away).
    target = kin.position(q + 0.01 * torch.randn(64, 7, generator=gen, dtype=torch.float64))
    assert (target - kin.position(q)).norm(dim=-1).median() > 5e-3
    q2 = dls_step(kin, q, target, iterations=5, damping=1e-3)
    assert (kin.position(q2) - target).norm(dim=-1).max() < 1e-4
    lo, hi = robot.limits(torch.float64)
    assert bool(((q2 >= lo) & (q2 <= hi)).all())


@pytest.mark.parametrize("backend", ["fast", "pk", "pinocchio"])
def test_bad_input_raises_typed_errors(backend):
    kin = kinematics(load_robot("iiwa14"), backend)
    with pytest.raises(ShapeError, match=r"\(\.\.\., 7\)"):
        kin.position(torch.zeros(6))
    with pytest.raises(ShapeError, match=r"torch\.Tensor"):
        kin.position([0.0] * 7)
    with pytest.raises(ShapeError, match="floating-point"):
        kin.position(torch.zeros(7, dtype=torch.long))
    bad = torch.zeros(3, 7)
    bad[1, 2] = float("nan")
    with pytest.raises(NonFiniteError, match="finite"):
        kin.jacobian(bad)
    bad[1, 2] = float("inf")
    with pytest.raises(NonFiniteError):
        kin.pose(bad)


def test_unknown_backend():
    with pytest.raises(ConfigError, match="fast, pk, pinocchio"):
        kinematics(load_robot("iiwa14"), "mujoco")


def test_pk_backend_is_pytorch_kinematics():
    kin = kinematics(load_robot("panda"), "pk")
    assert isinstance(kin, PkKinematics)
    import pytorch_kinematics as pk

    assert isinstance(kin._chain(torch.float64, torch.device("cpu")), pk.SerialChain)


def test_kinematics_cache_never_serves_another_robot():
    """Robots built one after another (ids may be reused once one is freed) get their own kinematics."""
    from kinlearn.body.kinematics import kinematics as kin_of

    seen = []
    for name in ("iiwa14", "panda", "ur5", "iiwa14"):
        robot = load_robot(name)
        robot = type(robot)(robot.name, robot.urdf, robot.ee_frame)  # a fresh object each time
        k = kin_of(robot)
        assert k.robot is robot
        seen.append(float(k.position(torch.zeros(robot.dof, dtype=torch.float64))[2]))
    assert seen[0] == seen[3] and seen[0] != seen[1]


@pytest.mark.parametrize("name", ALL_ROBOTS)
def test_approach_axis_is_the_last_joints_and_pointing_steps_reach_a_pose(name):
    """The approach axis is the last joint's (in the base frame, by the position Jacobian: turning
    the last joint does not move a point on that axis), pointing toward the end effector; pointing
    steps from random joints reach reachable targets with the axis turned onto a given direction
    (most of them, as position IK from random joints does), within the limits, its columns the
    Jacobian's."""
    import numpy as np

    from kinlearn.body.kinematics import approach_axis, pointing_dls_step

    robot = load_robot(name)
    kin = kinematics(robot, "fast")
    a = approach_axis(robot)
    assert abs(np.linalg.norm(a) - 1.0) < 1e-12
    g = torch.Generator().manual_seed(0)
    q = robot.sample(64, g, dtype=torch.float64, margin=0.1)
    T, J, W = kin.pose_and_axes(q)
    torch.testing.assert_close(J, kin.jacobian(q))
    world = T[:, :3, :3] @ torch.as_tensor(a)
    torch.testing.assert_close(world, W[..., -1])  # the last joint's axis, its sign toward the tip
    d = world
    targets = T[:, :3, 3]
    q0 = robot.sample(64, g, dtype=torch.float64, margin=0.05)
    q1 = pointing_dls_step(kin, dls_step(kin, q0, targets, iterations=60, damping=0.02), targets, d, 60, 0.02)
    lo, hi = robot.limits(torch.float64)
    assert bool(((q1 >= lo) & (q1 <= hi)).all())
    T1 = kin.pose(q1)
    reached = (T1[:, :3, 3] - targets).norm(dim=-1) < 1e-3
    pointed = ((T1[:, :3, :3] @ torch.as_tensor(a)) * d).sum(-1) > math.cos(math.radians(1.0))
    assert float((reached & pointed).double().mean()) >= 0.4
