"""The batching policy server behind `roboview-serve-policy`: openpi's websocket protocol, one model for every
connection, requests that arrive together batched into one forward pass (`BatchingServer`), a policy per
connection for types that keep state (`PolicyService`), and openpi-server's own one-request-at-a-time server
as the reference (`OneRequestPolicy`). Its configuration is `ServeConfig` (the verb's flags)."""

from __future__ import annotations

import asyncio
import concurrent.futures
import http
import logging
import os
import signal
import sys
import threading
import time
import traceback
from dataclasses import dataclass

import numpy as np

from roboview.policies.base import AgentView, ChunkPredictor, PolicyConfig, missing_policy_type
from roboview.policies.factory import build_policy
from roboview.policies.serving.openpi_wire import (
    EPISODE_KEY,
    OBS_FORMATS,
    ROBOVIEW_KEY,
    episode_from_message,
    wire_format,
)
from roboview.sim.cameras import check_image_size
from roboview.tasks import DEFAULT_TASK, TASKS
from roboview.tasks.env import EE_STATE_KEY, STATE_KEY

log = logging.getLogger(__name__)

SERVERS = ("roboview", "openpi")


@dataclass
class ServeConfig:
    # Required: --policy.type=NAME (no default).
    policy: PolicyConfig = None  # type: ignore[assignment]
    # Interface to listen on (0.0.0.0: every interface; 127.0.0.1: this machine only).
    host: str = "127.0.0.1"
    # TCP port (0: any free port, printed at start).
    port: int = 8000
    # Observation layout the clients send: droid, libero, aloha, custom (with --key_map); see roboview.policies.serving.openpi_wire.
    obs_format: str = "droid"
    # custom layout: comma-separated wire_key=SOURCE, SOURCE = camera:NAME, camera_chw:NAME, depth:NAME, state,
    # state[i:j] or instruction (as --policy.key_map of the openpi policy).
    key_map: str = ""
    # The task whose env defines the action and observation spaces the policy is built for: pick_place, push, libero,
    # liberoplus or metaworld (roboview.tasks).
    task: str = DEFAULT_TASK
    # Image side the clients send; 0: the policy's own (a checkpoint's input size), else 224.
    image_size: int = 0
    # Connections served at once (one model slot each).
    max_clients: int = 16
    # Once a request is in, how long (ms) to wait for the other connections' requests before the forward pass.
    gather_ms: float = 5.0
    # roboview (batches across connections) or openpi (openpi-server's WebsocketPolicyServer, one at a time).
    server: str = "roboview"
    # Name of an environment variable holding an API key: when it is set, connections must send
    # `Authorization: Api-Key <key>` (openpi's header; `--policy.api_key_env` on the client) or get 401.
    api_key_env: str = "ROBOVIEW_SERVE_API_KEY"
    # Intra-op threads of a torch policy; 0: torch's default. An evaluation's in-process rows equal the
    # served ones when both use the same count (float reductions depend on it).
    threads: int = 0

    def __post_init__(self) -> None:
        if self.policy is None:
            raise ValueError(missing_policy_type())
        if not 0 <= self.port <= 65535:
            raise ValueError(f"--port={self.port} must lie in 0..65535")
        if self.obs_format not in OBS_FORMATS:
            raise ValueError(f"unknown --obs_format={self.obs_format!r}; allowed: {', '.join(OBS_FORMATS)}")
        if self.task not in TASKS:
            raise ValueError(f"unknown --task={self.task!r}; allowed: {', '.join(TASKS)}")
        if self.server not in SERVERS:
            raise ValueError(f"unknown --server={self.server!r}; allowed: {', '.join(SERVERS)}")
        if self.max_clients < 1 or self.gather_ms < 0 or self.threads < 0:
            raise ValueError(
                f"--max_clients={self.max_clients} must be ≥ 1, --gather_ms={self.gather_ms} "
                f"and --threads={self.threads} ≥ 0"
            )
        if self.image_size:  # 0: the policy's own size
            check_image_size(self.image_size, "--image_size", why="or 0 for the policy's own size")
        if self.server == "openpi" and os.environ.get(self.api_key_env):
            raise ValueError(
                f"--server=openpi does not check API keys; unset {self.api_key_env} or use --server=roboview"
            )
        if self.policy.privileged:
            raise ValueError(
                f"--policy.type={self.policy.type} reads the simulator's state and cannot be served; "
                "serve a policy that acts from observations (lerobot, vision, vlm_simple, …)"
            )


class _Session:
    """One connection's own policy (types without a batched model), reset at each new episode."""

    def __init__(self, service: PolicyService) -> None:
        self.service = service
        self.policy = None
        self.instruction: str | None = None

    def infer(self, obs: dict, instruction: str, episode: dict | None) -> np.ndarray:
        from roboview.policies.base import Episode

        if self.policy is None:
            self.policy = build_policy(self.service.config, self.service.view)
        if episode is not None:
            self.policy.reset(episode_from_message(episode, instruction))
            self.instruction = instruction
        elif instruction != self.instruction:  # another client's new episode: no seed, no calibration
            view = self.service.view
            self.policy.reset(Episode(view.task, instruction, 0, {}, view.image_size))
            self.instruction = instruction
        self.service.requests += 1
        self.service.forward_passes += 1
        return np.asarray(self.policy.select_action(obs), np.float32)[None]

    def close(self) -> None:
        close = getattr(self.policy, "close", None)
        if close is not None:
            close()


class PolicyService:
    """The policy behind the socket: a batched model (one slot per connection) or one policy per connection."""

    def __init__(self, cfg: ServeConfig) -> None:
        os.environ.setdefault("MUJOCO_GL", "egl")
        self.config = cfg.policy
        own = cfg.policy.input_image_size()
        if own is not None and cfg.image_size and cfg.image_size != own:
            raise ValueError(
                f"--image_size={cfg.image_size} but the policy takes {own}×{own} images; drop the flag"
            )
        self.image_size = own or cfg.image_size or 224
        cameras = cfg.policy.observed_cameras()
        self.format = wire_format(cfg.obs_format, cameras, cfg.key_map, cfg.policy.depth)
        self.control = cfg.policy.env_control()
        self.view = AgentView.of_task(cfg.task, cameras, self.image_size, cfg.policy.depth, self.control)
        # The wire's state is the policy's: the EE state for a policy acting in an end-effector control.
        self.state_key = STATE_KEY if self.control == "joint" else EE_STATE_KEY
        self.batched = (
            cfg.policy.build_batched(self.view, cfg.max_clients) if cfg.policy.batchable() else None
        )
        if not isinstance(self.batched, ChunkPredictor):
            self.batched = None
        name = self.batched.name if self.batched is not None else cfg.policy.type
        self.horizon = getattr(self.batched, "n_action_steps", 1) if self.batched is not None else 1
        self.metadata = {
            ROBOVIEW_KEY: {
                "policy": cfg.policy.name or name,
                "policy_type": cfg.policy.type,
                "checkpoint": cfg.policy.checkpoint,
                "cameras": list(cameras),
                "image_size": self.image_size,
                "obs_format": cfg.obs_format,
                "action_horizon": self.horizon,
                "batched": self.batched is not None,
                "task": cfg.task,
                "control": self.control,
            }
        }
        if cfg.threads and "torch" in sys.modules:
            sys.modules["torch"].set_num_threads(cfg.threads)
        self.requests = 0
        self.forward_passes = 0

    def decode(self, request: dict) -> tuple[dict, str, dict | None]:
        width = self.view.observation_space[self.state_key].shape[0]
        obs, instruction = self.format.decode(request, self.image_size, self.state_key, width)
        return obs, instruction, request.get(EPISODE_KEY)

    def predict(self, batch: dict[int, tuple[dict, str]]) -> dict[int, np.ndarray]:
        """One forward pass over slot -> (observation, instruction): each slot's next chunk, (H, 8)."""
        chunks = self.batched.predict_chunks(
            {s: o for s, (o, _) in batch.items()}, instructions={s: i for s, (_, i) in batch.items()}
        )
        self.requests += len(batch)
        self.forward_passes += 1
        return {slot: np.stack(actions).astype(np.float32) for slot, actions in chunks.items()}

    def close(self) -> None:
        if self.batched is not None:
            self.batched.close()


class OneRequestPolicy:
    """The service as an openpi `BasePolicy` (`infer(obs) -> {"actions": …}`), for openpi-server's own server."""

    def __init__(self, service: PolicyService) -> None:
        self.service = service
        self.session = _Session(service)
        self.lock = threading.Lock()

    def infer(self, request: dict) -> dict:
        obs, instruction, episode = self.service.decode(request)
        with self.lock:
            if self.service.batched is not None:
                return {"actions": self.service.predict({0: (obs, instruction)})[0]}
            return {"actions": self.session.infer(obs, instruction, episode)}

    def reset(self) -> None:
        pass


def _gate(api_key: str | None):
    """`process_request`: /healthz answers OK; with a key, a connection without it is refused (401)."""

    def check(connection, request):
        if request.path == "/healthz":
            return connection.respond(http.HTTPStatus.OK, "OK\n")
        if api_key and request.headers.get("Authorization") != f"Api-Key {api_key}":
            return connection.respond(
                http.HTTPStatus.UNAUTHORIZED, "missing or wrong API key (Authorization: Api-Key …)\n"
            )
        return None

    return check


class BatchingServer:
    """openpi's protocol over asyncio websockets; requests of all connections gathered into forward passes."""

    def __init__(
        self, service: PolicyService, max_clients: int, gather_s: float, api_key: str | None = None
    ) -> None:
        self.service = service
        self.api_key = api_key
        self.gather_s = gather_s
        self.free = list(range(max_clients))[::-1]
        self.connected = 0
        self.model = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="model")
        self.sessions = concurrent.futures.ThreadPoolExecutor(max_clients, thread_name_prefix="session")
        self.queue: asyncio.Queue | None = None

    async def _infer(self, slot: int, session: _Session, request: dict) -> np.ndarray:
        loop = asyncio.get_running_loop()
        obs, instruction, episode = self.service.decode(request)
        if self.service.batched is None:
            return await loop.run_in_executor(self.sessions, session.infer, obs, instruction, episode)
        future = loop.create_future()
        await self.queue.put((slot, obs, instruction, future))
        return await future

    async def _batcher(self) -> None:
        loop = asyncio.get_running_loop()
        while True:
            pending = [await self.queue.get()]
            deadline = loop.time() + self.gather_s
            while len(pending) < self.connected:
                try:
                    pending.append(self.queue.get_nowait())
                    continue
                except asyncio.QueueEmpty:
                    pass
                left = deadline - loop.time()
                if left <= 0:
                    break
                try:
                    pending.append(await asyncio.wait_for(self.queue.get(), left))
                except TimeoutError:
                    break
            batch = {slot: (obs, instruction) for slot, obs, instruction, _ in pending}
            try:
                chunks = await loop.run_in_executor(self.model, self.service.predict, batch)
            except Exception as exc:
                for *_, future in pending:
                    if not future.done():
                        future.set_exception(exc)
                continue
            for slot, _, _, future in pending:
                if not future.done():
                    future.set_result(chunks[slot])

    async def _handler(self, websocket) -> None:
        import websockets
        from openpi_client import msgpack_numpy

        if not self.free:
            await websocket.close(
                code=1013, reason=f"server full ({len(self.free)} free slots); try again later"
            )
            return
        slot = self.free.pop()
        self.connected += 1
        session = _Session(self.service)
        packer = msgpack_numpy.Packer()
        try:
            await websocket.send(packer.pack(self.service.metadata))
            while True:
                try:
                    message = await websocket.recv()
                except websockets.ConnectionClosed:
                    break
                start = time.monotonic()
                try:
                    actions = await self._infer(slot, session, msgpack_numpy.unpackb(message))
                except Exception:
                    await websocket.send(traceback.format_exc())
                    await websocket.close(
                        code=1011, reason="Internal server error. Traceback included in previous frame."
                    )
                    break
                await websocket.send(
                    packer.pack(
                        {"actions": actions, "server_timing": {"infer_ms": 1000 * (time.monotonic() - start)}}
                    )
                )
        finally:
            self.connected -= 1
            self.free.append(slot)
            session.close()

    async def serve(
        self, host: str, port: int, ready: threading.Event | None = None, bound: list | None = None
    ):
        from websockets.asyncio.server import serve

        self.queue = asyncio.Queue()
        batcher = asyncio.create_task(self._batcher())
        async with serve(
            self._handler, host, port, compression=None, max_size=None, process_request=_gate(self.api_key)
        ) as server:
            if bound is not None:
                bound.append(server.sockets[0].getsockname()[1])
            if ready is not None:
                ready.set()
            try:
                await server.serve_forever()
            finally:
                batcher.cancel()


def stop_on_sigterm() -> None:
    """SIGTERM ends the server as Ctrl-C does (the summary line is printed, the model released)."""

    def stop(*_):
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, stop)
