"""Execution backends: a local process pool (spawn) or Ray actors. Same rows for the same seeds.

Both keep a bounded number of episodes in flight and yield results as they finish. A worker that
dies loses only its episode in flight: it is logged, the worker replaced, and the episode retried
(at most `max_retries` times; then it is yielded as a row of status `infra_error`, `roboview.eval.running.rollout.lost_row`,
and the run goes on: the evaluator re-runs such episodes later and on a rerun).

On a Ray cluster the actors spread over the nodes. A node that is lost takes its actors' episodes in flight
with it: they are retried on the surviving nodes, and an actor is replaced only while the cluster still has a
CPU for it, so the run finishes on fewer workers. A head node that stops answering ends the run with
`ClusterLost`; the rows already written stay, and the same command on a new cluster resumes.
"""

from __future__ import annotations

import logging
import socket
import threading
import time
from collections.abc import Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import replace

from roboview.core.ray_cluster import ClusterLost, connect
from roboview.core.workers import WorkerPool
from roboview.eval.running.policy_server import PolicyServer
from roboview.eval.running.rollout import EpisodeResult, EvalWorker, WorkerSpec, WorkItem, lost_row
from roboview.tasks import load_task

log = logging.getLogger(__name__)

BACKENDS = ("local", "ray")


class _HeadWatch(threading.Thread):
    """Polls the Ray head's GCS port; `lost` once it refused `misses` connections in a row."""

    def __init__(self, address: str, period_s: float = 1.0, misses: int = 3) -> None:
        super().__init__(daemon=True, name="ray-head-watch")
        host, _, port = address.rpartition(":")
        self.target = (host or "127.0.0.1", int(port))
        self.period_s, self.misses, self.lost = period_s, misses, False
        self.stop = threading.Event()

    def run(self) -> None:
        failed = 0
        while not self.stop.wait(self.period_s):
            try:
                socket.create_connection(self.target, timeout=self.period_s).close()
                failed = 0
            except OSError:
                failed += 1
                if failed >= self.misses:
                    self.lost = True
                    return

    def lost_error(self) -> ClusterLost:
        """What ends the run once the head is lost."""
        return ClusterLost(
            f"the Ray head at {self.target[0]}:{self.target[1]} stopped answering; the episodes already written "
            "are kept: start a cluster and rerun the same command (with its --eval.ray_address) to resume"
        )


def _retry(work: WorkItem, tries: dict, max_retries: int, why: str) -> bool:
    """Count one more death of the worker running `work`: True to run it again, False once it has died more than
    `max_retries` times (the episode is then recorded as ended by infrastructure: `_lost`)."""
    tries[work.key] = tries.get(work.key, 0) + 1
    if tries[work.key] > max_retries:
        log.error(
            "worker died running %s repeat %d (%s) %d times: recorded as an infrastructure error",
            *work.key,
            why,
            tries[work.key],
        )
        return False
    log.warning(
        "worker died running %s repeat %d (%s); retry %d/%d", *work.key, why, tries[work.key], max_retries
    )
    return True


def _lost(
    spec: WorkerSpec, chunk: tuple[WorkItem, ...], tries: dict, why: str
) -> Iterator[tuple[WorkItem, EpisodeResult]]:
    """infra_error rows for the episodes of a chunk whose worker kept dying."""
    reason = f"infrastructure error: the worker died {tries[chunk[0].key]} times running this episode ({why})"
    for work in chunk:
        yield work, EpisodeResult(lost_row(work, reason, spec.policy.name or None))


def _after_death(
    spec: WorkerSpec, work: tuple[WorkItem, ...], queue: list, tries: dict, max_retries: int, why: str
) -> Iterator[tuple[WorkItem, EpisodeResult]]:
    """A chunk whose worker died: back on the queue, or, once it has died more than `max_retries` times, its
    infra_error rows."""
    if _retry(work[0], tries, max_retries, why):
        queue.append(work)
    else:
        yield from _lost(spec, work, tries, why)


def chunks(spec: WorkerSpec, items: Iterable[WorkItem]) -> list[tuple[WorkItem, ...]]:
    """What one worker call runs: one episode, or with K envs per worker 2K (slots refill as episodes end). One
    world's episodes are queued together (`Task.world_of`: a LIBERO task's model is compiled once per worker, not
    once per episode); within a world, in the run's order."""
    task = load_task(spec.task)
    items = sorted(items, key=lambda work: task.world_of(work.item.instance))
    size = 1 if spec.envs_per_worker == 1 else 2 * spec.envs_per_worker
    return [tuple(items[i : i + size]) for i in range(0, len(items), size)]


def run_local(
    spec: WorkerSpec, items: Iterable[WorkItem], num_workers: int, max_retries: int = 2
) -> Iterator[tuple[WorkItem, EpisodeResult]]:
    queue = chunks(spec, items)[::-1]
    tries: dict = {}
    while queue:
        # With a policy server: one server per pool (a replaced pool gets a fresh one, worker ids and all).
        server = (
            PolicyServer(spec.policy, spec.task, spec.image_size, num_workers, spec.envs_per_worker)
            if spec.policy_server
            else None
        )
        pool = WorkerPool(
            num_workers,
            EvalWorker,
            (spec if server is None else replace(spec, server=server.handle),),
            method="run_batch",
            preload=spec.policy.worker_imports(),
        )
        in_flight: dict = {}
        broken = False
        try:
            while (queue or in_flight) and not broken:
                while queue and len(in_flight) < 2 * num_workers:
                    work = queue.pop()
                    in_flight[pool.submit(list(work))] = work
                done, _ = wait(in_flight, return_when=FIRST_COMPLETED)
                # In submission order, so that one worker's journal reads as its queue did.
                for future in [f for f in in_flight if f in done]:
                    work = in_flight.pop(future)
                    try:
                        results = future.result()
                    except BrokenProcessPool as exc:
                        # A worker died: the pool is gone, so every episode in flight is requeued.
                        broken = True
                        why = str(exc) or "worker process died"
                        yield from _after_death(spec, work, queue, tries, max_retries, why)
                        continue
                    yield from zip(work, results)
            for work in in_flight.values():
                queue.append(work)
        except (
            KeyboardInterrupt,
            GeneratorExit,
        ):  # Ctrl-C, or the consumer stopped: in-flight episodes are lost
            pool.close(now=True)
            raise
        finally:
            pool.close()
            if server is not None:
                server.close()


def _gcs_address(address: str | None) -> str | None:
    """host:port of the cluster's head (its GCS) once connected, for the watchdog; None if unknown."""
    import ray

    try:
        found = ray.get_runtime_context().gcs_address
    except Exception:  # noqa: BLE001 — older Ray: no watchdog
        found = None
    return found or (address if address and ":" in address and not address.startswith("ray://") else None)


def run_ray(
    spec: WorkerSpec,
    items: Iterable[WorkItem],
    num_workers: int,
    address: str | None = None,
    max_retries: int = 2,
    stats: dict | None = None,
    place_timeout_s: float = 60.0,
) -> Iterator[tuple[WorkItem, EpisodeResult]]:
    """Episodes on Ray actors (`num_workers` of them, spread over the cluster's nodes); `stats`, when given,
    receives the cluster address, episodes per node id and the actors lost. A replacement actor that no node
    takes within `place_timeout_s` (the cluster lost the CPU it ran on) is dropped: the run goes on with fewer."""
    import ray
    from ray.exceptions import RayActorError

    if spec.policy_server:
        raise ValueError("a policy server runs with the local backend only (backend=local)")
    connect(address, num_workers)
    watch = _watch_head(address)
    stats = _cluster_stats(stats, address)
    workers = _RayWorkers(spec, num_workers)
    queue = chunks(spec, items)[::-1]
    tries: dict = {}
    lost = False
    try:
        while queue or workers.in_flight:
            workers.place(place_timeout_s)
            workers.submit(queue)
            workers.check_any_left(queue)
            ready = workers.wait_one(timeout_s=1.0)
            if watch is not None and watch.lost:
                lost = True
                raise watch.lost_error()
            if ready is None:
                if not workers.in_flight:
                    time.sleep(0.5)
                continue
            slot, work = workers.in_flight.pop(ready)
            try:
                results = ray.get(ready)
            except RayActorError as exc:
                stats["lost_actors"] += 1
                yield from _after_death(spec, work, queue, tries, max_retries, type(exc).__name__)
                workers.restart(slot)
                continue
            node = workers.node_of(slot)
            stats["nodes"][node] = stats["nodes"].get(node, 0) + len(work)
            yield from zip(work, results)
            workers.idle.append(slot)
    finally:
        if watch is not None:
            watch.stop.set()
        if not lost:
            workers.kill()


def _watch_head(address: str | None) -> _HeadWatch | None:
    """A started watch on the cluster head's GCS port (a cluster given by address whose head is known), else None."""
    if address and (gcs := _gcs_address(address)):
        watch = _HeadWatch(gcs)
        watch.start()
        return watch
    return None


def _cluster_stats(stats: dict | None, address: str | None) -> dict:
    """The stats dict `run_ray` fills: episodes per node and actors lost, accumulated over the calls of one run
    (adaptive rounds call once per round), and the cluster's address."""
    stats = stats if stats is not None else {}
    stats.setdefault("nodes", {})
    stats.setdefault("lost_actors", 0)
    stats["address"] = address or "local"
    return stats


class _RayWorkers:
    """The actors of one `run_ray` call by slot: each slot's actor with the reference to the node id it reports
    once placed, the idle slots, the replacements still waiting for a node (since when) and the batches in
    flight (reference → (slot, chunk))."""

    def __init__(self, spec: WorkerSpec, num_workers: int) -> None:
        import ray

        self.spec = spec
        self.actor_cls = ray.remote(num_cpus=1)(EvalWorker).options(scheduling_strategy="SPREAD")
        self.actors = {rank: self._start(rank) for rank in range(num_workers)}
        self.idle = list(range(num_workers))
        self.starting: dict[int, float] = {}
        self.in_flight: dict = {}

    def _start(self, rank: int) -> tuple:
        """A new actor for slot `rank`, and the reference to the node id it reports once a node runs it."""
        import ray

        actor = self.actor_cls.remote(self.spec, rank)
        return actor, actor.__ray_call__.remote(lambda worker: ray.get_runtime_context().get_node_id())

    def place(self, timeout_s: float) -> None:
        """A replacement works once a node has taken it; one no node took within `timeout_s` is dropped."""
        import ray

        for slot, since in list(self.starting.items()):
            if ray.wait([self.actors[slot][1]], timeout=0)[0]:
                del self.starting[slot]
                self.idle.append(slot)
            elif time.monotonic() - since > timeout_s:
                log.warning(
                    "no Ray node took a replacement worker in %.0f s: continuing with fewer workers",
                    timeout_s,
                )
                ray.kill(self.actors.pop(slot)[0])
                del self.starting[slot]

    def submit(self, queue: list[tuple[WorkItem, ...]]) -> None:
        """Give each idle actor the next chunk of the queue (taken from its end)."""
        while queue and self.idle:
            slot = self.idle.pop()
            work = queue.pop()
            self.in_flight[self.actors[slot][0].run_batch.remote(list(work))] = (slot, work)

    def check_any_left(self, queue: list[tuple[WorkItem, ...]]) -> None:
        """ClusterLost when no actor is working or waiting for a node: every one was lost and none replaced."""
        if not self.in_flight and not self.starting:
            raise ClusterLost(
                f"every Ray worker was lost and no node took a new one; {sum(map(len, queue))} "
                "episode(s) left: rerun the same command on a cluster to finish them"
            )

    def wait_one(self, timeout_s: float):
        """The reference of a finished batch, waiting at most `timeout_s`; None when none finished."""
        import ray

        if not self.in_flight:
            return None
        ready, _ = ray.wait(list(self.in_flight), num_returns=1, timeout=timeout_s)
        return ready[0] if ready else None

    def restart(self, slot: int) -> None:
        """A new actor in a slot whose actor died; it works once a node takes it (`place`)."""
        self.actors[slot] = self._start(slot)
        self.starting[slot] = time.monotonic()

    def node_of(self, slot: int) -> str:
        """The id of the node a slot's actor runs on ("unknown" when it does not say in time)."""
        import ray
        from ray.exceptions import GetTimeoutError, RayActorError

        try:
            return ray.get(self.actors[slot][1], timeout=10)
        except (GetTimeoutError, RayActorError):
            return "unknown"

    def kill(self) -> None:
        """End every actor of the run."""
        import ray

        for actor, _ in self.actors.values():
            ray.kill(actor)
