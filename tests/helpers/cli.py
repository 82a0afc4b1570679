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
the fork server does not have, starts a fresh interpreter instead, so it sees exactly what it asked for; so does
every run on a Python without the internals a fork needs (`cpython_internals`). tests/core/test_cli_runner.py runs
the same cases both ways and compares them.
"""

from __future__ import annotations

import functools
import multiprocessing
import os
import runpy
import signal
import socket
import subprocess
import sys
import tempfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass
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


# What the forked runs need of CPython beyond its documented interface, looked up in one place
# (`cpython_internals`). Checked against CPython 3.12.1 and 3.13.0, identical in all of it:
#   atexit._run_exitfuncs                    a process multiprocessing started ends with os._exit, which skips the
#                                            exit handlers: the run calls them, as an interpreter does at its exit
#   multiprocessing.process._parent_process  set to None: the run is a main process, with no parent process
#   multiprocessing.forkserver._forkserver   and its _forkserver_address, _forkserver_alive_fd, _forkserver_pid:
#                                            the run's own fork server, started as a fork (`_start_fork_server`, a
#                                            copy of ForkServer.ensure_running that forks instead of exec'ing a
#                                            fresh interpreter), handed to multiprocessing as if it had started it
#   multiprocessing.forkserver.main          the server's loop, with the parameters SERVER_MAIN
#   multiprocessing.connection.arbitrary_address   the server's socket path, as ensure_running picks it
# Where the first two are missing (another Python), `start` runs every command in a fresh interpreter: slower,
# equally correct. Where only the fork-server part differs (e.g. a `main` that also takes an auth key), runs are
# still forked and their pools start multiprocessing's own fork server, from a fresh interpreter.
SERVER_MAIN = ("listener_fd", "alive_r", "preload", "main_path", "sys_path")
SERVER_STATE = ("_forkserver_address", "_forkserver_alive_fd", "_forkserver_pid")


@dataclass(frozen=True)
class Internals:
    """The CPython internals a forked run uses, as functions (see `cpython_internals`)."""

    run_exit_handlers: Callable[[], None]
    forget_parent_process: Callable[[], None]
    # (listener_fd, alive_r): serve forks until the last client exits; None: this Python's fork server differs
    serve_forks: Callable[[int, int], None] | None
    socket_address: Callable[[], str] | None
    # (address, alive_w, pid): the server multiprocessing's pools of this process then use
    adopt_fork_server: Callable[[str, int, int], None] | None


@functools.cache
def cpython_internals() -> Internals | None:
    """CPython's private names the forked runs rest on (listed above), checked present and of the expected shape;
    None where they are not, and commands then run in fresh interpreters."""
    import atexit
    import inspect
    from multiprocessing import connection, forkserver, process

    run_exit_handlers = getattr(atexit, "_run_exitfuncs", None)
    if sys.implementation.name != "cpython" or not callable(run_exit_handlers):
        return None
    if not hasattr(process, "_parent_process"):
        return None
    forget = lambda: setattr(process, "_parent_process", None)  # noqa: E731
    server = getattr(forkserver, "_forkserver", None)
    main = getattr(forkserver, "main", None)
    usable = (
        all(hasattr(server, name) for name in SERVER_STATE)
        and callable(main)
        and list(inspect.signature(main).parameters) == [*SERVER_MAIN]
        and callable(getattr(connection, "arbitrary_address", None))
        and os.path.isdir("/proc/self/fd")  # the server closes what it should not inherit by listing them
    )
    if not usable:
        return Internals(run_exit_handlers, forget, None, None, None)

    def adopt(address: str, alive_w: int, pid: int) -> None:
        server._forkserver_address, server._forkserver_alive_fd, server._forkserver_pid = (
            address,
            alive_w,
            pid,
        )

    return Internals(
        run_exit_handlers,
        forget,
        lambda listener_fd, alive_r: main(listener_fd, alive_r, []),
        lambda: connection.arbitrary_address("AF_UNIX"),
        adopt,
    )


def _child(
    module: str, argv: list[str], env: dict[str, str], cwd: str, out: str, err: str, new_session: bool
) -> None:
    """In the forked child: the run's streams, environment, folder and argv, then the module as `__main__`."""
    internals = cpython_internals()
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
    internals.forget_parent_process()
    multiprocessing.set_start_method(None, force=True)
    _start_fork_server(internals)
    sys.argv = [module, *argv]
    # As in a fresh `python -m`, the module itself is not imported yet (its imports are: that is the saving).
    sys.modules.pop(module, None)
    _exit(_run_main(module), internals)


def _run_main(module: str) -> int | None:
    """Run `module` as `__main__`; its exit status as the interpreter reports it (None: ended by Ctrl-C)."""
    try:
        runpy.run_module(module, run_name="__main__", alter_sys=True)
    except SystemExit as exc:
        if exc.code is None or isinstance(exc.code, int):
            return exc.code or 0
        print(exc.code, file=sys.stderr)  # `sys.exit("message")`: the message, status 1
        return 1
    except KeyboardInterrupt:
        sys.excepthook(*sys.exc_info())
        return None
    except BaseException:  # as the interpreter does: the traceback on stderr, status 1
        sys.excepthook(*sys.exc_info())
        return 1
    return 0


def _exit(code: int | None, internals: Internals) -> None:
    """As an interpreter ends: the exit handlers, the streams flushed, the status; an uncaught KeyboardInterrupt
    ends it by SIGINT (a shell's status 130), as CPython does."""
    try:
        internals.run_exit_handlers()
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        if code is None:
            signal.signal(signal.SIGINT, signal.SIG_DFL)
            os.kill(os.getpid(), signal.SIGINT)
            code = 128 + signal.SIGINT  # (CPython's status where the signal did not end it)
        os._exit(code)


def _start_fork_server(internals: Internals) -> None:
    """The run's own fork server (roboview.core.workers), started now as a fork of this process instead of from a
    fresh interpreter when the run's first pool needs it.

    multiprocessing starts a fork server by running `python -c "from multiprocessing.forkserver import main; ..."`
    with the listening socket and the "alive" pipe's read end, which then imports its preloads: seconds of CPU for
    a policy's libraries, once per command-line run that starts a pool. This process has imported them all already
    and, just forked from the test process's fork server, runs one thread and holds no GL context: a fork of it now
    is that server, its modules already there. Its descriptors are closed but for stdin, stdout, stderr, the socket
    and the pipe (what the fresh interpreter inherits), and it serves the run's pools as multiprocessing's own
    `main` until the last of its clients exits; the run's workers are its children, as they would be."""
    from multiprocessing import resource_tracker

    if (
        internals.serve_forks is None
        or internals.socket_address is None
        or internals.adopt_fork_server is None
    ):
        return  # another multiprocessing: the run's first pool starts its own server
    resource_tracker.ensure_running()
    listener = socket.socket(socket.AF_UNIX)
    address = internals.socket_address()
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
            internals.serve_forks(listener.fileno(), alive_r)
        finally:
            os._exit(0)
    listener.close()
    os.close(alive_r)
    internals.adopt_fork_server(address, alive_w, pid)


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
    if cpython_internals() is not None and not _needs_fresh(env):
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
