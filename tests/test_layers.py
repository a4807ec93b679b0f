"""The package's layers: every import points down a floor (or stays on its own), and no import circle.

The floors follow the data, one sub-package each: errors, files and the polyline metrics → ``body``
(the robot and its kinematics) → ``collision`` (and ``viz``, which draws the robot and obstacles) →
``data`` (babbling, endpoints) → ``models`` → ``training`` → ``planning`` → ``evaluation`` → ``cli``.
The graph is read from the source (``ast``), module-level imports and imports inside functions alike,
so a lazy import cannot hide a dependency running up. ``KNOWN_UPWARD`` lists upward imports that are
tolerated as debts (none today); a new one fails this test.
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "kinlearn"

#: Each sub-package is one floor; a module's floor is its sub-package's.
FLOORS: dict[str, int] = {
    "errors": 0, "checks": 0, "io": 0, "runs": 0,  # errors, input checks, files, run directories
    "memo": 0,  # results of pure computations kept on disk between processes
    "lazy": 0,  # packages whose names are imported when first used
    "polyline": 0,  # the paper's trajectory metrics of a polyline of points
    "body": 1,  # the robot, its kinematics and state layout
    "collision": 2,  # collision geometry, scenes, benchmark problems
    "viz": 2,  # drawing the robot and obstacles: needs only the robot, so any layer can show itself
    "data": 3,  # babbling, endpoint pairs
    "models": 4,  # FM/IM, trajectory models, body model, Algorithm 1's rollout
    "training": 5,
    "planning": 6,
    "evaluation": 7,
    "train": 5,  # the trainers' public home (kinlearn.train: re-exports, by purpose)
    "baselines": 6,  # the baselines' public home and their registry (kinlearn.baselines)
    "": 8, "__main__": 8, "cli": 8, "loading": 8,  # the public surface (kinlearn.load) and the command line
}  # fmt: skip

#: Upward imports that exist today (importer, imported): debts, not permissions to add more.
KNOWN_UPWARD: set[tuple[str, str]] = set()


#: Imports forbidden even though they point down: planning (loading and running a planner) uses models,
#: never training code.
FORBIDDEN = {("planning", "training")}


def _modules() -> dict[str, Path]:
    out = {}
    for f in PACKAGE.rglob("*.py"):
        parts = f.relative_to(PACKAGE).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = f
    return out


def _imports(modules: dict[str, Path]) -> dict[str, set[str]]:
    graph = {}
    for name, f in modules.items():
        package = name.split(".") if f.name == "__init__.py" and name else name.split(".")[:-1]
        found = set()
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package[: len(package) - (node.level - 1)] if node.level > 1 else package
                    target = ".".join([*base, *([node.module] if node.module else [])])
                elif node.module and node.module.startswith("kinlearn"):
                    target = node.module.removeprefix("kinlearn").lstrip(".")
                else:
                    continue
                for cand in (target, *(f"{target}.{a.name}".lstrip(".") for a in node.names)):
                    if cand in modules and cand != name:
                        found.add(cand)
            elif isinstance(node, ast.Import):
                for a in node.names:
                    if a.name.startswith("kinlearn"):
                        cand = a.name.removeprefix("kinlearn").lstrip(".")
                        if cand in modules and cand != name:
                            found.add(cand)
        graph[name] = found
    return graph


def _floor(name: str) -> int:
    top = name.split(".")[0]
    if top in FLOORS:
        return FLOORS[top]
    raise AssertionError(
        f"module kinlearn.{name} is in no floor's sub-package: move it into one, or add its sub-package to "
        "FLOORS in tests/test_layers.py"
    )


def test_every_module_has_a_floor():
    for name in _modules():
        _floor(name)


def test_imports_point_down():
    graph = _imports(_modules())
    upward = {(a, b) for a, targets in graph.items() for b in targets if _floor(b) > _floor(a)}
    new = upward - KNOWN_UPWARD
    assert not new, f"imports running up a floor: {sorted(new)}"
    assert not (KNOWN_UPWARD - upward), f"listed debts that are gone (remove them): {KNOWN_UPWARD - upward}"


def test_planning_imports_no_training_code():
    graph = _imports(_modules())
    bad = {
        (a, b)
        for a, targets in graph.items()
        for b in targets
        if (a.split(".")[0], b.split(".")[0]) in FORBIDDEN
    }
    assert not bad, f"forbidden imports: {sorted(bad)}"


def test_no_import_circle():
    graph = _imports(_modules())
    state: dict[str, int] = {}

    def visit(u: str, stack: list[str]) -> None:
        state[u] = 1
        stack.append(u)
        for v in sorted(graph[u]):
            if state.get(v) == 1:
                raise AssertionError("import circle: " + " → ".join([*stack[stack.index(v) :], v]))
            if not state.get(v):
                visit(v, stack)
        stack.pop()
        state[u] = 2

    for u in sorted(graph):
        if not state.get(u):
            visit(u, [])
