"""The package's layers: every import points down a floor (or stays on its own), and no import circle.

The floors follow the data: errors and files → the robot and its kinematics → collision geometry →
data (babbling, endpoints) → models → training → planning → evaluation → command line. The graph is
read from the source (``ast``), module-level imports and imports inside functions alike, so a lazy
import cannot hide a dependency running up. ``KNOWN_UPWARD`` lists the upward imports that exist
today, each to be removed; a new one fails this test.
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "kinlearn"

FLOORS: dict[str, int] = {
    # 0: errors, state layout, files, run directories
    "errors": 0, "state": 0, "io": 0, "runs": 0,
    # 1: the robot and its kinematics
    "robot": 1, "kinematics": 1,
    # 2: collision geometry, scenes and benchmark problems
    "collision": 2, "collision.body": 2, "collision.scene": 2, "collision.distance": 2,
    "collision.check": 2, "collision.fast": 2, "collision.problems": 2,
    # 3: data
    "babbling": 3, "endpoints": 3,
    # 4: models (and Algorithm 1's rollout)
    "models": 4, "path_model": 4, "obstacle_model": 4, "body_model": 4, "trajectory": 4, "rectify": 4,
    # 5: training
    "train": 5, "train_tm": 5, "train_tm_seeds": 5, "train_path": 5, "train_obstacles": 5, "imitation": 5,
    # 6: planning
    "plan": 6, "planner": 6, "inference": 6, "baselines": 6, "obstacle_baselines": 6, "timing": 6,
    # 7: evaluation and looking
    "metrics": 7, "workspace": 7, "obstacle_eval": 7, "plots": 7, "model_error": 7, "reproduce": 7,
    "viz": 7, "viz._scene": 7, "viz.animate": 7, "viz.viewer": 7,
    # 8: the public surface and the command line
    "": 8, "__main__": 8, "cli": 8, "cli_planning": 8, "cli_body": 8, "cli_view": 8,
}  # fmt: skip

#: Upward imports that exist today (importer, imported): debts, not permissions to add more.
KNOWN_UPWARD = {
    ("imitation", "baselines"),  # the imitation teacher is a baseline planner
    ("train_tm", "metrics"),  # held-out evaluation at the end of TM training
    ("body_model", "train"),  # the learned body reuses the generic training loop (inside a function)
    ("plan", "viz"),  # Plan.show()/animate() (inside the methods)
}


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
    if name in FLOORS:
        return FLOORS[name]
    raise AssertionError(f"module kinlearn.{name} has no floor: add it to FLOORS in tests/test_layers.py")


def test_every_module_has_a_floor():
    for name in _modules():
        _floor(name)


def test_imports_point_down():
    graph = _imports(_modules())
    upward = {(a, b) for a, targets in graph.items() for b in targets if _floor(b) > _floor(a)}
    new = upward - KNOWN_UPWARD
    assert not new, f"imports running up a floor: {sorted(new)}"
    assert not (KNOWN_UPWARD - upward), f"listed debts that are gone (remove them): {KNOWN_UPWARD - upward}"


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
