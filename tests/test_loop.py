"""kinlearn.training.loop: resume equals an uninterrupted run, one checkpoint format (earlier ones still
resume), refusals of another configuration, divergence; optimisers, schedules, seeding, the run log and
the generic fit. (The trainers that run in the loop are tested beside their modules.)"""

import json

import numpy as np
import pytest
import torch

from kinlearn.errors import CheckpointError, ConfigError, DatasetError, TrainingDivergedError
from kinlearn.io import load_checkpoint, save_checkpoint
from kinlearn.training.loop import (
    OptimConfig,
    RunLogger,
    TrainConfig,
    TrainingLoop,
    fit,
    make_optimizer,
    seed_everything,
)

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
# Optimisers, schedules, seeding, the run log, the generic fit
# --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("cfg", "cls"),
    [
        (OptimConfig("adam", 1e-3), torch.optim.Adam),
        (OptimConfig("adamw", 1e-3, weight_decay=4e-3), torch.optim.AdamW),
        (OptimConfig("rmsprop", 1e-3, alpha=0.9, momentum=0.5), torch.optim.RMSprop),
        (OptimConfig("sgd", 0.5, momentum=0.9), torch.optim.SGD),
    ],
)
def test_make_optimizer(cfg, cls):
    p = torch.nn.Parameter(torch.zeros(3))
    opt = make_optimizer(cfg, [p])
    assert isinstance(opt, cls)
    group = opt.param_groups[0]
    assert group["lr"] == cfg.lr and group["weight_decay"] == cfg.weight_decay
    if cfg.name == "rmsprop":
        assert group["alpha"] == 0.9 and group["momentum"] == 0.5


@pytest.mark.parametrize(
    "kwargs",
    [
        {"name": "lbfgs"},
        {"lr": 0.0},
        {"lr": -1.0},
        {"lr": float("nan")},
        {"lr": float("inf")},
        {"alpha": 1.0},
        {"weight_decay": -1.0},
    ],
)
def test_bad_optim_config(kwargs):
    with pytest.raises(ConfigError):
        OptimConfig(**kwargs)


def test_bad_train_config():
    for kwargs in ({"epochs": 0}, {"val_fraction": 1.0}, {"schedule": "step"}, {"min_lr_ratio": 2.0}):
        with pytest.raises(ConfigError):
            TrainConfig(**kwargs)


def test_cosine_schedule():
    cfg = TrainConfig(optim=OptimConfig(lr=1.0), schedule="cosine", min_lr_ratio=0.1)
    assert cfg.lr_at(0, 101) == 1.0
    assert cfg.lr_at(50, 101) == pytest.approx(0.55)
    assert cfg.lr_at(100, 101) == pytest.approx(0.1)


def test_seed_everything():
    g = seed_everything(5)
    a = (torch.rand(3), np.random.rand(), torch.rand(2, generator=g))  # noqa: NPY002
    g = seed_everything(5)
    b = (torch.rand(3), np.random.rand(), torch.rand(2, generator=g))  # noqa: NPY002
    assert torch.equal(a[0], b[0]) and a[1] == b[1] and torch.equal(a[2], b[2])


def test_run_logger(tmp_path):
    with RunLogger(tmp_path / "run") as log:
        log.log({"epoch": 1, "loss": 0.5})
        log.log({"epoch": 2, "loss": 0.25, "note": "x"})
    lines = (tmp_path / "run" / "metrics.jsonl").read_text().splitlines()
    assert [json.loads(line)["loss"] for line in lines] == [0.5, 0.25]


def test_fit_is_generic_and_rejects_mismatched_tensors():
    torch.manual_seed(0)
    x = torch.randn(512, 2)
    y = x @ torch.tensor([[2.0], [-1.0]])
    model = torch.nn.Linear(2, 1)
    cfg = TrainConfig(optim=OptimConfig("sgd", 0.1), epochs=20, batch_size=64, progress=False)
    hist = fit(model, (x, y), (x, y), cfg, loss_fn=lambda m, a, b: (m(a) - b).square().mean())
    assert len(hist) == 20 and hist[-1]["val_loss"] < 1e-4
    with pytest.raises(DatasetError):
        fit(model, (x, y[:5]), None, cfg, loss_fn=lambda m, a, b: m(a).sum())


def test_one_schedule_for_every_trainer():
    from kinlearn.training.loop import make_schedule

    p = torch.nn.Parameter(torch.zeros(1))
    opt = torch.optim.SGD([p], lr=2.0)
    sched = make_schedule(opt, "cosine", 4)
    rates = []
    for _ in range(6):
        rates.append(sched.get_last_lr()[0])
        opt.step()
        sched.step()
    assert rates == pytest.approx([2.0, 1.0 + 2**-0.5, 1.0, 1.0 - 2**-0.5, 0.0, 0.0])
    constant = make_schedule(torch.optim.SGD([p], lr=0.5), "constant", 4)
    assert constant.get_last_lr() == [0.5]
    with pytest.raises(ConfigError, match="constant' or 'cosine"):
        make_schedule(opt, "linear", 4)
