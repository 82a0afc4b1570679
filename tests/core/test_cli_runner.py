"""The tests' command-line runner (tests/helpers/cli.py) answers as a fresh interpreter does: the same exit status,
output, error message, traceback, Ctrl-C status and environment for each case below, run both ways."""

from __future__ import annotations

import atexit
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.helpers import cli

pytestmark = pytest.mark.slow

# A module written for these checks: `python -m fidelity_target CASE` does what CASE names.
TARGET = """
import atexit
import multiprocessing
import os
import sys
import time
from pathlib import Path


def fail(what):
    raise ValueError(f"boom: {what}")


def main(case):
    atexit.register(print, "exit handler ran", file=sys.stderr)
    if case == "ok":
        print("out line", __name__, sys.argv[1:])
        print("err line", file=sys.stderr)
    elif case == "exit_message":
        sys.exit("a message for the user")
    elif case == "exit_status":
        sys.exit(3)
    elif case == "raise":
        fail("raised")
    elif case == "interrupt":
        raise KeyboardInterrupt
    elif case == "wait":
        Path("ready").write_text("ready")
        time.sleep(60)
    elif case == "env":
        print(os.environ.get("ROBOVIEW_FIDELITY_CHECK"), os.getcwd())
    elif case == "pool":  # worker processes from a fork server (the run's own, in a forked run)
        with multiprocessing.get_context("forkserver").Pool(2) as pool:
            print(pool.map(abs, [-1, -2, 3]), multiprocessing.current_process().name)


if __name__ == "__main__":  # (a pool's workers import the module again)
    main(sys.argv[1])
"""
MODULE = "fidelity_target"


@pytest.fixture()
def folder(tmp_path: Path) -> Path:
    (tmp_path / f"{MODULE}.py").write_text(TARGET)
    return tmp_path


def forked(folder: Path, *args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    proc = cli.start(MODULE, *args, env=env, cwd=folder)
    assert isinstance(proc, cli.Run), "the runner started a fresh interpreter: nothing forked to compare"
    out, err = proc.communicate(timeout=60)
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


def fresh(folder: Path, *args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    command = [sys.executable, "-m", MODULE, *args]
    return subprocess.run(command, cwd=folder, env=env, capture_output=True, text=True, timeout=60)


def own_frames(stderr: str, folder: Path) -> str:
    """A traceback less the frames of the code that ran the module (runpy's, the runner's): only its own."""
    kept, skipping = [], False
    for line in stderr.splitlines():
        if line.startswith('  File "'):
            skipping = str(folder) not in line
        elif not line.startswith("    "):
            skipping = False
        if not skipping:
            kept.append(line)
    return "\n".join(kept)


@pytest.mark.parametrize("case", ["ok", "exit_message", "exit_status", "pool"])
def test_status_and_output_are_a_fresh_interpreters(folder, case):
    a, b = forked(folder, case), fresh(folder, case)
    assert (a.returncode, a.stdout, a.stderr) == (b.returncode, b.stdout, b.stderr)
    expected = {"ok": 0, "exit_message": 1, "exit_status": 3, "pool": 0}[case]
    assert a.returncode == expected and a.stderr.endswith("exit handler ran\n"), a.stderr
    if case == "ok":
        assert a.stdout == "out line __main__ ['ok']\n" and a.stderr == "err line\nexit handler ran\n"
    if case == "exit_message":
        assert a.stderr == "a message for the user\nexit handler ran\n"
    if case == "pool":
        assert a.stdout == "[1, 2, 3] MainProcess\n"


@pytest.mark.parametrize("case", ["raise", "interrupt"])
def test_an_uncaught_exception_is_a_fresh_interpreters(folder, case):
    a, b = forked(folder, case), fresh(folder, case)
    assert a.returncode == b.returncode == {"raise": 1, "interrupt": -signal.SIGINT}[case]
    assert own_frames(a.stderr, folder) == own_frames(b.stderr, folder), (a.stderr, b.stderr)
    last = {"raise": "ValueError: boom: raised", "interrupt": "KeyboardInterrupt"}[case]
    assert a.stderr.startswith("Traceback (most recent call last):\n")
    assert a.stderr.splitlines()[-2:] == [last, "exit handler ran"], a.stderr


def interrupted(proc, folder: Path) -> tuple[int, str]:
    deadline = time.time() + 60
    while not (folder / "ready").exists() and time.time() < deadline:
        time.sleep(0.02)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    (folder / "ready").unlink()
    return proc.returncode, err


def default_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_ctrl_c_ends_a_run_as_it_ends_a_fresh_interpreter(folder):
    run = cli.start(MODULE, "wait", cwd=folder)
    assert isinstance(run, cli.Run)
    a = interrupted(run, folder)
    # As a terminal starts it: Ctrl-C's default action (a test run started in the background, as `cmd &` in a script
    # is, inherits SIGINT ignored, and an interpreter that starts with SIGINT ignored never raises KeyboardInterrupt).
    popen = subprocess.Popen(
        [sys.executable, "-m", MODULE, "wait"],
        cwd=folder,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=default_sigint,
    )
    b = interrupted(popen, folder)
    assert a[0] == b[0] == -signal.SIGINT
    assert own_frames(a[1], folder) == own_frames(b[1], folder), (a[1], b[1])


def test_the_calls_environment_and_folder_reach_the_module(folder):
    env = os.environ | {"ROBOVIEW_FIDELITY_CHECK": "seen"}
    a, b = forked(folder, "env", env=env), fresh(folder, "env", env=env)
    assert a.stdout == b.stdout == f"seen {folder}\n"
    assert "ROBOVIEW_FIDELITY_CHECK" not in os.environ  # set for the call only


def test_without_the_internals_a_fork_needs_a_run_is_a_fresh_interpreter(folder, monkeypatch):
    """A Python whose atexit lacks `_run_exitfuncs` (one of the private names the fork rests on) gets fresh
    interpreters, whose answers are the fresh interpreter's."""
    assert cli.cpython_internals() is not None  # this Python: forked
    with monkeypatch.context() as patch:
        patch.delattr(atexit, "_run_exitfuncs")
        cli.cpython_internals.cache_clear()
        try:
            assert cli.cpython_internals() is None
            proc = cli.start(MODULE, "exit_message", cwd=folder)
        finally:
            cli.cpython_internals.cache_clear()
    assert isinstance(proc, subprocess.Popen)
    _, err = proc.communicate(timeout=60)
    assert (proc.returncode, err) == (1, "a message for the user\nexit handler ran\n")
    assert cli.cpython_internals() is not None
