"""The learned collision body: the BodySpheres interface, constant base spheres, training that learns,
checkpoints (round trip, wrong robot, resume), the collision functions taking it, its validation and
the train-body command."""

import argparse
import json
from pathlib import Path

import numpy as np
import pytest
import torch

from kinlearn import load_robot
from kinlearn.collision import body_obstacle_distance, body_spheres, check_path, clearances, in_collision
from kinlearn.data.problems import ProblemSet
from kinlearn.errors import CheckpointError, ConfigError, DatasetError, NonFiniteError, ShapeError
from kinlearn.io import load_checkpoint, save_checkpoint
from kinlearn.models.body import BODY_KIND, BodyModelConfig, LearnedBody, load_body_model, save_body_model
from kinlearn.training.body import HELDOUT_PROBLEMS, train_body_model, validate_body_model

TINY = BodyModelConfig(hidden=(48, 48), epochs=6, batch_size=128, lr=1e-2, samples=3000, val_fraction=0.1)


@pytest.fixture(scope="module")
def analytic(robot):
    return body_spheres(robot)


@pytest.fixture(scope="module")
def untrained():
    torch.manual_seed(0)
    return LearnedBody(TINY).eval()


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    run = tmp_path_factory.mktemp("body")
    return train_body_model(TINY, run, progress=False), run


@pytest.fixture(scope="module")
def problems():
    return ProblemSet.load(HELDOUT_PROBLEMS)[::102]  # 10 problems across the three families


def test_interface_shapes_dtypes_and_copied_geometry(untrained, analytic, robot):
    q64 = robot.sample((4, 5), torch.Generator().manual_seed(0), dtype=torch.float64)
    c64 = untrained(q64)
    assert c64.shape == (4, 5, analytic.num_spheres, 3) and c64.dtype == torch.float64
    c32 = untrained(q64.float())
    assert c32.dtype == torch.float32
    assert torch.allclose(c32.double(), c64, atol=1e-5)
    assert untrained(q64[0, 0]).shape == (analytic.num_spheres, 3)
    assert torch.equal(untrained(q64.numpy()), c64)  # numpy joints are taken too
    assert untrained.num_spheres == analytic.num_spheres and untrained.robot.name == "iiwa14"
    for key in ("radii", "link", "pairs", "floor_mask", "lever"):
        assert torch.equal(getattr(untrained, key), getattr(analytic, key)), key
    assert untrained.radii_like(c32).dtype == torch.float32
    with pytest.raises(ShapeError):
        untrained(torch.zeros(3, 6))
    with pytest.raises(NonFiniteError):
        untrained(torch.full((2, 7), float("nan")))


def test_base_spheres_are_the_analytic_constants(untrained, analytic, robot):
    q = robot.sample(64, torch.Generator().manual_seed(1), dtype=torch.float64)
    nb = int((analytic.link == 0).sum())
    assert nb > 0
    c, ref = untrained(q), analytic(q)
    assert torch.equal(c[:, :nb], ref[:, :nb])
    assert not torch.allclose(c[:, nb:], ref[:, nb:], atol=1e-2)  # the rest is learned (untrained here)


def test_differentiable_in_the_joints(untrained, robot):
    q = robot.sample(3, torch.Generator().manual_seed(2), dtype=torch.float64).requires_grad_(True)
    untrained(q).square().sum().backward()
    assert q.grad is not None and bool(torch.isfinite(q.grad).all()) and float(q.grad.abs().sum()) > 0


def test_margin_inflates_the_radii(analytic):
    body = LearnedBody(TINY)
    body.set_margin(0.004)
    assert torch.allclose(body.radii, analytic.radii + 0.004) and float(body.margin) == pytest.approx(0.004)
    body.set_margin(0.0)
    assert torch.equal(body.radii, analytic.radii)
    for bad in (-0.001, float("nan"), float("inf")):
        with pytest.raises(ConfigError):
            body.set_margin(bad)


def test_config_rejects_bad_values():
    for bad in ({"hidden": ()}, {"hidden": (8, 0)}, {"activation": "sigmoid"}, {"epochs": 0}, {"lr": -1.0}):
        with pytest.raises(ConfigError):
            BodyModelConfig(**bad)
    with pytest.raises(ConfigError):
        BodyModelConfig.from_dict({**TINY.to_dict(), "colour": "red"})
    assert BodyModelConfig.from_dict(TINY.to_dict()) == TINY


def test_training_reduces_the_centre_error(trained, untrained):
    result, run = trained
    hist = result.history
    assert len(hist) == TINY.epochs and (run / "metrics.jsonl").is_file()
    assert hist[-1]["val_centre_err_mm"] < 0.5 * hist[0]["val_centre_err_mm"]
    before = validate_body_model(untrained, n=2000, seed=5, problems=None)
    after = validate_body_model(result.model, n=2000, seed=5, problems=None)
    assert after["centre_err_mm_mean"] < 0.3 * before["centre_err_mm_mean"]


def test_save_load_round_trip_and_wrong_robot(trained, tmp_path, robot):
    model = trained[0].model
    q = robot.sample(16, torch.Generator().manual_seed(3), dtype=torch.float64)
    model.set_margin(0.003)
    try:
        path = save_body_model(model, tmp_path / "body.pt")
        back = load_body_model(path, robot)
        assert torch.equal(back(q), model(q)) and torch.equal(back.radii, model.radii)
        assert back.config == model.config and float(back.margin) == pytest.approx(0.003)
        assert load_body_model(path, "iiwa14") is not None
        with pytest.raises(CheckpointError, match="panda"):
            load_body_model(path, "panda")
        # The training checkpoint (weights + optimiser state) loads as a model too.
        assert torch.equal(load_body_model(trained[1] / "body.pt")(q), model.set_margin(0.0)(q))
    finally:
        model.set_margin(0.0)
    payload = load_checkpoint(path, kind=BODY_KIND)
    newer = tmp_path / "newer.pt"
    save_checkpoint(
        newer,
        kind=BODY_KIND,
        robot="iiwa14",
        config={**payload["config"], "body_format": 99},
        state_dict=payload["state_dict"],
    )
    with pytest.raises(CheckpointError, match="format"):
        load_body_model(newer)
    changed = tmp_path / "changed.pt"
    sd = dict(payload["state_dict"])
    sd["radii"] = sd["radii"] * 1.5  # geometry unlike the bundled sphere model
    save_checkpoint(changed, kind=BODY_KIND, robot="iiwa14", config=payload["config"], state_dict=sd)
    with pytest.raises(CheckpointError, match="sphere model"):
        load_body_model(changed)
    with pytest.raises(CheckpointError):
        load_body_model(tmp_path / "missing.pt")


def test_resume_reproduces_an_uninterrupted_run(tmp_path, monkeypatch):
    cfg = BodyModelConfig(hidden=(16,), epochs=4, batch_size=256, lr=5e-3, samples=1000, seed=3)
    whole = train_body_model(cfg, tmp_path / "whole", progress=False)

    import kinlearn.training.body as bm

    real_save, saves = bm.save_body_model, []

    def dying_save(model, path, extra=None):
        if len(saves) == 2:
            raise KeyboardInterrupt  # killed during epoch 3: the checkpoint holds epoch 2
        saves.append(extra["step"])
        return real_save(model, path, extra)

    monkeypatch.setattr(bm, "save_body_model", dying_save)
    with pytest.raises(KeyboardInterrupt):
        train_body_model(cfg, tmp_path / "cut", progress=False)
    monkeypatch.setattr(bm, "save_body_model", real_save)
    assert load_checkpoint(tmp_path / "cut" / "body.pt", kind=BODY_KIND)["extra"]["step"] == 2
    resumed = train_body_model(cfg, tmp_path / "cut", progress=False, resume=True)
    for key, value in whole.model.state_dict().items():
        assert torch.equal(value, resumed.model.state_dict()[key]), key
    assert [h["epoch"] for h in resumed.history] == [1, 2, 3, 4]
    lines = (tmp_path / "cut" / "metrics.jsonl").read_text().splitlines()
    assert [json.loads(x)["epoch"] for x in lines] == [1, 2, 3, 4]
    with pytest.raises(CheckpointError):  # another configuration
        train_body_model(
            BodyModelConfig(**{**cfg.to_dict(), "hidden": (8,)}),
            tmp_path / "cut",
            progress=False,
            resume=True,
        )
    other = load_robot("iiwa14").sample(1000, torch.Generator().manual_seed(9), dtype=torch.float64)
    with pytest.raises(CheckpointError, match="data"):  # other data
        train_body_model(cfg, tmp_path / "cut", other, progress=False, resume=True)


def test_training_data_sources(tmp_path, robot):
    from kinlearn.data.babbling import BabblingConfig, babble

    data = babble(BabblingConfig(walkers=20, steps=40, seed=1))
    cfg = BodyModelConfig(hidden=(8,), epochs=1, samples=10, batch_size=64)
    path = data.save(tmp_path / "babbling.npz")
    res = train_body_model(cfg, None, path, progress=False)
    assert res.data["source"] == "babbling" and res.data["configurations"] == len(data)
    assert res.checkpoint is None
    with pytest.raises(DatasetError):  # a babbling file of another robot
        train_body_model(BodyModelConfig(**{**cfg.to_dict(), "robot": "panda"}), None, path, progress=False)
    with pytest.raises(ShapeError):
        train_body_model(cfg, None, torch.zeros(10, 6), progress=False)
    with pytest.raises(DatasetError):
        train_body_model(cfg, None, [[0.0] * 7], progress=False)


def test_collision_functions_take_the_learned_body(trained, analytic, problems):
    model = trained[0].model
    lines = torch.stack((problems.start, problems.goal), dim=1)
    res = check_path(model, lines, problems.scene)
    ref = check_path(analytic, lines, problems.scene)
    assert res.collision_free.shape == (len(problems),) and res.collision_free.dtype == torch.bool
    assert torch.equal(res.checked, ref.checked)  # the same travel bounds: the same checked configurations
    q = problems.start.clone().requires_grad_(True)
    d, s = clearances(model, q, problems.scene)
    (d.sum() + s.sum()).backward()
    assert d.shape == s.shape == (len(problems),) and bool(torch.isfinite(q.grad).all())
    c = model(problems.start)
    assert (
        body_obstacle_distance(c, model.radii, problems.scene, floor_mask=model.floor_mask).shape == d.shape
    )
    try:  # a margin of a metre: every configuration collides
        model.set_margin(1.0)
        assert not bool(check_path(model, lines, problems.scene).collision_free.any())
        assert bool(in_collision(model, problems.start, problems.scene).all())
    finally:
        model.set_margin(0.0)


def test_validation_keys_and_values(trained, untrained, problems):
    model = trained[0].model
    res = validate_body_model(model, n=1000, seed=7, problems=problems, configs_per_scene=8)
    ref = validate_body_model(untrained, n=1000, seed=7, problems=problems, configs_per_scene=8)
    for key in ("centre_err_mm_mean", "centre_err_mm_p99", "centre_err_mm_max"):
        assert np.isfinite(res[key]) and res[key] < ref[key], key
    assert res["centre_err_mm_mean"] <= res["centre_err_mm_p99"] <= res["centre_err_mm_max"]
    assert len(res["centre_err_mm_p99_by_link"]) == 7
    assert res["configs_n"] == 8 * len(problems) and res["lines_n"] == len(problems)
    for what in ("configs", "lines"):
        for key in ("collision_rate", "false_free_rate", "false_collision_rate", "agreement"):
            value = res[f"{what}_{key}"]
            assert value is None or 0.0 <= value <= 1.0, (what, key)
        assert res[f"{what}_false_free"] + res[f"{what}_false_collision"] <= res[f"{what}_n"]
    # The analytic body's verdict on the straight lines is the problem set's "hard" flag.
    assert res["lines_collision_rate"] == pytest.approx(float(problems.hard.double().mean()))
    # The learned body agrees with the analytic one more often than chance would.
    assert res["configs_agreement"] >= ref["configs_agreement"] - 1e-12
    json.dumps(res)  # JSON-able
    with pytest.raises(ConfigError):
        validate_body_model(model, body_spheres(load_robot("iiwa14"), dense=True), n=10, problems=None)


def test_train_body_command(tmp_path, problems):
    from kinlearn.cli.body import register

    parser = argparse.ArgumentParser()
    register(parser.add_subparsers())
    few = problems.save(tmp_path / "few.npz")
    run = tmp_path / "run"
    argv = ["train-body", "--run-dir", str(run), "--samples", "1500", "--epochs", "2", "--hidden", "16"]
    argv += ["--validate", "500", "--problems", str(few), "--margin", "p99", "--no-progress"]
    args = parser.parse_args(argv)
    assert args.run(args) == 0
    res = json.loads((run / "validation.json").read_text())
    assert res["margin_mm"] == 0.0 and res["with_margin"]["margin_mm"] == pytest.approx(
        res["centre_err_mm_p99"]
    )
    body = load_body_model(run / "body.pt", "iiwa14")
    assert float(body.margin) * 1e3 == pytest.approx(res["centre_err_mm_p99"])
    assert json.loads((run / "config.json").read_text())["command"] == "train-body"
    with pytest.raises(SystemExit):
        parser.parse_args(["train-body", "--hidden", "16,x"])
    with pytest.raises(SystemExit):
        parser.parse_args(["train-body", "--margin", "-1"])


def test_shipped_body_model_if_present():
    path = Path(__file__).resolve().parents[1] / "kinlearn" / "checkpoints" / "iiwa14" / "body.pt"
    if not path.is_file():
        pytest.skip("no shipped body model")
    body = load_body_model(path, "iiwa14")
    assert path.stat().st_size <= 300_000
    res = validate_body_model(body.set_margin(0.0), n=2000, seed=11, problems=None)
    assert res["centre_err_mm_p99"] < 10.0
