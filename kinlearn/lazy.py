"""Packages whose public names are imported when first used (PEP 562), so that importing the package
costs nothing until a name is asked for (``import kinlearn`` and ``kinlearn --help`` load no torch).

A package lists its names as imports under ``if TYPE_CHECKING:`` (read from its source, so that
type checkers, readers and the layer test see every dependency) and ends with::

    __getattr__, __dir__ = lazy_package(__name__, __file__, __all__)

``moved`` maps names that left the package's ``__all__`` to where they are now, as a dotted path
(``"kinlearn.train.train_fm"``, or under a new name ``"kinlearn.baselines.JointLine"``): they still
resolve, for one release, with a :class:`~kinlearn.errors.KinlearnDeprecationWarning` (a
:class:`DeprecationWarning`) naming it. Works for a plain module too
(``kinlearn.train``).
"""

from __future__ import annotations

import ast
import importlib
import sys
import warnings
from collections.abc import Callable, Mapping
from pathlib import Path

from .errors import KinlearnDeprecationWarning

__all__ = ["lazy_package"]


def _table(file: str) -> dict[str, str]:
    """Name → the module it comes from, as the file's ``TYPE_CHECKING`` imports list them."""
    tree = ast.parse(Path(file).read_text(encoding="utf-8"))
    table = {}
    for node in tree.body:
        if isinstance(node, ast.If) and getattr(node.test, "id", None) == "TYPE_CHECKING":
            for imp in node.body:
                if isinstance(imp, ast.ImportFrom):
                    for alias in imp.names:
                        table[alias.asname or alias.name] = "." * imp.level + (imp.module or "")
    return table


def lazy_package(
    package: str, file: str, names: list[str], moved: Mapping[str, str] | None = None
) -> tuple[Callable[[str], object], Callable[[], list[str]]]:
    """The module ``__getattr__`` and ``__dir__`` of ``package`` (its ``__file__``, its ``__all__``)."""
    moved = dict(moved or {})
    table: dict[str, str] | None = None

    def __getattr__(name: str):
        nonlocal table
        module = sys.modules[package]
        if name in moved:
            home, _, attr = moved[name].rpartition(".")
            warnings.warn(
                f"{package}.{name} moved to {moved[name]}; the old name goes in the next release",
                KinlearnDeprecationWarning,
                stacklevel=2,
            )
            return getattr(importlib.import_module(home), attr)  # not cached: it warns on every use
        if table is None:
            table = _table(file)
        if name in table:
            value = getattr(importlib.import_module(table[name], module.__package__), name)
        elif "__path__" not in vars(module) or name.startswith("__"):  # no sub-module by that name
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        else:
            try:  # a sub-package or module (kinlearn.collision, kinlearn.models.chain, ...)
                value = importlib.import_module(f".{name}", package)
            except ModuleNotFoundError as exc:
                if exc.name != f"{package}.{name}":
                    raise
                raise AttributeError(f"module {package!r} has no attribute {name!r}") from None
        setattr(module, name, value)
        return value

    def __dir__() -> list[str]:
        return sorted(set(vars(sys.modules[package])) | set(names))

    return __getattr__, __dir__
