"""tests/helpers/cli.py runs a command as a fresh `python -m` does: the same output, exit status, environment, working
folder, exit handlers and multiprocessing state, though it is a fork of the preloaded fork server."""

import os
import subprocess
import sys

import pytest

from tests.helpers import cli

pytestmark = pytest.mark.slow

PROBE = """import atexit, os, sys, multiprocessing as mp
atexit.register(lambda: print("exit handler ran"))
print(sys.argv[1:], os.getcwd(), os.environ.get("ROBOVIEW_PROBE"), mp.get_start_method(allow_none=True),
      mp.parent_process(), mp.current_process().name, __name__)
print("to stderr", file=sys.stderr)
what = sys.argv[1]
if what == "raise":
    raise ValueError("boom")
if what == "interrupt":
    raise KeyboardInterrupt
if what == "message":
    sys.exit("bad input: say what to do")
sys.exit(int(what))
"""


@pytest.mark.parametrize("what", ["0", "3", "raise", "interrupt", "message"])
def test_a_forked_run_is_what_a_fresh_interpreter_gives(tmp_path, what):
    (tmp_path / "probe_cli.py").write_text(PROBE)
    env = {"ROBOVIEW_PROBE": f"value-{what}"}
    forked = cli.start("probe_cli", what, env=os.environ | env, cwd=tmp_path)
    assert isinstance(forked, cli.Run)  # the fork, not the fallback
    out, err = forked.communicate(timeout=60)
    fresh = subprocess.run(
        [sys.executable, "-m", "probe_cli", what],
        cwd=tmp_path,
        env=os.environ | env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert (forked.returncode, out) == (fresh.returncode, fresh.stdout)
    assert err.splitlines()[0] == "to stderr" and err.splitlines()[-1] == fresh.stderr.splitlines()[-1]
    assert out.endswith("exit handler ran\n") and f"value-{what}" in out and "MainProcess __main__" in out


def test_a_changed_import_time_variable_gets_a_fresh_interpreter(tmp_path):
    (tmp_path / "probe_cli.py").write_text(PROBE)
    proc = cli.start("probe_cli", "0", env=os.environ | {"HF_HUB_OFFLINE": "0"}, cwd=tmp_path)
    assert isinstance(proc, subprocess.Popen)
    out, _ = proc.communicate(timeout=60)
    assert proc.returncode == 0 and "exit handler ran" in out
