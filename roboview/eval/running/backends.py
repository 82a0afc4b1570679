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
import os
import socket
import threading
import time
from collections.abc import Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import replace

from roboview.core.workers import WorkerPool
from roboview.eval.running.policy_server import PolicyServer
from roboview.eval.running.rollout import EpisodeResult, EvalWorker, WorkerSpec, WorkItem, lost_row

log = logging.getLogger(__name__)

BACKENDS = ("local", "ray")


class ClusterLost(RuntimeError):
    """The Ray cluster's head stopped answering, or no node is left to run on."""


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


def chunks(spec: WorkerSpec, items: Iterable[WorkItem]) -> list[tuple[WorkItem, ...]]:
    """What one worker call runs: one episode, or with K envs per worker 2K (slots refill as episodes end)."""
    items = list(items)
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
        )
        in_flight: dict = {}
        broken = False
        try:
            while (queue or in_flight) and not broken:
                while queue and len(in_flight) < 2 * num_workers:
                    work = queue.pop()
                    in_flight[pool.submit(list(work))] = work
                done, _ = wait(in_flight, return_when=FIRST_COMPLETED)
                for future in done:
                    work = in_flight.pop(future)
                    try:
                        results = future.result()
                    except BrokenProcessPool as exc:
                        # A worker died: the pool is gone, so every episode in flight is requeued.
                        broken = True
                        why = str(exc) or "worker process died"
                        if _retry(work[0], tries, max_retries, why):
                            queue.append(work)
                        else:
                            yield from _lost(spec, work, tries, why)
                        continue
                    yield from zip(work, results)
            for work in in_flight.values():
                queue.append(work)
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
    from ray.exceptions import GetTimeoutError, RayActorError

    if spec.policy_server:
        raise ValueError("a policy server runs with the local backend only (backend=local)")

    env = {"env_vars": {"MUJOCO_GL": "egl", "PYOPENGL_PLATFORM": "egl"}}
    if not ray.is_initialized():
        if address:
            # Without its head the driver exits after this long (Ray's default, 60 s, only delays the exit: the
            # head watch below has already stopped the run).
            os.environ.setdefault("RAY_gcs_rpc_server_reconnect_timeout_s", "15")
            try:
                ray.init(address=address, log_to_driver=False, runtime_env=env)
            except ConnectionError as exc:
                raise ClusterLost(
                    f"no Ray cluster answers at --eval.ray_address={address} ({exc}); start one "
                    "(ray start --head) or drop the flag to run a local Ray instance"
                ) from None
        else:
            # "local": a new instance of our own, never a cluster `ray start` left on this machine.
            ray.init(
                address="local",
                num_cpus=num_workers,
                include_dashboard=False,
                log_to_driver=False,
                runtime_env=env,
            )
    watch = None
    if address and (gcs := _gcs_address(address)):
        watch = _HeadWatch(gcs)
        watch.start()
    stats = stats if stats is not None else {}
    # accumulated over the calls of one run (adaptive rounds call once per round)
    stats.setdefault("nodes", {})
    stats.setdefault("lost_actors", 0)
    stats["address"] = address or "local"
    actor_cls = ray.remote(num_cpus=1)(EvalWorker).options(scheduling_strategy="SPREAD")

    def start(rank: int):
        actor = actor_cls.remote(spec, rank)
        return actor, actor.__ray_call__.remote(lambda self: ray.get_runtime_context().get_node_id())

    actors = {rank: start(rank) for rank in range(num_workers)}
    queue = chunks(spec, items)[::-1]
    tries: dict = {}
    in_flight: dict = {}
    idle = list(range(num_workers))
    starting: dict[int, float] = {}  # replacement actors not yet placed on a node → since when
    lost = False
    try:
        while queue or in_flight:
            for slot, since in list(starting.items()):  # a replacement works once a node has taken it
                if ray.wait([actors[slot][1]], timeout=0)[0]:
                    del starting[slot]
                    idle.append(slot)
                elif time.monotonic() - since > place_timeout_s:
                    log.warning(
                        "no Ray node took a replacement worker in %.0f s: continuing with fewer workers",
                        place_timeout_s,
                    )
                    ray.kill(actors.pop(slot)[0])
                    del starting[slot]
            while queue and idle:
                slot = idle.pop()
                work = queue.pop()
                in_flight[actors[slot][0].run_batch.remote(list(work))] = (slot, work)
            if not in_flight and not starting:
                raise ClusterLost(
                    f"every Ray worker was lost and no node took a new one; {sum(map(len, queue))} "
                    "episode(s) left: rerun the same command on a cluster to finish them"
                )
            ready, _ = ray.wait(list(in_flight), num_returns=1, timeout=1.0) if in_flight else ([], [])
            if watch is not None and watch.lost:
                lost = True
                raise ClusterLost(
                    f"the Ray head at {watch.target[0]}:{watch.target[1]} stopped answering; the "
                    "episodes already written are kept: start a cluster and rerun the same command "
                    "(with its --eval.ray_address) to resume"
                )
            if not ready:
                if not in_flight:
                    time.sleep(0.5)
                continue
            slot, work = in_flight.pop(ready[0])
            try:
                results = ray.get(ready[0])
            except RayActorError as exc:
                stats["lost_actors"] += 1
                if _retry(work[0], tries, max_retries, type(exc).__name__):
                    queue.append(work)
                else:
                    yield from _lost(spec, work, tries, type(exc).__name__)
                actors[slot] = start(slot)
                starting[slot] = time.monotonic()
                continue
            try:
                node = ray.get(actors[slot][1], timeout=10)
            except (GetTimeoutError, RayActorError):
                node = "unknown"
            stats["nodes"][node] = stats["nodes"].get(node, 0) + len(work)
            yield from zip(work, results)
            idle.append(slot)
    finally:
        if watch is not None:
            watch.stop.set()
        if not lost:
            for actor, _ in actors.values():
                ray.kill(actor)
