"""The README's and docs/' commands read as a user reads them: every ```bash block's commands (continuations
joined, the block's variables expanded), the RoboView module each runs, and `python -m MODULE --help` run once per
module for the flags it documents."""

from __future__ import annotations

import functools
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

from roboview.pipelines._console import VERBS, script_name
from tests.helpers import ROOT


@functools.cache
def help_run(module: str) -> subprocess.CompletedProcess:
    """`python -m module --help`, run once per module and in this process (runpy runs the module as `-m` does, at
    80 columns as in a pipe): its exit code, stdout and stderr."""
    import runpy

    run = lambda: runpy.run_module(module, run_name="__main__", alter_sys=True)  # noqa: E731
    return _help_in_process(module, run, [sys.executable, "-m", module, "--help"])


def script_help_run(script: Path) -> subprocess.CompletedProcess:
    """An installed console script's `--help`: the script's own file run in this process as its interpreter runs
    it (`runpy.run_path` as `__main__`), at 80 columns: its exit code, stdout and stderr."""
    import runpy

    run = lambda: runpy.run_path(str(script), run_name="__main__")  # noqa: E731
    return _help_in_process(str(script), run, [str(script), "--help"])


def _help_in_process(argv0: str, run, args: list[str]) -> subprocess.CompletedProcess:
    import contextlib
    import io
    import traceback
    import warnings

    out, err, code = io.StringIO(), io.StringIO(), 0
    argv, columns = sys.argv, os.environ.get("COLUMNS")
    sys.argv, os.environ["COLUMNS"] = [argv0, "--help"], "80"
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # a module imported before, run again as __main__
            run()
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else int(exc.code is not None)
    except Exception:  # noqa: BLE001  (reported as the process would: a traceback and exit code 1)
        code = 1
        err.write(traceback.format_exc())
    finally:
        sys.argv = argv
        if columns is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = columns
    return subprocess.CompletedProcess(args, code, out.getvalue(), err.getvalue())


PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
# Console scripts and the module each stands for (pyproject.toml [project.scripts], one per verb).
SCRIPTS = {script_name(verb): f"roboview.pipelines.{verb}" for verb in VERBS}


ASSIGNMENT = re.compile(r"^([A-Za-z_]\w*)=(\"[^\"]*\"|'[^']*'|\S*)$")


def _expand(command: str, variables: dict[str, str]) -> str:
    """The command with the block's shell variables ($E, ${E}) replaced by their values."""
    return re.sub(r"\$\{?([A-Za-z_]\w*)\}?", lambda m: variables.get(m.group(1), m.group(0)), command)


def bash_commands(page: Path) -> list[tuple[int, str]]:
    """(line, command) of every command in the page's ```bash blocks, backslash continuations joined and
    variables assigned earlier in the block (E="roboview-evaluate ...") expanded."""
    commands, block, start, pending, variables = [], False, 0, "", {}
    for number, line in enumerate(page.read_text().splitlines(), 1):
        if line.startswith("```"):
            block, variables = line.strip() == "```bash", {}
            continue
        if not block:
            continue
        if not pending:
            start = number
        pending += line.rstrip("\\").rstrip() + " " if line.rstrip().endswith("\\") else line
        if not line.rstrip().endswith("\\"):
            command = " ".join(pending.split())
            assigned = ASSIGNMENT.match(command.strip())
            if assigned:
                variables[assigned.group(1)] = assigned.group(2).strip("\"'")
            elif command.strip() and not command.lstrip().startswith("#"):
                commands.append((start, _expand(command.strip(), variables)))
            pending = ""
    return commands


def bash_blocks(page: Path) -> list[tuple[int, list[str]]]:
    """(line, lines) of every ```bash block of the page."""
    blocks, current, start = [], None, 0
    for number, line in enumerate(page.read_text().splitlines(), 1):
        if line.startswith("```"):
            if current is not None:
                blocks.append((start, current))
                current = None
            elif line.strip() == "```bash":
                current, start = [], number
            continue
        if current is not None:
            current.append(line)
    return blocks


def _module_of(command: str) -> tuple[str, list[str]] | None:
    """The RoboView module a command runs and its arguments; None for other programs."""
    try:
        words = shlex.split(command.split(" # ")[0].split(" &")[0], comments=False)
    except ValueError:
        return None
    for i, word in enumerate(words):
        if word.endswith("python") or word.endswith("python3"):
            if i + 2 < len(words) + 1 and words[i + 1 : i + 2] == ["-m"]:
                return words[i + 2], words[i + 3 :]
        if Path(word).name in SCRIPTS:
            return SCRIPTS[Path(word).name], words[i + 1 :]
    return None


def help_text(module: str) -> str:
    proc = help_run(module)
    assert proc.returncode == 0, f"{module} --help failed: {proc.stderr[-800:]}"
    return proc.stdout


def _all_commands() -> list[tuple[str, int, str, str, list[str]]]:
    found = []
    for page in PAGES:
        for line, command in bash_commands(page):
            parsed = _module_of(command)
            if parsed and parsed[0].startswith(("roboview.", "benchmarks.")):
                found.append((str(page.relative_to(ROOT)), line, command, *parsed))
    return found


def documented_flag_problems() -> list[str]:
    """Every flag a page passes to a RoboView command that the command's --help does not document
    (tests/core/test_cli_help.py asserts there are none, in the process that runs each --help once)."""
    commands = _all_commands()
    assert len(commands) > 30  # the pages document the tools
    wrong = []
    for page, line, _command, module, args in commands:
        for arg in args:
            if arg.startswith("--"):
                flag = arg.split("=", 1)[0]
                if not re.search(rf"(^|\s){re.escape(flag)}(\s|$|,|=)", help_text(module)):
                    wrong.append(f"{page}:{line}: {module} has no {flag}")
    return wrong
