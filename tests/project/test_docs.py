"""The README and docs/ are true to the code: every bash command's flags exist, every link resolves, and the
pages speak of the product only."""

from __future__ import annotations

import re

import pytest

from roboview.pipelines._console import VERBS
from tests.helpers import ROOT
from tests.helpers.docs import PAGES, bash_blocks, bash_commands

pytestmark = pytest.mark.slow


def test_bash_blocks_hold_no_placeholders():
    bad = [
        f"{page.relative_to(ROOT)}:{line}: {command[:100]}"
        for page in PAGES
        for line, command in bash_commands(page)
        if re.search(r"(\.\.\.|…|\s\[--|=\[|<[A-Z_]+>|=[A-Z](\s|,|/|$))", command)
    ]
    assert not bad, "placeholders in bash blocks:\n" + "\n".join(bad)


def test_bash_blocks_are_commands():
    """No block is only comments, and none ends on a comment that stands for commands not written."""
    bad = []
    for page in PAGES:
        for line, lines in bash_blocks(page):
            text = [entry.strip() for entry in lines if entry.strip()]
            if not text or text[-1].startswith("#") or all(entry.startswith("#") for entry in text):
                bad.append(f"{page.relative_to(ROOT)}:{line}")
    assert not bad, "bash blocks without a command after their comments:\n" + "\n".join(bad)


def test_links_resolve():
    broken = []
    for page in PAGES:
        text = page.read_text()
        for target in re.findall(r"\]\(([^)\s]+)\)", text):
            if target.startswith(("http://", "https://", "mailto:", "#")):
                continue
            path = (page.parent / target.split("#")[0]).resolve()
            if not path.exists():
                broken.append(f"{page.relative_to(ROOT)}: {target}")
        broken += [
            f"{page.relative_to(ROOT)}: absolute path {m}"
            for m in re.findall(r"(?<![\w.])/(?:work|tmp)/\S+", text)
        ]
    assert not broken, "\n".join(broken)


# The phrases a product page must not hold, assembled from parts so that this file, which the same rule covers,
# does not hold them either: words about how the project was made, and files outside the repository.
_MADE = (
    "sess" + "ion \\d",
    "this sess" + "ion",
    "sess" + "ions?\\b(?! of)",
    "iss" + "ue \\d+",
    "was l" + "ent",
    "withdr" + "awn",
    "found on the w" + "ay",
    "is g" + "one",
)
HISTORY = re.compile(r"\b(" + "|".join(_MADE) + ")", re.IGNORECASE)
OUTSIDE = ("DESIGN" + ".md", ".." + "/shared")


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_pages_speak_of_the_product(page):
    text = page.read_text()
    assert not [name for name in OUTSIDE if name in text]
    if page.name != "CHANGELOG.md":
        found = sorted({m.group(0) for m in HISTORY.finditer(text)})
        assert not found, f"{page.relative_to(ROOT)} speaks of how it was made: {found}"


def test_readme_is_a_guide():
    lines = (ROOT / "README.md").read_text().splitlines()
    assert len(lines) <= 230
    headings = [line for line in lines if line.startswith("## ")]
    for expected in ("Install", "Quick start", "Evaluate your own policy", "Documentation"):
        assert any(expected in h for h in headings), f"README lacks a '{expected}' section"


# What a page may run: `python -m MODULE` and the console scripts (`roboview-<verb>`, `.venv/bin/roboview-<verb>`).
PYTHON_M = re.compile(r"python[0-9.]*\s+-m\s+([A-Za-z_][\w.]*)(<)?")
CONSOLE = re.compile(r"(?<![\w./-])roboview-[a-z][a-z0-9-]*\b(?![./-])")
RUN_FILE = re.compile(r"(?:^|\s)(?:bash|sh|python[0-9.]*)\s+((?:[\w-]+/)*[\w-]+\.(?:py|sh))\b")
# Names of the form roboview-… on the pages that are not commands: the classic-CV stand-in's model id.
NOT_COMMANDS = {"roboview-classic-cv-standin"}
# The pages whose commands must run: every page but the changelog, which names what was renamed or removed.
RUNNABLE = [page for page in PAGES if page.name != "CHANGELOG.md"]


def unresolved_commands(text: str, where: str) -> list[str]:
    """Every `python -m MODULE` of `text` whose module does not resolve in this interpreter (RoboView's own, the
    studies in benchmarks/, and third-party ones alike), every `roboview-…` name that is no installed console
    script, and every script file run with bash / python that does not exist in the repository."""
    import importlib.metadata
    import importlib.util

    scripts = {e.name for e in importlib.metadata.entry_points(group="console_scripts")}
    bad = []
    for number, line in enumerate(text.splitlines(), 1):
        for match in PYTHON_M.finditer(line):
            module, template = match.group(1), match.group(2)
            if template and module.endswith("."):  # `python -m roboview.pipelines.<verb>`
                continue
            try:
                found = importlib.util.find_spec(module) is not None
            except (ImportError, ValueError):
                found = False
            if not found:
                bad.append(f"{where}:{number}: python -m {module}: no such module")
        for name in CONSOLE.findall(line):
            if name not in scripts and name not in NOT_COMMANDS:
                bad.append(f"{where}:{number}: {name}: no such console script")
        for path in RUN_FILE.findall(line):
            if not (ROOT / path).is_file():
                bad.append(f"{where}:{number}: {path}: no such file")
    return bad


def test_every_documented_command_resolves():
    """Every module, console script and script file the README and docs/ (docs/results included) name exists."""
    bad = [
        line
        for page in RUNNABLE
        for line in unresolved_commands(page.read_text(), str(page.relative_to(ROOT)))
    ]
    assert not bad, "documented commands that do not run:\n" + "\n".join(bad)


def test_the_command_resolver_fails_on_what_does_not_exist():
    # Modules moved under roboview/ once left `python -m pipelines.*` lines behind; a removed verb, a wrong script.
    text = (
        "python -m pipelines.evaluate --benchmark.path=x\n"
        ".venv/bin/python -m roboview.pipelines.evalute\n"
        "roboview-eval --benchmark.path=x && roboview-build --preset=tiny\n"
        "bash benchmarks/no_such_study.sh\n"
        "python -m roboview.pipelines.evaluate; python -m benchmarks.throughput; roboview-verify --results=x\n"
        "`python -m roboview.pipelines.<verb>`; model roboview-classic-cv-standin; outputs/roboview-demo\n"
    )
    assert unresolved_commands(text, "page.md") == [
        "page.md:1: python -m pipelines.evaluate: no such module",
        "page.md:2: python -m roboview.pipelines.evalute: no such module",
        "page.md:3: roboview-eval: no such console script",
        "page.md:3: roboview-build: no such console script",
        "page.md:4: benchmarks/no_such_study.sh: no such file",
    ]


def _listed_in_layout() -> tuple[str, str]:
    import roboview

    return (ROOT / "docs" / "layout.md").read_text(), roboview.__doc__


def test_layout_and_the_package_docstring_list_every_room_verb_and_study():
    layout, docstring = _listed_in_layout()
    rooms = sorted(
        {
            str(p.parent.relative_to(ROOT / "roboview"))
            for p in (ROOT / "roboview").rglob("*.py")
            if "__pycache__" not in p.parts and p.parent != ROOT / "roboview"
        }
    )
    top = sorted({r.split("/")[0] for r in rooms})
    assert {"core", "eval", "libero", "metaworld", "pipelines"} <= set(top)
    missing = [f"{r}/" for r in rooms if f"{r.rpartition('/')[2]}/" not in layout]
    missing += [f"roboview/__init__.py: {r}/" for r in top if f"{r}/" not in docstring]
    eval_rooms = [r.partition("/")[2] for r in rooms if r.startswith("eval/") and r.count("/") == 1]
    missing += [f"roboview/__init__.py: eval/{r}/" for r in eval_rooms if f"{r}/" not in docstring]
    missing += [f"verb {v}" for v in VERBS if not re.search(rf"\b{v}\b", layout)]
    missing += [f"roboview/__init__.py: verb {v}" for v in VERBS if not re.search(rf"\b{v}\b", docstring)]
    studies = [p for p in sorted((ROOT / "benchmarks").iterdir()) if p.suffix in (".py", ".sh")]
    for study in studies:
        if study.name == "__init__.py":
            continue
        if study.name not in layout:
            missing.append(f"benchmarks/{study.name}")
        if (study.stem if study.suffix == ".py" else study.name) not in docstring:
            missing.append(f"roboview/__init__.py: benchmarks/{study.name}")
    assert not missing, "not listed in docs/layout.md or roboview/__init__.py: " + ", ".join(missing)
