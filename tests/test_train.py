"""Training: optimisers, logging, seeding, learning beats trivial predictors, resume, validation."""

import copy
import functools
import json
import os
import time

import pytest
import torch

from kinlearn import CheckpointError, ConfigError, kinematics, load_robot
from kinlearn.data.babbling import BabblingConfig, babble
from kinlearn.errors import DatasetError
from kinlearn.models.forward_inverse import (
    AnalyticFM,
    AnalyticIM,
    FMConfig,
    IMConfig,
    LearnedFM,
    LearnedIM,
    fm_config,
    im_config,
    load_fm,
    load_im,
)
from kinlearn.training.forward_inverse import (
    format_validation_table,
    train_config,
    train_fm,
    train_im,
    train_im_distal,
    validate_models,
)
from kinlearn.training.loop import OptimConfig, TrainConfig


@pytest.fixture(scope="module")
def data():
    return babble(BabblingConfig(walkers=200, steps=150, seed=0))


@pytest.fixture(scope="module")
def fresh():
    return babble(BabblingConfig(walkers=200, steps=25, seed=99))


def tiny(kind, **kw):
    return train_config(kind, "tiny", progress=False, **kw)


def test_unknown_presets_are_refused():
    with pytest.raises(ConfigError):
        train_config("fm", "huge")
    with pytest.raises(ConfigError):
        train_config("tm")


def test_presets_are_the_papers():
    fm, im = train_config("fm", "paper"), train_config("im", "paper")
    assert (fm.optim.name, fm.optim.lr, fm.epochs, fm.batch_size) == ("adam", 1e-3, 60, 256)
    assert (im.optim.name, im.optim.lr, im.optim.weight_decay, im.epochs, im.batch_size) == (
        "adamw",
        1e-3,
        4e-3,
        100,
        256,
    )
    assert fm.schedule == im.schedule == "constant"
    assert TrainConfig.from_dict(json.loads(json.dumps(im.to_dict()))) == im


# --------------------------------------------------------------------------------------------------
# Forward and inverse models
# --------------------------------------------------------------------------------------------------


def test_learned_fm_beats_the_identity_predictor_by_5x(data, fresh):
    result = train_fm(data, fm_config("iiwa14", "tiny"), tiny("fm"))
    with torch.no_grad():
        pred = result.model(fresh.s, fresh.a)
    mse = float((pred - fresh.s_next).square().mean())
    trivial = float((fresh.s - fresh.s_next).square().mean())
    assert mse * 5 <= trivial
    # The end-effector part alone (harder: the joints part is nearly linear) improves too.
    L = fresh.layout
    ef_mse = float((pred[:, L.ef] - fresh.s_next[:, L.ef]).square().mean())
    assert ef_mse * 2 <= float((fresh.s[:, L.ef] - fresh.s_next[:, L.ef]).square().mean())
    assert [r["epoch"] for r in result.history] == [1, 2, 3, 4]


def test_learned_im_beats_the_zero_action(data, fresh):
    """The IM's action, executed on the robot, lands ≥ 5× closer (in MSE) to the target than a = 0.

    The action itself cannot beat a = 0 by 5× in MSE on babbling data: the input (s, ef(t+1)) does
    not determine the 7 joint changes (a redundant arm; joint 7 of the iiwa does not move the
    end-effector position at all), so the best predictor is a conditional mean (see docs/models.md).
    """
    result = train_im(data, im_config("iiwa14", "tiny"), tiny("im", epochs=6))
    L = fresh.layout
    target = fresh.s_next[:, L.ef]
    with torch.no_grad():
        a_hat = result.model(fresh.s, target)
    assert float((a_hat - fresh.a).square().mean()) < float(fresh.a.square().mean())
    kin = kinematics(load_robot("iiwa14"), "fast")
    executed = kin.position(fresh.s[:, L.joints] + a_hat)
    mse = float((executed - target).square().sum(-1).mean())
    trivial = float((fresh.s[:, L.ef] - target).square().sum(-1).mean())
    assert mse * 5 <= trivial


def test_each_trainer_refuses_the_other_kind_of_model(data):
    with pytest.raises(ConfigError, match="train_fm trains a LearnedFM, got LearnedIM"):
        train_fm(data, LearnedIM(IMConfig(robot="iiwa14", dof=7)), tiny("fm"))
    with pytest.raises(ConfigError, match="train_im trains a LearnedIM, got LearnedFM"):
        train_im(data, LearnedFM(FMConfig(robot="iiwa14", dof=7)), tiny("im"))


def test_panda_babble_and_train(tmp_path):
    d = babble(BabblingConfig(robot="panda", walkers=100, steps=40, seed=2))
    fm = train_fm(d, fm_config("panda", "tiny"), tiny("fm", epochs=1), run_dir=tmp_path)
    im = train_im(d, im_config("panda", "tiny"), tiny("im", epochs=1), run_dir=tmp_path)
    assert fm.model.layout.size == im.model.layout.size == 10
    assert load_fm(tmp_path / "fm.pt", robot="panda").robot_name == "panda"
    assert load_im(tmp_path / "im.pt", robot="panda").dof == 7
    with pytest.raises(DatasetError, match="panda"):
        train_fm(d, fm_config("iiwa14", "tiny"), tiny("fm", epochs=1))


def test_training_writes_metrics_and_a_loadable_checkpoint(data, tmp_path):
    train_fm(data, fm_config("iiwa14", "tiny"), tiny("fm", epochs=2), run_dir=tmp_path)
    records = [json.loads(line) for line in (tmp_path / "metrics.jsonl").read_text().splitlines()]
    assert [r["epoch"] for r in records] == [1, 2]
    assert {"train_loss", "val_loss", "val_ef_mae_mm", "val_joints_mae_rad", "lr"} <= set(records[0])
    fm = load_fm(tmp_path / "fm.pt", robot="iiwa14")
    assert isinstance(fm, LearnedFM) and fm.config.normalize


def test_resume_continues_from_the_saved_epoch_and_matches_an_uninterrupted_run(data, tmp_path):
    small = data.subset(slice(0, 6000))
    whole = train_im(small, im_config("iiwa14", "tiny"), tiny("im", epochs=3), run_dir=tmp_path / "a")
    # "Interrupted" after 2 epochs, then resumed to 3.
    train_im(small, im_config("iiwa14", "tiny"), tiny("im", epochs=2), run_dir=tmp_path / "b")
    resumed = train_im(
        small, im_config("iiwa14", "tiny"), tiny("im", epochs=3), run_dir=tmp_path / "b", resume=True
    )
    assert [r["epoch"] for r in resumed.history] == [1, 2, 3]
    lines = (tmp_path / "b" / "metrics.jsonl").read_text().splitlines()
    assert [json.loads(line)["epoch"] for line in lines] == [1, 2, 3]
    for (name, p), q in zip(
        whole.model.state_dict().items(), resumed.model.state_dict().values(), strict=True
    ):
        assert torch.equal(p, q), name
    # Resuming a finished run trains no further.
    again = train_im(
        small, im_config("iiwa14", "tiny"), tiny("im", epochs=3), run_dir=tmp_path / "b", resume=True
    )
    assert len(again.history) == 3


def test_resume_from_a_foreign_checkpoint_is_refused(data, tmp_path):
    small = data.subset(slice(0, 2000))
    train_fm(small, fm_config("iiwa14", "tiny"), tiny("fm", epochs=1), run_dir=tmp_path)
    (tmp_path / "fm.pt").write_bytes(b"garbage")
    with pytest.raises(CheckpointError):
        train_fm(small, fm_config("iiwa14", "tiny"), tiny("fm", epochs=2), run_dir=tmp_path, resume=True)


# --------------------------------------------------------------------------------------------------
# Validation
# --------------------------------------------------------------------------------------------------


def test_validation_of_the_analytic_models():
    res = validate_models(AnalyticFM("iiwa14"), AnalyticIM("iiwa14", iterations=3), "iiwa14", n=5000, seed=3)
    assert res["n"] == 5000
    assert res["fm_ef_mae_mm"] == 0.0 and res["fm_joints_mae_rad"] < 1e-7
    assert res["im_exec_err_mm_median"] < 0.1
    assert res["fm_ef_mae_mm_identity"] > 10.0 and res["im_action_mae_rad_zero"] > 0.01
    table = format_validation_table([("analytic", res), ("again", res)])
    assert "| FM ef MAE (mm) | 0.000 | 0.000 | 1.100 | ≤ 0.500 |" in table
    only_fm = validate_models(AnalyticFM("ur5"), None, "ur5", n=1000)
    assert "im_action_mae_rad" not in only_fm and "IM action" not in format_validation_table(only_fm)


def test_validation_refuses_a_model_of_another_robot():
    with pytest.raises(ConfigError, match="panda"):
        validate_models(AnalyticFM("panda"), None, "iiwa14", n=100)


# --------------------------------------------------------------------------------------------------
# The difference forward model and the IM trained through the FM
# --------------------------------------------------------------------------------------------------


def test_difference_fm_needs_predict_delta_and_telescopes(gen):
    with pytest.raises(ConfigError, match="predict_delta"):
        fm_config("iiwa14", "paper", ef_mode="difference")
    fm = LearnedFM(fm_config("iiwa14", "improved", fk_hidden=(16,)))
    robot = load_robot("iiwa14")
    theta = robot.sample(4, gen, margin=0.5)
    s = torch.cat((theta, kinematics(robot).position(theta)), dim=-1)
    s0 = s
    with torch.no_grad():
        for _ in range(5):  # a rollout of five steps
            a = 0.05 * torch.randn(4, 7, generator=gen)
            s = torch.cat((s[:, :7] + a, fm(s, a)[:, 7:]), dim=-1)
        # ef(t) = ef(0) + g(θ(t)) − g(θ(0)): the per-step errors do not add up
        expected = s0[:, 7:] + fm._g(s[:, :7]) - fm._g(s0[:, :7])
    assert torch.allclose(s[:, 7:], expected, atol=1e-5)


def test_difference_fm_learns_better_than_the_direct_head(data, fresh):
    def ef_mae(preset_overrides):
        cfg = fm_config("iiwa14", "tiny", **preset_overrides)
        model = train_fm(data, cfg, tiny("fm", epochs=4)).model
        with torch.no_grad():
            return float((model(fresh.s, fresh.a)[:, 7:] - fresh.s_next[:, 7:]).abs().mean())

    assert ef_mae({"ef_mode": "difference", "fk_hidden": (64, 64)}) < ef_mae({})


def test_im_trained_through_the_fm_reaches_targets_better(data, fresh, tmp_path):
    fm = AnalyticFM(load_robot("iiwa14"))  # a perfect FM isolates what the refinement does to the IM
    im = train_im(data, im_config("iiwa14", "tiny"), tiny("im", epochs=3)).model
    L = fresh.layout
    target = fresh.s_next[:, L.ef]

    def reach_mse():
        with torch.no_grad():
            return float((fm(fresh.s, im(fresh.s, target))[:, L.ef] - target).square().sum(-1).mean())

    before = reach_mse()
    learned_fm = LearnedFM(fm_config("iiwa14", "tiny"))
    frozen = {k: v.clone() for k, v in learned_fm.state_dict().items()}
    train_im_distal(data, copy.deepcopy(im), learned_fm, tiny("im", epochs=1))  # the FM stays unchanged
    assert all(torch.equal(frozen[k], v) for k, v in learned_fm.state_dict().items())
    res = train_im_distal(data, im, fm, tiny("im", epochs=3), run_dir=tmp_path)
    assert reach_mse() < 0.5 * before
    assert load_im(res.checkpoint, robot="iiwa14") is not None
    with pytest.raises(ConfigError, match="panda"):
        train_im_distal(data, im, AnalyticFM(load_robot("panda")), tiny("im", epochs=1))
    with pytest.raises(ConfigError, match="action_weight"):
        train_im_distal(data, im, fm, tiny("im", epochs=1), action_weight=-1.0)
    with pytest.raises(ConfigError, match="LearnedIM"):
        train_im_distal(data, AnalyticIM(load_robot("iiwa14")), fm, tiny("im", epochs=1))


# --------------------------------------------------------------------------------------------------
# Resume checks, divergence, and kill -9 during checkpoint writes
# --------------------------------------------------------------------------------------------------


def test_resume_with_another_config_model_or_data_is_refused(data, tmp_path):
    """Case 2 of the resume checks: what a run was trained with is checked, not taken on trust."""
    small = data.subset(slice(0, 2000))
    train_fm(small, fm_config("iiwa14", "tiny"), tiny("fm", epochs=1), run_dir=tmp_path)
    before = (tmp_path / "fm.pt").read_bytes()
    with pytest.raises(CheckpointError, match=r"optim\.lr: 0\.003 → 0\.01"):
        cfg = tiny("fm", epochs=2, optim=OptimConfig("adam", 0.01))
        train_fm(small, fm_config("iiwa14", "tiny"), cfg, run_dir=tmp_path, resume=True)
    with pytest.raises(CheckpointError, match="data_sha256"):
        other = data.subset(slice(2000, 4000))
        train_fm(other, fm_config("iiwa14", "tiny"), tiny("fm", epochs=2), run_dir=tmp_path, resume=True)
    # another architecture: a typed refusal naming the difference, not torch's size-mismatch error
    with pytest.raises(CheckpointError, match=r"model .*predict_delta"):
        train_fm(small, fm_config("iiwa14", "paper"), tiny("fm", epochs=2), run_dir=tmp_path, resume=True)
    assert (tmp_path / "fm.pt").read_bytes() == before  # refused before anything was written
    # a constant-rate run may be extended: the rate does not depend on the number of epochs
    more = train_fm(small, fm_config("iiwa14", "tiny"), tiny("fm", epochs=2), run_dir=tmp_path, resume=True)
    assert [r["epoch"] for r in more.history] == [1, 2]


def test_an_exploding_loss_is_divergence_even_when_finite(data):
    """Case 5: lr = 1e9 gives a huge but finite loss; it is reported, not trained on."""
    from kinlearn.errors import TrainingDivergedError

    cfg = tiny("fm", epochs=2, optim=OptimConfig("sgd", 1e9))
    with pytest.raises(TrainingDivergedError, match="lower the learning rate"):
        train_fm(data.subset(slice(0, 2000)), fm_config("iiwa14", "tiny"), cfg)


#: A process that imports kinlearn once, then runs each command line read from stdin in a forked child
#: (so that each run does not pay for importing torch, seconds, again): prints the child's pid, then
#: its exit status.
_FORKER = """
import os, sys, torch
torch.set_num_threads(1)
torch.optim.Adam([torch.nn.Parameter(torch.zeros(1))])  # its first use imports torch._dynamo (seconds)
from kinlearn.cli.main import main
for line in sys.stdin:
    pid = os.fork()
    if pid == 0:
        sys.stdout = sys.stderr = open(os.devnull, "w")
        os._exit(main(line.rstrip("\\n").split("\\t")))
    print(pid, flush=True)
    print(os.waitpid(pid, 0)[1], flush=True)
"""


def _running(pid: int) -> bool:
    try:
        os.kill(pid, 0)  # the forker reaps its child as soon as it ends
    except ProcessLookupError:
        return False
    return True


def _wait_for_write(run, alive, deadline, after_epoch=0):
    """Poll until ``after_epoch`` epochs are logged and a checkpoint write is in progress (its
    temporary file exists), or the process ends; True if a write was caught."""
    log = run / "metrics.jsonl"
    while alive() and time.monotonic() < deadline:
        if (len(log.read_text().splitlines()) if log.is_file() else 0) >= after_epoch:
            break
        time.sleep(0.005)  # leave the CPU to the training
    while alive() and time.monotonic() < deadline:
        if any(run.glob(".fm.pt.*.tmp")):  # busy: a write lasts about a millisecond
            return True
    return False


@pytest.mark.slow
def test_kill_9_during_checkpoint_writes_then_resume_is_bit_identical(tmp_path):
    """Training is killed with SIGKILL (no clean-up can run) while it writes a checkpoint, three times,
    each time resumed with --resume; the final weights equal an uninterrupted run's bit for bit and
    no temporary file is left behind."""
    import random
    import signal
    import subprocess
    import sys

    from kinlearn.cli.main import main

    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    forker = subprocess.Popen(  # starts (imports) while the uninterrupted run trains
        [sys.executable, "-c", _FORKER], env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    assert main(["babble", "--transitions", "1500", "--walkers", "50", "--run-dir", str(tmp_path / "b")]) == 0
    # many short epochs (3 steps each) make the checkpoint writes a good share of the time
    args = ["train-fm", "--preset", "tiny", "--epochs", "150", "--batch-size", "512", "--validate", "0"]
    args += ["--data", str(tmp_path / "b" / "babbling.npz"), "--no-progress"]
    assert main([*args, "--run-dir", str(tmp_path / "whole")]) == 0

    run = tmp_path / "killed"
    rng = random.Random(0)
    orphans, epoch = 0, 0
    try:
        for attempt in range(3):
            resume = ["--resume"] * (attempt > 0)
            forker.stdin.write("\t".join([*args, "--run-dir", str(run), *resume]) + "\n")
            forker.stdin.flush()
            child = int(forker.stdout.readline())

            # a random moment: inside the checkpoint write after 2 to 8 more epochs
            alive = functools.partial(_running, child)
            if _wait_for_write(run, alive, time.monotonic() + 60, after_epoch=epoch + rng.randint(2, 8)):
                os.kill(child, signal.SIGKILL)
            status = int(forker.stdout.readline())
            assert os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL, f"not killed: {status}"
            orphans += len(list(run.glob(".*.tmp")))
            epoch = torch.load(run / "fm.pt", weights_only=True)["extra"]["step"]
            assert 1 <= epoch < 150
    finally:
        forker.stdin.close()
        forker.wait(timeout=60)
    assert main([*args, "--run-dir", str(run), "--resume"]) == 0
    assert orphans > 0, "no kill landed inside a write"
    assert list(run.rglob("*.tmp")) == []  # the temporary files the kills left are gone
    whole = load_fm(tmp_path / "whole" / "fm.pt")
    resumed = load_fm(run / "fm.pt")
    for (name, a), b in zip(whole.state_dict().items(), resumed.state_dict().values(), strict=True):
        assert torch.equal(a, b), name
    epochs = [json.loads(line)["epoch"] for line in (run / "metrics.jsonl").read_text().splitlines()]
    assert epochs == list(range(1, 151))
