"""One model for many render workers: the GPU layout (`--eval.policy_server=true`, local backend).

Rendering is CPU work and scales with processes; a checkpoint's forward pass is GPU work and scales
with batch size. With `--eval.policy_server=true` the evaluator starts one *policy server* process that
holds the only copy of the model (on `--policy.device`, e.g. cuda) and `num_workers` render workers,
each stepping `envs_per_worker` envs in lockstep. A worker keeps each slot's action queue and, when
a slot's queue runs dry, sends that slot's observation (the only time its cameras are rendered); the
server gathers what the workers have sent (waiting at most `GATHER_S` for the others once one request is
in), predicts every requested slot's next chunk in one forward pass, and answers each worker. Slot ids
are global (worker × envs_per_worker + slot): each episode keeps its own instruction and seed.

    workers (CPU, num_workers processes)              policy server (1 process, the GPU)
    ┌ env 0 … env K-1 ┐  obs of slots whose chunk ran out ──►  gather ─► one forward pass (B ≤ N·K) ─┐
    └ lockstep step   ┘  ◄── their next n_action_steps actions ◄─────────────────────────────────────┘

Only types whose config builds a natively batched policy (`PolicyConfig.build_batched`: chunked
LeRobot checkpoints) can be served; others are refused before any work.
"""

from __future__ import annotations

import collections
import logging
import multiprocessing as mp
import os
import queue
from dataclasses import dataclass

import numpy as np

from roboview.policies.base import AgentView, ChunkPredictor, Episode, PolicyConfig

log = logging.getLogger(__name__)

GATHER_S = 0.005  # once a request is in, how long to wait for the other workers' requests
# A worker gives up on an answer after this long (a server that died building its model never answers).
REPLY_TIMEOUT_S = 600.0


@dataclass
class ServerHandle:
    """What a worker needs to reach the server (queues travel to spawned workers at their creation)."""

    requests: mp.Queue
    replies: list  # one mp.Queue per worker id
    ids: mp.Queue  # worker ids 0..N-1, each taken by one worker at start
    envs_per_worker: int


class RemotePolicy:
    """A worker's `PolicyBatch`-compatible proxy. It keeps each slot's action queue itself and asks the
    server only when a slot's queue is empty: one round trip (and one camera read) per chunk, not per step."""

    batched = True

    def __init__(self, handle: ServerHandle) -> None:
        self.handle = handle
        self.worker = handle.ids.get(timeout=120)
        self._reply = handle.replies[self.worker]
        self.queues = [collections.deque() for _ in range(handle.envs_per_worker)]
        self.name = self._ask(("hello", self.worker))

    def _slot(self, slot: int) -> int:
        return self.worker * self.handle.envs_per_worker + slot

    def _ask(self, message: tuple):
        self.handle.requests.put(message)
        try:
            status, payload = self._reply.get(timeout=REPLY_TIMEOUT_S)
        except queue.Empty:
            raise RuntimeError(
                f"policy server did not answer within {REPLY_TIMEOUT_S:.0f} s (did it fail to load "
                "the model? its error is in the log above)"
            ) from None
        if status == "error":
            raise RuntimeError(f"policy server: {payload}")
        return payload

    def policy(self, slot: int):
        return self

    def reset(self, slot: int, episode: Episode) -> None:
        self.queues[slot].clear()
        self._ask(("reset", self.worker, self._slot(slot), episode))

    def select_actions(self, observations: dict[int, dict]) -> dict[int, np.ndarray]:
        empty = [s for s in observations if not self.queues[s]]
        if empty:
            # Plain dicts: a lazy observation renders the cameras here, in the worker, once per chunk.
            sent = {self._slot(s): {k: observations[s][k] for k in observations[s]} for s in empty}
            chunks = self._ask(("chunks", self.worker, sent))
            for s in empty:
                self.queues[s].extend(chunks[self._slot(s)])
        return {s: self.queues[s].popleft() for s in observations}

    def failure_reason(self, slot: int) -> str:
        return ""

    def episode_record(self, slot: int) -> dict:
        return {}

    def close(self) -> None:
        pass


def serve(
    config: PolicyConfig,
    task: str,
    cameras: tuple[str, ...],
    image_size: int,
    slots: int,
    requests: mp.Queue,
    replies: list,
    num_workers: int,
) -> None:
    """The server process: build the batched policy once, then answer requests until ("stop",)."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    policy = config.build_batched(
        AgentView.of_task(task, cameras, image_size, control=config.env_control()), slots
    )
    if not isinstance(policy, ChunkPredictor):
        raise SystemExit(f"policy type {config.type!r} cannot be served (no batched chunk prediction)")
    while True:
        pending = [requests.get()]
        while sum(m[0] == "chunks" for m in pending) < num_workers:  # gather the other workers' requests
            try:
                pending.append(requests.get(timeout=GATHER_S))
            except queue.Empty:
                break
        if any(m[0] == "stop" for m in pending):
            break
        chunk_requests = []
        for message in pending:
            kind, worker = message[0], message[1]
            try:
                if kind == "hello":
                    replies[worker].put(("ok", policy.name))
                elif kind == "reset":
                    policy.reset(message[3], message[2])
                    replies[worker].put(("ok", None))
                else:
                    chunk_requests.append(message)
            except Exception as exc:  # the worker records it as the episode's failure
                replies[worker].put(("error", f"{type(exc).__name__}: {exc}"))
        if chunk_requests:
            merged = {
                slot: obs for _, _, observations in chunk_requests for slot, obs in observations.items()
            }
            try:
                chunks = policy.predict_chunks(merged)
                for _, worker, observations in chunk_requests:
                    replies[worker].put(("ok", {s: chunks[s] for s in observations}))
            except Exception as exc:
                for _, worker, _ in chunk_requests:
                    replies[worker].put(("error", f"{type(exc).__name__}: {exc}"))
    policy.close()


class PolicyServer:
    """Start the server process for `num_workers` workers of `envs_per_worker` envs each; `handle` goes into
    every worker's spec."""

    def __init__(
        self, config: PolicyConfig, task: str, image_size: int, num_workers: int, envs_per_worker: int
    ):
        ctx = mp.get_context("spawn")
        self.requests = ctx.Queue()
        self.replies = [ctx.Queue() for _ in range(num_workers)]
        self.ids = ctx.Queue()
        for worker in range(num_workers):
            self.ids.put(worker)
        self.handle = ServerHandle(self.requests, self.replies, self.ids, envs_per_worker)
        self.process = ctx.Process(
            target=serve,
            name="roboview-policy-server",
            daemon=True,
            args=(
                config,
                task,
                config.observed_cameras(),
                image_size,
                num_workers * envs_per_worker,
                self.requests,
                self.replies,
                num_workers,
            ),
        )
        self.process.start()

    def close(self) -> None:
        self.requests.put(("stop",))
        self.process.join(timeout=30)
        if self.process.is_alive():
            self.process.terminate()
