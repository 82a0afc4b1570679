"""No import cycles between RoboView's modules, counting imports inside functions too (a lazy import that
breaks a cycle at run time still ties the two modules together)."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).parents[1]
PACKAGES = ("eval", "policies", "pipelines", "roboview_data", "roboview_lerobot", "benchmarks")


def _modules() -> dict[str, Path]:
    found = {}
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            parts = path.relative_to(ROOT).with_suffix("").parts
            found[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return found


def import_graph() -> dict[str, set[str]]:
    """module → the project modules it imports (the named module itself, not the packages above it)."""
    modules = _modules()
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        edges = set()
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    base = ".".join(package.split(".")[: len(package.split(".")) - node.level + 1] + ([base] if base else []))
                targets = [f"{base}.{alias.name}" if f"{base}.{alias.name}" in modules else base for alias in node.names]
            else:
                continue
            edges |= {t for t in targets if t in modules and t != name}
        graph[name] = edges
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan), each as a cycle path."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_the_project_has_no_import_cycle():
    found = cycles(import_graph())
    assert not found, "import cycles: " + "; ".join(" ↔ ".join(c) for c in found)


def test_the_cycle_finder_finds_a_cycle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert cycles(graph) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []
    # The real graph holds the edges the modules declare, lazy ones included.
    graph = import_graph()
    assert "eval.statistics.tables" in graph["eval.statistics.compare"] and "policies.base" in graph["policies.vlm.sgl"]
    assert "eval.statistics.metrics" not in graph["eval.statistics.compare"] and "policies.vlm.sgl" not in graph["policies.base"]
    assert "eval.statistics.adaptive" in graph["pipelines.evaluate"]  # imported inside a method


# The house's floors, lowest first: a module imports only from its own package or a lower floor (an arrow
# back up would tie the lower floor to everything above it). roboview_lerobot stands beside the statistics:
# it reads results as eval.running writes them, nothing above.
FLOORS = {"roboview_data": 0, "policies": 1, "eval": 2, "eval.running": 2, "eval.statistics": 3,
          "roboview_lerobot": 3, "eval.reporting": 4, "pipelines": 5, "benchmarks": 6}


def floor_of(module: str) -> str:
    parts = module.split(".")
    return ".".join(parts[:2]) if parts[0] == "eval" and len(parts) > 1 else parts[0]


def upward_imports(graph: dict[str, set[str]]) -> list[str]:
    """Every edge from a module to one on another floor that is not below its own."""
    return sorted(f"{a} → {b}" for a, targets in graph.items() for b in targets
                  if floor_of(a) != floor_of(b) and FLOORS[floor_of(b)] >= FLOORS[floor_of(a)])


def test_no_module_imports_from_a_higher_floor():
    graph = import_graph()
    assert {floor_of(m) for m in graph} <= set(FLOORS), "a package without a floor: add it to FLOORS"
    found = upward_imports(graph)
    assert not found, "imports from a higher floor: " + "; ".join(found)
    # The rule sees an arrow back up, a lazy one too.
    assert upward_imports({"roboview_lerobot.convert": {"pipelines._cli"}, "pipelines._cli": set()}) == [
        "roboview_lerobot.convert → pipelines._cli"]
    assert upward_imports({"eval.statistics.x": {"roboview_lerobot.y"}, "roboview_lerobot.y": set()}) == [
        "eval.statistics.x → roboview_lerobot.y"]


def test_importing_the_package_registers_the_gym_ids():
    import subprocess
    import sys

    code = ("import gymnasium, roboview_data; from roboview_data.sim.tasks import TASKS; "
            "print(sorted(t.gym_id for t in TASKS.values() if t.gym_id in gymnasium.registry))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-800:]
    assert proc.stdout.strip() == "['RoboView/PickPlace-v0', 'RoboView/Push-v0']"
