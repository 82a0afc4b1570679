"""Every verb's --help names every value an option accepts when those values are a closed set: a Literal or enum
field, a registry's `--X.type`, or a string (or list of strings) its config checks against a fixed collection, found
by reading each config's `__post_init__` and by handing each string field a value no set holds and reading the
"allowed: …" its error lists. --help's text comes from `roboview.core.cli_help.help_sections`, what `format_help`
prints, in this process."""

from __future__ import annotations

import ast
import dataclasses
import enum
import functools
import importlib
import inspect
import re
import sys
import textwrap
import types
import typing

import pytest

from roboview.core.cli_fields import dataclass_of, is_choice
from roboview.core.cli_help import help_sections
from roboview.pipelines._console import MODULES
from tests.helpers import ROOT

pytestmark = pytest.mark.fast

BOGUS = "zz-no-such-value"


@dataclasses.dataclass(frozen=True)
class Option:
    """A config field as a flag: where --help lists it (`section`: the registry type's heading, or None)."""

    flag: str
    owner: type
    field: str
    kind: object
    section: str | None


def config_class(module: str) -> type:
    """The config dataclass a verb hands to cli_main."""
    source = (ROOT / (module.replace(".", "/") + ".py")).read_text()
    return getattr(importlib.import_module(module), re.search(r"cli_main\(\s*(\w+)", source).group(1))


def options(cls: type, prefix: str = "--", section: str | None = None) -> list[Option]:
    """Every flag of a config, nested configs' and every registered type's included (as --help walks them)."""
    found = []
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        kind = hints.get(f.name, f.type)
        if is_choice(kind):
            found.append(Option(f"{prefix}{f.name}.type", cls, f.name, kind, section))
            if dataclasses.is_dataclass(kind):
                found += options(kind, f"{prefix}{f.name}.", section)
            for name, choice in kind.get_known_choices().items():
                found += options(choice, f"{prefix}{f.name}.", f"{prefix}{f.name}.type={name}")
        elif (nested := dataclass_of(kind)) is not None:
            found += options(nested, f"{prefix}{f.name}.", section)
        elif f.init:
            found.append(Option(f"{prefix}{f.name}", cls, f.name, kind, section))
    return found


def typed_values(kind: object) -> tuple[str, ...]:
    """The values a Literal, an enum or a registry type admits (also inside `X | None` and `list[X]`)."""
    if is_choice(kind):
        return tuple(kind.get_known_choices())
    if isinstance(kind, type) and issubclass(kind, enum.Enum):
        return tuple(str(m.value) for m in kind)
    if typing.get_origin(kind) is typing.Literal:
        return tuple(map(str, typing.get_args(kind)))
    if typing.get_origin(kind) in (typing.Union, types.UnionType, list, tuple, set, frozenset):
        return tuple(v for arg in typing.get_args(kind) for v in typed_values(arg))
    return ()


def constant_strings(node: ast.expr, names: dict) -> tuple[str, ...]:
    """The strings a fixed collection holds: a name, attribute or argument-free call of the module, or a literal."""
    simple = isinstance(node, (ast.Name, ast.Attribute, ast.Tuple, ast.List, ast.Set)) or (
        isinstance(node, ast.Call) and not node.args and not node.keywords
    )
    try:
        value = eval(compile(ast.Expression(node), "<check>", "eval"), dict(names)) if simple else None
    except Exception:  # noqa: BLE001  (a local name, a call that needs the config: not a fixed collection)
        return ()
    if (
        isinstance(value, (tuple, list, set, frozenset, dict))
        and value
        and all(isinstance(v, str) for v in value)
    ):
        return tuple(value)
    return ()


def checking_functions(cls: type) -> list:
    """The `__post_init__`s of a config and its project bases, and the methods they call on `self`."""
    found: list = []
    for klass in cls.__mro__:
        post = vars(klass).get("__post_init__")
        if post is None or not klass.__module__.startswith("roboview"):
            continue
        found.append(post)
        tree = ast.parse(textwrap.dedent(inspect.getsource(post)))
        for call in ast.walk(tree):
            target = getattr(call, "func", None)
            if isinstance(target, ast.Attribute) and getattr(target.value, "id", "") == "self":
                method = getattr(cls, target.attr, None)
                if inspect.isfunction(method) and method not in found:
                    found.append(method)
    return found


def bindings(tree: ast.AST) -> list[dict[str, ast.expr]]:
    """The local names a check may test: `x = self.f` aliases, and each row of a loop over a literal table
    (`for name, value, allowed in (("a", self.a, A), …)`)."""
    aliases = {
        node.targets[0].id: node.value
        for node in ast.walk(tree)
        if isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Name)
    }
    found = [aliases]
    for loop in (n for n in ast.walk(tree) if isinstance(n, ast.For) and isinstance(n.target, ast.Tuple)):
        rows = loop.iter.elts if isinstance(loop.iter, (ast.Tuple, ast.List)) else []
        names = [getattr(t, "id", None) for t in loop.target.elts]
        found += [aliases | dict(zip(names, row.elts)) for row in rows if isinstance(row, ast.Tuple)]
    return found


def self_field(node: ast.expr, env: dict[str, ast.expr]) -> str | None:
    for _ in range(3):  # through aliases
        node = env.get(node.id, node) if isinstance(node, ast.Name) else node
    if isinstance(node, ast.Attribute) and getattr(node.value, "id", "") == "self":
        return node.attr
    return None


def validated(cls: type) -> dict[str, tuple[str, ...]]:
    """field → the fixed strings a check of the config raises unless the field's value is among (`if X not in S:
    raise`, also `if X and X not in S: raise`)."""
    names = vars(sys.modules[cls.__module__])
    found: dict[str, tuple[str, ...]] = {}
    for function in checking_functions(cls):
        tree = ast.parse(textwrap.dedent(inspect.getsource(function)))
        envs = bindings(tree)
        for node in ast.walk(tree):
            if not (isinstance(node, ast.If) and any(isinstance(s, ast.Raise) for s in node.body)):
                continue
            test = node.test.values[-1] if isinstance(node.test, ast.BoolOp) else node.test
            if not (isinstance(test, ast.Compare) and [type(op) for op in test.ops] == [ast.NotIn]):
                continue
            for env in envs:
                field, collection = self_field(test.left, env), test.comparators[0]
                for _ in range(3):
                    collection = (
                        env.get(collection.id, collection) if isinstance(collection, ast.Name) else collection
                    )
                if field and (values := constant_strings(collection, names)):
                    found[field] = values
    return found


def probed(option: Option) -> tuple[str, ...]:
    """The values the error lists when the config is made with this field set to a value no set holds ("unknown
    --x='…'; allowed: a, b"); () where it takes the value, or fails for another reason first."""
    listing = typing.get_origin(option.kind) is list
    if not (option.kind in (str, str | None) or option.kind == list[str]):
        return ()
    try:
        option.owner(**{option.field: [BOGUS] if listing else BOGUS})
    except Exception as exc:  # noqa: BLE001  (whatever the check raises: its message is what is read)
        message = str(exc)
        listed = re.search(r"(?:allowed|known): ([\w.:-]+(?:, [\w.:-]+)+)\.?$", message)
        if BOGUS in message and listed:
            return tuple(listed.group(1).split(", "))
    return ()


@functools.cache
def closed_options(config: type) -> list[tuple[Option, tuple[str, ...]]]:
    """Every option of a verb whose accepted values are a closed set, with those values."""
    found = []
    checked = {}
    for option in options(config):
        if option.owner not in checked:
            checked[option.owner] = validated(option.owner)
        values = typed_values(option.kind) or checked[option.owner].get(option.field) or probed(option)
        if values:
            found.append((option, values))
    return found


@functools.cache
def shown_sections(config: type) -> list:
    return help_sections(config)


def described(config: type, option: Option) -> str:
    """What --help shows of an option: its metavar, description and default (in its registry type's section, or
    the section of the type listed before it that shares the field)."""
    sections = shown_sections(config)
    entries = [(s.title, f) for s in sections for f in s.flags if f.name == option.flag]
    kinds = {o.section: o.owner for o in options(config) if o.section}
    shown = [f for title, f in entries if title == option.section or option.section is None]
    if not shown:
        declared = next(k for k in option.owner.__mro__ if option.field in vars(k).get("__annotations__", {}))
        shown = [f for title, f in entries if title in kinds and issubclass(kinds[title], declared)]
    return " ".join(f"{f.metavar} {f.help} {f.default or ''}" for f in shown)


@pytest.fixture(scope="module", autouse=True)
def policy_types():
    from roboview.policies.types import load_policy_types

    load_policy_types()  # as a command does before it parses: every --policy.type


@pytest.mark.parametrize("module", MODULES)
def test_help_names_every_value_an_option_accepts(module):
    config = config_class(module)
    missing = {}
    for option, values in closed_options(config):
        text = described(config, option)
        absent = [v for v in values if v and not re.search(rf"(?<![\w-]){re.escape(v)}(?![\w-])", text)]
        if absent:
            missing[f"{option.flag}{f' under {option.section}' if option.section else ''}"] = absent
    assert not missing, f"{module} --help does not name: {missing}"


def test_the_closed_sets_are_found():
    """Each way a closed set is declared is read: a registry type, a check against a constant, a loop over a table
    of checks, a check through a local alias, a registry that lists its names in its error."""
    found = {
        (module.rpartition(".")[2], option.flag, option.section): set(values)
        for module in MODULES
        for option, values in closed_options(config_class(module))
    }
    assert found[("evaluate", "--policy.type", None)] >= {"expert", "vision", "lerobot", "openpi"}
    assert found[("train", "--device", None)] == {"auto", "cpu", "cuda"}
    assert found[("evaluate", "--policy.gripper", "--policy.type=openpi")] == {"continuous", "binary"}
    assert found[("evaluate", "--policy.control", "--policy.type=lerobot")] == {"joint", "ee_delta", "ee_abs"}
    assert found[("audit", "--format", None)] == {"vla_eval", "inspect_robots", "gauntlet", "xevals"}
    assert len(found) >= 30
