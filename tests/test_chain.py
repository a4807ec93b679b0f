"""The chain FM (kinlearn.models.chain): exact against the analytic robots, its Jacobians against
autograd and the fast kinematics, the URDF export through Pinocchio and pytorch-kinematics, the
position solver (compiled against torch, batch-independent, within the limits, a move of zero),
the IM through the FM, checkpoints."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from conftest import ALL_ROBOTS

from kinlearn.body.kinematics import kinematics
from kinlearn.body.robot import load_robot
from kinlearn.errors import CheckpointError, ConfigError
from kinlearn.models.chain import (
    ChainConfig,
    ChainFM,
    ThroughFMIM,
    chain_parameter_jacobian,
    chain_position,
    chain_urdf,
    solve_position,
)
from kinlearn.models.forward_inverse import AnalyticFM, load_fm, save_model


def _within(robot, n, gen, frac=0.9):
    lo, hi = robot.limits(torch.float64)
    mid, half = (lo + hi) / 2, (hi - lo) / 2 * frac
    return mid + half * (2 * torch.rand(n, robot.dof, generator=gen, dtype=torch.float64) - 1)


@pytest.mark.parametrize("name", ALL_ROBOTS)
def test_chain_of_a_urdf_is_its_kinematics(name, gen):
    robot = load_robot(name)
    q = robot.sample(300, gen, dtype=torch.float64)
    ref = robot.sample(1, gen, dtype=torch.float64)[0].numpy()
    chain = ChainFM.from_robot(robot, reference=ref)
    fk = kinematics(robot, "fast")
    assert torch.allclose(chain.position(q), fk.position(q), atol=1e-12, rtol=0)
    p, J = chain.position_and_jacobian(q[:20])
    assert torch.allclose(p, fk.position(q[:20]), atol=1e-12, rtol=0)
    J_ref = fk.jacobian(q[:20])[..., :3, :]
    assert torch.allclose(J, J_ref, atol=1e-10, rtol=0)
    # The FM interface: θ' = θ + a, ef' = p(θ'), as the analytic FM.
    s = AnalyticFM(robot).layout.join(q[:5], fk.position(q[:5]))
    a = 0.05 * torch.ones(5, robot.dof, dtype=torch.float64)
    assert torch.allclose(chain(s, a), AnalyticFM(robot)(s, a), atol=1e-12, rtol=0)


def test_parameter_jacobian_against_autograd(gen):
    n = 7
    w = torch.randn(n, 3, generator=gen, dtype=torch.float64)
    q = torch.randn(n, 3, generator=gen, dtype=torch.float64)
    tip = torch.randn(3, generator=gen, dtype=torch.float64)
    phi = torch.randn(6, n, generator=gen, dtype=torch.float64)
    x = torch.cat((w.flatten(), q.flatten(), tip))

    def f(x):
        ww = x[: 3 * n].reshape(n, 3)
        return chain_position(
            ww / ww.norm(dim=-1, keepdim=True), x[3 * n : 6 * n].reshape(n, 3), x[6 * n :], phi
        )

    p, J = chain_parameter_jacobian(w, q, tip, phi)
    assert torch.allclose(p, f(x), atol=1e-14, rtol=0)
    assert torch.allclose(J, torch.func.jacrev(f)(x), atol=1e-12, rtol=0)


@pytest.mark.parametrize("name", ALL_ROBOTS)
def test_urdf_export_round_trip(name, gen, tmp_path):
    """The exported URDF's FK equals the chain's, through Pinocchio and pytorch-kinematics."""
    robot = load_robot(name)
    chain = ChainFM.from_robot(robot, reference=robot.sample(1, gen, dtype=torch.float64)[0].numpy())
    path = tmp_path / f"{name}_chain.urdf"
    path.write_text(chain_urdf(chain, name=f"{name}_chain", joint_names=robot.joint_names))
    exported = load_robot(path, "ee")
    assert exported.joint_names == robot.joint_names
    np.testing.assert_allclose(exported.lower, robot.lower)
    q = robot.sample(200, gen, dtype=torch.float64)
    for backend in ("pinocchio", "pk"):
        got = kinematics(exported, backend).position(q)
        assert torch.allclose(got, chain.position(q), atol=1e-9, rtol=0), backend


@pytest.mark.parametrize("name", ["iiwa14", "ur5"])
def test_solver_compiled_matches_torch(name, gen):
    robot = load_robot(name)
    chain = ChainFM.from_robot(robot, reference=robot.sample(1, gen, dtype=torch.float64)[0].numpy())
    lo, hi = robot.limits(torch.float64)
    q0, goal = _within(robot, 100, gen), kinematics(robot).position(_within(robot, 100, gen))
    # One descent (no restart choice): the same steps to rounding where it converges (a descent that
    # does not, at a limit or a singularity, amplifies rounding from step to step).
    a, ea = solve_position(chain, q0, goal, lo, hi, restarts=1, iterations=25, backend="compiled")
    b, eb = solve_position(chain, q0, goal, lo, hi, restarts=1, iterations=25, backend="torch")
    done = (ea < 1e-9) & (eb < 1e-9)
    assert done.float().mean() >= 0.6
    # (a redundant arm's converged descents may part by rounding along the null space: 1e-6 rad)
    assert torch.allclose(a[done], b[done], atol=1e-5, rtol=0)
    # With restarts both reach the goal where either does.
    a, ea = solve_position(chain, q0, goal, lo, hi, backend="compiled")
    b, eb = solve_position(chain, q0, goal, lo, hi, backend="torch")
    assert ((ea <= 2e-4) == (eb <= 2e-4)).float().mean() >= 0.98
    assert (ea <= 2e-4).float().mean() >= 0.98
    for theta, e in ((a, ea), (b, eb)):
        assert bool(((theta >= lo) & (theta <= hi)).all())
        err = (kinematics(robot).position(theta) - goal).norm(dim=-1)
        assert torch.allclose(err, e.to(err), atol=1e-9)


def test_solver_is_batch_independent_and_keeps_a_reached_start(gen):
    robot = load_robot("iiwa14")
    chain = ChainFM.from_robot(robot)
    lo, hi = robot.limits(torch.float64)
    q0, goal = _within(robot, 40, gen), kinematics(robot).position(_within(robot, 40, gen))
    goal[3] = chain.position(q0[3])  # already there
    for backend in ("compiled", "torch"):
        batch, _ = solve_position(chain, q0, goal, lo, hi, backend=backend)
        for k in (0, 3, 17):
            alone, _ = solve_position(chain, q0[k : k + 1], goal[k : k + 1], lo, hi, backend=backend)
            assert torch.allclose(alone[0], batch[k], atol=1e-9, rtol=0)
        assert torch.equal(batch[3], q0[3])


def test_solver_refuses_bad_settings(gen):
    robot = load_robot("iiwa14")
    chain = ChainFM.from_robot(robot)
    lo, hi = robot.limits(torch.float64)
    q0 = _within(robot, 2, gen)
    with pytest.raises(ConfigError):
        solve_position(chain, q0, torch.zeros(2, 3, dtype=torch.float64), lo, hi, restarts=0)
    with pytest.raises(ConfigError):
        solve_position(chain, q0, torch.zeros(2, 3, dtype=torch.float64), lo, hi, backend="gpu")
    with pytest.raises(ConfigError):  # the compiled kernel takes a chain, not the analytic FM
        solve_position(
            AnalyticFM(robot), q0, torch.zeros(2, 3, dtype=torch.float64), lo, hi, backend="compiled"
        )


def test_im_through_the_fm_reaches_its_targets(gen):
    """Executed through the analytic FK, the IM's actions reach targets one babbling step away."""
    robot = load_robot("iiwa14")
    chain = ChainFM.from_robot(robot)
    lo, hi = robot.limits(torch.float64)
    im = ThroughFMIM(chain, lo, hi, iterations=3, max_step=0.083)
    fk = kinematics(robot)
    q = _within(robot, 500, gen)
    a_true = (torch.rand(q.shape, generator=gen, dtype=torch.float64) * 2 - 1) * 0.083
    target = fk.position((q + a_true).clamp(lo, hi))
    s = im.layout.join(q, fk.position(q))
    a = im(s, target)
    assert float(a.abs().max()) <= 0.083 + 1e-12
    err = (fk.position(q + a) - target).norm(dim=-1)
    assert float(err.mean()) < 1e-3
    with pytest.raises(ConfigError):
        ThroughFMIM(chain, lo, hi, iterations=0)


def test_chain_checkpoint_round_trip(tmp_path, gen):
    robot = load_robot("panda")
    chain = ChainFM.from_robot(robot)
    path = save_model(chain, tmp_path / "chain.pt", extra={"joint_names": list(robot.joint_names)})
    back = load_fm(path, robot="panda")
    assert isinstance(back, ChainFM) and back.residual is None
    q = robot.sample(50, gen, dtype=torch.float64)
    assert torch.equal(back.position(q), chain.position(q))
    with pytest.raises(CheckpointError):
        load_fm(path, robot="iiwa14")
    withres = ChainFM(ChainConfig(robot="panda", dof=7, residual=(8,)))
    back = load_fm(save_model(withres, tmp_path / "res.pt"))
    assert back.residual is not None
    with pytest.raises(ConfigError):
        ChainConfig(dof=0)
    with pytest.raises(ConfigError):
        ChainConfig(residual=(0,))


@pytest.mark.parametrize("name", ["panda", "ur5", "iiwa14"])
def test_moves_keeping_orientation_reach_small_moves_without_turning_the_hand(name, gen):
    """The compiled pose-keeping steps (the retreat stage's kept chains, :func:`chain_retreats`' second
    kind): small moves of the hand from
    configurations inside the limits are mostly reached with its orientation held (by the fast
    kinematics, not the chain), within the limits; a target at the hand itself moves nothing."""
    from kinlearn.models.chain_kernel import chain_positions, chain_retreats

    def moves_keeping_orientation(*args, **kwargs):
        return chain_retreats(*args, **kwargs, tolerance=1e-4)[1]

    robot = load_robot(name)
    chain = ChainFM.from_robot(robot)
    arrays = chain.kernel_arrays()
    lo, hi = (t.numpy() for t in robot.limits(torch.float64))
    q0 = _within(robot, 50, gen, frac=0.6).numpy()
    p0 = chain_positions(*arrays, q0)
    step = 0.02 * torch.nn.functional.normalize(
        torch.randn(50, 2, 3, generator=gen, dtype=torch.float64), dim=-1
    )
    targets = p0[:, None] + np.cumsum(step.numpy(), axis=1)  # two moves of 2 cm, one after the other
    out = moves_keeping_orientation(*arrays, q0, targets, lo, hi, iterations=15, damping=0.05, weight=0.1)
    assert out.shape == (50, 2, robot.dof) and ((out >= lo) & (out <= hi)).all()
    kin = kinematics(robot)
    reached = np.linalg.norm(kin.position(torch.from_numpy(out)).numpy() - targets, axis=-1)
    R0 = kin.pose(torch.from_numpy(q0))[:, :3, :3].numpy()
    Rk = kin.pose(torch.from_numpy(out))[..., :3, :3].numpy()
    cos = (np.einsum("nij,nkij->nk", R0, Rk) - 1) / 2
    turn = np.degrees(np.arccos(np.clip(cos, -1, 1)))
    # (near a singularity or a limit 15 damped steps do not hold both: most moves do)
    assert np.mean((reached < 1e-3) & (turn < 0.5)) >= 0.6
    assert np.median(turn) < 0.2 and np.median(reached) < 5e-4
    still = moves_keeping_orientation(
        *arrays, q0, p0[:, None], lo, hi, iterations=15, damping=0.05, weight=0.1
    )
    np.testing.assert_allclose(still[:, 0], q0, atol=1e-9)


@pytest.mark.parametrize("name", ["panda", "ur5"])
def test_a_chain_of_position_targets_is_solved_as_target_after_target(name, gen):
    """The compiled continuation (the retreat stage's turning chains, :func:`chain_retreats`' first kind)
    gives, to the bit, the joints of one :func:`solve_position_numba` per target from the joints of the
    one before; within the limits."""
    from kinlearn.models.chain_kernel import chain_positions, chain_retreats, solve_position_numba

    robot = load_robot(name)
    arrays = ChainFM.from_robot(robot).kernel_arrays()
    lo, hi = (t.numpy() for t in robot.limits(torch.float64))
    q0 = _within(robot, 20, gen, frac=0.6).numpy()
    step = 0.1 * torch.nn.functional.normalize(
        torch.randn(20, 3, 3, generator=gen, dtype=torch.float64), dim=-1
    )
    targets = chain_positions(*arrays, q0)[:, None] + np.cumsum(step.numpy(), axis=1)
    out = chain_retreats(
        *arrays, q0, targets, lo, hi, iterations=15, damping=0.05, tolerance=1e-4, weight=0.1
    )[0]
    assert out.shape == (20, 3, robot.dof) and ((out >= lo) & (out <= hi)).all()
    q = q0
    for k in range(3):
        q, _ = solve_position_numba(
            *arrays,
            q,
            targets[:, k],
            lo,
            hi,
            np.zeros((0, robot.dof)),
            iterations=15,
            damping=0.05,
            tolerance=1e-4,
        )
        assert np.array_equal(out[:, k], q)
    assert np.median(np.linalg.norm(chain_positions(*arrays, out[:, -1]) - targets[:, -1], axis=-1)) < 1e-3
