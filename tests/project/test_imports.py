"""The import graph of RoboView's modules: no cycle, counting imports inside functions (a lazy import that
breaks a cycle at run time still ties the two modules together), imports by name (a registry's module list,
`importlib.import_module("pkg.mod")`, a "pkg.mod:Class" a registry resolves) and the packages an import runs
first (`import a.b.c` runs `a/b/__init__.py`: a module of a wing imports the wing's `__init__`); no module importing
from a higher floor; and no module, test or benchmark importing another module's private (`_`-prefixed) name: what
other modules need is public and documented."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

pytestmark = pytest.mark.fast

ROOT = Path(__file__).resolve().parents[2]
# What is searched for modules: the one installed package and the throughput studies beside it.
PACKAGES = ("roboview", "benchmarks")


def _modules(packages: tuple[str, ...] = PACKAGES) -> dict[str, Path]:
    found = {}
    for package in packages:
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
    run = {
        id(b)
        for node in ast.walk(tree)
        if isinstance(node, (ast.List, ast.Tuple))
        for a, b in zip(node.elts, node.elts[1:])
        if isinstance(a, ast.Constant) and a.value == "-m"
    }
    # An entry-point group's name (`ENTRY_POINT_GROUP = "roboview.tasks"`, `entry_points(group=...)`) names a group
    # of a package's metadata, not a module.
    groups = {
        id(node.value)
        for node in ast.walk(tree)
        if (
            isinstance(node, ast.Assign)
            and any(getattr(t, "id", "").endswith("_GROUP") for t in node.targets)
        )
        or (isinstance(node, ast.keyword) and node.arg == "group")
    }
    found = set()
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Call)
            and node.args
            and isinstance(node.args[0], ast.Constant)
            and isinstance(node.args[0].value, str)
            and (getattr(node.func, "attr", None) or getattr(node.func, "id", None)) == "import_module"
        ):
            found.add(node.args[0].value)
        elif (
            isinstance(node, ast.Constant)
            and isinstance(node.value, str)
            and id(node) not in docstrings | run | groups
            and MODULE_STRING.match(node.value)
        ):
            found.add(node.value.partition(":")[0])
    return found


def packages_above(module: str) -> set[str]:
    """The packages importing `module` runs first: `a` and `a.b` for `a.b.c`."""
    parts = module.split(".")
    return {".".join(parts[:i]) for i in range(1, len(parts))}


def import_graph() -> dict[str, set[str]]:
    """module → the project modules it imports."""
    return graph_of(
        {name: (path.name == "__init__.py", path.read_text()) for name, path in _modules().items()}
    )


def graph_of(sources: dict[str, tuple[bool, str]]) -> dict[str, set[str]]:
    """module → the project modules it imports, from each module's (is a package, source): what it names, and the
    packages above each of those that are not its own (`roboview.libero.task` imported from outside runs
    `roboview/libero/__init__.py` first; a module's own packages are already running)."""
    modules = set(sources)
    graph: dict[str, set[str]] = {}
    for name, (is_package, source) in sources.items():
        edges = set()
        package = name if is_package else name.rpartition(".")[0]
        tree = ast.parse(source, name)
        edges |= {t for t in named_modules(tree) if t in modules and t != name}
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    base = ".".join(
                        package.split(".")[: len(package.split(".")) - node.level + 1]
                        + ([base] if base else [])
                    )
                targets = [
                    f"{base}.{alias.name}" if f"{base}.{alias.name}" in modules else base
                    for alias in node.names
                ]
            else:
                continue
            edges |= {t for t in targets if t in modules and t != name}
        above = {p for t in edges for p in packages_above(t)} - packages_above(name) - {name}
        graph[name] = edges | (above & modules)
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


def private_imports(name: str, source: str, modules: set[str]) -> list[str]:
    """`from M import _x` lines of module `name` (its source) where M is another project module: one
    "module:line: from M import _x" each. A private submodule of the importer's own package (roboview.pipelines._cli
    for roboview.pipelines.evaluate) is the package's own and allowed; dunder names are not private."""
    found = []
    package = name.rpartition(".")[0]
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.ImportFrom):
            continue
        base = node.module or ""
        if node.level:
            parts = name.split(".")[: -node.level]
            base = ".".join(parts + ([base] if base else []))
        if base not in modules or base == name:
            continue
        for alias in node.names:
            private = alias.name.startswith("_") and not alias.name.startswith("__")
            own_submodule = f"{base}.{alias.name}" in modules and base == package
            if private and not own_submodule:
                found.append(f"{name}:{node.lineno}: from {base} import {alias.name}")
    return found


def test_no_module_imports_another_modules_private_name():
    modules = _modules((*PACKAGES, "tests"))
    found = [
        line
        for name, path in sorted(modules.items())
        for line in private_imports(name, path.read_text(), set(modules))
    ]
    assert not found, "private names imported from another module (make them public): " + "; ".join(found)


def test_the_private_import_check_flags_a_private_import():
    modules = {
        "roboview.eval.statistics.metrics",
        "roboview.eval.statistics.context",
        "roboview.pipelines",
        "roboview.pipelines._cli",
        "roboview.pipelines.evaluate",
    }
    old = "from roboview.eval.statistics.metrics import _interval, _lrt_fields, compute_metrics, __doc__\n"
    assert private_imports("roboview.eval.statistics.context", old, modules) == [
        "roboview.eval.statistics.context:1: from roboview.eval.statistics.metrics import _interval",
        "roboview.eval.statistics.context:1: from roboview.eval.statistics.metrics import _lrt_fields",
    ]
    lazy = "def f():\n    from .metrics import _Table\n"  # relative and inside a function
    assert private_imports("roboview.eval.statistics.context", lazy, modules) == [
        "roboview.eval.statistics.context:2: from roboview.eval.statistics.metrics import _Table"
    ]
    # A package's own private module, and third-party private names, are not the project's modules' privates.
    fine = "from roboview.pipelines import _cli\nfrom roboview.pipelines._cli import main\nfrom lerobot.envs.utils import _Lazy\n"
    assert private_imports("roboview.pipelines.evaluate", fine, modules) == []
    assert private_imports(
        "roboview.eval.statistics.context", "from roboview.pipelines import _cli\n", modules
    ) == ["roboview.eval.statistics.context:1: from roboview.pipelines import _cli"]


def test_the_project_has_no_import_cycle():
    found = cycles(import_graph())
    assert not found, "import cycles: " + "; ".join(" ↔ ".join(c) for c in found)


def test_imports_by_name_are_edges():
    code = '''"""Docstring naming roboview.sim.env is no import."""
import importlib
MODULES = ("roboview.policies.vision", "not.a.module")
TASK = dict(env="roboview.tasks.push:PushEnv")
importlib.import_module("eval")
cmd = ["python", "-m", "roboview.pipelines.evaluate"]
label = "a plain string, not.a.name:either"
ENTRY_POINT_GROUP = "roboview.tasks"
eps = entry_points(group="roboview.factors")
'''
    found = named_modules(ast.parse(code))
    assert found == {"roboview.policies.vision", "not.a.module", "roboview.tasks.push", "eval"}
    # In the project: a registry's module list, "module:Class" targets, the console scripts' modules.
    graph = import_graph()
    assert (
        "roboview.policies.vision" in graph["roboview.policies.types"]
        and "roboview.policies.vision" not in graph["roboview.policies.base"]
    )
    # The registries name no task module and no wing: those are `roboview.tasks` entry points (pyproject.toml).
    assert not {m for m in graph["roboview.tasks"] if m.startswith(("roboview.libero", "roboview.metaworld"))}
    assert "roboview.tasks.pick_place" not in graph["roboview.tasks"] | graph["roboview.core.registry"]
    # A wing's module imports the contract's package, which its imports run first (its own package is running).
    assert "roboview.tasks" in graph["roboview.libero.plus_task"]
    assert "roboview.libero" not in graph["roboview.libero.plus_task"]
    # the default expert, "module:Class"
    assert "roboview.tasks.env" in graph["roboview.tasks.base"]
    assert "roboview.variation.factors.color" in graph["roboview.variation.factors"]
    assert "roboview.pipelines.collect" in graph["roboview.pipelines._console"]
    assert "roboview.integrations.lerobot.env" in graph["roboview.integrations.lerobot"]


def test_a_circle_through_a_package_run_first_is_a_cycle():
    """The task registry once imported each wing's task module by name (a tuple of module strings), and each wing's
    `__init__` imported the registry back: the circle ran through the wing's package, which importing its task
    module runs first, and held only through import order."""
    sources = {
        "roboview.tasks": (True, 'import importlib\nWINGS = ("roboview.libero.task",)\n'),
        "roboview.tasks.base": (False, "TASKS = {}\n"),
        "roboview.libero": (True, "import roboview.tasks\n"),
        "roboview.libero.task": (False, "from roboview.tasks.base import TASKS\n"),
    }
    graph = graph_of(sources)
    assert graph["roboview.tasks"] == {"roboview.libero.task", "roboview.libero"}
    assert graph["roboview.libero.task"] == {"roboview.tasks.base", "roboview.tasks"}
    assert cycles(graph) == [["roboview.libero", "roboview.libero.task", "roboview.tasks"]]
    # Named through `importlib.import_module` the same.
    sources["roboview.tasks"] = (True, 'import importlib\nimportlib.import_module("roboview.libero.task")\n')
    assert cycles(graph_of(sources)) == [["roboview.libero", "roboview.libero.task", "roboview.tasks"]]
    # The wing importing the contract module alone: its package imports no wing, so no circle.
    sources["roboview.libero"] = (True, "")
    sources["roboview.tasks"] = (True, "from roboview.tasks.base import TASKS\n")
    assert cycles(graph_of(sources)) == []
    # A package importing its own modules (the factor registry its factors) is no circle: they run inside it.
    own = {
        "pkg": (True, 'MODULES = ("pkg.a",)\n'),
        "pkg.a": (False, "from pkg.base import X\n"),
        "pkg.base": (False, ""),
    }
    assert graph_of(own)["pkg.a"] == {"pkg.base"} and cycles(graph_of(own)) == []


def test_the_cycle_finder_finds_a_cycle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert cycles(graph) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []
    # The real graph holds the edges the modules declare, lazy ones included.
    graph = import_graph()
    assert (
        "roboview.eval.statistics.tables" in graph["roboview.eval.statistics.compare"]
        and "roboview.policies.base" in graph["roboview.policies.vlm.sgl"]
    )
    assert (
        "roboview.eval.statistics.metrics" not in graph["roboview.eval.statistics.compare"]
        and "roboview.policies.vlm.sgl" not in graph["roboview.policies.base"]
    )
    assert (
        "roboview.eval.statistics.adaptive" in graph["roboview.eval.campaign.config"]
    )  # imported inside a method


def test_reading_the_task_registry_registers_the_gym_ids():
    import subprocess
    import sys

    code = (
        "import gymnasium, roboview.tasks; from roboview.tasks import TASKS; "
        "assert not [i for i in gymnasium.registry if i.startswith('RoboView/')], 'registered by an import'; "
        "print(sorted(t.gym_id for t in TASKS.values() if t.gym_id in gymnasium.registry))"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-800:]
    assert proc.stdout.strip() == (
        "['RoboView/Libero-v0', 'RoboView/LiberoPlus-v0', 'RoboView/MetaWorld-v0', 'RoboView/PickPlace-v0', "
        "'RoboView/Push-v0']"
    )


# The floors, lowest first: a module imports only from its own floor or those below it.
FLOORS = (
    (
        "roboview.core.errors",
        "roboview.core.files",
        "roboview.core.folders",
        "roboview.core.cli",
        "roboview.core.cli_errors",
        "roboview.core.cli_fields",
        "roboview.core.cli_flags",
        "roboview.core.cli_help",
        "roboview.core.workers",
        "roboview.core.ray_cluster",
        "roboview.core.registry",
        "roboview.core.external_assets",
    ),
    ("roboview.sim",),
    ("roboview.variation",),
    ("roboview.tasks", "roboview.libero", "roboview.metaworld"),
    ("roboview.benchmark", "roboview.demos"),
    ("roboview.policies",),
    ("roboview.eval.running",),
    ("roboview.eval.statistics",),
    ("roboview.eval.reporting",),
    ("roboview.eval.verification",),
    ("roboview.eval.campaign", "roboview.eval"),
    ("roboview.integrations",),
    ("roboview.pipelines", "benchmarks"),
)


def wing_imports(graph: dict[str, set[str]], wings: list[str]) -> list[str]:
    """Edges into a world's wing from outside it: only the wing's own throughput studies (`benchmarks.<world>_*`) may
    cross (the registries import the wings through their `roboview.tasks` entry points, pyproject.toml)."""

    def inside(module: str, wing: str) -> bool:
        return module == wing or module.startswith(wing + ".")

    return sorted(
        f"{module} → {target}"
        for module, targets in graph.items()
        for target in targets
        for wing in wings
        if inside(target, wing)
        and not inside(module, wing)
        and not module.startswith(f"benchmarks.{wing.rpartition('.')[2]}_")
    )


def test_nothing_outside_a_world_imports_its_wing():
    from roboview.tasks.world import WORLDS

    wings = [w.wing for w in WORLDS.values() if w.wing]
    assert "roboview.libero" in wings
    found = wing_imports(import_graph(), wings)
    assert not found, (
        "imports into a world's wing from outside it (read the World's facts instead): " + "; ".join(found)
    )
    # The policy clients once imported LIBERO's task module for its render size and camera names.
    assert wing_imports({"roboview.policies.openpi": {"roboview.libero.task"}}, wings) == [
        "roboview.policies.openpi → roboview.libero.task"
    ]
    assert wing_imports({"benchmarks.libero_throughput": {"roboview.libero.task"}}, wings) == []


def floor_of(module: str) -> int:
    """The floor of the longest prefix that names `module` or a package above it (`roboview` itself, which
    imports nothing, is on the lowest)."""
    if module == "roboview":
        return 0
    best, floor = -1, None
    for level, prefixes in enumerate(FLOORS):
        for prefix in prefixes:
            if (module == prefix or module.startswith(prefix + ".")) and len(prefix) > best:
                best, floor = len(prefix), level
    assert floor is not None, f"{module} is on no floor: add it to FLOORS"
    return floor


def upward_imports(graph: dict[str, set[str]]) -> list[str]:
    return sorted(
        f"{module} → {target}"
        for module, targets in graph.items()
        for target in targets
        if floor_of(target) > floor_of(module)
    )


def test_no_module_imports_from_a_higher_floor():
    found = upward_imports(import_graph())
    assert not found, "imports from a higher floor: " + "; ".join(found)
    assert upward_imports({"roboview.integrations.lerobot.convert": {"roboview.pipelines._cli"}}) == [
        "roboview.integrations.lerobot.convert → roboview.pipelines._cli"
    ]
    # The world importing the factor registry is an arrow back up; a factor importing the world is not.
    assert upward_imports({"roboview.sim.scene": {"roboview.variation.factors"}}) == [
        "roboview.sim.scene → roboview.variation.factors"
    ]
    assert upward_imports({"roboview.variation.factors.object_size": {"roboview.sim.scene"}}) == []


def test_eval_has_named_rooms_only():
    """eval/ holds rooms only, each on a floor of its own: no module sits loose beside them."""
    eval_dir = ROOT / "roboview" / "eval"
    loose = sorted(p.name for p in eval_dir.glob("*.py") if p.name != "__init__.py")
    assert not loose, f"modules loose in roboview/eval/ (give them a room): {loose}"
    rooms = sorted(p.name for p in eval_dir.iterdir() if p.is_dir() and any(p.glob("*.py")))
    assert rooms == ["campaign", "reporting", "running", "statistics", "verification"]
    floors = [level for level in FLOORS for prefix in level if prefix.startswith("roboview.eval.")]
    assert [f"roboview.eval.{r}" in {p for level in floors for p in level} for r in rooms] == [True] * 5
    assert floor_of("roboview.eval.campaign.runner") > floor_of("roboview.eval.verification.replay")
