"""Forward and inverse models: analytic ones against FK, learned ones' structure, checkpoints."""

import pytest
import torch

from kinlearn import CheckpointError, ConfigError, NonFiniteError, ShapeError, kinematics, load_robot
from kinlearn.body.state import StateLayout
from kinlearn.io import save_checkpoint
from kinlearn.models.forward_inverse import (
    AnalyticFM,
    AnalyticIM,
    FMConfig,
    ForwardModel,
    IMConfig,
    InverseModel,
    LearnedFM,
    LearnedIM,
    fm_config,
    im_config,
    load_fm,
    load_im,
    save_model,
)


def states(robot, shape, gen, dtype=torch.float64, margin=0.3):
    theta = robot.sample(shape, gen, dtype=dtype, margin=margin)
    return StateLayout(robot.dof).join(theta, kinematics(robot, "fast").position(theta))


# --------------------------------------------------------------------------------------------------
# Analytic models
# --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["iiwa14", "panda", "ur5"])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_analytic_fm_is_fk_exactly(name, dtype, gen):
    robot = load_robot(name)
    fm = AnalyticFM(robot)
    assert isinstance(fm, ForwardModel) and fm.robot_name == name and fm.layout == StateLayout(robot.dof)
    s = states(robot, (4, 25), gen, dtype)
    a = 0.05 * torch.randn((4, 25, robot.dof), generator=gen, dtype=dtype)
    out = fm(s, a)
    theta = s[..., fm.layout.joints] + a
    assert out.shape == s.shape and out.dtype == dtype
    assert torch.equal(out[..., fm.layout.joints], theta)
    assert torch.equal(out[..., fm.layout.ef], kinematics(robot, "fast").position(theta))
    ref = kinematics(robot, "pinocchio").position(theta.double())
    assert float((out[..., fm.layout.ef].double() - ref).abs().max()) < (
        1e-12 if dtype == torch.float64 else 1e-5
    )


def test_analytic_fm_broadcasts_one_state_over_many_actions(gen):
    robot = load_robot("iiwa14")
    fm = AnalyticFM(robot)
    s = states(robot, (), gen)
    a = 0.01 * torch.randn((5, 7), generator=gen, dtype=torch.float64)
    out = fm(s, a)
    assert out.shape == (5, 10)
    assert torch.equal(out, fm(s.expand(5, 10), a))


@pytest.mark.parametrize("name", ["iiwa14", "panda"])
def test_analytic_im_reaches_a_1cm_target_within_0_1mm(name, gen):
    robot = load_robot(name)
    kin = kinematics(robot, "fast")
    s = states(robot, 400, gen, margin=0.5)
    L = StateLayout(robot.dof)
    # Away from singular configurations (there a 1 cm move outward may be out of reach): the
    # smallest singular value of the position Jacobian above 0.05 m/rad, ≈ 95% of random samples.
    well_conditioned = torch.linalg.svdvals(kin.jacobian(s[:, L.joints]))[:, -1] > 0.05
    assert float(well_conditioned.double().mean()) > 0.9
    s = s[well_conditioned]
    direction = torch.nn.functional.normalize(
        torch.randn((len(s), 3), generator=gen, dtype=torch.float64), dim=-1
    )
    target = s[:, L.ef] + 0.01 * direction
    im = AnalyticIM(robot, iterations=5, damping=1e-3)
    assert isinstance(im, InverseModel)
    a = im(s, target)
    theta = s[:, L.joints] + a
    lo, hi = robot.limits(torch.float64)
    assert bool(((theta >= lo) & (theta <= hi)).all())
    err = (kin.position(theta) - target).norm(dim=-1)
    assert float(err.max()) < 1e-4
    # One iteration with the default damping already does most of the work.
    err1 = (kin.position(s[:, L.joints] + AnalyticIM(robot)(s, target)) - target).norm(dim=-1)
    assert float(err1.median()) < 2e-3


def test_analytic_im_respects_limits_for_unreachable_targets(gen):
    robot = load_robot("iiwa14")
    s = states(robot, 50, gen)
    target = torch.tensor([3.0, 3.0, 3.0], dtype=torch.float64).expand(50, 3)
    a = AnalyticIM(robot, iterations=10)(s, target)
    theta = s[:, :7] + a
    lo, hi = robot.limits(torch.float64)
    assert bool(((theta >= lo - 1e-12) & (theta <= hi + 1e-12)).all())


def test_analytic_im_is_differentiable(gen):
    robot = load_robot("iiwa14")
    im = AnalyticIM(robot, iterations=2)
    s = states(robot, 2, gen, margin=0.6).requires_grad_(True)
    target = (s.detach()[:, 7:] + 0.02).requires_grad_(True)
    assert torch.autograd.gradcheck(lambda s_, t_: im(s_, t_), (s, target), eps=1e-6, atol=1e-5)


def test_analytic_models_reject_bad_input(gen):
    fm, im = AnalyticFM("iiwa14"), AnalyticIM("iiwa14")
    s = torch.zeros(3, 10)
    with pytest.raises(ShapeError):
        fm(torch.zeros(3, 9), torch.zeros(3, 7))
    with pytest.raises(ShapeError):
        fm(s, torch.zeros(3, 6))
    with pytest.raises(ShapeError):
        im(s, torch.zeros(3, 2))
    with pytest.raises(ShapeError):
        im(s.long(), torch.zeros(3, 3))
    with pytest.raises(NonFiniteError):
        fm(s, torch.full((3, 7), float("nan")))
    with pytest.raises(NonFiniteError):
        im(s, torch.full((3, 3), float("inf")))
    with pytest.raises(ConfigError):
        AnalyticIM("iiwa14", iterations=0)


# --------------------------------------------------------------------------------------------------
# Learned models
# --------------------------------------------------------------------------------------------------


def n_params(m):
    return sum(p.numel() for p in m.parameters())


def test_paper_architectures():
    fm, im = LearnedFM(fm_config("iiwa14")), LearnedIM(im_config("iiwa14"))
    # The paper's Sect. 4 and Cibula et al. 2024, Sect. 4.1: FM 17 → 30 tanh → (20 tanh → 7) and (20 tanh → 3); IM 13 → 40-60-60-40 tanh → 7.
    assert n_params(fm) == (17 * 30 + 30) + (30 * 20 + 20 + 20 * 7 + 7) + (30 * 20 + 20 + 20 * 3 + 3) == 1990
    assert n_params(im) == 13 * 40 + 40 + 40 * 60 + 60 + 60 * 60 + 60 + 60 * 40 + 40 + 40 * 7 + 7 == 9407
    assert sum(isinstance(m, torch.nn.Tanh) for m in fm.modules()) == 3
    assert sum(isinstance(m, torch.nn.Tanh) for m in im.modules()) == 4
    assert not list(fm.buffers()) and not list(im.buffers())  # no normalisation in the paper preset


@pytest.mark.parametrize("preset", ["paper", "improved"])
@pytest.mark.parametrize("name", ["iiwa14", "ur5"])
def test_every_learned_parameter_gets_a_gradient(preset, name, gen):
    robot = load_robot(name)
    for model in (LearnedFM(fm_config(name, preset)), LearnedIM(im_config(name, preset))):
        s = states(robot, 8, gen, torch.float32)
        a = 0.05 * torch.randn((8, robot.dof), generator=gen)
        loss = model.training_loss(s, a, states(robot, 8, gen, torch.float32))
        loss.backward()
        named = dict(model.named_parameters())
        assert named, "the model registered no parameters"
        for pname, p in named.items():
            assert p.grad is not None and bool((p.grad != 0).any()), f"{pname} receives no gradient"


def test_learned_models_batch_dims_dtype_and_input_gradients(gen):
    robot = load_robot("panda")
    fm, im = LearnedFM(fm_config("panda", "improved")), LearnedIM(im_config("panda", "improved"))
    s = states(robot, (2, 3), gen, torch.float32).requires_grad_(True)
    a = (0.05 * torch.randn((2, 3, 7), generator=gen)).requires_grad_(True)
    out = fm(s, a)
    assert out.shape == (2, 3, 10) and out.dtype == torch.float32
    act = im(s, out[..., 7:])
    assert act.shape == (2, 3, 7)
    act.sum().backward()
    assert s.grad is not None and a.grad is not None and bool((a.grad != 0).any())
    s64 = s.detach().double()
    assert fm.double()(s64, a.detach().double()).dtype == torch.float64


def test_predict_delta_and_normalisation():
    cfg = FMConfig(normalize=True, predict_delta=True)
    fm = LearnedFM(cfg)
    assert {k for k, _ in fm.named_buffers()} == {
        "in_norm.mean",
        "in_norm.std",
        "out_norm.mean",
        "out_norm.std",
    }
    s = torch.randn(100, 10)
    a = 0.05 * torch.randn(100, 7)
    s_next = s + torch.cat((a, 0.01 * torch.randn(100, 3)), dim=-1)
    fm.fit_normalization(s, a, s_next)
    assert torch.allclose(fm.out_norm.mean, (s_next - s).mean(0).double().float(), atol=1e-6)
    # With zero output weights the delta model predicts the mean delta on top of s.
    for head in (fm.joints_head, fm.ef_head):
        torch.nn.init.zeros_(head[-1].weight)
        torch.nn.init.zeros_(head[-1].bias)
    with torch.no_grad():
        assert torch.allclose(fm(s, a), s + fm.out_norm.mean, atol=1e-6)


def test_model_config_checks_and_round_trip():
    with pytest.raises(ConfigError):
        FMConfig(activation="sigmoidal")
    with pytest.raises(ConfigError):
        IMConfig(hidden=())
    with pytest.raises(ConfigError):
        FMConfig(shared=(0,))
    with pytest.raises(ConfigError):
        fm_config("iiwa14", "huge")
    with pytest.raises(ConfigError):
        FMConfig.from_dict({"robot": "iiwa14", "width": 3})
    cfg = im_config("ur5", "improved")
    assert cfg.dof == 6 and IMConfig.from_dict(cfg.to_dict()) == cfg


def test_learned_models_reject_bad_input():
    fm, im = LearnedFM(), LearnedIM()
    with pytest.raises(ShapeError):
        fm(torch.zeros(2, 10), torch.zeros(2, 6))
    with pytest.raises(ShapeError):
        im(torch.zeros(2, 11), torch.zeros(2, 3))
    with pytest.raises(NonFiniteError):
        im(torch.zeros(2, 10), torch.tensor([[0.0, float("nan"), 0.0]] * 2))


# --------------------------------------------------------------------------------------------------
# Checkpoints
# --------------------------------------------------------------------------------------------------


def test_checkpoint_round_trip(tmp_path, gen):
    robot = load_robot("iiwa14")
    s = states(robot, 16, gen, torch.float32)
    a = 0.05 * torch.randn((16, 7), generator=gen)
    fm = LearnedFM(fm_config("iiwa14", "improved"))
    fm.fit_normalization(s, a, s + 0.01)
    im = LearnedIM(im_config("iiwa14", "paper"))
    save_model(fm, tmp_path / "fm.pt", extra={"epoch": 3})
    save_model(im, tmp_path / "im.pt")
    fm2, im2 = load_fm(tmp_path / "fm.pt", robot="iiwa14"), load_im(tmp_path / "im.pt")
    assert isinstance(fm2, LearnedFM) and fm2.config == fm.config and not fm2.training
    with torch.no_grad():
        assert torch.equal(fm2(s, a), fm(s, a))
        assert torch.equal(im2(s, s[:, 7:]), im(s, s[:, 7:]))


def test_analytic_models_round_trip(tmp_path):
    save_model(AnalyticIM("panda", iterations=3, damping=0.02), tmp_path / "im.pt")
    im = load_im(tmp_path / "im.pt", robot="panda")
    assert isinstance(im, AnalyticIM) and im.iterations == 3 and im.damping == 0.02
    save_model(AnalyticFM("ur5"), tmp_path / "fm.pt")
    assert isinstance(load_fm(tmp_path / "fm.pt"), AnalyticFM)


def test_checkpoint_errors(tmp_path):
    path = save_model(LearnedFM(fm_config("iiwa14")), tmp_path / "fm.pt")
    with pytest.raises(CheckpointError, match="panda"):
        load_fm(path, robot="panda")
    with pytest.raises(CheckpointError, match="'fm'"):
        load_im(path)
    corrupt = tmp_path / "corrupt.pt"
    corrupt.write_bytes(path.read_bytes()[:200])
    with pytest.raises(CheckpointError):
        load_fm(corrupt)
    with pytest.raises(CheckpointError):
        load_fm(tmp_path / "missing.pt")
    # A config that does not match the weights.
    bad = save_checkpoint(
        tmp_path / "bad.pt",
        kind="fm",
        robot="iiwa14",
        config={"type": "learned", **FMConfig(shared=(31,)).to_dict()},
        state_dict=LearnedFM().state_dict(),
    )
    with pytest.raises(CheckpointError, match="rebuild"):
        load_fm(bad)
    odd = save_checkpoint(
        tmp_path / "odd.pt", kind="im", robot="iiwa14", config={"type": "magic"}, state_dict={}
    )
    with pytest.raises(CheckpointError, match="magic"):
        load_im(odd)
    with pytest.raises(ConfigError):
        save_model(torch.nn.Linear(2, 2), tmp_path / "x.pt")
