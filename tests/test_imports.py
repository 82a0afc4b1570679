"""No import cycles between RoboView's modules, counting imports inside functions too (a lazy import that
breaks a cycle at run time still ties the two modules together) and imports by name (a registry's module
list, `importlib.import_module("pkg.mod")`, a "pkg.mod:Class" a registry resolves): each ties two modules
as firmly."""

from __future__ import annotations

import ast
import re
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


# A string naming a module below a package ("pkg.mod") or an attribute of one ("pkg.mod:Class").
MODULE_STRING = re.compile(r"^[a-z_][a-z0-9_]*(\.[a-z0-9_]+)+(:[A-Za-z_][\w.]*)?$")


def named_modules(tree: ast.AST) -> set[str]:
    """What a module imports by name: a literal given to `import_module`, and every other string constant
    (docstrings aside) that names a module or a module's attribute ("pkg.mod:Class"), as registries declare
    them (a module list, an env or expert class, a gymnasium entry point) for a helper to import."""
    docstrings = {id(node.value) for node in ast.walk(tree) if isinstance(node, ast.Expr)}
    # `[python, "-m", "pkg.mod"]` runs a module in another process: no import.
    run = {id(b) for node in ast.walk(tree) if isinstance(node, (ast.List, ast.Tuple))
           for a, b in zip(node.elts, node.elts[1:]) if isinstance(a, ast.Constant) and a.value == "-m"}
    found = set()
    for node in ast.walk(tree):
        if (isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant)
                and isinstance(node.args[0].value, str)
                and (getattr(node.func, "attr", None) or getattr(node.func, "id", None)) == "import_module"):
            found.add(node.args[0].value)
        elif (isinstance(node, ast.Constant) and isinstance(node.value, str)
                and id(node) not in docstrings | run and MODULE_STRING.match(node.value)):
            found.add(node.value.partition(":")[0])
    return found


def import_graph() -> dict[str, set[str]]:
    """module → the project modules it imports (the named module itself, not the packages above it)."""
    modules = _modules()
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        edges = set()
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        tree = ast.parse(path.read_text(), str(path))
        edges |= {t for t in named_modules(tree) if t in modules and t != name}
        for node in ast.walk(tree):
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


# Circles being taken apart in roboview_data.sim and roboview_data.variation: a task's env and expert named by
# "module:Class" import the task registry back; a factor applier needs the scene that applies the factors.
# The test fails on a new circle, and on one listed here that is gone (then delete its line).
KNOWN_CIRCLES = [
    ["roboview_data.sim.scene", "roboview_data.variation.factors",
     "roboview_data.variation.factors.object_size"],
    ["roboview_data.sim.env", "roboview_data.sim.expert", "roboview_data.sim.push",
     "roboview_data.sim.tasks"],
]


def test_the_project_has_no_import_cycle():
    found = cycles(import_graph())
    new = [c for c in found if c not in KNOWN_CIRCLES]
    gone = [c for c in KNOWN_CIRCLES if c not in found]
    assert not new, "import cycles: " + "; ".join(" ↔ ".join(c) for c in new)
    assert not gone, "gone, delete from KNOWN_CIRCLES: " + "; ".join(" ↔ ".join(c) for c in gone)


def test_imports_by_name_are_edges():
    code = '''"""Docstring naming roboview_data.sim.env is no import."""
import importlib
MODULES = ("policies.vision", "not.a.module")
TASK = dict(env="roboview_data.sim.push:PushEnv")
importlib.import_module("eval")
cmd = ["python", "-m", "pipelines.evaluate"]
label = "a plain string, not.a.name:either"
'''
    found = named_modules(ast.parse(code))
    assert found == {"policies.vision", "not.a.module", "roboview_data.sim.push", "eval"}
    # In the project: a registry's module list, "module:Class" targets, the console scripts' modules.
    graph = import_graph()
    assert "policies.vision" in graph["policies.types"] and "policies.vision" not in graph["policies.base"]
    assert {"roboview_data.sim.env", "roboview_data.sim.push"} <= graph["roboview_data.sim.tasks"]
    assert "roboview_data.variation.factors.color" in graph["roboview_data.variation.factors"]
    assert "pipelines.collect" in graph["pipelines._console"]
    assert "roboview_lerobot.env" in graph["roboview_lerobot"]


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
