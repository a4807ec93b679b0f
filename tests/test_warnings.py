"""Every warning kinlearn emits derives from :class:`kinlearn.KinlearnWarning`, so that one filter
silences or escalates them all: the package's source is walked for ``warnings.warn`` calls, and the
category of each is resolved in its module and checked."""

from __future__ import annotations

import ast
import importlib
import warnings
from pathlib import Path

import pytest

import kinlearn
import kinlearn.errors as errors

PACKAGE = Path(kinlearn.__file__).resolve().parent


def _module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _warn_calls() -> list[tuple[Path, int, ast.expr | None]]:
    """(file, line, category expression or None) of every ``warnings.warn(...)``/``warn(...)`` call."""
    calls = []
    for path in sorted(PACKAGE.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if not isinstance(node, ast.Call):
                continue
            f = node.func
            named = (
                isinstance(f, ast.Attribute)
                and f.attr == "warn"
                and isinstance(f.value, ast.Name)
                and f.value.id == "warnings"
            ) or (isinstance(f, ast.Name) and f.id == "warn")
            if not named:
                continue
            category = node.args[1] if len(node.args) > 1 else None
            for kw in node.keywords:
                if kw.arg == "category":
                    category = kw.value
            calls.append((path, node.lineno, category))
    return calls


def test_the_walk_finds_the_package_warnings():
    calls = _warn_calls()
    files = {p.name for p, _, _ in calls}
    assert len(calls) >= 8 and {"io.py", "lazy.py", "recorded.py", "planner.py"} <= files


@pytest.mark.parametrize("path,line,category", _warn_calls(), ids=lambda v: getattr(v, "name", str(v)))
def test_every_warning_emitted_is_a_kinlearn_warning(path, line, category):
    where = f"{path.relative_to(PACKAGE.parent)}:{line}"
    assert category is not None, (
        f"{where}: warns with the default UserWarning; give it a KinlearnWarning class"
    )
    module = importlib.import_module(_module_name(path))
    value = eval(compile(ast.Expression(category), where, "eval"), vars(module))  # a name or an attribute
    assert isinstance(value, type) and issubclass(value, kinlearn.KinlearnWarning), (where, value)


def test_every_warning_class_is_a_kinlearn_warning_and_says_when():
    classes = [c for c in vars(errors).values() if isinstance(c, type) and issubclass(c, Warning)]
    assert len(classes) >= 8
    for cls in classes:
        assert issubclass(cls, kinlearn.KinlearnWarning), cls
        assert cls.__doc__ and len(cls.__doc__) > 40, cls
    assert issubclass(errors.KinlearnDeprecationWarning, DeprecationWarning)


def test_one_filter_turns_every_kinlearn_warning_into_an_error():
    with warnings.catch_warnings():
        warnings.simplefilter("error", kinlearn.KinlearnWarning)
        with pytest.raises(DeprecationWarning, match=r"kinlearn\.baselines\.JointLine"):
            kinlearn.JointInterpolation  # noqa: B018 - an old name, moved
        with pytest.raises(errors.KinlearnDeprecationWarning):
            kinlearn.babble  # noqa: B018
