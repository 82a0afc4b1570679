"""One worker-pool helper for every pipeline that fans work out to processes (collect, build, evaluate).

Each worker process builds one heavy object once — a `DemoCollector`, an `InstanceRenderer`, an
`EvalWorker`: an env with its renderer and maybe a policy — and then runs one of its methods on each
item it is sent. Processes start from a fork server that imported the factory's module and the policy's
libraries once (EGL contexts do not survive `fork`, and the server holds none: each worker makes its own),
take the parent's environment of the moment, and end with their parent: a worker blocks on its task queue, and
when the parent is killed with SIGKILL nobody closes that queue, so without `exit_with_parent` it would linger
forever (≈ 640 MB each). Workers ignore Ctrl-C (they are started with SIGINT blocked, so one still starting prints
no traceback): the parent takes it, ends them and says what was saved.

    with WorkerPool(2, InstanceRenderer, (224, thresholds), method="record") as pool:
        for record in pool.imap(instances):     # ordered, bounded look-ahead
            ...
"""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Future, ProcessPoolExecutor
from typing import Any

POLL_S = 1.0
_STATE: Any = None
_RANK = 0


def worker_rank() -> int:
    """This worker's index in its pool (0 … num_workers-1; 0 outside a pool): what a policy spread over
    several servers uses to pick one (`--policy.url=A,B`: worker i talks to server i mod 2)."""
    return _RANK


def set_worker_rank(rank: int) -> None:
    global _RANK
    _RANK = rank


def threads_per_worker(workers: int, requested: int = 0) -> int:
    """CPU threads each worker's inference gets: `requested`, else the cores not already busy (the 1-minute load
    average) split between the workers, at least 1. On a busy machine more threads than free cores only contend:
    one worker given both cores of a loaded 2-core machine ran an episode 5–6× slower than with one thread."""
    if requested:
        return requested
    cores = os.cpu_count() or 1
    try:
        busy = os.getloadavg()[0]
    except OSError:  # no load average on this platform: the cores, split
        busy = 0.0
    return max(1, int(max(1.0, cores - busy) // workers))


def alive(pid: int) -> bool:
    """Whether process `pid` is running (a zombie, dead but not yet reaped, is not)."""
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rpartition(")")[2].split()[0] != "Z"
    except FileNotFoundError:
        return False
    except OSError:  # no /proc (macOS): the signal-0 probe
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        except PermissionError:
            pass
        return True


def exit_with_parent(parent: int | None = None, poll_s: float = POLL_S) -> None:
    """End this process (from a daemon thread) as soon as the process that started it has died.

    `parent` is the pid the parent gave when it started this process (its fork server's pid is this process's own
    parent pid, so the parent is watched by pid). Read here instead, a parent killed while this process was still
    importing would already be gone, and the watch would wait on its adopter forever."""
    parent = os.getppid() if parent is None else parent
    if not alive(parent):
        os._exit(1)  # the parent died before this process got this far

    def watch() -> None:
        while True:
            time.sleep(poll_s)
            if not alive(parent):
                os._exit(1)  # no cleanup to run: the parent that wanted the results is gone

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()


def _init(
    factory: Callable[..., Any], args: tuple, counter: Any, parent: int, environ: dict[str, str]
) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C and ends the workers
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})  # blocked while the process started
    if os.environ != environ:  # the parent's environment now, not the fork server's when it started
        os.environ.clear()
        os.environ.update(environ)
    os.environ.setdefault("MUJOCO_GL", "egl")
    exit_with_parent(parent)
    with counter.get_lock():  # ranks in start order: 0 … num_workers-1
        set_worker_rank(counter.value)
        counter.value += 1
    global _STATE
    _STATE = factory(*args)


def _call(method: str, item: Any) -> Any:
    return getattr(_STATE, method)(item)


_PRELOAD: set[str] = set()


def preload(*modules: str) -> None:
    """Modules this process's fork server imports beside those its first pool names. The server starts with the first
    pool and keeps that list, so a process that starts pools of several kinds (an expert pool, then a checkpoint
    pool) names what all of them use before the first one; a server already running is left as it is."""
    _PRELOAD.update(modules)


def start_context(preload: tuple[str, ...]) -> Any:
    """The context worker processes start from: a fork server (one per process, started by the first pool) that
    has imported `preload` (the factory's module, the policy's libraries) once, so each worker is a fork of a process
    that already imported them instead of a fresh interpreter importing them again. The server itself holds no
    EGL context (it only imports), so every worker still makes its own. Where there is no fork server (not Linux or
    macOS): spawned processes."""
    if "forkserver" not in mp.get_all_start_methods():
        return mp.get_context("spawn")
    ctx = mp.get_context("forkserver")
    ctx.set_forkserver_preload([*main_module(), *sorted(set(preload) | _PRELOAD)])
    return ctx


def main_module() -> list[str]:
    """The running program's main module, as a fork server's preload names it: `__main__` (a script: the server
    runs it once) and, for `python -m MODULE`, MODULE itself. Each worker of a fork server re-runs the main module
    (multiprocessing's `__mp_main__`); imported by the server first, that costs the worker nothing. Unnamed, a
    `-m` program's workers each import it and all it imports again (a policy's libraries: seconds of CPU each)."""
    spec = getattr(sys.modules.get("__main__"), "__spec__", None)
    return ["__main__", *([spec.name] if spec is not None and spec.name else [])]


class WorkerPool:
    """`num_workers` spawned processes, each holding `factory(*args)`; items go to its `method`."""

    def __init__(
        self,
        num_workers: int,
        factory: Callable[..., Any],
        args: tuple = (),
        method: str = "run",
        preload: tuple[str, ...] = (),
    ) -> None:
        if num_workers < 1:
            raise ValueError(f"num_workers={num_workers} must be at least 1")
        self.num_workers = num_workers
        self.method = method
        ctx = start_context((factory.__module__, *preload))
        self._executor = ProcessPoolExecutor(
            num_workers,
            mp_context=ctx,
            initializer=_init,
            initargs=(factory, args, ctx.Value("i", 0), os.getpid(), dict(os.environ)),
        )

    def submit(self, item: Any) -> Future:
        # A submit may start a worker process: it is started with SIGINT blocked (the mask is inherited across its
        # exec; its initializer then ignores SIGINT and unblocks it), so a Ctrl-C during its start-up leaves it
        # alone. Here the signal is only held back while the process starts, and delivered right after.
        if threading.current_thread() is not threading.main_thread():
            return self._executor.submit(_call, self.method, item)
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            return self._executor.submit(_call, self.method, item)
        finally:
            signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})

    def imap(self, items: Iterable[Any], lookahead: int | None = None) -> Iterator[Any]:
        """Results in the order of `items` (which may be endless), at most `lookahead` in flight."""
        lookahead = lookahead or 2 * self.num_workers  # bounded: memory stays flat
        pending: deque[Future] = deque()
        it = iter(items)
        for item in it:
            pending.append(self.submit(item))
            if len(pending) >= lookahead:
                yield pending.popleft().result()
        while pending:
            yield pending.popleft().result()

    def close(self, now: bool = False) -> None:
        """Wait for the items in flight and end the workers; `now`: end them at once (their items are lost)."""
        if now:
            for process in list((self._executor._processes or {}).values()):  # noqa: SLF001
                process.terminate()
        self._executor.shutdown(wait=True, cancel_futures=True)

    def __enter__(self) -> WorkerPool:
        return self

    def __exit__(self, kind: type[BaseException] | None, *exc: object) -> None:
        self.close(now=kind is not None and issubclass(kind, KeyboardInterrupt))
