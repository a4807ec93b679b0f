"""Prose that is checked: the claims of the README and the docs that a test can hold to the code.

- the README's layout table names every top-level module and sub-package of ``kinlearn`` at the floor
  ``tests/test_layers.py`` gives it, and nothing that does not exist;
- the list of built-in baselines in ``kinlearn.baselines``' docstring is the registry's;
- the API reference documents every front-door name and every error and warning;
- every figure in a README table under a ``python benchmarks/<script>.py`` command is a cell of that
  benchmark's stored result (``benchmarks/results/``): the README shows current numbers only;
- README and docs name no internal milestone and keep within their size.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

from test_layers import FLOORS

import kinlearn
import kinlearn.errors as errors
from kinlearn import baselines

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")


def _tables(text: str) -> list[tuple[int, list[list[str]]]]:
    """(line of its header, rows of cells) of every markdown table of ``text``, rule row left out."""
    out, rows, start = [], [], 0
    for i, line in enumerate([*text.splitlines(), ""]):
        if line.startswith("|"):
            if not rows:
                start = i
            rows.append([c.strip() for c in line.strip().strip("|").split("|")])
        elif rows:
            out.append((start, [r for r in rows if not set("".join(r)) <= set(":- ")]))
            rows = []
    return out


def test_the_readme_layout_table_is_the_package():
    (_, rows), *_ = [t for t in _tables(README) if t[1][0][:2] == ["floor", "package"]]
    named = {}
    for floor, package, _ in rows[1:]:
        for name in re.findall(r"`([^`]+)`", package):
            named[name.rstrip("/")] = int(floor)
    top = {p.stem for p in (ROOT / "kinlearn").glob("*.py") if p.stem != "__init__"}
    top |= {p.parent.name for p in (ROOT / "kinlearn").glob("*/__init__.py")}
    assert set(named) == top, f"README layout: missing {top - set(named)}, not in kinlearn {set(named) - top}"
    wrong = {n: (f, FLOORS[n]) for n, f in named.items() if FLOORS.get(n) != f}
    assert not wrong, f"README layout floors against tests/test_layers.py (README, layers): {wrong}"


def test_the_baselines_docstring_lists_the_registry():
    doc = baselines.__doc__ or ""
    listed = dict(re.findall(r"^``([a-z-]+)``\s+:class:`(\w+)`", doc, re.M))
    registry = {name: baselines.get(name).__name__ for name in baselines.names()}
    assert listed == registry, f"kinlearn.baselines' docstring lists {listed}, the registry holds {registry}"


def test_the_api_reference_covers_the_front_door_and_every_error_and_warning():
    api = (ROOT / "docs" / "api.md").read_text(encoding="utf-8")
    blocks = set(re.findall(r"^::: ([\w.]+)", api, re.M))
    classes = {n for n, c in vars(errors).items() if isinstance(c, type) and c.__module__ == errors.__name__}
    assert "kinlearn.errors" in blocks  # renders every public class of the module
    missing = []
    for name in kinlearn.__all__:
        if name in classes or name == "__version__":
            continue
        value = getattr(kinlearn, name)
        home = f"{getattr(value, '__module__', '')}.{name}"
        if f"kinlearn.{name}" not in blocks and home not in blocks:
            missing.append(name)
    assert not missing, f"docs/api.md documents no {missing}"
    assert "`kinlearn.__version__`" in api
    assert all(not n.startswith("_") for n in classes)  # mkdocstrings leaves out private names


def _result_cells() -> dict[str, set[str]]:
    cells: dict[str, set[str]] = {}
    for path in (ROOT / "benchmarks" / "results").glob("*.json"):
        record = json.loads(path.read_text(encoding="utf-8"))
        script = re.search(r"benchmarks/(\w+)\.py", record["command"]).group(1)
        cells.setdefault(script, set()).update(_leaves(record["figures"]))
    return cells


def _leaves(value: object) -> list[str]:
    if isinstance(value, dict):
        return [x for v in value.values() for x in _leaves(v)]
    if isinstance(value, list):
        return [x for v in value for x in _leaves(v)]
    return [str(value).strip()]


def test_every_readme_figure_is_a_current_result():
    cells = _result_cells()
    lines = README.splitlines()
    checked = 0
    for start, rows in _tables(README):
        before = "\n".join(lines[max(0, start - 6) : start])
        command = re.findall(r"python benchmarks/(\w+)\.py", before)
        if not command:
            continue
        script = command[-1]
        assert script in cells, f"README line {start + 1}: no stored result of benchmarks/{script}.py"
        for row in rows[1:]:
            for cell in row:
                value = cell.replace("**", "").strip()
                if re.search(r"\d", value):
                    assert value in cells[script], (
                        f"README line {start + 1}: {value!r} is not in benchmarks/{script}.py's result"
                    )
                    checked += 1
    assert checked >= 20


def test_no_milestone_and_a_short_readme():
    assert len(README.splitlines()) <= 200
    texts = [ROOT / "README.md", ROOT / "CHANGELOG.md", *sorted((ROOT / "docs").glob("*.md"))]
    for path in texts:
        hits = re.findall(r"\bstops? [0-9]+", path.read_text(encoding="utf-8"), re.I)
        assert not hits, f"{path.name} speaks of milestones: {hits[:3]}"
    figures = [p.name for p in (ROOT / "docs" / "figures").iterdir()]
    assert not [f for f in figures if re.search(r"_s[0-9]+\.", f)], figures
