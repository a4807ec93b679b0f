"""Checkpoint format 2: content hash, dependencies by identity, atomic writes; inputs at the API boundary."""

import os
import shutil
import subprocess
import sys

import numpy as np
import pytest
import torch

import kinlearn
from kinlearn import CheckpointError, ConfigError, ShapeError, UnknownRobotError
from kinlearn.data.babbling import BabblingConfig, babble
from kinlearn.data.endpoints import EndpointConfig, make_endpoints
from kinlearn.errors import DTypeError, UnverifiedCheckpointWarning
from kinlearn.io import (
    CHECKPOINT_FORMAT,
    atomic_write,
    content_sha256,
    file_sha256,
    half_weights,
    load_checkpoint,
    remove_stale_tmp,
    resolve_dependency,
    save_checkpoint,
)
from kinlearn.models.forward_inverse import LearnedFM, fm_config, im_config, load_fm
from kinlearn.planning.planner import DEFAULT_CHECKPOINTS, Planner
from kinlearn.training.forward_inverse import train_config, train_fm, train_im
from kinlearn.training.tm import build_fm_im, load_tm, tm_preset, train_tm


def _save_fm(path, **kw):
    model = LearnedFM(fm_config("iiwa14", "tiny"))
    return save_checkpoint(
        path, kind="fm", robot="iiwa14", config={"type": "learned"}, state_dict=model.state_dict(), **kw
    ), model


# --------------------------------------------------------------------------------------------------
# Content hash
# --------------------------------------------------------------------------------------------------


def test_flipped_bytes_in_the_weights_are_detected(tmp_path):
    """Case 3: 64 bytes flipped inside a weight tensor of a checkpoint no longer load silently."""
    path, model = _save_fm(tmp_path / "fm.pt")
    payload = load_checkpoint(path, kind="fm")
    assert payload["format"] == CHECKPOINT_FORMAT == 2 and len(payload["sha256"]) == 64
    raw = bytearray(path.read_bytes())
    weight = max(model.state_dict().values(), key=lambda t: t.numel())
    at = raw.find(weight.numpy().tobytes())
    assert at > 0
    raw[at + 8 : at + 72] = bytes(b ^ 0x5A for b in raw[at + 8 : at + 72])
    (tmp_path / "flipped.pt").write_bytes(raw)
    with pytest.raises(CheckpointError, match="corrupt or was modified"):
        load_checkpoint(tmp_path / "flipped.pt", kind="fm")
    # an edit through torch.save (a plausible-looking checkpoint) is detected as well
    payload["state_dict"][next(iter(payload["state_dict"]))] += 1e-3
    torch.save(payload, tmp_path / "edited.pt")
    with pytest.raises(CheckpointError, match="corrupt or was modified"):
        load_checkpoint(tmp_path / "edited.pt", kind="fm")


def test_format_1_still_loads_and_unknown_formats_are_refused(tmp_path):
    model = LearnedFM(fm_config("iiwa14", "tiny"))
    old = {"format": 1, "kind": "fm", "robot": "iiwa14", "config": {}, "state_dict": model.state_dict()}
    torch.save(old, tmp_path / "v1.pt")
    with pytest.warns(UnverifiedCheckpointWarning, match="cannot be verified"):
        assert load_checkpoint(tmp_path / "v1.pt", kind="fm")["depends"] == {}
    old["state_dict"][next(iter(old["state_dict"]))] += 1.0  # tampered: nothing can tell, so it warns
    torch.save(old, tmp_path / "v1.pt")
    with pytest.raises(CheckpointError, match="strict"):
        load_checkpoint(tmp_path / "v1.pt", kind="fm", strict=True)
    torch.save({**old, "format": 99}, tmp_path / "v99.pt")
    with pytest.raises(CheckpointError, match="format 99"):
        load_checkpoint(tmp_path / "v99.pt", kind="fm")
    # the planner shipped inside the package loads whatever its format
    shipped = load_checkpoint(DEFAULT_CHECKPOINTS / "iiwa14" / "tm.pt", kind=None, robot="iiwa14")
    assert shipped["format"] in (1, 2)


def test_content_hash_is_canonical():
    a = {"w": torch.arange(6.0).reshape(2, 3), "cfg": {"x": (1, 2), "y": None}, 3: [1.5, "s"]}
    b = {3: [1.5, "s"], "cfg": {"y": None, "x": [1, 2]}, "w": torch.arange(6.0).reshape(2, 3)}
    assert content_sha256(a) == content_sha256(b)
    for changed in (
        {**a, "w": torch.arange(6.0).reshape(3, 2)},  # same bytes, other shape
        {**a, "w": torch.arange(6.0, dtype=torch.float64).reshape(2, 3)},
        {**a, 3: [1.5, "t"]},
        {**a, "cfg": {"x": (1, 2), "y": 0}},
    ):
        assert content_sha256(changed) != content_sha256(a)


# --------------------------------------------------------------------------------------------------
# Dependencies by identity
# --------------------------------------------------------------------------------------------------


def test_dependencies_are_relative_and_verified(tmp_path):
    fm_path, _ = _save_fm(tmp_path / "models" / "fm.pt")
    tm_path = tmp_path / "runs" / "tm" / "tm.pt"
    save_checkpoint(tm_path, kind="tm", robot="iiwa14", config={}, state_dict={}, depends={"fm": fm_path})
    payload = load_checkpoint(tm_path, kind="tm")
    assert payload["depends"]["fm"] == {"path": "../../models/fm.pt", "sha256": file_sha256(fm_path)}
    assert resolve_dependency(tm_path, payload, "fm") == fm_path
    # the whole tree moves: relative references still hold
    shutil.move(tmp_path / "runs", tmp_path / "moved")
    shutil.move(tmp_path / "models", tmp_path / "moved-models")
    lone = tmp_path / "moved" / "tm" / "tm.pt"
    with pytest.raises(
        CheckpointError, match=r"fm \.\./\.\./models/fm\.pt of sha256 [0-9a-f]{64}; no such file"
    ):
        resolve_dependency(lone, payload, "fm")
    # ... and the file beside the checkpoint is the fallback
    shutil.copy(tmp_path / "moved-models" / "fm.pt", lone.parent / "fm.pt")
    assert resolve_dependency(lone, payload, "fm") == lone.parent / "fm.pt"
    # another model under the same name is refused, naming both hashes
    _save_fm(lone.parent / "fm.pt")
    with pytest.raises(CheckpointError, match="another model"):
        resolve_dependency(lone, payload, "fm")
    with pytest.raises(CheckpointError, match="no dependency 'im'"):
        resolve_dependency(lone, payload, "im")


@pytest.fixture(scope="module")
def learned_models(tmp_path_factory):
    root = tmp_path_factory.mktemp("models")
    data = babble(BabblingConfig(walkers=100, steps=30, seed=0))
    tiny = train_config("fm", "tiny", epochs=1, progress=False)
    train_fm(data, fm_config("iiwa14", "tiny"), tiny, run_dir=root / "models")
    train_im(
        data,
        im_config("iiwa14", "tiny"),
        train_config("im", "tiny", epochs=1, progress=False),
        run_dir=root / "models",
    )
    train_fm(
        data,
        fm_config("iiwa14", "tiny"),
        train_config("fm", "tiny", epochs=1, seed=5, progress=False),
        run_dir=root / "other",
    )
    pairs = make_endpoints(EndpointConfig(n=24, seed=1))
    return root, pairs


def test_a_tm_records_its_fm_and_im_by_identity_not_by_absolute_path(learned_models, tmp_path):
    """Case 3: no absolute path in tm.pt; a folder holding only tm.pt says which FM it needs."""
    root, pairs = learned_models
    models = tmp_path / "models"
    shutil.copytree(root / "models", models)
    cfg = tm_preset("default", models_dir=str(models.resolve()), epochs=1, batch_size=8)
    train_tm(cfg, tmp_path / "tm", pairs, progress=False)
    payload = load_checkpoint(tmp_path / "tm" / "tm.pt", kind="tm")
    assert set(payload["config"]) == {"tm", "fm", "im", "im_iterations", "im_damping"}  # the model's own
    assert payload["extra"]["train_config"]["models_dir"] is None  # how it was trained: no folder either
    assert str(tmp_path) not in repr({k: payload[k] for k in ("config", "depends", "extra")})
    assert payload["depends"]["fm"]["path"] == "../models/fm.pt"
    _, loaded = load_tm(tmp_path / "tm" / "tm.pt")
    assert loaded.models_dir == str(models)
    fm, _ = build_fm_im(loaded)
    assert all(
        torch.equal(a, b)
        for a, b in zip(
            fm.state_dict().values(), load_fm(models / "fm.pt").state_dict().values(), strict=True
        )
    )
    assert Planner.load(tmp_path / "tm").tm is not None
    # tm.pt alone in a folder: a typed error naming the file and hash it needs
    alone = tmp_path / "elsewhere" / "alone"
    alone.mkdir(parents=True)
    shutil.copy(tmp_path / "tm" / "tm.pt", alone / "tm.pt")
    with pytest.raises(CheckpointError, match=r"made with fm \.\./models/fm\.pt of sha256 [0-9a-f]{64}"):
        load_tm(alone / "tm.pt")
    with pytest.raises(CheckpointError, match=r"made with fm \.\./models/fm\.pt of sha256 [0-9a-f]{64}"):
        Planner.load(alone)  # the planner's own reader says the same
    # another FM swapped in under the trained TM: refused
    shutil.copy(root / "other" / "fm.pt", models / "fm.pt")
    with pytest.raises(CheckpointError, match="another model"):
        load_tm(tmp_path / "tm" / "tm.pt")
    with pytest.raises(CheckpointError, match="another model"):
        Planner.load(tmp_path / "tm")
    assert load_tm(tmp_path / "tm" / "tm.pt", resolve=False)[1].models_dir is None


def test_resuming_a_tm_through_another_fm_or_pairs_is_refused(learned_models, tmp_path):
    root, pairs = learned_models
    models = tmp_path / "models"
    shutil.copytree(root / "models", models)
    cfg = tm_preset("default", models_dir=str(models), epochs=1, batch_size=8)
    train_tm(cfg, tmp_path / "tm", pairs, progress=False)
    before = (tmp_path / "tm" / "tm.pt").read_bytes()
    with pytest.raises(CheckpointError, match="training pairs: sha256"):
        train_tm(cfg, tmp_path / "tm", make_endpoints(EndpointConfig(n=24, seed=2)), progress=False)
    shutil.copy(root / "other" / "fm.pt", models / "fm.pt")
    with pytest.raises(CheckpointError, match=r"fm .*another model"):
        train_tm(cfg, tmp_path / "tm", pairs, progress=False)
    assert (tmp_path / "tm" / "tm.pt").read_bytes() == before


# --------------------------------------------------------------------------------------------------
# Atomic writes
# --------------------------------------------------------------------------------------------------


def test_a_failed_write_leaves_no_temporary_file_and_the_old_file_intact(tmp_path):
    target = tmp_path / "x.json"
    target.write_text("old")

    def fail(p):
        p.write_text("half")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError):
        atomic_write(target, fail)
    assert target.read_text() == "old" and sorted(p.name for p in tmp_path.iterdir()) == ["x.json"]


def test_a_temporary_file_left_by_kill_9_is_removed_by_the_next_write(tmp_path):
    code = (
        "import os, sys; from kinlearn.io import atomic_write\n"
        "def write(p):\n    p.write_text('half'); os.kill(os.getpid(), 9)\n"
        "atomic_write(sys.argv[1], write)\n"
    )
    target = tmp_path / "x.json"
    proc = subprocess.run([sys.executable, "-c", code, str(target)], check=False)
    assert proc.returncode == -9
    (orphan,) = tmp_path.glob(".x.json.*.tmp")
    assert not target.exists()
    atomic_write(target, lambda p: p.write_text("whole"))
    assert target.read_text() == "whole" and not orphan.exists()
    # a temporary file of a process that is still running is left alone
    busy = tmp_path / f".x.json.{os.getppid()}.tmp"
    busy.write_text("writing")
    assert remove_stale_tmp(tmp_path) == [] and busy.exists()


# --------------------------------------------------------------------------------------------------
# Inputs at the API boundary (case 6)
# --------------------------------------------------------------------------------------------------


def test_kinematics_takes_a_robot_name():
    kin = kinlearn.kinematics("iiwa14")
    assert kin.robot is kinlearn.load_robot("iiwa14")
    assert torch.allclose(
        kin.position(torch.zeros(7, dtype=torch.float64)),
        torch.tensor([0.0, 0.0, 1.306], dtype=torch.float64),
    )
    with pytest.raises(UnknownRobotError, match="valid names"):
        kinlearn.kinematics("iiwa15")
    with pytest.raises(ConfigError, match="Robot or a robot name"):
        kinlearn.kinematics(42)


def test_kinematics_takes_numpy_arrays_and_refuses_bool_and_complex():
    kin = kinlearn.kinematics("iiwa14")
    q = np.random.default_rng(0).uniform(-1.0, 1.0, (4, 7))
    p = kin.position(q)
    assert isinstance(p, torch.Tensor) and p.dtype == torch.float64 and p.shape == (4, 3)
    assert torch.equal(p, kin.position(torch.from_numpy(q)))
    assert kin.position(q.astype(np.float32)).dtype == torch.float32
    for bad in (
        torch.ones(7, dtype=torch.bool),
        torch.zeros(7, dtype=torch.complex64),
        np.zeros(7, dtype=bool),
    ):
        with pytest.raises(DTypeError, match="real numbers"):
            kin.position(bad)
    assert issubclass(DTypeError, ShapeError)


def test_half_weights_halve_layers_only_and_load_back_into_float32():
    torch.manual_seed(0)
    net = torch.nn.Sequential(torch.nn.Linear(4, 8), torch.nn.Tanh(), torch.nn.Linear(8, 2))
    net.register_buffer("in_mean", torch.randn(4, dtype=torch.float64))
    half = half_weights(net.state_dict())
    assert half["0.weight"].dtype == half["2.bias"].dtype == torch.float16
    assert half["in_mean"].dtype == torch.float64 and torch.equal(half["in_mean"], net.in_mean)
    copy = torch.nn.Sequential(torch.nn.Linear(4, 8), torch.nn.Tanh(), torch.nn.Linear(8, 2))
    copy.register_buffer("in_mean", torch.zeros(4, dtype=torch.float64))
    copy.load_state_dict(half)
    assert copy[0].weight.dtype == torch.float32
    x = torch.randn(16, 4)
    torch.testing.assert_close(copy(x), net(x), atol=5e-3, rtol=5e-3)
    assert not torch.equal(copy(x), net(x))  # rounded, not the same numbers
