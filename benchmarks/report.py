"""Render docs/results.md from the benchmarks' results (``benchmarks/results/*.json``).

    python benchmarks/report.py [--results benchmarks/results] [--out docs/results.md] [--check]

Each result file (written by :func:`_common.write_result`, its layout in that docstring) becomes one
section: its title, the command that regenerates it, when and where it was measured (commit, date, CPU,
cores, threads, versions), its notes, then its figures in the order written (a table as a markdown
table under its caption, a number or a string as a line, a mapping as a sub-section). Sections are
ordered by :data:`ORDER`, then by name. The output depends on the result files alone (no clock, no
machine), so rendering twice gives the same bytes; ``--check`` exits 1 if ``--out`` differs from it,
as CI does (``tests/test_results.py``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
OUT = ROOT / "docs" / "results.md"
SCHEMA = 1

#: Benchmarks whose results come first, in this order (what a reader looks for first; a benchmark's
#: results per arm or option, ``<benchmark>_<suffix>``, together); the others follow by name.
ORDER = (
    "workspace_planner",
    "position_goals",
    "plan_latency",
    "identification",
    "fm_im_ablation",
    "obstacle_families",
    "ball_problems",
    "ur5_gripper",
    "ur5_limits",
    "panda_limits",
    "kinematics_speed",
    "babbling_speed",
)

HEAD = """# Results

Rendered by `python benchmarks/report.py` from the benchmarks' own results (`benchmarks/results/*.json`,
each written by the benchmark that measured it): do not edit by hand. Each section gives the command
that regenerates it and the commit, date and machine it was measured on. What each benchmark does is in
its script's docstring and in [benchmarks.md](benchmarks.md). Times depend on the machine and on its
load; compare the rows of one table, measured in the same run.
"""


class ResultError(ValueError):
    """A result file that cannot be rendered (not JSON, another schema, a field missing)."""


def load(results: Path = RESULTS) -> list[dict]:
    """Every result file under ``results``, checked, in the order of the page."""
    out = []
    for path in sorted(Path(results).glob("*.json")):
        try:
            record = json.loads(path.read_text(encoding="utf-8"))
        except json.JSONDecodeError as exc:
            raise ResultError(f"{path}: not JSON ({exc})") from exc
        if not isinstance(record, dict) or record.get("schema") != SCHEMA:
            raise ResultError(
                f"{path}: schema {record.get('schema') if isinstance(record, dict) else None}, not {SCHEMA}"
            )
        missing = {"name", "title", "command", "commit", "date", "machine", "versions", "figures"} - set(
            record
        )
        if missing:
            raise ResultError(f"{path}: no {sorted(missing)}")
        if record["name"] != path.stem:
            raise ResultError(f"{path}: its name is {record['name']!r}")
        out.append(record)
    return sorted(out, key=lambda r: (_rank(r["name"]), r["name"]))


def _rank(name: str) -> int:
    """Where a result goes on the page: its benchmark's place in :data:`ORDER` (``obstacle_families_ur5``
    is an ``obstacle_families`` result), after them all when not listed."""
    for i, stem in enumerate(ORDER):
        if name == stem or name.startswith(stem + "_"):
            return i
    return len(ORDER)


def render(records: list[dict]) -> str:
    """The page, as text."""
    parts = [HEAD]
    for r in records:
        parts.append(_section(r))
    return "\n".join(parts).rstrip() + "\n"


def _section(r: dict) -> str:
    m = r["machine"]
    versions = ", ".join(f"{k} {v}" for k, v in r["versions"].items())
    commit = f"`{r['commit']}`" + (" (with uncommitted changes)" if r.get("dirty") else "")
    lines = [
        f"## {r['title']}",
        "",
        "```bash",
        r["command"],
        "```",
        "",
        f"Measured {r['date']} at commit {commit} on {m['cpu']} ({m['cores']} cores, {m['threads']} "
        f"thread{'s' if m['threads'] != 1 else ''}"
        + (f", load average {m['load']:g}" if m.get("load") is not None else "")
        + f"); {versions}.",
        "",
    ]
    if r.get("notes"):
        lines += [r["notes"].strip(), ""]
    lines += _figures(r["figures"], depth=3)
    return "\n".join(lines)


def _figures(figures: dict, depth: int) -> list[str]:
    lines: list[str] = []
    scalars = [(k, v) for k, v in figures.items() if not isinstance(v, (dict, list))]
    if scalars:
        lines += [f"- {k}: {_cell(v)}" for k, v in scalars] + [""]
    for key, value in figures.items():
        if isinstance(value, dict) and "columns" in value and "rows" in value:
            lines += [f"{'#' * depth} {key[0].upper() + key[1:]}", ""]
            if value.get("caption"):
                lines += [value["caption"], ""]
            lines += [*_table(value["columns"], value["rows"]), ""]
        elif isinstance(value, dict):
            lines += [f"{'#' * depth} {key[0].upper() + key[1:]}", "", *_figures(value, min(depth + 1, 6))]
        elif isinstance(value, list):
            lines += [f"- {key}: " + ", ".join(_cell(v) for v in value), ""]
    return lines


def _table(columns: list, rows: list) -> list[str]:
    numeric = [all(_is_number(row[i]) for row in rows) and rows for i in range(len(columns))]
    out = ["| " + " | ".join(_cell(c) for c in columns) + " |"]
    out.append("|" + "|".join("--:" if n else ":--" for n in numeric) + "|")
    out += ["| " + " | ".join(_cell(c) for c in row) + " |" for row in rows]
    return out


def _is_number(v: object) -> bool:
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        return True
    s = str(v).strip().rstrip("%×").replace(",", "").replace("—", "")
    try:
        float(s.split(" ")[0]) if s else None
    except ValueError:
        return False
    return True


def _cell(v: object) -> str:
    if v is None:
        return "—"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v).replace("|", "\\|").replace("\n", " ")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--results", type=Path, default=RESULTS)
    ap.add_argument("--out", type=Path, default=OUT)
    ap.add_argument("--check", action="store_true", help="exit 1 if --out is not what the results render to")
    args = ap.parse_args(argv)
    text = render(load(args.results))
    if args.check:
        current = args.out.read_text(encoding="utf-8") if args.out.exists() else ""
        if current != text:
            print(f"{args.out} is not what {args.results} renders to: run python benchmarks/report.py")
            return 1
        return 0
    args.out.write_text(text, encoding="utf-8")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
