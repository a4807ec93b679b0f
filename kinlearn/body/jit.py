"""The one decorator of the package's compiled kernels (numba), importable without importing numba.

A concept keeps its compiled twin beside its torch reference (a primitive kind's distance, the body's
FK, the success rule), and those modules are imported by code that never checks a path (building a
scene, loading a robot). numba takes most of a second to import, so :func:`jit` does not import it:
a function decorated before numba is loaded is held as a :class:`Pending` stand-in, and :func:`ready`
(called by every module that runs kernels, before it imports them) imports numba, compiles nothing yet,
and puts a numba dispatcher in place of every stand-in, under every name any ``kinlearn`` module bound it
to. Functions decorated after that are dispatchers at once. Each dispatcher compiles on its first call
(nothing at import) and keeps its machine code on disk (``cache=True``), so a later process loads it.

numba's disk cache checks only the file a function is written in, while a kernel carries the machine code
of the kernels it calls, written in other files (a kind's distance inside the dense-check walk). Every
kernel's cache is therefore stamped with the sizes and times of all the files kernels are written in
(:data:`SOURCES`): editing any of them recompiles every kernel once, never a stale one.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

__all__ = ["SOURCES", "Pending", "jit", "ready"]

#: Options of every kernel: the GIL released, IEEE arithmetic (no fast-math reordering: the kernels'
#: numbers are those of their torch references to the bit where they say so).
OPTIONS = {"cache": True, "nogil": True, "fastmath": False}

_PACKAGE = Path(__file__).resolve().parents[1]
#: Where the kernels are written, relative to the package: every ``.py`` file of these names or in these
#: folders stamps every kernel's cache (a file whose kernels others call belongs here).
SOURCES = (
    "body/fk.py",
    "body/jit.py",
    "body/travel.py",
    "collision/configurations.py",
    "collision/kinds",
    "collision/kernel.py",
    "collision/kernel_body.py",
    "collision/kernel_scene.py",
    "collision/probe.py",
    "collision/walk.py",
    "planning/inference.py",
    "planning/judge.py",
)

_PENDING: list[Pending] = []
_STAMP: tuple | None = None


class Pending:
    """A kernel decorated before numba was loaded: its Python function and options, until :func:`ready`
    replaces it by a dispatcher. Called from Python, it makes the kernels ready and calls its own."""

    __slots__ = ("compiled", "options", "py_func")

    def __init__(self, py_func, options: dict):
        self.py_func, self.options, self.compiled = py_func, options, None

    def __call__(self, *args, **kwargs):
        ready()
        return self.compiled(*args, **kwargs)

    def __repr__(self) -> str:
        return f"<kernel {self.py_func.__module__}.{self.py_func.__qualname__} (numba not loaded yet)>"


def _stamp() -> tuple:
    """The sizes and modification times of every kernel source file (:data:`SOURCES`)."""
    global _STAMP
    if _STAMP is None:
        files = []
        for entry in SOURCES:
            path = _PACKAGE / entry
            files += sorted(path.rglob("*.py")) if path.is_dir() else [path]
        stamp = []
        for f in files:
            try:
                st = os.stat(f)
            except OSError:
                continue
            stamp.append((str(f.relative_to(_PACKAGE)), st.st_mtime_ns, st.st_size))
        _STAMP = tuple(stamp)
    return _STAMP


def _compile(py_func, options: dict):
    import numba

    disp = numba.njit(**{**OPTIONS, **options})(py_func)
    cache_file = getattr(getattr(disp, "_cache", None), "_cache_file", None)
    if cache_file is not None and hasattr(cache_file, "_source_stamp"):
        cache_file._source_stamp = (cache_file._source_stamp, _stamp())
    return disp


def jit(fn=None, /, **options):
    """Decorate a kernel: ``@jit`` or ``@jit(inline="always")`` (numba options over :data:`OPTIONS`).
    Gives a numba dispatcher once numba is loaded (:func:`ready`), a :class:`Pending` stand-in before."""

    def wrap(py_func):
        if "numba" in sys.modules and _READY[0]:
            return _compile(py_func, options)
        pending = Pending(py_func, options)
        _PENDING.append(pending)
        return pending

    return wrap(fn) if fn is not None else wrap


_READY = [False]


def ready() -> None:
    """Load numba and put a dispatcher in place of every :class:`Pending` kernel, under every name a
    loaded ``kinlearn`` module holds it by (compiling nothing: each compiles on its first call)."""
    if _READY[0] and not _PENDING:
        return
    _READY[0] = True
    while _PENDING:
        pending = _PENDING.pop(0)
        pending.compiled = _compile(pending.py_func, pending.options)
    for name, module in list(sys.modules.items()):
        if module is None or not (name == "kinlearn" or name.startswith("kinlearn.")):
            continue
        space = getattr(module, "__dict__", None)
        if not space:
            continue
        for key, value in list(space.items()):
            if type(value) is Pending:
                space[key] = value.compiled
