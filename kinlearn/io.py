"""Files that users keep: checkpoints, datasets and JSON, written atomically and checked on load.

A checkpoint is a plain dict saved with ``torch.save``: ``format`` (this module's version),
``kind`` (e.g. ``"fm"``), ``robot`` (name), ``config`` (a JSON-able dict to rebuild the model),
``state_dict`` and optional ``extra`` (epoch, optimiser state, ...). Never a pickled module:
loading uses ``weights_only=True``.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch

from .errors import CheckpointError, DatasetError

__all__ = [
    "FORMAT_VERSION",
    "atomic_write",
    "load_checkpoint",
    "load_npz",
    "read_json",
    "save_checkpoint",
    "save_npz",
    "write_json",
]

FORMAT_VERSION = 1


def atomic_write(path: str | Path, write: Callable[[Path], None]) -> Path:
    """Call ``write(tmp)`` on a temporary file beside ``path``, then rename it onto ``path``.

    A crash midway leaves the old file (if any) intact, never a half-written one.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        write(Path(tmp))
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600 files; give the usual permissions
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_json(path: str | Path, obj: Any) -> Path:
    return atomic_write(path, lambda p: p.write_text(json.dumps(obj, indent=2, sort_keys=True) + "\n"))


def read_json(path: str | Path) -> Any:
    return json.loads(Path(path).read_text())


def save_checkpoint(
    path: str | Path,
    *,
    kind: str,
    robot: str,
    config: dict,
    state_dict: dict,
    extra: dict | None = None,
) -> Path:
    """Save a checkpoint atomically (see the module docstring for its contents)."""
    payload = {
        "format": FORMAT_VERSION,
        "kind": kind,
        "robot": robot,
        "config": config,
        "state_dict": state_dict,
        "extra": extra or {},
    }
    return atomic_write(path, lambda p: torch.save(payload, p))


def load_checkpoint(path: str | Path, *, kind: str, robot: str | None = None) -> dict:
    """Load and check a checkpoint: it must exist, be readable, of this format, ``kind`` and ``robot``."""
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
    if payload["format"] != FORMAT_VERSION:
        raise CheckpointError(
            f"{path} has checkpoint format {payload['format']}, this kinlearn reads format {FORMAT_VERSION}"
        )
    if payload.get("kind") != kind:
        raise CheckpointError(f"{path} holds a {payload.get('kind')!r} model, expected a {kind!r} model")
    if robot is not None and payload.get("robot") != robot:
        raise CheckpointError(f"{path} was trained for robot {payload.get('robot')!r}, not {robot!r}")
    return payload


def save_npz(path: str | Path, *, kind: str, robot: str, config: dict, arrays: dict[str, np.ndarray]) -> Path:
    """Save arrays with their config and robot name as ``.npz``, atomically."""
    meta = json.dumps({"format": FORMAT_VERSION, "kind": kind, "robot": robot, "config": config})

    def write(p: Path) -> None:
        with open(p, "wb") as fh:
            np.savez(fh, __meta__=np.array(meta), **arrays)

    return atomic_write(path, write)


def load_npz(path: str | Path, *, kind: str, robot: str | None = None) -> tuple[dict, dict[str, np.ndarray]]:
    """Load a dataset saved by :func:`save_npz`; returns ``(meta, arrays)``. Checks format, kind and robot."""
    path = Path(path)
    if not path.is_file():
        raise DatasetError(f"no dataset file at {path}")
    try:
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(str(data["__meta__"]))
            arrays = {k: data[k] for k in data.files if k != "__meta__"}
    except Exception as exc:
        raise DatasetError(
            f"{path} is not a readable kinlearn dataset ({type(exc).__name__}: {exc})"
        ) from exc
    if meta.get("format") != FORMAT_VERSION:
        raise DatasetError(f"{path} has dataset format {meta.get('format')}, expected {FORMAT_VERSION}")
    if meta.get("kind") != kind:
        raise DatasetError(f"{path} holds a {meta.get('kind')!r} dataset, expected {kind!r}")
    if robot is not None and meta.get("robot") != robot:
        raise DatasetError(f"{path} was made for robot {meta.get('robot')!r}, not {robot!r}")
    return meta, arrays
