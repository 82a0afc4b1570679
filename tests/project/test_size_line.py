"""The size line the package keeps: no function over 60 lines and no module over 500 (tests and the throughput
studies aside), unless its docstring says why (a sentence starting "Long because"). The functions and modules
over the line today are listed below with their size: the list may only shrink, and a listed one may not grow —
split it where that makes it clearer, then delete its line here."""

import ast
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

PACKAGE = Path(__file__).resolve().parents[2] / "roboview"
MAX_FUNCTION_LINES = 60
MAX_MODULE_LINES = 500
EXCUSE = "Long because"

# Over the line today, with their current size (a ceiling).
OVERSIZE_FUNCTIONS = {}
OVERSIZE_MODULES = {}


def sizes() -> tuple[dict[str, int], dict[str, int]]:
    """(module → lines, "module:function" → lines) for everything over the line without an excuse."""
    modules, functions = {}, {}
    for path in sorted(PACKAGE.rglob("*.py")):
        text = path.read_text()
        tree = ast.parse(text)
        name = ".".join(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        lines = len(text.splitlines())
        if lines > MAX_MODULE_LINES and EXCUSE not in (ast.get_docstring(tree) or ""):
            modules[name] = lines
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                length = node.end_lineno - node.lineno + 1
                if length > MAX_FUNCTION_LINES and EXCUSE not in (ast.get_docstring(node) or ""):
                    functions[f"{name}:{node.name}"] = length
    return modules, functions


def test_nothing_new_crosses_the_size_line_and_nothing_listed_grows():
    modules, functions = sizes()
    new = sorted(set(functions) - set(OVERSIZE_FUNCTIONS)) + sorted(set(modules) - set(OVERSIZE_MODULES))
    assert not new, f"over {MAX_FUNCTION_LINES} lines (function) or {MAX_MODULE_LINES} (module): {new}"
    grown = [f"{k}: {v} > {OVERSIZE_FUNCTIONS[k]}" for k, v in functions.items() if v > OVERSIZE_FUNCTIONS[k]]
    grown += [f"{k}: {v} > {OVERSIZE_MODULES[k]}" for k, v in modules.items() if v > OVERSIZE_MODULES[k]]
    assert not grown, f"listed over the line and grown: {grown}"
    fixed = sorted(set(OVERSIZE_FUNCTIONS) - set(functions)) + sorted(set(OVERSIZE_MODULES) - set(modules))
    assert not fixed, f"back under the line: delete from the lists in this file: {fixed}"
