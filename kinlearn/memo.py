"""Results of pure, deterministic computations kept on disk between processes.

A fresh process that plans among obstacles first works out facts about its collision body that depend on
the body alone: which sphere pairs overlap at nearly every configuration (an SRDF's disabled pairs) and
which are proven never to touch within the joint limits. Each costs a tenth of a second or more, every
process, for the same answer. :func:`remembered` keeps such an answer in a file named by the SHA-256 of
everything it depends on (the inputs' bytes, the computation's name, parameters and source files),
so a later process reads it instead.

The folder is ``$KINLEARN_CACHE_DIR`` when set (``off`` or an empty value keeps nothing on disk), else
``$XDG_CACHE_HOME/kinlearn``, else ``~/.cache/kinlearn``. It is only a cache: a file that cannot be read,
holds the wrong shape or type, or cannot be written is recomputed (and rewritten where possible); nothing
is ever downloaded. Files are written atomically (:func:`kinlearn.io.atomic_write`), so concurrent
processes see a whole file or none. Deleting the folder is always safe.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Callable
from pathlib import Path

import numpy as np

__all__ = ["cache_dir", "remembered"]

#: Bumped when a remembered computation changes its meaning without its inputs changing.
_FORMAT = 1


def cache_dir() -> Path | None:
    """The folder :func:`remembered` keeps its files in, or None where caching on disk is off."""
    env = os.environ.get("KINLEARN_CACHE_DIR")
    if env is not None:
        return None if env.strip() in ("", "off") else Path(env).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg).expanduser() if xdg else Path.home() / ".cache"
    return base / "kinlearn"


def _key(name: str, parts: tuple, code: tuple[str, ...]) -> str:
    h = hashlib.sha256(f"{name}\0{_FORMAT}".encode())
    for file in code:
        h.update(b"\0f" + _source(file))
    for part in parts:
        if isinstance(part, bytes):
            h.update(b"\0b%d:" % len(part))
            h.update(part)
        elif isinstance(part, np.ndarray):
            a = np.ascontiguousarray(part)
            h.update(f"\0a{a.dtype.str}{a.shape}".encode())
            h.update(a.tobytes())
        else:
            h.update(f"\0{type(part).__name__}:{part!r}".encode())
    return h.hexdigest()[:40]


def _source(file: str) -> bytes:
    hit = _SOURCES.get(file)
    if hit is None:
        hit = _SOURCES[file] = hashlib.sha256(Path(file).read_bytes()).digest()
    return hit


_SOURCES: dict[str, bytes] = {}


def remembered(
    name: str, parts: tuple, compute: Callable[[], np.ndarray], *, dtype, shape, code: tuple[str, ...] = ()
) -> np.ndarray:
    """``compute()`` (an array of ``dtype`` and ``shape``), read from the cache where a process already
    computed it for the same ``name``, ``parts`` (arrays, bytes, numbers, strings: everything the result
    depends on) and ``code`` (the source files of the computation: an edit to them is a new key), else
    computed and kept. The array returned is read-only."""
    folder = cache_dir()
    path = None if folder is None else folder / f"{name}-{_key(name, parts, code)}.npy"
    if path is not None and path.is_file():
        try:
            out = np.load(path, allow_pickle=False)
            if out.dtype == np.dtype(dtype) and out.shape == tuple(shape):
                out.flags.writeable = False
                return out
        except (OSError, ValueError, EOFError):
            pass
    out = np.ascontiguousarray(compute(), dtype=dtype)
    if out.shape != tuple(shape):
        raise ValueError(f"{name}: computed shape {out.shape}, expected {tuple(shape)}")
    if path is not None:
        _keep(path, out)
    out.flags.writeable = False
    return out


def _keep(path: Path, out: np.ndarray) -> None:
    from .errors import OutputError
    from .io import atomic_write

    def write(tmp: Path) -> None:
        with open(tmp, "wb") as fh:
            np.save(fh, out, allow_pickle=False)

    try:
        atomic_write(path, write)
    except (OutputError, OSError):  # a cache that cannot be written is no cache: compute each time
        pass
