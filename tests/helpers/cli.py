"""Command-line runs for the tests, as `python -m MODULE ARGS` runs them, started as forks of a process that has
already imported RoboView and LeRobot.

A fresh interpreter spends seconds importing torch, LeRobot's policies and RoboView before a command does anything
(10 CPU-seconds for `import lerobot.policies` on a 2-core machine). Here each run is a child of the test process's
fork server (`roboview.core.workers`, preloaded by tests/conftest.py): a real process of its own, with its own
argv, environment, working folder, stdout and stderr (files, read back when it ends), exit status and signals, that
runs the module with `runpy` as `__main__` and its exit handlers before it exits. A run's own worker pools get
their fork server the same way: a fork of the run made before the module starts (`_start_fork_server`), not a fresh
interpreter importing the policy's libraries again.

What a fork cannot change is what the preloaded modules read when they were imported. A run whose environment
differs from the test run's in a variable read at import time (`IMPORT_TIME`), or that puts a folder on PYTHONPATH
the fork server does not have, starts a fresh interpreter instead, so it sees exactly what it asked for.
"""

from __future__ import annotations

import atexit
import multiprocessing
import os
import runpy
import signal
import socket
import subprocess
import sys
import tempfile
import traceback
from collections.abc import Mapping
from multiprocessing import process as mp_process
from pathlib import Path

from roboview.core import workers
from tests.helpers import ROOT

# Variables that modules the fork server preloads read when imported (rendering backend, thread pools; and every
# HF_* / HUGGINGFACE_* one: folders, endpoint, offline mode): a run that sets them differently gets a fresh
# interpreter. Mesa's driver choice (GALLIUM_DRIVER, LIBGL_ALWAYS_SOFTWARE) is not among them: Mesa reads it when a
# process makes its first EGL display, which the fork server, importing only, never does.
IMPORT_TIME = (
    "MUJOCO_GL",
    "PYOPENGL_PLATFORM",
    "LP_NUM_THREADS",
    "OMP_NUM_THREADS",
    "MKL_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "TORCH_HOME",
)
_RUN_ENV = dict(os.environ)  # the environment the test run (and so its fork server) started with


def _child(
    module: str, argv: list[str], env: dict[str, str], cwd: str, out: str, err: str, new_session: bool
) -> None:
    """In the forked child: the run's streams, environment, folder and argv, then the module as `__main__`."""
    # A process group of its own (Popen's start_new_session), signalled as a terminal's Ctrl-C is.
    if new_session:
        os.setsid()
    for fd, path in ((1, out), (2, err)):
        handle = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
        os.dup2(handle, fd)
        os.close(handle)
    os.environ.clear()
    os.environ.update(env)
    os.chdir(cwd)
    # `python -m` puts the working folder first on the path, then PYTHONPATH's folders.
    extra = [cwd, *filter(None, env.get("PYTHONPATH", "").split(os.pathsep))]
    sys.path[:0] = [p for p in extra if p not in sys.path]
    # SIGINT raises KeyboardInterrupt and is not blocked, as a shell leaves it, whatever pytest's worker had.
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    signal.signal(signal.SIGCHLD, signal.SIG_DFL)
    # A main process, as in a fresh interpreter: no parent process, and multiprocessing's default start method
    # (fork on Linux; a fork server's child would otherwise default to the fork server, so a library's worker
    # processes, e.g. lerobot-eval's vector envs, would each start from a fresh interpreter).
    multiprocessing.current_process().name = "MainProcess"
    mp_process._parent_process = None
    multiprocessing.set_start_method(None, force=True)
    _start_fork_server()
    sys.argv = [module, *argv]
    # As in a fresh `python -m`, the module itself is not imported yet (its imports are: that is the saving).
    sys.modules.pop(module, None)
    code: object = 0
    try:
        runpy.run_module(module, run_name="__main__", alter_sys=True)
    except SystemExit as exc:
        code = exc.code
    except BaseException:  # as the interpreter does: the traceback on stderr, status 1
        traceback.print_exc()
        code = 1
    try:
        atexit._run_exitfuncs()
    finally:
        if code is not None and not isinstance(code, int):
            print(code, file=sys.stderr)
            code = 1
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code or 0)


# multiprocessing.forkserver.main's parameters, the ones `_start_fork_server` passes (Python 3.12's).
SERVER_MAIN = ("listener_fd", "alive_r", "preload", "main_path", "sys_path")


def _start_fork_server() -> None:
    """The run's own fork server (roboview.core.workers), started now as a fork of this process instead of from a
    fresh interpreter when the run's first pool needs it.

    multiprocessing starts a fork server by running `python -c "from multiprocessing.forkserver import main; ..."`
    with the listening socket and the "alive" pipe's read end, which then imports its preloads: seconds of CPU for
    a policy's libraries, once per command-line run that starts a pool. This process has imported them all already
    and, just forked from the test process's fork server, runs one thread and holds no GL context: a fork of it now
    is that server, its modules already there. Its descriptors are closed but for stdin, stdout, stderr, the socket
    and the pipe (what the fresh interpreter inherits), and it serves the run's pools as multiprocessing's own
    `main` until the last of its clients exits; the run's workers are its children, as they would be."""
    import inspect
    from multiprocessing import connection, forkserver, resource_tracker

    known = list(inspect.signature(forkserver.main).parameters) == [*SERVER_MAIN]
    if not known or not os.path.isdir("/proc/self/fd"):
        return  # another multiprocessing (its server takes more, e.g. an auth key) or no /proc: it starts its own
    server = forkserver._forkserver
    resource_tracker.ensure_running()
    listener = socket.socket(socket.AF_UNIX)
    address = connection.arbitrary_address("AF_UNIX")
    listener.bind(address)
    os.chmod(address, 0o600)
    listener.listen()
    alive_r, alive_w = os.pipe()
    pid = os.fork()
    if pid == 0:
        keep = {0, 1, 2, listener.fileno(), alive_r}
        for fd in map(int, os.listdir("/proc/self/fd")):
            if fd not in keep:
                try:
                    os.close(fd)
                except OSError:  # the descriptor listdir read /proc/self/fd with, already gone
                    pass
        try:
            forkserver.main(listener.fileno(), alive_r, [])
        finally:
            os._exit(0)
    listener.close()
    os.close(alive_r)
    server._forkserver_address, server._forkserver_alive_fd, server._forkserver_pid = address, alive_w, pid


class Run:
    """A started command (subprocess.Popen's interface, the part the tests use): pid, poll, wait, send_signal,
    terminate, kill, communicate and returncode; its stdout and stderr are read when it has ended."""

    def __init__(
        self,
        module: str,
        args: list[str],
        env: dict[str, str],
        cwd: Path,
        merge: bool,
        new_session: bool = False,
    ) -> None:
        self.args = [sys.executable, "-m", module, *args]
        self._dir = tempfile.TemporaryDirectory(prefix="roboview-cli-")
        self._out, self._err = Path(self._dir.name) / "stdout", Path(self._dir.name) / "stderr"
        self._merge = merge
        ctx = workers.start_context(())
        err = self._out if merge else self._err
        self._process = ctx.Process(
            target=_child, args=(module, args, env, str(cwd), str(self._out), str(err), new_session)
        )
        self._process.start()
        self.pid = self._process.pid

    @property
    def returncode(self) -> int | None:
        return self._process.exitcode

    def poll(self) -> int | None:
        return self._process.exitcode

    def wait(self, timeout: float | None = None) -> int:
        self._process.join(timeout)
        if self._process.exitcode is None:
            raise subprocess.TimeoutExpired(self.args, timeout)
        return self._process.exitcode

    def send_signal(self, sig: int) -> None:
        if self._process.exitcode is None:
            os.kill(self.pid, sig)

    def terminate(self) -> None:
        self.send_signal(signal.SIGTERM)

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)

    def output(self) -> tuple[str, str]:
        read = lambda path: path.read_text(errors="replace") if path.exists() else ""  # noqa: E731
        return read(self._out), "" if self._merge else read(self._err)

    def communicate(self, timeout: float | None = None) -> tuple[str, str]:
        self.wait(timeout)
        return self.output()


def import_time_changes(env: Mapping[str, str]) -> dict[str, tuple[str | None, str | None]]:
    """The variables read at import time whose value in `env` is not the test run's: name → (run's, env's)."""
    names = {*IMPORT_TIME, *(n for n in {*env, *_RUN_ENV} if n.startswith(("HF_", "HUGGINGFACE_")))}
    return {
        name: (_RUN_ENV.get(name), env.get(name))
        for name in sorted(names)
        if env.get(name) != _RUN_ENV.get(name)
    }


def restore_import_time(names) -> None:
    """Put this process's variables `names` back to the test run's values."""
    for name in names:
        if _RUN_ENV.get(name) is None:
            os.environ.pop(name, None)
        else:
            os.environ[name] = _RUN_ENV[name]


def _needs_fresh(env: Mapping[str, str]) -> bool:
    if import_time_changes(env):
        return True
    known = {str(ROOT), *sys.path}
    return any(p not in known for p in filter(None, env.get("PYTHONPATH", "").split(os.pathsep)))


def start(
    module: str,
    *args: str,
    env: Mapping[str, str] | None = None,
    cwd: Path = ROOT,
    merge: bool = False,
    new_session: bool = False,
) -> Run | subprocess.Popen:
    """`python -m module args` started in `cwd` with `env` (default: this process's); `merge` sends stderr to
    stdout; `new_session` gives it a session and process group of its own (`os.killpg(run.pid, sig)` then signals
    it and its workers, as a terminal's Ctrl-C or a lost machine does). A fork of the preloaded server, or a fresh
    interpreter where `env` needs one (see the module's doc)."""
    env = dict(os.environ if env is None else env)
    if not _needs_fresh(env):
        return Run(module, list(args), env, Path(cwd), merge, new_session)
    command = [sys.executable, "-m", module, *args]
    err = subprocess.STDOUT if merge else subprocess.PIPE
    return subprocess.Popen(
        command,
        cwd=cwd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=err,
        text=True,
        start_new_session=new_session,
        preexec_fn=terminal_signals if new_session else None,
    )


def terminal_signals() -> None:
    """In a fresh interpreter's child before exec: SIGINT as a shell leaves it (a runner's worker may ignore or
    block it, and exec keeps both)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def run(
    module: str,
    *args: str,
    env: Mapping[str, str] | None = None,
    cwd: Path = ROOT,
    merge: bool = False,
    timeout: float = 600,
) -> subprocess.CompletedProcess:
    """`start(...)` to its end: its exit status, stdout and stderr (subprocess.run's result with
    capture_output=True, text=True; subprocess.TimeoutExpired after killing it past `timeout`)."""
    proc = start(module, *args, env=env, cwd=cwd, merge=merge)
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        raise
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err or "")
