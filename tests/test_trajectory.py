"""Trajectory model, rectification (Algorithm 1), the loss presets and TM training."""

import copy
import dataclasses
import json

import pytest
import torch

from kinlearn import ConfigError, kinematics
from kinlearn.body.state import StateLayout
from kinlearn.data.endpoints import EndpointConfig, load_endpoints, make_endpoints, save_endpoints
from kinlearn.errors import CheckpointError, DatasetError
from kinlearn.models.forward_inverse import (
    AnalyticFM,
    AnalyticIM,
    FMConfig,
    IMConfig,
    LearnedFM,
    LearnedIM,
)
from kinlearn.models.rollout import LossConfig, rectify, tm_loss
from kinlearn.models.trajectory import TMConfig, TrajectoryModel
from kinlearn.training.tm import load_tm, tm_preset, train_tm


@pytest.fixture(scope="module")
def pairs():
    return make_endpoints(EndpointConfig(n=160, seed=3))


def test_endpoints_reproducible_and_in_region(pairs, robot):
    again = make_endpoints(EndpointConfig(n=160, seed=3))
    assert torch.equal(pairs.start, again.start) and torch.equal(pairs.goal, again.goal)
    lay = StateLayout(robot.dof)
    kin = kinematics(robot)
    for s in (pairs.start, pairs.goal):
        theta, ef = lay.split(s)
        robot.check_joints(theta)
        assert (kin.position(theta) - ef).abs().max() < 1e-5
    x0, x1, y0, y1, z0, z1 = (0.3, 0.85, -0.5, 0.5, 0.1, 0.3)
    g = pairs.goal[:, lay.ef]
    assert bool(((g[:, 0] >= x0) & (g[:, 0] <= x1) & (g[:, 1] >= y0) & (g[:, 1] <= y1)).all())
    assert bool(((g[:, 2] >= z0) & (g[:, 2] <= z1)).all())
    assert ((pairs.goal[:, lay.ef] - pairs.start[:, lay.ef]).norm(dim=-1) >= 0.2).all()


def test_endpoints_save_load_and_robot_check(pairs, tmp_path):
    path = save_endpoints(pairs, tmp_path / "pairs.npz")
    back = load_endpoints(path, robot="iiwa14")
    assert torch.equal(back.start, pairs.start) and back.config == pairs.config
    with pytest.raises(DatasetError, match="panda"):
        load_endpoints(path, robot="panda")


def test_tm_shapes_and_every_parameter_gets_gradient(pairs):
    tm = TrajectoryModel(TMConfig(h0="learned"))
    tm.fit_normalization(pairs.start, pairs.goal)
    wp = tm(pairs.start[:8], pairs.goal[:8])
    assert wp.shape == (8, 10, 3)
    wp.pow(2).sum().backward()
    names = [n for n, p in tm.named_parameters()]
    assert any(n.startswith("gru.") for n in names) and any(n.startswith("head.") for n in names)
    for name, p in tm.named_parameters():
        assert p.grad is not None and p.grad.abs().sum() > 0, name
    # leading batch dimensions
    assert tm(pairs.start[:6].reshape(2, 3, 10), pairs.goal[:6].reshape(2, 3, 10)).shape == (2, 3, 10, 3)


def test_tm_parameter_count_matches_paper_architecture():
    tm = TrajectoryModel(TMConfig(normalize=False))
    # GRU(20 → 20): 3·(20·20 + 20·20 + 20 + 20) = 2520; shared 20·20 + 20 = 420; head 20·10 + 10 + 10·3 + 3 = 243
    assert sum(p.numel() for p in tm.parameters()) == 2520 + 420 + 243


def test_tm_is_deterministic_by_default_and_random_h0_is_not(pairs):
    tm = TrajectoryModel(TMConfig())
    assert torch.equal(tm(pairs.start, pairs.goal), tm(pairs.start, pairs.goal))
    rnd = TrajectoryModel(TMConfig(h0="random"))
    assert not torch.equal(rnd(pairs.start, pairs.goal), rnd(pairs.start, pairs.goal))


def test_bad_tm_config():
    with pytest.raises(ConfigError, match="h0"):
        TMConfig(h0="noise")
    with pytest.raises(ConfigError, match="steps"):
        TMConfig(steps=1)
    with pytest.raises(ConfigError, match="paper, released, smooth"):
        LossConfig.preset("fancy")


def test_batched_rectification_equals_per_sample_loop(pairs, robot):
    lay = StateLayout(robot.dof)
    fm, im = AnalyticFM(robot), AnalyticIM(robot, iterations=2)
    s0, sT = pairs.start[:5].double(), pairs.goal[:5].double()
    wp = torch.linspace(0, 1, 12, dtype=torch.float64)[1:-1, None] * (
        sT[:, None, lay.ef] - s0[:, None, lay.ef]
    )
    wp = wp + s0[:, None, lay.ef]
    states, actions = rectify(wp, s0, sT, fm, im, lay)
    for n in range(5):  # the authors' structure: one sample, one model call at a time
        s = s0[n]
        for t in range(11):
            target = wp[n, t] if t < 10 else sT[n, lay.ef]
            a = im(s, target)
            s = fm(s, a)
            assert torch.allclose(a, actions[n, t], atol=1e-12)
            assert torch.allclose(s, states[n, t], atol=1e-12)


def test_analytic_rectification_is_consistent_with_fk(pairs, robot):
    lay = StateLayout(robot.dof)
    tm = TrajectoryModel(TMConfig())
    tm.fit_normalization(pairs.start, pairs.goal)
    s0, sT = pairs.start[:32], pairs.goal[:32]
    with torch.no_grad():
        states, actions = rectify(tm(s0, sT), s0, sT, AnalyticFM(robot), AnalyticIM(robot), lay)
    theta, ef = lay.split(states)
    assert torch.allclose(ef, kinematics(robot).position(theta), atol=1e-6)
    # joints are the start plus the cumulative actions
    assert torch.allclose(theta, s0[:, None, lay.joints] + actions.cumsum(1), atol=1e-5)


def test_loss_presets_known_values(robot):
    lay = StateLayout(robot.dof)
    s0 = torch.zeros(1, 10)
    sT = torch.zeros(1, 10)
    sT[0, 7] = 1.1  # goal 1.1 m along x; T = 11 → spacing 0.1
    line = torch.stack([torch.tensor([0.1 * k, 0.0, 0.0]) for k in range(1, 11)])[None]
    rect = torch.cat((line, sT[:, None, lay.ef]), dim=1)
    rect = torch.cat((torch.zeros(1, 11, 7), rect), dim=-1)
    _, terms = tm_loss(line, rect, s0, sT, lay, LossConfig.preset("smooth"))
    assert float(terms["smoothness"]) < 1e-10 and float(terms["rectification"]) == 0.0
    assert float(terms["start"]) < 1e-12 and float(terms["goal"]) < 1e-12  # one spacing from each end
    loss, terms = tm_loss(line, rect, s0, sT, lay, LossConfig.preset("paper"))
    # Eq. 4: ŝ(1) and ŝ(T−1) are one spacing (0.1 m along x) from the endpoints: MSE over 3 coordinates
    assert float(terms["paper_l_tm"]) == pytest.approx(2 * 0.01 / 3, rel=1e-5)
    assert float(loss) == pytest.approx(2 * 0.01 / 3, rel=1e-5)
    released, _ = tm_loss(line, rect + 1.0, s0, sT, lay, LossConfig.preset("released"))
    assert float(released) == pytest.approx(2 * 0.01 / 3, rel=1e-5)  # ignores the rectification term


def _tiny(robot="iiwa14", **kw):
    kw = {"epochs": 3, "batch_size": 32, **kw}
    return tm_preset("default", robot=robot, fm="analytic", im="analytic", **kw)


def test_training_lowers_loss_and_keeps_fm_im_frozen(pairs, tmp_path, robot):
    fm = LearnedFM(FMConfig(robot="iiwa14", dof=7))
    im = LearnedIM(IMConfig(robot="iiwa14", dof=7))
    before = (copy.deepcopy(fm.state_dict()), copy.deepcopy(im.state_dict()))
    cfg = tm_preset(
        "paper",
        fm="learned",
        im="learned",
        epochs=10,
        batch_size=16,
        # gradients flow through FM/IM, which must still not change
        loss=dataclasses.replace(LossConfig.preset("paper"), gradient="through"),
    )
    train_tm(cfg, tmp_path, pairs, fm=fm, im=im, progress=False)
    for old, new in zip(before, (fm.state_dict(), im.state_dict()), strict=True):
        for k in old:
            assert torch.equal(old[k], new[k]), k
    losses = [
        json.loads(line)["train/loss"] for line in (tmp_path / "metrics.jsonl").read_text().splitlines()
    ]
    assert losses[-1] < 0.5 * losses[0]


def test_resume_continues_from_saved_epoch(pairs, tmp_path):
    three = _tiny(schedule="constant")
    full = train_tm(three, tmp_path / "full", pairs, progress=False)
    # An interrupted run: the checkpoint of a 3-epoch run as it stood after epoch 2.
    two = dataclasses.replace(_tiny(schedule="constant"), epochs=2)
    train_tm(two, tmp_path / "cut", pairs, progress=False)
    resumed = train_tm(three, tmp_path / "cut", pairs, progress=False)
    lines = (tmp_path / "cut" / "metrics.jsonl").read_text().splitlines()
    assert [json.loads(x)["epoch"] for x in lines] == [1, 2, 3]  # only epoch 3 ran after resuming
    for a, b in zip(full.state_dict().values(), resumed.state_dict().values(), strict=True):
        assert torch.equal(a, b)
    # Resuming with another configuration is refused rather than mixing two runs.
    with pytest.raises(CheckpointError, match="another configuration"):
        train_tm(_tiny(batch_size=8), tmp_path / "cut", pairs, progress=False)


def test_reference_parity_trains_only_the_shared_layer(pairs, tmp_path):
    cfg = tm_preset("reference-parity", fm="analytic", im="analytic", epochs=1)
    small = pairs.split(20)[0]
    torch.manual_seed(0)
    init = TrajectoryModel(cfg.tm).state_dict()
    tm = train_tm(cfg, tmp_path, small, progress=False)
    changed = {k for k in init if not torch.equal(init[k], tm.state_dict()[k])}
    # Trained: the shared layer only. Recorded from the pairs, not trained: the domain.
    assert changed == {"shared.0.weight", "shared.0.bias", "domain_lo", "domain_hi"}


def test_load_tm_checks_robot(pairs, tmp_path):
    train_tm(_tiny(), tmp_path, pairs.split(32)[0], progress=False)
    tm, cfg = load_tm(tmp_path / "tm.pt", robot="iiwa14")
    assert cfg.fm == "analytic" and tm.config.steps == 11
    with pytest.raises(CheckpointError, match="panda"):
        load_tm(tmp_path / "tm.pt", robot="panda")


def test_training_config_errors(pairs, tmp_path):
    with pytest.raises(ConfigError, match="learned"):
        tm_preset("default", fm="neural")
    with pytest.raises(ConfigError, match="models_dir"):
        train_tm(tm_preset("default", epochs=1), tmp_path, pairs, progress=False)
    with pytest.raises(ConfigError, match="panda"):
        train_tm(_tiny(robot="panda"), tmp_path, pairs, progress=False)


def test_rectify_refinement_and_exact_joints(pairs, robot):
    lay = StateLayout(robot.dof)
    fm = AnalyticFM(robot)
    weak_im = AnalyticIM(robot, iterations=1, damping=0.2)  # heavily damped: undershoots every target
    s0, sT = pairs.start[:32].double(), pairs.goal[:32].double()
    frac = torch.linspace(0, 1, 12, dtype=torch.float64)[1:-1, None]
    wp = s0[:, None, lay.ef] + frac * (sT[:, None, lay.ef] - s0[:, None, lay.ef])
    targets = torch.cat((wp, sT[:, None, lay.ef]), dim=1)

    def reach_error(**kw):
        states, actions = rectify(wp, s0, sT, fm, weak_im, lay, **kw)
        return float((states[..., lay.ef] - targets).norm(dim=-1).mean()), states, actions

    plain, _, _ = reach_error()
    refined, _, _ = reach_error(refine=2)
    assert refined < 0.5 * plain
    _, states, actions = reach_error(refine=1, exact_joints=True)
    assert torch.equal(
        states[..., lay.joints], s0[:, None, lay.joints] + actions.cumsum(1)
    ) or torch.allclose(states[..., lay.joints], s0[:, None, lay.joints] + actions.cumsum(1), atol=1e-12)


def test_divergence_is_a_typed_error_and_reproduce_records_it(pairs, tmp_path):
    from kinlearn.errors import TrainingDivergedError
    from kinlearn.evaluation.reproduce import _job
    from kinlearn.training.loop import OptimConfig

    cfg = _tiny(optim=OptimConfig("sgd", 1e6), epochs=2)
    with pytest.raises(TrainingDivergedError, match="lower the learning rate"):
        train_tm(cfg, tmp_path / "tm", pairs, progress=False)
    # In a sweep, a diverged run is a result, not a crash.
    save_endpoints(pairs, tmp_path / "pairs.npz")
    job = {
        "kind": "tm",
        "name": "sgd-huge",
        "config": cfg.to_dict(),
        "run_dir": str(tmp_path / "job"),
        "train": str(tmp_path / "pairs.npz"),
        "heldout": str(tmp_path / "pairs.npz"),
        "limit": None,
    }
    (result,) = _job(job)
    assert result["name"] == "sgd-huge" and "diverged" in result["diverged"]
    # the same for seeds trained in lockstep: each diverged seed is a result
    seeds = {**job, "kind": "seeds", "seeds": [0, 1], "names": ["a", "b"]}
    seeds["run_dirs"] = [str(tmp_path / "a"), str(tmp_path / "b")]
    results = _job(seeds)
    assert [r["name"] for r in results] == ["a", "b"] and all("diverged" in r for r in results)


def test_endpoint_config_errors():
    with pytest.raises(ConfigError, match="positive"):
        make_endpoints(EndpointConfig(n=0))
    with pytest.raises(ConfigError, match="7 joint values"):
        make_endpoints(EndpointConfig(n=4, home=(0.0, 0.1)))
    with pytest.raises(ConfigError, match=r"EndpointConfig\.region must be 6 finite numbers"):
        EndpointConfig(region=(0.5, 0.3, 0.0, 1.0, 0.0, 1.0))  # x_min > x_max
    with pytest.raises(ConfigError, match=r"EndpointConfig\.region must be 6 finite numbers"):
        EndpointConfig(region=(0.0, 1.0, 0.0, 1.0))
    with pytest.raises(ConfigError, match="widen the region"):
        make_endpoints(EndpointConfig(n=4, region=(5.0, 6.0, 5.0, 6.0, 5.0, 6.0)))
