"""The one training loop: resume equals an uninterrupted run, one checkpoint format (earlier ones still
resume), refusals of another configuration, divergence; and the imitation trainer that runs in it."""

import json

import pytest
import torch

from kinlearn.data.endpoints import EndpointConfig, make_endpoints
from kinlearn.errors import CheckpointError, TrainingDivergedError
from kinlearn.io import load_checkpoint, save_checkpoint
from kinlearn.training import imitation
from kinlearn.training.imitation import load_imitation, train_imitation
from kinlearn.training.loop import OptimConfig, TrainingLoop

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


def _same(a: torch.nn.Module, b: torch.nn.Module) -> bool:
    pairs = zip(a.state_dict().values(), b.state_dict().values(), strict=True)
    return all(torch.equal(x, y) for x, y in pairs)


def _regression(run_dir, *, iterations=6, lr=0.05, resume=True, die_at=None, seed=0):
    """A linear model fitted by a :class:`TrainingLoop` of ``iterations`` iterations (a record and a
    checkpoint every second one); ``die_at``: interrupt the run in that iteration."""
    torch.manual_seed(seed)
    model = torch.nn.Linear(3, 1)
    gen = torch.Generator().manual_seed(seed)
    w = torch.tensor([[1.0], [-2.0], [0.5]])

    def save(path, extra):
        save_checkpoint(
            path, kind="test", robot="none", config={}, state_dict=model.state_dict(), extra=extra
        )

    loop = TrainingLoop(
        model,
        OptimConfig("adam", lr),
        total=iterations,
        generator=gen,
        train_config={"lr": lr, "iterations": iterations, "schedule": "cosine"},
        schedule="cosine",
        unit="iteration",
        record_every=2,
        run_dir=run_dir,
        checkpoint=run_dir / "model.pt",
        save=save,
        progress=False,
    )
    if resume:
        loop.resume(lambda path: load_checkpoint(path, kind="test"))

    def step(i):
        if i == die_at:
            raise KeyboardInterrupt
        x = torch.randn(16, 3, generator=gen)
        return {"loss": float(loop.step((model(x) - x @ w).square().mean(), check=True))}

    return model, loop.run(step)


def test_a_resumed_loop_ends_where_an_uninterrupted_one_does(tmp_path):
    whole, history = _regression(tmp_path / "whole")
    assert [r["iteration"] for r in history] == [2, 4, 6]
    with pytest.raises(KeyboardInterrupt):
        _regression(tmp_path / "cut", die_at=4)  # its checkpoint holds iteration 4
    extra = load_checkpoint(tmp_path / "cut" / "model.pt", kind="test")["extra"]
    assert set(extra) == STATE_KEYS and (extra["step"], extra["unit"]) == (4, "iteration")
    resumed, history = _regression(tmp_path / "cut")
    assert _same(whole, resumed)
    assert [r["iteration"] for r in history] == [2, 4, 6]
    lines = (tmp_path / "cut" / "metrics.jsonl").read_text().splitlines()
    assert [json.loads(x)["iteration"] for x in lines] == [2, 4, 6]
    # without resume the run starts over, its log too
    again, history = _regression(tmp_path / "cut", resume=False)
    assert _same(whole, again) and len((tmp_path / "cut" / "metrics.jsonl").read_text().splitlines()) == 3


def test_a_checkpoint_of_an_earlier_format_resumes(tmp_path):
    """Before the one loop: the counter was named for its unit, and no schedule or torch state was kept
    (the FM/IM trainer set its rate by hand); the schedule is rebuilt from the counter."""
    whole, _ = _regression(tmp_path / "whole")
    with pytest.raises(KeyboardInterrupt):
        _regression(tmp_path / "cut", die_at=4)
    path = tmp_path / "cut" / "model.pt"
    payload = load_checkpoint(path, kind="test")
    extra = {k: v for k, v in payload["extra"].items() if k not in ("step", "unit", "scheduler", "torch_rng")}
    for group in extra["optimizer"]["param_groups"]:
        del group["initial_lr"]
    save_checkpoint(
        path,
        kind="test",
        robot="none",
        config={},
        state_dict=payload["state_dict"],
        extra={**extra, "epoch": 4},
    )
    resumed, _ = _regression(tmp_path / "cut")
    assert _same(whole, resumed)


def test_the_loop_refuses_another_configuration_or_no_training_state(tmp_path):
    _regression(tmp_path, iterations=2)
    before = (tmp_path / "model.pt").read_bytes()
    with pytest.raises(CheckpointError, match=r"another configuration \(lr: 0\.05 → 0\.1\)"):
        _regression(tmp_path, iterations=2, lr=0.1)
    assert (tmp_path / "model.pt").read_bytes() == before  # refused before anything was written
    torch.manual_seed(0)
    save_checkpoint(
        tmp_path / "model.pt",
        kind="test",
        robot="none",
        config={},
        state_dict=torch.nn.Linear(3, 1).state_dict(),
    )
    with pytest.raises(CheckpointError, match="no training state"):
        _regression(tmp_path, iterations=2)


def test_divergence_is_raised_by_the_loop(tmp_path):
    with pytest.raises(TrainingDivergedError, match=r"diverged at iteration \d+.*lower the learning rate"):
        _regression(tmp_path, iterations=40, lr=1e9)


# --------------------------------------------------------------------------------------------------
# The imitation trainer in the loop
# --------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def pairs():
    return make_endpoints(EndpointConfig(n=48, seed=5))


FAST = OptimConfig(name="adam", lr=1e-2)


def test_imitation_resumes_to_the_uninterrupted_weights(pairs, tmp_path, monkeypatch):
    kw = dict(epochs=3, batch_size=16, optim=FAST, seed=1, progress=False)
    plain_history: list[float] = []
    plain = train_imitation(pairs, history=plain_history, **kw)  # no run folder: nothing written
    whole = train_imitation(pairs, run_dir=tmp_path / "whole", **kw)
    assert _same(plain, whole)
    real, saves = imitation.save_checkpoint, []

    def dying(path, **fields):
        if len(saves) == 2:
            raise KeyboardInterrupt  # killed during epoch 3: the checkpoint holds epoch 2
        saves.append(fields["extra"]["step"])
        return real(path, **fields)

    monkeypatch.setattr(imitation, "save_checkpoint", dying)
    with pytest.raises(KeyboardInterrupt):
        train_imitation(pairs, run_dir=tmp_path / "cut", **kw)
    monkeypatch.setattr(imitation, "save_checkpoint", real)
    history: list[float] = []
    resumed = train_imitation(pairs, run_dir=tmp_path / "cut", history=history, **kw)
    assert saves == [1, 2] and _same(whole, resumed)
    assert history == plain_history and len(history) == 3
    lines = (tmp_path / "cut" / "metrics.jsonl").read_text().splitlines()
    assert [json.loads(x)["epoch"] for x in lines] == [1, 2, 3]
    payload = load_checkpoint(tmp_path / "cut" / "imitation.pt", kind="tm-imitation", robot="iiwa14")
    assert STATE_KEYS <= set(payload["extra"]) and payload["extra"]["step"] == 3
    assert _same(load_imitation(tmp_path / "cut" / "imitation.pt"), whole)


def test_imitation_refuses_to_resume_another_run(pairs, tmp_path):
    kw = dict(epochs=1, batch_size=16, seed=1, progress=False, run_dir=tmp_path)
    train_imitation(pairs, optim=FAST, **kw)
    with pytest.raises(CheckpointError, match=r"optim\.lr: 0\.01 → 0\.02"):
        train_imitation(pairs, optim=OptimConfig(name="adam", lr=2e-2), **kw)
    with pytest.raises(CheckpointError, match="data_sha256"):
        train_imitation(make_endpoints(EndpointConfig(n=48, seed=6)), optim=FAST, **kw)
    train_imitation(make_endpoints(EndpointConfig(n=48, seed=6)), optim=FAST, resume=False, **kw)


def test_imitation_divergence_is_a_typed_error(pairs):
    with pytest.raises(TrainingDivergedError, match="imitation TM training diverged at epoch"):
        train_imitation(pairs, epochs=3, batch_size=16, optim=OptimConfig("sgd", 1e6), progress=False)
