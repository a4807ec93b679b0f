"""A run directory is written by one command at a time: its lock names the holder, and a lock left by
a killed run is cleared by the next writer."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time

import pytest

from kinlearn.errors import RunDirectoryError
from kinlearn.runs import LOCK_FILE, open_run, release_locks


def _open(path):
    return open_run(path, command="babble", config={"n": 1}, outputs=("babbling.npz",))


def _lock_by(path, pid):
    path.mkdir(parents=True, exist_ok=True)
    record = {"pid": pid, "host": socket.gethostname(), "command": "train-tm", "since": time.time()}
    (path / LOCK_FILE).write_text(json.dumps(record))


def test_a_second_writer_is_refused_naming_the_holder(tmp_path):
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        _lock_by(tmp_path / "run", other.pid)
        with pytest.raises(RunDirectoryError, match=rf"train-tm \(process {other.pid} on"):
            _open(tmp_path / "run")
    finally:
        other.kill()
        other.wait()
    # The holder is gone: its lock is stale, cleared by the next writer, which then holds it.
    run_dir = _open(tmp_path / "run").begin()
    assert json.loads((run_dir / LOCK_FILE).read_text())["pid"] == os.getpid()
    release_locks()
    assert not (run_dir / LOCK_FILE).exists()


def test_a_command_holds_the_lock_while_it_runs_and_frees_it_after(tmp_path, capsys):
    from kinlearn.cli.main import main

    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    run_dir = tmp_path / "babble"
    try:
        _lock_by(run_dir, other.pid)
        assert main(["babble", "--transitions", "100", "--walkers", "10", "--run-dir", str(run_dir)]) == 2
        assert "being written by another command" in capsys.readouterr().err
        assert not (run_dir / "config.json").exists()
    finally:
        other.kill()
        other.wait()
    assert main(["babble", "--transitions", "100", "--walkers", "10", "--run-dir", str(run_dir)]) == 0
    assert (run_dir / "babbling.npz").is_file() and not (run_dir / LOCK_FILE).exists()


_POOL = """
import concurrent.futures as cf, multiprocessing as mp, os, time
from kinlearn.runs import die_with_parent
if __name__ == "__main__":
    ctx = mp.get_context("spawn")
    pool = cf.ProcessPoolExecutor(1, mp_context=ctx, initializer=die_with_parent, initargs=(os.getpid(),))
    print(pool.submit(os.getpid).result(), flush=True)
    pool.submit(time.sleep, 60)  # the worker busy, as a training job keeps it
    time.sleep(60)
"""


def _running(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"  # a zombie has ended
    except FileNotFoundError:
        return False


@pytest.mark.skipif(not os.path.isdir("/proc"), reason="reads process states from /proc")
def test_workers_die_with_their_parent_even_on_kill_9(tmp_path):
    import signal

    script = tmp_path / "pool.py"
    script.write_text(_POOL)
    parent = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True)
    worker = int(parent.stdout.readline())
    assert _running(worker)
    parent.send_signal(signal.SIGKILL)
    parent.wait()
    deadline = time.monotonic() + 5.0  # the bound: no worker alive 5 s after the parent
    while _running(worker) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _running(worker)
