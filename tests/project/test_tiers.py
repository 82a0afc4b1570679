"""The two test tiers (tests/conftest.py): every test module declares exactly one, fast or slow, so no test is in
neither or both; a run refuses a test outside them, and a fast test that takes a slow fixture."""

from __future__ import annotations

import ast
from dataclasses import dataclass, field

import pytest

from tests.conftest import SLOW_FIXTURES, TIERS, schedule, tier_of, tier_problems
from tests.helpers import ROOT

pytestmark = pytest.mark.fast


def declared_tiers(source: str) -> list[str]:
    """The tiers a module's top-level `pytestmark` names (`pytest.mark.fast`, alone or in a list)."""
    for node in ast.parse(source).body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "pytestmark" for t in node.targets):
            return [
                n.attr
                for n in ast.walk(node.value)
                if isinstance(n, ast.Attribute)
                and n.attr in TIERS
                and getattr(n.value, "attr", None) == "mark"
            ]
    return []


def test_every_test_module_declares_exactly_one_tier():
    modules = sorted((ROOT / "tests").rglob("test_*.py"))
    assert len(modules) > 60
    wrong = {
        str(p.relative_to(ROOT)): tiers for p in modules if len(tiers := declared_tiers(p.read_text())) != 1
    }
    assert not wrong, (
        f"test modules without exactly one tier (pytestmark = pytest.mark.fast or slow): {wrong}"
    )
    tiers = [declared_tiers(p.read_text())[0] for p in modules]
    assert tiers.count("fast") >= 15 and tiers.count("slow") >= 40


def test_declared_tiers_reads_a_module_as_the_check_does():
    assert declared_tiers("import pytest\npytestmark = pytest.mark.slow\n") == ["slow"]
    assert declared_tiers("pytestmark = [pytest.mark.fast, pytest.mark.skipif(True, reason='x')]\n") == [
        "fast"
    ]
    assert declared_tiers("pytestmark = [pytest.mark.fast, pytest.mark.slow]\n") == ["fast", "slow"]
    assert declared_tiers("import pytest\n") == []


@dataclass
class Mark:
    name: str


@dataclass
class Item:
    """What the tier check reads of a collected test: its node id, its markers closest first, its fixtures."""

    nodeid: str
    marks: list[str]
    fixturenames: list[str] = field(default_factory=list)

    def iter_markers(self):
        return (Mark(m) for m in self.marks)


def test_the_closest_marker_decides_and_tests_outside_the_tiers_are_named():
    fast = Item("t.py::a", ["fast"])
    moved = Item(
        "t.py::b", ["slow", "parametrize", "fast"], ["tiny_benchmark"]
    )  # its own mark, then its module's
    none = Item("t.py::c", ["parametrize"])
    slow_fixture = Item("t.py::d", ["fast"], ["tmp_path", "env"])
    assert [tier_of(i) for i in (fast, moved, none, slow_fixture)] == ["fast", "slow", None, "fast"]
    assert tier_problems([fast, moved]) == []
    assert tier_problems([none, slow_fixture]) == [
        "t.py::c: no tier; declare `pytestmark = pytest.mark.fast` (or slow) in its module",
        "t.py::d: marked fast but takes env; mark it `@pytest.mark.slow`",
    ]
    assert {"env", "tiny_benchmark", "tiny_checkpoint"} <= SLOW_FIXTURES


def test_files_are_handed_out_by_their_count_of_tests_with_schedule_first_files_before():
    items = [
        Item("a.py::x", ["fast"]),
        Item("b.py::x", ["slow"]),
        Item("b.py::y", ["slow"]),
        Item("sweeps.py::x", ["slow", "schedule_first"]),
        Item("sweeps.py::y", ["slow", "schedule_first"]),
        Item("ray.py::x", ["slow", "schedule_first"]),
        Item("c.py::x", ["fast"]),
        Item("c.py::y", ["fast"]),
        Item("c.py::z", ["fast"]),
        Item("d.py::x", ["fast"]),
    ]
    order = [i.nodeid for i in schedule(items)]
    # The schedule_first files first, fewest tests first (ray 1, sweeps 2); then by count (c 3, b 2); a and d tie at
    # 1 and keep their collected order; a file stays whole.
    assert order == [
        "ray.py::x",
        "sweeps.py::x",
        "sweeps.py::y",
        "c.py::x",
        "c.py::y",
        "c.py::z",
        "b.py::x",
        "b.py::y",
        "a.py::x",
        "d.py::x",
    ]
    assert schedule(list(reversed(items)))[0].nodeid == "ray.py::x"
