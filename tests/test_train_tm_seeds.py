"""Seeds trained in lockstep are the runs train_tm makes one by one."""

import dataclasses
import json

import pytest
import torch

from kinlearn.data.endpoints import EndpointConfig, make_endpoints
from kinlearn.errors import CheckpointError, ConfigError, TrainingDivergedError
from kinlearn.io import load_checkpoint, save_checkpoint
from kinlearn.models.trajectory import TMConfig, TrajectoryModel
from kinlearn.planning.planner import Planner
from kinlearn.training.loop import OptimConfig
from kinlearn.training.tm import load_tm, tm_preset, train_tm
from kinlearn.training.tm_seeds import stacked_forward, train_tm_seeds


@pytest.fixture(scope="module")
def pairs():
    return make_endpoints(EndpointConfig(robot="iiwa14", n=96, seed=5))


def _config(**over):
    over = {"fm": "analytic", "im": "analytic", "epochs": 2, "batch_size": 32, **over}
    return tm_preset("paper", loss="paper", **{"optim": OptimConfig(name="adam", lr=1e-3), **over})


def _max_diff(a: torch.nn.Module, b: torch.nn.Module) -> float:
    sa, sb = a.state_dict(), b.state_dict()
    assert sa.keys() == sb.keys()
    return max(float((sa[k].double() - sb[k].double()).abs().max()) for k in sa)


@pytest.mark.parametrize("h0", ["zeros", "learned"])
def test_stacked_forward_is_each_members_forward(h0, pairs):
    members = []
    for seed in (0, 1, 2):
        torch.manual_seed(seed)
        tm = TrajectoryModel(TMConfig(h0=h0))
        tm.fit_normalization(pairs.start, pairs.goal)
        if h0 == "learned":
            torch.nn.init.normal_(tm.h0)
        members.append(tm)
    s0 = torch.stack([pairs.start[k : k + 8] for k in (0, 8, 16)])
    sT = torch.stack([pairs.goal[k : k + 8] for k in (0, 8, 16)])
    out = stacked_forward(members, s0, sT)
    for m, tm in enumerate(members):
        torch.testing.assert_close(out[m], tm(s0[m], sT[m]), atol=1e-6, rtol=1e-5)


def test_lockstep_seeds_match_separate_runs_and_resume(tmp_path, pairs):
    cfg = _config()
    dirs = [tmp_path / "lock" / f"s{s}" for s in (3, 4)]
    runs = train_tm_seeds(cfg, [3, 4], dirs, pairs, progress=False)
    for seed, d in zip((3, 4), dirs, strict=True):
        alone = train_tm(
            dataclasses.replace(cfg, seed=seed), tmp_path / f"alone{seed}", pairs, progress=False
        )
        assert _max_diff(runs[seed], alone) < 1e-5
        # the run folder is train_tm's: a planner loads it, its log and config are there
        loaded, loaded_cfg = load_tm(d / "tm.pt")
        assert loaded_cfg.seed == seed and _max_diff(loaded, alone) < 1e-5
        assert len((d / "metrics.jsonl").read_text().splitlines()) == cfg.epochs
        assert json.loads((d / "config.json").read_text())["seed"] == seed
        Planner.load(d)
    # one epoch, then a resumed second one, ends where the two epochs in one go ended
    part = [tmp_path / "part" / f"s{s}" for s in (3, 4)]
    train_tm_seeds(dataclasses.replace(cfg, epochs=1), [3, 4], part, pairs, progress=False)
    with pytest.raises(CheckpointError, match="another configuration"):
        train_tm_seeds(_config(batch_size=16), [3, 4], part, pairs, progress=False)
    resumed = train_tm_seeds(cfg, [3, 4], part, pairs, progress=False)
    for seed in (3, 4):
        assert _max_diff(resumed[seed], runs[seed]) < 1e-6
    # a member's checkpoint is train_tm's too: it resumes there as well
    more = train_tm(dataclasses.replace(cfg, seed=3, epochs=3), part[0], pairs, progress=False)
    assert _max_diff(more, runs[3]) > 0


def test_diverging_seeds_stop_and_say_why(tmp_path, pairs):
    cfg = _config(optim=OptimConfig(name="sgd", lr=1e4))
    dirs = [tmp_path / f"s{s}" for s in (0, 1)]
    runs = train_tm_seeds(cfg, [0, 1], dirs, pairs, progress=False)
    for seed, d in zip((0, 1), dirs, strict=True):
        assert isinstance(runs[seed], TrainingDivergedError)
        assert "diverged" in json.loads((d / "diverged.json").read_text())["reason"]


def test_lockstep_refuses_what_it_cannot_train(tmp_path, pairs):
    with pytest.raises(ConfigError, match="one-layer"):
        train_tm_seeds(_config(tm={"gru_layers": 2}), [0, 1], [tmp_path / "a", tmp_path / "b"], pairs)
    with pytest.raises(ConfigError, match="trainable"):
        train_tm_seeds(_config(trainable="shared"), [0, 1], [tmp_path / "a", tmp_path / "b"], pairs)
    with pytest.raises(ConfigError, match="TM config is for 'panda'"):
        other = dataclasses.replace(_config(), tm=TMConfig(robot="panda", dof=7))
        train_tm_seeds(other, [0, 1], [tmp_path / "a", tmp_path / "b"], pairs)
    with pytest.raises(ConfigError, match="one run folder per seed"):
        train_tm_seeds(_config(), [0, 0], [tmp_path / "a", tmp_path / "b"], pairs)


def test_checkpoints_from_before_the_model_training_split_still_load_and_resume(tmp_path, pairs):
    """tm.pt used to store the whole training config as its config; such runs load, plan and resume."""
    cfg = _config(epochs=1)
    run = tmp_path / "old"
    train_tm(cfg, run, pairs, progress=False)
    new = load_checkpoint(run / "tm.pt", kind="tm")
    old_extra = {k: v for k, v in new["extra"].items() if k != "train_config"}
    save_checkpoint(
        run / "tm.pt",
        kind="tm",
        robot=new["robot"],
        config=new["extra"]["train_config"],
        state_dict=new["state_dict"],
        extra=old_extra,
    )
    _, loaded_cfg = load_tm(run / "tm.pt")
    assert loaded_cfg.optim == cfg.optim and loaded_cfg.epochs == 1
    Planner.load(run)
    more = train_tm(dataclasses.replace(cfg, epochs=2), run, pairs, progress=False)  # resumes epoch 2
    again = train_tm(dataclasses.replace(cfg, epochs=2), tmp_path / "fresh", pairs, progress=False)
    assert _max_diff(more, again) < 1e-6
    assert "optim" not in load_checkpoint(run / "tm.pt", kind="tm")["config"]  # rewritten in the new form
    # an old run naming a learned FM it recorded by no identity, with none beside it: a typed error
    lost = tmp_path / "lost"
    lost.mkdir()
    save_checkpoint(
        lost / "tm.pt",
        kind="tm",
        robot=new["robot"],
        config={**new["extra"]["train_config"], "fm": "learned", "models_dir": str(tmp_path / "gone")},
        state_dict=new["state_dict"],
    )
    with pytest.raises(CheckpointError, match=r"cannot find the fm\.pt"):
        Planner.load(lost)
