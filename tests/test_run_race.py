"""Runs that cannot race: the run directory's lock is taken before the new-run decision and held to the
end, so a second writer into the same folder is refused naming the holder; a lock or an output that
cannot be written (full disk, read-only) is a typed error and leaves nothing that blocks the re-run;
export-urdf writes a temporary file, checks it through Pinocchio, then renames it, and never replaces
an existing file without --overwrite."""

from __future__ import annotations

import errno
import json
import os
import subprocess
import sys
import textwrap
import time

import pytest
import torch

import kinlearn.runs as runs
from kinlearn.body.kinematics import kinematics
from kinlearn.body.robot import load_robot
from kinlearn.cli.main import main
from kinlearn.errors import OutputError, RunDirectoryError
from kinlearn.io import atomic_write
from kinlearn.runs import LOCK_FILE, open_run, release_locks
from kinlearn.training.identify import Identification, IdentifyConfig, identify


def _open(path, **kw):
    return open_run(path, command="identify", config={"n": 1}, outputs=("chain.pt", "report.json"), **kw)


def test_a_second_writer_started_into_the_same_new_folder_is_refused_naming_the_first(tmp_path):
    """Before, both decided the folder was new (nothing written yet), both fitted, and the slower one
    replaced the finished run."""
    path = tmp_path / "new"
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            textwrap.dedent(f"""
                import time
                from kinlearn.runs import open_run
                open_run({str(path)!r}, command="identify", config={{"n": 1}}, outputs=("chain.pt",))
                print("decided", flush=True)
                time.sleep(60)
            """),
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout.readline().strip() == "decided"
        with pytest.raises(RunDirectoryError, match=rf"identify \(process {holder.pid} on"):
            _open(path)
    finally:
        holder.kill()
        holder.wait()
    run = _open(path)  # the holder is gone: its lock is stale and the folder new
    assert run.mode == "new"
    release_locks()


def _fail_link(code):
    def fake(src, dst, *args, **kwargs):
        raise OSError(code, os.strerror(code), str(dst))

    return fake


@pytest.mark.parametrize("code, says", [(errno.ENOSPC, "the disk is full"), (errno.EROFS, "read-only")])
def test_a_lock_that_cannot_be_written_is_typed_and_leaves_nothing(tmp_path, monkeypatch, code, says):
    monkeypatch.setattr(runs.os, "link", _fail_link(code))
    with pytest.raises(OutputError, match=says):
        _open(tmp_path / "a" / "run")
    assert not (tmp_path / "a").exists()  # the folders made for the lock are gone again


def test_a_lock_being_written_is_not_taken_for_a_stale_one(tmp_path):
    path = tmp_path / "run"
    path.mkdir()
    (path / LOCK_FILE).write_text('{"pid": 12')  # torn: its writer is writing it this moment
    with pytest.raises(RunDirectoryError, match="a command that is starting"):
        _open(path)
    old = time.time() - 60
    os.utime(path / LOCK_FILE, (old, old))  # torn and old: stale
    assert _open(path).mode == "new"
    release_locks()


def test_a_run_that_failed_before_any_output_blocks_no_rerun(tmp_path):
    run = _open(tmp_path / "run")
    run.begin()  # config.json written; then the fit's output fails (say the disk fills up)
    release_locks()
    assert (tmp_path / "run" / "config.json").is_file()
    assert _open(tmp_path / "run").mode == "new"  # no --overwrite needed
    release_locks()
    (tmp_path / "run" / "report.json").write_text("{}")
    with pytest.raises(RunDirectoryError, match="--overwrite"):
        _open(tmp_path / "run")


def test_torch_failing_to_write_on_a_full_disk_is_typed_and_leaves_no_file(tmp_path):
    def write(p):
        p.write_bytes(b"part")
        raise RuntimeError("basic_ios::clear: iostream error")

    with pytest.raises(OutputError, match="the disk is full"):
        atomic_write(tmp_path / "chain.pt", write)
    assert list(tmp_path.iterdir()) == []


@pytest.fixture(scope="module")
def chain_pt(tmp_path_factory):
    robot = load_robot("iiwa14")
    gen = torch.Generator().manual_seed(0)
    q = robot.sample(1500, gen, dtype=torch.float64)
    ef = kinematics(robot, "pinocchio").position(q) + 1e-3 * torch.randn(
        1500, 3, generator=gen, dtype=torch.float64
    )
    result = identify((q, ef), robot=robot, config=IdentifyConfig(iterations=5))
    return result.save(tmp_path_factory.mktemp("chain") / "chain.pt")


def test_export_urdf_never_replaces_a_file_without_overwrite(chain_pt, tmp_path, capsys):
    out = tmp_path / "arm.urdf"
    out.write_text("<robot name='prior'/>")
    assert main(["export-urdf", str(chain_pt), "--out", str(out)]) == 2
    assert "--overwrite" in capsys.readouterr().err and out.read_text() == "<robot name='prior'/>"
    assert main(["export-urdf", str(chain_pt), "--out", str(out), "--overwrite", "--name", 'a"<b>&']) == 0
    assert load_robot(out, "iiwa_link_ee").dof == 7
    assert not (tmp_path / f".arm.urdf.{LOCK_FILE}").exists()  # released at the end


def test_export_urdf_checks_before_it_writes(chain_pt, tmp_path, monkeypatch, capsys):
    out = tmp_path / "arm.urdf"
    good = Identification.urdf
    monkeypatch.setattr(
        Identification, "urdf", lambda self, name=None: good(self, name).replace("<robot", "<rob", 1)
    )
    assert main(["export-urdf", str(chain_pt), "--out", str(out)]) == 2
    assert "nothing was written" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # no URDF, no temporary file, no lock


def test_export_urdf_holds_a_lock_on_its_file(chain_pt, tmp_path, capsys):
    out = tmp_path / "arm.urdf"
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        lock = tmp_path / f".{out.name}.kinlearn.lock"
        lock.write_text(json.dumps({"pid": other.pid, "host": os.uname().nodename, "command": "export-urdf"}))
        assert main(["export-urdf", str(chain_pt), "--out", str(out)]) == 2
        assert f"process {other.pid}" in capsys.readouterr().err and not out.exists()
    finally:
        other.kill()
        other.wait()
