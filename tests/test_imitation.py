"""The supervised (imitation) trajectory-model baseline, and its trainer in the training loop."""

import json

import pytest
import torch

from kinlearn import ConfigError, load_robot
from kinlearn.data.endpoints import EndpointConfig, make_endpoints
from kinlearn.errors import CheckpointError, TrainingDivergedError
from kinlearn.io import load_checkpoint
from kinlearn.models.forward_inverse import AnalyticFM, AnalyticIM
from kinlearn.models.trajectory import TMConfig, TrajectoryModel
from kinlearn.planning.baselines import joint_line
from kinlearn.planning.planner import Planner
from kinlearn.training import imitation
from kinlearn.training.imitation import imitation_loss, imitation_targets, load_imitation, train_imitation
from kinlearn.training.loop import OptimConfig

FAST = OptimConfig(name="adam", lr=1e-2)


@pytest.fixture(scope="module")
def pairs():
    return make_endpoints(EndpointConfig(n=128, seed=5))


@pytest.fixture(scope="module")
def trained(pairs):
    history: list[float] = []
    tm = train_imitation(pairs, epochs=20, batch_size=16, optim=FAST, seed=0, progress=False, history=history)
    return tm, history


def test_targets_are_fk_of_joint_interpolation(pairs):
    robot = load_robot("iiwa14")
    targets = imitation_targets(pairs)
    assert targets.shape == (len(pairs), 10, 3)
    expected = joint_line(robot, pairs.start, pairs.goal, steps=11).waypoints
    assert torch.equal(targets, expected)


def test_training_loss_falls(trained):
    _, history = trained
    assert len(history) == 20
    assert history[-1] < 0.3 * history[0]


def test_waypoints_approach_the_targets(pairs, trained):
    tm, _ = trained
    torch.manual_seed(0)
    untrained = TrajectoryModel(TMConfig())
    untrained.fit_normalization(pairs.start, pairs.goal)
    targets = imitation_targets(pairs)
    before = imitation_loss(untrained, pairs, targets)
    after = imitation_loss(tm, pairs, targets)
    assert after < 0.3 * before
    with torch.no_grad():
        err_after = (tm(pairs.start, pairs.goal) - targets).norm(dim=-1).mean()
        err_before = (untrained(pairs.start, pairs.goal) - targets).norm(dim=-1).mean()
    assert err_after < 0.6 * err_before


def test_deterministic_for_a_seed(pairs, trained):
    tm, _ = trained
    again = train_imitation(pairs, epochs=20, batch_size=16, optim=FAST, seed=0, progress=False)
    for a, b in zip(tm.state_dict().values(), again.state_dict().values(), strict=True):
        assert torch.equal(a, b)


def test_planner_plans_with_the_imitation_tm(pairs, trained):
    tm, _ = trained
    robot = load_robot("iiwa14")
    planner = Planner(robot, tm, AnalyticFM(robot), AnalyticIM(robot))
    plan = planner.plan(pairs.start[:5], pairs.goal[:5])
    assert plan.waypoints.shape == (5, 10, 3) and plan.joints.shape == (5, 12, 7)
    # Through the exact FM/IM the rollout follows the imitated TM's waypoints.
    tracking = (plan.ef[:, 1:-1] - plan.waypoints).norm(dim=-1)
    assert float(tracking.median()) < 1e-3  # the executed path goes through the TM's waypoints
    assert torch.equal(plan.joints[:, 0], pairs.start[:5, :7])


def test_bad_arguments(pairs):
    with pytest.raises(ConfigError):
        train_imitation(pairs, epochs=0, progress=False)
    with pytest.raises(ConfigError, match="panda"):
        train_imitation(pairs, epochs=1, progress=False, tm_config=TMConfig(robot="panda", dof=7))


# --------------------------------------------------------------------------------------------------
# The imitation trainer in the loop: resume, refusals, divergence
# --------------------------------------------------------------------------------------------------


def _same(a: torch.nn.Module, b: torch.nn.Module) -> bool:
    pairs = zip(a.state_dict().values(), b.state_dict().values(), strict=True)
    return all(torch.equal(x, y) for x, y in pairs)


#: The training state a run's checkpoint holds beside the weights (the loop's own: tests/test_loop.py).
STATE_KEYS = {
    "step",
    "unit",
    "optimizer",
    "scheduler",
    "generator",
    "torch_rng",
    "loss_ref",
    "train_config",
    "history",
}


@pytest.fixture(scope="module")
def few_pairs():
    return make_endpoints(EndpointConfig(n=48, seed=5))


def test_imitation_resumes_to_the_uninterrupted_weights(few_pairs, tmp_path, monkeypatch):
    kw = dict(epochs=3, batch_size=16, optim=FAST, seed=1, progress=False)
    plain_history: list[float] = []
    plain = train_imitation(few_pairs, history=plain_history, **kw)  # no run folder: nothing written
    whole = train_imitation(few_pairs, run_dir=tmp_path / "whole", **kw)
    assert _same(plain, whole)
    real, saves = imitation.save_checkpoint, []

    def dying(path, **fields):
        if len(saves) == 2:
            raise KeyboardInterrupt  # killed during epoch 3: the checkpoint holds epoch 2
        saves.append(fields["extra"]["step"])
        return real(path, **fields)

    monkeypatch.setattr(imitation, "save_checkpoint", dying)
    with pytest.raises(KeyboardInterrupt):
        train_imitation(few_pairs, run_dir=tmp_path / "cut", **kw)
    monkeypatch.setattr(imitation, "save_checkpoint", real)
    history: list[float] = []
    resumed = train_imitation(few_pairs, run_dir=tmp_path / "cut", history=history, **kw)
    assert saves == [1, 2] and _same(whole, resumed)
    assert history == plain_history and len(history) == 3
    lines = (tmp_path / "cut" / "metrics.jsonl").read_text().splitlines()
    assert [json.loads(x)["epoch"] for x in lines] == [1, 2, 3]
    payload = load_checkpoint(tmp_path / "cut" / "imitation.pt", kind="tm-imitation", robot="iiwa14")
    assert STATE_KEYS <= set(payload["extra"]) and payload["extra"]["step"] == 3
    assert _same(load_imitation(tmp_path / "cut" / "imitation.pt"), whole)


def test_imitation_refuses_to_resume_another_run(few_pairs, tmp_path):
    kw = dict(epochs=1, batch_size=16, seed=1, progress=False, run_dir=tmp_path)
    train_imitation(few_pairs, optim=FAST, **kw)
    with pytest.raises(CheckpointError, match=r"optim\.lr: 0\.01 → 0\.02"):
        train_imitation(few_pairs, optim=OptimConfig(name="adam", lr=2e-2), **kw)
    with pytest.raises(CheckpointError, match="data_sha256"):
        train_imitation(make_endpoints(EndpointConfig(n=48, seed=6)), optim=FAST, **kw)
    train_imitation(make_endpoints(EndpointConfig(n=48, seed=6)), optim=FAST, resume=False, **kw)


def test_imitation_divergence_is_a_typed_error(few_pairs):
    with pytest.raises(TrainingDivergedError, match="imitation TM training diverged at epoch"):
        train_imitation(few_pairs, epochs=3, batch_size=16, optim=OptimConfig("sgd", 1e6), progress=False)
