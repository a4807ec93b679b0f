"""The run-directory policy (kinlearn.runs): new, resume (same config only), overwrite, refuse."""

import json
import os

import pytest

from kinlearn.errors import ConfigError, RunDirectoryError
from kinlearn.runs import LOCK_FILE, diff_configs, open_run, release_locks

OUTPUTS = ("model.pt", "metrics.jsonl", "stage")
CONFIG = {"train": {"lr": 0.001, "epochs": 3, "progress": True}, "data": {"path": "a.npz", "sha256": "ab"}}


def _finished(path, command="train-x", config=CONFIG):
    run = open_run(path, command=command, config=config, outputs=OUTPUTS, meta={"args": {"x": 1}})
    run.begin()
    (path / "model.pt").write_bytes(b"weights")
    (path / "stage").mkdir()
    (path / "stage" / "part.pt").write_bytes(b"part")
    return run


def test_a_new_folder_is_checked_without_writing_anything(tmp_path):
    path = tmp_path / "run"
    run = open_run(path, command="train-x", config=CONFIG, outputs=OUTPUTS)
    assert run.mode == "new" and not run.resumed
    # nothing is written before begin() but the lock the decision was taken under, held to the end
    assert [p.name for p in path.iterdir()] == [LOCK_FILE]
    release_locks()  # a command refused or failed before begin(): its folder is gone again
    assert not path.exists()
    run = open_run(path, command="train-x", config=CONFIG, outputs=OUTPUTS)
    run.begin()
    record = json.loads((path / "config.json").read_text())
    assert record["command"] == "train-x" and record["train"]["lr"] == 0.001
    # an existing empty folder, or one holding unrelated files, is new as well
    (tmp_path / "empty").mkdir()
    (tmp_path / "empty" / "notes.txt").write_text("mine")
    assert open_run(tmp_path / "empty", command="train-x", config=CONFIG, outputs=OUTPUTS).mode == "new"


def test_a_held_folder_is_refused_without_resume_or_overwrite(tmp_path):
    _finished(tmp_path)
    before = (tmp_path / "config.json").read_bytes()
    with pytest.raises(RunDirectoryError, match=r"already holds a train-x run .*--resume.*--overwrite"):
        open_run(tmp_path, command="train-x", config=CONFIG, outputs=OUTPUTS)
    # a command that cannot resume does not suggest it
    with pytest.raises(RunDirectoryError) as exc:
        open_run(tmp_path, command="train-x", config=CONFIG, outputs=OUTPUTS, resumable=False)
    assert "--resume" not in str(exc.value)
    # outputs without config.json (an interrupted or hand-made folder) are held too
    (tmp_path / "config.json").unlink()
    with pytest.raises(RunDirectoryError, match=r"model\.pt"):
        open_run(tmp_path, command="train-x", config=CONFIG, outputs=OUTPUTS)
    assert isinstance(RunDirectoryError("x"), ConfigError)
    (tmp_path / "config.json").write_bytes(before)


def test_resume_needs_the_identical_configuration(tmp_path):
    _finished(tmp_path)
    same = {**CONFIG, "train": {**CONFIG["train"], "progress": False}}  # a progress bar changes nothing
    assert open_run(tmp_path, command="train-x", config=same, outputs=OUTPUTS, resume=True).resumed
    moved = {**CONFIG, "data": {"path": "elsewhere/a.npz", "sha256": "ab"}}  # same content, moved
    assert open_run(tmp_path, command="train-x", config=moved, outputs=OUTPUTS, resume=True).resumed
    changed = {"train": {"lr": 0.01, "epochs": 3}, "data": {"path": "b.npz", "sha256": "cd"}}
    with pytest.raises(RunDirectoryError, match=r"data\.sha256: \"ab\" → \"cd\"; train\.lr: 0\.001 → 0\.01"):
        open_run(tmp_path, command="train-x", config=changed, outputs=OUTPUTS, resume=True)
    with pytest.raises(RunDirectoryError, match="cannot be resumed"):
        open_run(tmp_path, command="train-x", config=CONFIG, outputs=OUTPUTS, resume=True, resumable=False)
    with pytest.raises(RunDirectoryError, match="exclude each other"):
        open_run(tmp_path, command="train-x", config=CONFIG, outputs=OUTPUTS, resume=True, overwrite=True)
    (tmp_path / "config.json").write_text("{}")  # no command recorded: nothing to check against
    with pytest.raises(RunDirectoryError, match="cannot check"):
        open_run(tmp_path, command="train-x", config=CONFIG, outputs=OUTPUTS, resume=True)


def test_overwrite_replaces_the_run_and_only_the_commands_files(tmp_path):
    _finished(tmp_path)
    (tmp_path / "notes.txt").write_text("mine")
    new = {"train": {"lr": 0.5}}
    run = open_run(tmp_path, command="train-x", config=new, outputs=OUTPUTS, overwrite=True)
    assert (tmp_path / "model.pt").is_file()  # still nothing deleted before begin()
    run.begin()
    assert not (tmp_path / "model.pt").exists() and not (tmp_path / "stage").exists()
    assert (tmp_path / "notes.txt").read_text() == "mine"
    assert json.loads((tmp_path / "config.json").read_text())["train"] == {"lr": 0.5}


def test_another_commands_run_is_never_replaced(tmp_path):
    _finished(tmp_path, command="babble")
    for flags in ({}, {"resume": True}, {"overwrite": True}):
        with pytest.raises(RunDirectoryError, match=r"holds a babble run .* not a train-x run"):
            open_run(tmp_path, command="train-x", config=CONFIG, outputs=OUTPUTS, **flags)
    (tmp_path / "file").write_text("x")
    with pytest.raises(RunDirectoryError, match="is a file"):
        open_run(tmp_path / "file", command="train-x", config=CONFIG, outputs=OUTPUTS)


def test_begin_removes_temporary_files_of_killed_writes(tmp_path):
    _finished(tmp_path)
    dead = tmp_path / ".model.pt.999999999.tmp"  # no such process
    mine_old = tmp_path / f".metrics.jsonl.{os.getpid()}.tmp"
    nested = tmp_path / "stage" / ".part.pt.999999999.tmp"
    for f in (dead, mine_old, nested):
        f.write_bytes(b"half")
    alive = tmp_path / f".model.pt.{os.getppid()}.tmp"  # a running process may still be writing it
    alive.write_bytes(b"busy")
    open_run(tmp_path, command="train-x", config=CONFIG, outputs=OUTPUTS, resume=True).begin()
    assert not dead.exists() and not mine_old.exists() and not nested.exists()
    assert alive.exists()


def test_diff_configs():
    assert diff_configs({"a": (1, 2)}, {"a": [1, 2]}) == []
    assert diff_configs({"a": {"b": 1}}, {"a": {"b": 1, "c": 2}}) == ["a.c: (absent) → 2"]
    assert diff_configs({"x": 1, "path": "p"}, {"x": 1, "path": "q"}, ignore=("path",)) == []
    assert diff_configs({"x": "a" * 100}, {"x": 1})[0].endswith("... → 1")
