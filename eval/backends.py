"""Execution backends: a local process pool (spawn) or Ray actors. Same rows for the same seeds.

Both keep a bounded number of episodes in flight and yield results as they finish. A worker that
dies loses only its episode in flight: it is logged, the worker replaced, and the episode retried
(at most `max_retries` times, then the run stops with an error naming it).
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import replace

from eval.policy_server import PolicyServer
from eval.rollout import EpisodeResult, EvalWorker, WorkerSpec, WorkItem
from roboview_data.workers import WorkerPool

log = logging.getLogger(__name__)

BACKENDS = ("local", "ray")


class EpisodeLost(RuntimeError):
    """An episode's worker died more often than allowed."""


def _retry(work: WorkItem, tries: dict, max_retries: int, why: str) -> None:
    tries[work.key] = tries.get(work.key, 0) + 1
    log.warning("worker died running %s repeat %d (%s); retry %d/%d", *work.key, why, tries[work.key], max_retries)
    if tries[work.key] > max_retries:
        raise EpisodeLost(f"episode {work.key[0]} repeat {work.key[1]} lost its worker {tries[work.key]} times")


def chunks(spec: WorkerSpec, items: Iterable[WorkItem]) -> list[tuple[WorkItem, ...]]:
    """What one worker call runs: one episode, or with K envs per worker 2K (slots refill as episodes end)."""
    items = list(items)
    size = 1 if spec.envs_per_worker == 1 else 2 * spec.envs_per_worker
    return [tuple(items[i:i + size]) for i in range(0, len(items), size)]


def run_local(spec: WorkerSpec, items: Iterable[WorkItem], num_workers: int,
              max_retries: int = 2) -> Iterator[tuple[WorkItem, EpisodeResult]]:
    queue = chunks(spec, items)[::-1]
    tries: dict = {}
    while queue:
        # With a policy server: one server per pool (a replaced pool gets a fresh one, worker ids and all).
        server = (PolicyServer(spec.policy, spec.task, spec.image_size, num_workers, spec.envs_per_worker)
                  if spec.policy_server else None)
        pool = WorkerPool(num_workers, EvalWorker, (spec if server is None else replace(spec, server=server.handle),),
                          method="run_batch")
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
                        _retry(work[0], tries, max_retries, str(exc) or "worker process died")
                        queue.append(work)
                        continue
                    yield from zip(work, results)
            for work in in_flight.values():
                queue.append(work)
        finally:
            pool.close()
            if server is not None:
                server.close()


def run_ray(spec: WorkerSpec, items: Iterable[WorkItem], num_workers: int, address: str | None = None,
            max_retries: int = 2) -> Iterator[tuple[WorkItem, EpisodeResult]]:
    import ray
    from ray.exceptions import RayActorError

    if spec.policy_server:
        raise ValueError("a policy server runs with the local backend only (backend=local)")

    if not ray.is_initialized():
        if address:
            ray.init(address=address, log_to_driver=False)
        else:
            ray.init(num_cpus=num_workers, include_dashboard=False, log_to_driver=False,
                     runtime_env={"env_vars": {"MUJOCO_GL": "egl", "PYOPENGL_PLATFORM": "egl"}})
    actor_cls = ray.remote(num_cpus=1)(EvalWorker)
    actors = [actor_cls.remote(spec, rank) for rank in range(num_workers)]
    queue = chunks(spec, items)[::-1]
    tries: dict = {}
    in_flight: dict = {}
    idle = list(range(num_workers))
    try:
        while queue or in_flight:
            while queue and idle:
                slot = idle.pop()
                work = queue.pop()
                in_flight[actors[slot].run_batch.remote(list(work))] = (slot, work)
            ready, _ = ray.wait(list(in_flight), num_returns=1)
            slot, work = in_flight.pop(ready[0])
            try:
                results = ray.get(ready[0])
            except RayActorError as exc:
                _retry(work[0], tries, max_retries, type(exc).__name__)
                actors[slot] = actor_cls.remote(spec, slot)
                queue.append(work)
            else:
                yield from zip(work, results)
            idle.append(slot)
    finally:
        for actor in actors:
            ray.kill(actor)
