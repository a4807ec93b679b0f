"""Files that users keep: checkpoints, datasets and JSON, written atomically and checked on load.

A checkpoint is a plain dict saved with ``torch.save``: ``format`` (:data:`CHECKPOINT_FORMAT`),
``kind`` (e.g. ``"fm"``), ``robot`` (name), ``config`` (a JSON-able dict to rebuild the model),
``state_dict``, ``extra`` (epoch, optimiser state, ...), ``depends`` (the checkpoints it was made
with, each as ``{"path": relative to the checkpoint's folder, "sha256": of that file}``) and
``sha256``, the content hash of all the rest (:func:`content_sha256`), verified on every load. Never
a pickled module: loading uses ``weights_only=True``. Format 1 (no hash, no ``depends``) still loads.

Every file is written to a temporary ``.<name>.<pid>.tmp`` beside its target and renamed onto it: an
interrupted write leaves the old file intact; the temporary file is deleted on an exception, and one
left by a killed process is deleted by the next write of the same file (:func:`remove_stale_tmp`).
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import shutil
import warnings
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch

from .errors import CheckpointError, DatasetError, OutputError, UnverifiedCheckpointWarning

__all__ = [
    "CHECKPOINT_FORMAT",
    "DATASET_FORMAT",
    "FORMAT_VERSION",
    "atomic_copy",
    "atomic_write",
    "check_output",
    "content_sha256",
    "file_sha256",
    "load_checkpoint",
    "load_npz",
    "read_json",
    "remove_stale_tmp",
    "resolve_dependency",
    "save_checkpoint",
    "save_npz",
    "write_json",
]

#: Version of the checkpoint layout written by :func:`save_checkpoint`. 2: content hash + ``depends``.
CHECKPOINT_FORMAT = 2
#: Checkpoint versions :func:`load_checkpoint` reads (1: no content hash, loaded unverified).
READABLE_CHECKPOINT_FORMATS = (1, 2)
#: Version of the ``.npz`` dataset layout written by :func:`save_npz`.
DATASET_FORMAT = 1
#: The checkpoint format (kept under its old name).
FORMAT_VERSION = CHECKPOINT_FORMAT


def _tmp_path(path: Path) -> Path:
    return path.with_name(f".{path.name}.{os.getpid()}.tmp")


def _pid_alive(pid: int) -> bool:
    if os.name != "posix":  # no cheap liveness test: treat every other writer as alive
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by someone else
        return True
    return True


def remove_stale_tmp(folder: str | Path, name: str | None = None) -> list[Path]:
    """Delete temporary files of :func:`atomic_write` left in ``folder`` by processes that are gone.

    ``name``: only those of the target file ``name``; otherwise every ``.<name>.<pid>.tmp`` in
    ``folder`` (not recursive). Files of a process still running are kept (it may be writing them);
    this process's own leftovers are deleted. Returns the deleted paths.
    """
    folder = Path(folder)
    if not folder.is_dir():
        return []
    removed = []
    for tmp in folder.glob(f".{name}.*.tmp" if name else ".*.tmp"):
        stem = tmp.name[1:-4]  # "<name>.<pid>"
        owner = stem.rsplit(".", 1)[-1]
        pid = int(owner) if owner.isdigit() else None  # older versions used random suffixes
        if pid is not None and pid != os.getpid() and _pid_alive(pid):
            continue
        try:
            tmp.unlink()
            removed.append(tmp)
        except FileNotFoundError:
            pass
    return removed


def check_output(path: str | Path) -> Path:
    """``path`` as a :class:`Path` a file can be written at, or :class:`~kinlearn.errors.OutputError`: not a
    folder, and its nearest existing folder above it a folder (not a file) this process may write in.
    Cheap: call it before long work whose result goes there. Missing folders are fine (they are made)."""
    path = Path(path)
    if path.is_dir():
        raise OutputError(f"cannot write {path}: it is a folder; give a file name")
    folder = path.parent
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    if not folder.is_dir():
        raise OutputError(f"cannot write {path}: {folder} is a file, not a folder; choose another path")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise OutputError(f"cannot write {path}: no permission to write in {folder}; choose another folder")
    return path


_DISK_FULL = (errno.ENOSPC, getattr(errno, "EDQUOT", errno.ENOSPC))


def _output_error(path: Path, exc: BaseException) -> OutputError:
    """``exc`` (raised while writing ``path``) as an :class:`OutputError` that says what to do."""
    code = getattr(exc, "errno", None)
    if code in _DISK_FULL or isinstance(exc, RuntimeError):  # torch's writer says "unexpected pos …"
        try:
            free = f"{shutil.disk_usage(path.parent).free / 2**20:.1f} MiB free"
        except OSError:
            free = "free space unknown"
        return OutputError(
            f"cannot write {path}: the disk is full ({free}; {type(exc).__name__}: {exc}). Free some space "
            "and run the command again (the old file, if any, is intact)"
        )
    what = {
        errno.EROFS: f"{path.parent} is on a read-only file system; choose another folder",
        errno.EACCES: f"no permission to write in {path.parent}; choose another folder",
        errno.EPERM: f"no permission to write in {path.parent}; choose another folder",
        errno.EISDIR: "a folder is in its place; give a file name",
        errno.ENOTDIR: "a file is in the way of its folder; choose another path",
    }.get(code, getattr(exc, "strerror", None) or str(exc))
    return OutputError(f"cannot write {path}: {what}")


def _is_write_failure(exc: BaseException, targets: tuple[Path, ...]) -> bool:
    """Whether ``exc`` is the filesystem refusing the write (not, say, a missing file ``write`` reads)."""
    if isinstance(exc, OSError) and not isinstance(exc, OutputError):
        if exc.errno in (*_DISK_FULL, errno.EROFS):
            return True
        return (
            exc.filename is None or Path(exc.filename) in targets or Path(exc.filename) == targets[0].parent
        )
    # torch.save's C++ writer reports a failed write (a full disk) as a RuntimeError of its own
    return isinstance(exc, RuntimeError) and any(
        m in str(exc) for m in ("inline_container", "PytorchStreamWriter", "basic_ios", "file write failed")
    )


def atomic_write(path: str | Path, write: Callable[[Path], None]) -> Path:
    """Call ``write(tmp)`` on a temporary file beside ``path``, then rename it onto ``path``.

    A crash midway leaves the old file (if any) intact, never a half-written one. The temporary file
    is deleted when ``write`` raises; one left by a killed process is deleted before this write. The
    one writer of every output file: a folder in the way, a file where a folder should be, no
    permission, a read-only or full disk raise :class:`~kinlearn.errors.OutputError` naming the path.
    """
    path = check_output(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise _output_error(path, exc) from exc
    remove_stale_tmp(path.parent, path.name)
    tmp = _tmp_path(path)
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException as exc:
        tmp.unlink(missing_ok=True)
        if _is_write_failure(exc, (tmp, path)):
            raise _output_error(path, exc) from exc
        raise
    return path


def atomic_copy(src: str | Path, dst: str | Path) -> Path:
    """Copy file ``src`` to ``dst`` atomically (see :func:`atomic_write`)."""
    return atomic_write(dst, lambda p: shutil.copyfile(src, p))


def file_sha256(path: str | Path) -> str:
    """SHA-256 of a file's bytes, as 64 hex digits."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _feed(h, obj: Any) -> None:
    """Feed ``obj`` to hash ``h`` in a canonical, unambiguous encoding (see :func:`content_sha256`)."""
    if isinstance(obj, torch.Tensor):
        t = obj.detach().cpu().contiguous()
        head = f"T{t.dtype}{tuple(t.shape)}".encode()
        h.update(b"%d:" % len(head) + head)
        h.update(t.reshape(-1).view(torch.uint8).numpy())  # a view: no copy of large tensors
    elif isinstance(obj, np.ndarray):
        _feed(h, torch.from_numpy(np.ascontiguousarray(obj)))
    elif isinstance(obj, Mapping):
        h.update(b"D%d:" % len(obj))
        for key in sorted(obj, key=lambda k: (type(k).__name__, repr(k))):
            _feed(h, key)
            _feed(h, obj[key])
    elif isinstance(obj, (list, tuple)):  # one encoding for both: a tuple may come back as a list
        h.update(b"L%d:" % len(obj))
        for item in obj:
            _feed(h, item)
    elif isinstance(obj, bytes):
        h.update(b"B%d:" % len(obj) + obj)
    else:  # None, bool, int, float, str and other plain values: their type and repr
        text = f"{type(obj).__name__}={obj!r}".encode()
        h.update(b"S%d:" % len(text) + text)


def content_sha256(obj: Any) -> str:
    """SHA-256 of a nested structure of dicts, lists, tensors and plain values, as 64 hex digits.

    Independent of how it is serialised: dict keys are sorted, tensors contribute their dtype, shape
    and bytes. Used as a checkpoint's content hash and as a fingerprint of training data.
    """
    h = hashlib.sha256()
    _feed(h, obj)
    return h.hexdigest()


def write_json(path: str | Path, obj: Any) -> Path:
    return atomic_write(path, lambda p: p.write_text(json.dumps(obj, indent=2, sort_keys=True) + "\n"))


def read_json(path: str | Path) -> Any:
    return json.loads(Path(path).read_text())


def _dependency_record(ckpt: Path, dep: str | Path | tuple[str | Path, str]) -> dict:
    path, sha = dep if isinstance(dep, tuple) else (dep, None)
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"dependency {path} of {ckpt} is not a file")
    try:
        rel = os.path.relpath(path.resolve(), ckpt.parent.resolve())
    except ValueError:  # another drive: only the file name can be kept
        rel = path.name
    return {"path": Path(rel).as_posix(), "sha256": sha or file_sha256(path)}


def save_checkpoint(
    path: str | Path,
    *,
    kind: str,
    robot: str,
    config: dict,
    state_dict: dict,
    extra: dict | None = None,
    depends: Mapping[str, str | Path | tuple[str | Path, str]] | None = None,
) -> Path:
    """Save a checkpoint atomically (see the module docstring for its contents).

    ``depends`` names the checkpoints this one was made with, e.g. ``{"fm": path, "im": path}``: each
    is recorded by its path relative to this checkpoint's folder and its file's SHA-256 (a value may
    be ``(path, sha256)`` when the hash is already known), and found again by
    :func:`resolve_dependency`.
    """
    path = Path(path)
    payload = {
        "format": CHECKPOINT_FORMAT,
        "kind": kind,
        "robot": robot,
        "config": config,
        "state_dict": state_dict,
        "extra": extra or {},
        "depends": {name: _dependency_record(path, dep) for name, dep in (depends or {}).items()},
    }
    payload["sha256"] = content_sha256(payload)
    return atomic_write(path, lambda p: torch.save(payload, p))


def half_weights(state_dict: Mapping[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """``state_dict`` with its layers' weights and biases as float16, for a smaller shipped file.

    Every other tensor (normalisation statistics, joint limits, fixed bases) keeps its precision. The
    weights load back into the model's float32 parameters: the model changes by their rounding only
    (a relative 5e-4), so what ships must be measured as shipped."""
    return {
        k: v.half() if v.is_floating_point() and k.rsplit(".", 1)[-1] in ("weight", "bias") else v
        for k, v in state_dict.items()
    }


def load_checkpoint(
    path: str | Path, *, kind: str | None, robot: str | None = None, strict: bool = False
) -> dict:
    """Load and check a checkpoint: it must exist, be readable, of a known format, ``kind`` (``None``:
    any) and ``robot`` (``None``: any), and its content must match its hash (format 2). Format 1 files
    carry no hash: they load with an :class:`~kinlearn.errors.UnverifiedCheckpointWarning`, or are refused
    with ``strict=True``. Raises :class:`~kinlearn.CheckpointError` naming what is wrong."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"no checkpoint file at {path}")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many types for corrupt files
        raise CheckpointError(
            f"{path} is not a readable kinlearn checkpoint ({type(exc).__name__}: {exc})"
        ) from exc
    if not isinstance(payload, dict) or "format" not in payload:
        raise CheckpointError(f"{path} is not a kinlearn checkpoint (no format field)")
    if payload["format"] not in READABLE_CHECKPOINT_FORMATS:
        raise CheckpointError(
            f"{path} has checkpoint format {payload['format']}; this kinlearn reads formats "
            f"{', '.join(map(str, READABLE_CHECKPOINT_FORMATS))} (a newer kinlearn wrote it?)"
        )
    if payload["format"] < 2:
        msg = (
            f"{path} is a format-{payload['format']} checkpoint, which records no content hash: its weights "
            "cannot be verified; save it again to record one"
        )
        if strict:
            raise CheckpointError(msg + " (refused: strict=True)")
        warnings.warn(msg, UnverifiedCheckpointWarning, stacklevel=2)
    else:
        stored = payload.pop("sha256", None)
        actual = content_sha256(payload)
        if stored != actual:
            raise CheckpointError(
                f"{path} is corrupt or was modified: its content hash is {actual}, the checkpoint records "
                f"{stored}; restore it from a copy or train it again"
            )
        payload["sha256"] = stored
    payload.setdefault("depends", {})
    payload.setdefault("extra", {})
    if kind is not None and payload.get("kind") != kind:
        raise CheckpointError(f"{path} holds a {payload.get('kind')!r} model, expected a {kind!r} model")
    if robot is not None and payload.get("robot") != robot:
        raise CheckpointError(f"{path} was trained for robot {payload.get('robot')!r}, not {robot!r}")
    return payload


def resolve_dependency(ckpt_path: str | Path, payload: dict, name: str) -> Path:
    """The file of dependency ``name`` recorded in checkpoint ``payload`` (loaded from ``ckpt_path``).

    Looked for at its recorded path relative to the checkpoint's folder, then under its file name
    beside the checkpoint; the file's SHA-256 must be the recorded one. Raises
    :class:`~kinlearn.CheckpointError` naming the expected file and hash when it is missing or differs.
    """
    ckpt_path = Path(ckpt_path)
    record = (payload.get("depends") or {}).get(name)
    if not isinstance(record, dict) or "path" not in record or "sha256" not in record:
        recorded = ", ".join(sorted(payload.get("depends") or {})) or "none"
        raise CheckpointError(f"{ckpt_path} records no dependency {name!r} (it records: {recorded})")
    rel, expected = Path(record["path"]), record["sha256"]
    candidates = [Path(os.path.normpath(ckpt_path.parent / rel)), ckpt_path.parent / rel.name]
    seen = []
    for cand in dict.fromkeys(candidates):  # ordered, without duplicates
        if cand.is_file():
            actual = file_sha256(cand)
            if actual == expected:
                return cand
            seen.append(f"{cand} has sha256 {actual}")
    made = f"{ckpt_path} was made with {name} {record['path']} of sha256 {expected}"
    if seen:
        raise CheckpointError(
            f"{made}, but {'; '.join(seen)}: another model. Put the {name} file it was made with beside it"
        )
    where = " or ".join(str(c) for c in dict.fromkeys(candidates))
    raise CheckpointError(f"{made}; no such file at {where}. Put that {name} file beside the checkpoint")


def save_npz(path: str | Path, *, kind: str, robot: str, config: dict, arrays: dict[str, np.ndarray]) -> Path:
    """Save arrays with their config and robot name as ``.npz``, atomically."""
    meta = json.dumps({"format": DATASET_FORMAT, "kind": kind, "robot": robot, "config": config})

    def write(p: Path) -> None:
        with open(p, "wb") as fh:
            np.savez(fh, __meta__=np.array(meta), **arrays)

    return atomic_write(path, write)


def load_npz(path: str | Path, *, kind: str, robot: str | None = None) -> tuple[dict, dict[str, np.ndarray]]:
    """Load a dataset saved by :func:`save_npz`; returns ``(meta, arrays)``. Checks format, kind and robot."""
    path = Path(path)
    if not path.is_file():
        raise DatasetError(f"no dataset file at {path}")
    with open(path, "rb") as fh:
        head = fh.read(256)
    if head[:4] != b"PK\x03\x04":  # an .npz is a zip archive; anything else is named for what it is
        first = head.split(b"\n", 1)[0]
        yaml_like = path.suffix.lower() in (".yaml", ".yml") or (b":" in first and b"," not in first)
        hint = (
            " (it looks like YAML: a MoveIt planning scene is read with Scene.from_moveit, "
            "`kinlearn plan --scene`)"
            if yaml_like
            else ""
        )
        raise DatasetError(f"{path} is not a readable kinlearn dataset: not an .npz (a zip archive){hint}")
    try:
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(str(data["__meta__"]))
            arrays = {k: data[k] for k in data.files if k != "__meta__"}
    except Exception as exc:
        raise DatasetError(
            f"{path} is not a readable kinlearn dataset ({type(exc).__name__}: {exc})"
        ) from exc
    if meta.get("format") != DATASET_FORMAT:
        raise DatasetError(f"{path} has dataset format {meta.get('format')}, expected {DATASET_FORMAT}")
    if meta.get("kind") != kind:
        raise DatasetError(f"{path} holds a {meta.get('kind')!r} dataset, expected {kind!r}")
    if robot is not None and meta.get("robot") != robot:
        raise DatasetError(f"{path} was made for robot {meta.get('robot')!r}, not {robot!r}")
    return meta, arrays
