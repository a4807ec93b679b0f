"""One policy for the run directory of every command: no silent overwrite, no silent config drift.

A run directory holds ``config.json`` (the command and its resolved configuration) beside the
command's outputs. :func:`open_run` decides, before anything is written, what may happen to it:

- it does not exist, or holds neither ``config.json`` nor any of the command's outputs (or a
  ``config.json`` of the same command beside none of its outputs: a run that failed before it wrote
  any, a full disk say, which blocks nothing): a new run;
- it holds a run and ``resume=True``: the run continues, if ``config.json`` records the same command
  with the same configuration (else :class:`~kinlearn.errors.RunDirectoryError` lists what differs);
- it holds a run and ``overwrite=True``: the run's ``config.json`` and outputs are deleted and it
  starts afresh (refused when the folder holds another command's run);
- otherwise: refused with :class:`~kinlearn.errors.RunDirectoryError`, a finished run or not.

The decision is taken under the run directory's lock (``.kinlearn.lock``: the writer's process id,
host, command and start), which :func:`open_run` takes first (creating the folder for it) and the
command holds to its end (:func:`release_locks`; a folder it made and left empty is removed): a
second writer into the folder, started at the same moment or later, gets a
:class:`~kinlearn.errors.RunDirectoryError` naming the holder, so two runs never both decide that the
folder is new. A lock whose process is gone (a killed run) is cleared by the next writer. A lock that
cannot be written (no space, a read-only file system, no permission) is an
:class:`~kinlearn.errors.OutputError` saying what to do.

:meth:`Run.begin` then deletes what ``--overwrite`` replaces and temporary files of killed writes,
and writes ``config.json``; commands call it once all their checks passed.
"""

from __future__ import annotations

import atexit
import errno
import json
import os
import shutil
import socket
import sys
import threading
import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from .errors import RunDirectoryError
from .io import _output_error, _pid_alive, check_output, read_json, remove_stale_tmp, write_json

__all__ = [
    "CONFIG_FILE",
    "IGNORED_KEYS",
    "LOCK_FILE",
    "META_KEYS",
    "Run",
    "acquire_lock",
    "die_with_parent",
    "diff_configs",
    "open_run",
    "release_locks",
]

#: The lock a writing command holds in its run directory.
LOCK_FILE = ".kinlearn.lock"
_HELD: dict[Path, Path | None] = {}  # locks this process holds → the folder it made for one (or None)


def _live_holder(path: Path, lock: Path | None = None) -> dict | None:
    """The record of the live process (other than this one) that holds ``path``'s lock, or None; a lock
    left by a process that is gone is deleted."""
    lock = path / LOCK_FILE if lock is None else lock
    try:
        holder = json.loads(lock.read_text())
        pid, host = int(holder["pid"]), str(holder["host"])
    except FileNotFoundError:
        return None
    except (OSError, ValueError, KeyError, TypeError):  # torn or foreign
        try:
            age = time.time() - lock.stat().st_mtime
        except OSError:
            return None
        if age < 10.0:  # being written this moment (where locks cannot be linked whole): held
            return {
                "pid": "?",
                "host": "?",
                "command": "a command that is starting",
                "since": time.time() - age,
            }
        lock.unlink(missing_ok=True)  # an old torn lock: as good as stale
        return None
    if host == socket.gethostname():
        if pid == os.getpid():
            return None
        if not _pid_alive(pid):
            lock.unlink(missing_ok=True)  # a killed run's
            return None
    return holder  # alive here, or on another host (cannot tell: kept)


def _refuse_held(path: Path, holder: dict, lock: Path | None = None) -> RunDirectoryError:
    since = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(float(holder.get("since", 0))))
    return RunDirectoryError(
        f"{path} is being written by another command: {holder.get('command')} (process {holder['pid']} on "
        f"{holder['host']}, since {since}); wait for it to end or stop it (if no such process runs, delete "
        f"{path / LOCK_FILE if lock is None else lock})"
    )


def _acquire(path: Path, command: str, made: Path | None = None, lock: Path | None = None) -> bool:
    """Take the lock of folder ``path`` (``lock``: its file, default ``path/.kinlearn.lock``); False if this
    process holds it already. ``made``: the folder made for it, removed at release when left empty."""
    lock = path / LOCK_FILE if lock is None else lock
    if lock in _HELD:
        return False
    record = {"pid": os.getpid(), "host": socket.gethostname(), "command": command, "since": time.time()}
    for _ in range(3):
        if _create_lock(lock, record):
            _HELD[lock] = made
            return True
        holder = _live_holder(path, lock)
        if holder is not None:
            raise _refuse_held(path, holder, lock)
        # a stale lock, cleared: try again
    raise RunDirectoryError(f"could not lock {path} ({lock} keeps reappearing)")


def _create_lock(lock: Path, record: dict) -> bool:
    """Create ``lock`` holding ``record``, whole or not at all; False if it exists. The record is written
    to a file of this process's first and linked to the lock's name (atomic: a second writer never reads
    a half-written lock and takes it for a stale one); where links are not supported, the lock is created
    exclusively and written. A lock that cannot be written is an :class:`~kinlearn.errors.OutputError`."""
    tmp = lock.with_name(f"{lock.name}.{os.getpid()}.tmp")
    try:
        try:
            tmp.write_text(json.dumps(record))
            os.link(tmp, lock)
            return True
        except FileExistsError:
            return False
        except OSError as exc:
            if exc.errno not in (errno.EPERM, errno.EXDEV, errno.EMLINK, getattr(errno, "EOPNOTSUPP", -1)):
                raise
        try:  # no links here: an exclusive create
            fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            return False
        try:
            with os.fdopen(fd, "w") as fh:
                json.dump(record, fh)
        except OSError:
            lock.unlink(missing_ok=True)
            raise
        return True
    except OSError as exc:  # no space, read-only, no permission: typed, with what to do
        raise _output_error(lock, exc) from exc
    finally:
        tmp.unlink(missing_ok=True)


def acquire_lock(path: str | Path, command: str, lock: str | Path | None = None) -> None:
    """Hold the lock of folder ``path`` (made if missing) for ``command`` until :func:`release_locks`: a
    second writer gets a :class:`~kinlearn.errors.RunDirectoryError` naming this one. ``lock``: the lock
    file (default ``path/.kinlearn.lock``; a command writing one file locks that file alone)."""
    path = Path(path)
    made = _make_folder(path, path / LOCK_FILE if lock is None else Path(lock))
    try:
        _acquire(path, command, made, None if lock is None else Path(lock))
    except BaseException:
        _remove_made(made)
        raise


def _make_folder(path: Path, target: Path) -> Path | None:
    """Create folder ``path`` (and its parents); the topmost folder made (None if it existed)."""
    if path.is_dir():
        return None
    top = path
    while not top.parent.exists() and top.parent != top:
        top = top.parent
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise _output_error(target, exc) from exc
    return top


def _remove_made(made: Path | None) -> None:
    """Remove the folders made for a lock (from the deepest up) where they are empty."""
    if made is None:
        return
    for folder in sorted((p for p in made.rglob("*") if p.is_dir()), key=lambda p: -len(p.parts)):
        try:
            folder.rmdir()
        except OSError:
            return
    try:
        made.rmdir()
    except OSError:
        pass


def _release(lock: Path) -> None:
    made = _HELD.pop(lock, None)
    try:
        if json.loads(lock.read_text()).get("pid") == os.getpid():
            lock.unlink()
    except (OSError, ValueError):
        pass
    _remove_made(made)


def release_locks() -> None:
    """Release the run-directory locks this process holds (at the end of a command, and at exit); a folder
    made for a lock and left empty (a command refused or failed before it wrote) is removed."""
    for lock in list(_HELD):
        _release(lock)


atexit.register(release_locks)


def die_with_parent(parent: int) -> None:
    """Make this (worker) process end when process ``parent`` ends, however it ends (``kill -9`` too):
    on Linux the kernel kills it (``prctl(PR_SET_PDEATHSIG, SIGKILL)``); everywhere a daemon thread
    checks twice a second that ``parent`` is still its parent. A worker pool's initializer
    (``initializer=die_with_parent, initargs=(os.getpid(),)``): orphans would go on writing into a run
    directory that a resumed run writes too."""
    if sys.platform.startswith("linux"):
        try:
            import ctypes
            import signal

            ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # 1: PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent:  # the parent ended before the above took hold
        os._exit(1)

    def watch() -> None:
        while True:
            time.sleep(0.5)
            if os.getppid() != parent:
                os._exit(1)

    threading.Thread(target=watch, name="die-with-parent", daemon=True).start()


#: The run record every command writes first.
CONFIG_FILE = "config.json"
#: Top-level keys of ``config.json`` that describe the invocation, not the configuration.
META_KEYS = ("args", "versions")
#: Keys (at any depth) that do not change results and are not compared on resume: progress bars,
#: and the paths of inputs that are identified by their content hash beside them.
IGNORED_KEYS = ("progress", "path")

_MISSING = object()


def _plain(obj: Any) -> Any:
    """``obj`` as JSON would give it back (tuples → lists, paths → strings)."""
    return json.loads(json.dumps(obj, default=str))


def _strip(obj: Any, ignore: Iterable[str]) -> Any:
    ignore = tuple(ignore)
    if isinstance(obj, dict):
        return {k: _strip(v, ignore) for k, v in obj.items() if k not in ignore}
    if isinstance(obj, list):
        return [_strip(v, ignore) for v in obj]
    return obj


def _short(value: Any) -> str:
    text = "(absent)" if value is _MISSING else json.dumps(value, sort_keys=True)
    return text if len(text) <= 80 else text[:77] + "..."


def diff_configs(old: Any, new: Any, ignore: Iterable[str] = (), prefix: str = "") -> list[str]:
    """What differs between two JSON-like configurations, as ``"key.path: old → new"`` lines.

    Keys named in ``ignore`` are skipped at any depth; tuples and lists compare alike.
    """
    ignore = tuple(ignore)
    old, new = _strip(_plain(old), ignore), _strip(_plain(new), ignore)
    out: list[str] = []

    def walk(a: Any, b: Any, where: str) -> None:
        if isinstance(a, dict) and isinstance(b, dict):
            for key in sorted(set(a) | set(b), key=str):
                walk(a.get(key, _MISSING), b.get(key, _MISSING), f"{where}.{key}" if where else str(key))
        elif a != b:
            out.append(f"{where or '(value)'}: {_short(a)} → {_short(b)}")

    walk(old, new, prefix)
    return out


@dataclass(frozen=True)
class Run:
    """A run directory cleared for writing by :func:`open_run`.

    ``mode``: ``"new"``, ``"resume"`` (continue the run there) or ``"overwrite"`` (replace it).
    """

    path: Path
    command: str
    mode: Literal["new", "resume", "overwrite"]
    outputs: tuple[str, ...]
    record: dict | None

    @property
    def resumed(self) -> bool:
        return self.mode == "resume"

    def begin(self) -> Path:
        """Create the folder, delete what ``overwrite`` replaces and stale temporary files, write
        ``config.json`` (unless the command keeps none); returns the folder."""
        made = _make_folder(self.path, self.path / CONFIG_FILE)
        _acquire(self.path, self.command, made)  # held since open_run; taken again if released since
        if self.mode == "overwrite":
            # config.json first: a folder never holds a config.json beside another run's outputs
            (self.path / CONFIG_FILE).unlink(missing_ok=True)
            for name in self.outputs:
                target = self.path / name
                if target.is_dir() and not target.is_symlink():
                    shutil.rmtree(target)
                else:
                    target.unlink(missing_ok=True)
        remove_stale_tmp(self.path)
        for name in self.outputs:
            if (self.path / name).is_dir():
                remove_stale_tmp(self.path / name)
        if self.record is not None:
            write_json(self.path / CONFIG_FILE, self.record)
        return self.path


def _recorded_command(path: Path) -> tuple[dict | None, str | None]:
    """``(config.json's content, its command)``; ``(None, None)`` when absent or not a run record."""
    cfg_path = path / CONFIG_FILE
    if not cfg_path.is_file():
        return None, None
    try:
        record = read_json(cfg_path)
    except (OSError, ValueError):
        return None, None
    if not isinstance(record, dict):
        return None, None
    command = record.get("command")
    return record, command if isinstance(command, str) else None


def open_run(
    path: str | Path,
    *,
    command: str,
    config: Mapping[str, Any],
    outputs: Sequence[str],
    resume: bool = False,
    overwrite: bool = False,
    resumable: bool = True,
    meta: Mapping[str, Any] | None = None,
    write_config: bool = True,
    ignore: Iterable[str] = IGNORED_KEYS,
    option: str = "--run-dir",
) -> Run:
    """Check run directory ``path`` for ``command`` (see the module docstring) under its lock, which it
    takes first (making the folder for it) and the command then holds until :func:`release_locks`;
    writes nothing else (a refusal releases the lock and removes a folder it made).

    ``config``: the resolved configuration, compared on ``resume`` (keys in ``ignore`` skipped at any
    depth); ``outputs``: the names of the files and folders the command writes there; ``resumable``:
    whether the command can continue a run (else only ``overwrite`` opens a held folder); ``meta``:
    recorded in ``config.json`` but not compared (the arguments, versions); ``write_config=False``
    for a command that keeps no ``config.json`` (``export``); ``option``: how messages name the folder's
    command-line option. Raises
    :class:`~kinlearn.errors.RunDirectoryError` when the folder may not be written.
    """
    path = Path(path)
    if resume and not resumable:
        raise RunDirectoryError(f"{command} runs cannot be resumed; use --overwrite or another {option}")
    if resume and overwrite:
        raise RunDirectoryError("--resume and --overwrite exclude each other: continue the run or replace it")
    if path.exists() and not path.is_dir():
        raise RunDirectoryError(f"{path} is a file, not a run directory")
    if path.is_dir() and (holder := _live_holder(path)) is not None:
        raise _refuse_held(path, holder)
    check_output(path / CONFIG_FILE)  # a file in the way, no permission: said now, before any work
    made = _make_folder(path, path / CONFIG_FILE)
    try:
        took = _acquire(path, command, made)
    except BaseException:
        _remove_made(made)
        raise
    try:
        return _decide(
            path, command, config, outputs, resume, overwrite, resumable, meta, write_config, ignore, option
        )
    except BaseException:
        if took:
            _release(path / LOCK_FILE)
        raise


def _decide(
    path, command, config, outputs, resume, overwrite, resumable, meta, write_config, ignore, option
) -> Run:
    """:func:`open_run`'s decision, taken under the folder's lock."""
    outputs = tuple(outputs)
    record = {"command": command, **_plain(dict(config)), **_plain(dict(meta or {}))}
    record = record if write_config else None
    held = [n for n in ((CONFIG_FILE,) if write_config else ()) + outputs if (path / n).exists()]
    stored, stored_command = _recorded_command(path)
    if held == [CONFIG_FILE] and stored_command == command and not resume:
        held = []  # a run of this command that failed before writing any output: nothing to keep
    if stored_command is not None and stored_command != command and not held:
        # another kind of run, none of whose files this command would touch: still not this command's
        raise RunDirectoryError(
            f"{path} holds a {stored_command} run ({CONFIG_FILE}), not a {command} run; choose another {option}"
        )
    if not held:
        return Run(path, command, "new", outputs, record)
    what = f"a {stored_command} run" if stored_command else f"the outputs of an earlier {command}"
    held_text = ", ".join(held)
    if stored_command is not None and stored_command != command:
        raise RunDirectoryError(
            f"{path} holds {what} ({held_text}), not a {command} run; choose another {option}"
        )
    if overwrite:
        return Run(path, command, "overwrite", outputs, record)
    if resume:
        if stored is None or stored_command is None:
            raise RunDirectoryError(
                f"{path} holds {held_text} but no {CONFIG_FILE} recording the command that made them, so "
                f"--resume cannot check that it continues the same configuration; use --overwrite or another "
                f"{option}"
            )
        skip = (*META_KEYS, "command")
        old = {k: v for k, v in stored.items() if k not in skip}
        new = {k: v for k, v in dict(config).items() if k not in skip}
        diffs = diff_configs(old, new, ignore)
        if diffs:
            shown = "; ".join(diffs[:12]) + (f"; and {len(diffs) - 12} more" if len(diffs) > 12 else "")
            raise RunDirectoryError(
                f"--resume: {path} holds a {command} run with another configuration ({shown}); resume "
                f"with the same options, --overwrite it, or choose another {option}"
            )
        return Run(path, command, "resume", outputs, record)
    how = "pass --resume to continue it with the same configuration, " if resumable else "pass "
    raise RunDirectoryError(
        f"{path} already holds {what} ({held_text}); {how}--overwrite to replace it, or choose another "
        f"{option}"
    )
