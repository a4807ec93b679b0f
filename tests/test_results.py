"""Results are data: every benchmark writes its figures through ``benchmarks/_common.write_result`` into
``benchmarks/results/<name>.json``, and ``docs/results.md`` is what ``benchmarks/report.py`` renders from
them, byte for byte (so a figure reaches the docs only by being measured, and a hand edit fails here)."""

from __future__ import annotations

import ast
import json
import math
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCHMARKS = ROOT / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))

import _common  # noqa: E402
import report  # noqa: E402


def test_docs_results_is_what_the_results_render_to():
    records = report.load()
    assert records, "benchmarks/results/ holds no result"
    text = report.render(records)
    assert (ROOT / "docs" / "results.md").read_text(encoding="utf-8") == text, (
        "docs/results.md is not what benchmarks/results/*.json render to: run python benchmarks/report.py"
    )
    assert report.render(report.load()) == text  # deterministic
    assert report.main(["--check"]) == 0


def test_every_result_names_the_command_that_regenerates_it():
    for record in report.load():
        words = record["command"].split()
        script = next(w for w in words if w.endswith(".py"))
        assert (ROOT / script).is_file(), (record["name"], script)
        assert script.startswith("benchmarks/"), record["command"]
        assert len(record["commit"]) >= 7 and record["machine"]["cores"] >= 1
        assert {"python", "kinlearn", "torch"} <= set(record["versions"])


def test_no_figure_appears_twice():
    titles = [r["title"] for r in report.load()]
    assert len(titles) == len(set(titles)), titles


def test_every_benchmark_that_measures_writes_a_result():
    """Each script that prints a table of figures hands them to write_result (the figure-making scripts
    and the problem generator excepted)."""
    makes_no_result = {"make_animation.py", "make_obstacle_problems.py", "viewer_screenshot.py", "report.py"}
    for path in sorted(BENCHMARKS.glob("[a-z]*.py")):
        if path.name in makes_no_result:
            continue
        called = {
            n.func.id
            for n in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
            if isinstance(n, ast.Call) and isinstance(n.func, ast.Name)
        }
        assert "write_result" in called, f"{path.name} writes no result"


def test_write_result_round_trip(tmp_path):
    import numpy as np

    figures = {
        "speed": _common.table(["batch", "ms"], [[1, np.float64(0.25)], [1024, 1.5]], caption="Median."),
        "dof": np.int64(7),
        "by arm": {"iiwa14": "100%", "panda": 0.95},
    }
    path = _common.write_result("demo", figures, command="python benchmarks/demo.py --n 3", root=tmp_path)
    record = json.loads(path.read_text())
    assert record["schema"] == report.SCHEMA and record["figures"]["dof"] == 7
    assert record["figures"]["speed"]["rows"][0] == [1, 0.25] and record["command"].endswith("--n 3")
    assert not list(tmp_path.glob(".*.tmp"))  # the atomic write left nothing behind
    text = report.render(report.load(tmp_path))
    assert "| batch | ms |" in text and "| 1024 | 1.5 |" in text and "- dof: 7" in text
    assert "python benchmarks/demo.py --n 3" in text and "### By arm" in text


@pytest.mark.parametrize(
    "figures, match",
    [
        ({"x": math.nan}, "NaN"),
        ({"x": {1: 2}}, "not a string"),
        ({"x": object()}, "object"),
        ({"t": {"columns": ["a"], "rows": [[1]]}, "u": _common.table(["a", "b"], [[1, 2]])}, None),
    ],
)
def test_write_result_refuses_what_json_cannot_hold(tmp_path, figures, match):
    if match is None:
        _common.write_result("ok", figures, command="python benchmarks/x.py", root=tmp_path)
        return
    with pytest.raises(ValueError, match=match):
        _common.write_result("bad", figures, command="python benchmarks/x.py", root=tmp_path)
    assert not list(tmp_path.iterdir())


def test_a_table_row_must_fit_its_header_and_a_stale_page_fails(tmp_path):
    with pytest.raises(ValueError, match="2 cells under 3 columns"):
        _common.table(["a", "b", "c"], [[1, 2]])
    _common.write_result("one", {"n": 1}, command="python benchmarks/x.py", root=tmp_path)
    out = tmp_path / "results.md"
    out.write_text("# Results\n\nwritten by hand\n")
    assert report.main(["--results", str(tmp_path), "--out", str(out), "--check"]) == 1
    assert report.main(["--results", str(tmp_path), "--out", str(out)]) == 0
    assert report.main(["--results", str(tmp_path), "--out", str(out), "--check"]) == 0
