"""Any vla-eval model server evaluated by RoboView's runner (`--policy.type=vla_eval`).

    vla-eval serve --config MODEL_SERVER.yaml          # or: python -m vla_eval.model_servers.lerobot ...
    roboview-evaluate --benchmark.path=outputs/benchmark --policy.type=vla_eval \\
        --policy.url=ws://gpu-host:8000 --policy.cameras=left_top,wrist --policy.image_size=224 \\
        --output_dir=outputs/eval/served

The protocol is vla-eval's (allenai/vla-evaluation-harness): a websocket of msgpack frames built and read by
vla-eval's own `pack_message` / `unpack_message` (arrays by its numpy codec, images as `--policy.image_format`).
HELLO first; the answer carries the server's action and observation specs, which are negotiated
(`roboview.policies.serving.vla_eval_specs`) before any episode: the env control, the cameras, the state. Then, per env slot,
one websocket: EPISODE_START with the instance's instruction, task and episode seed, one
OBSERVATION per step (`images` {camera: H×W×3 uint8}, `task_description`, the state as `states` and `state`,
the two spellings vla-eval's servers read), one ACTION back, EPISODE_END when the next episode starts. As in
vla-eval's own sync runner, action chunks live on the server (`PredictModelServer` buffers them per connection
and answers one action per observation); an answer that is a whole (H, D) chunk is played from its first row,
as PredictModelServer's continuous-inference path does. vla-eval's `Connection` is asyncio; RoboView's
policies are called synchronously, so the frames go over `websockets`' sync client.

Envs stepped in lockstep (`--eval.envs_per_worker=K`) get one connection each: every slot's observation is sent
before any answer is read, so a server with `max_batch_size > 1` (PredictModelServer's `predict_batch`) runs
them as one batch. **A served policy's randomness lives on the server**: the episode seed is sent in
EPISODE_START, and only a server that reads it reproduces RoboView's seeds.

Failures: a server that is down, or whose specs cannot be mapped, fails before any rollout naming the field.
An ERROR frame answering an observation (the model raised) fails that episode with the server's message as
the reason (the policy's failure). A connection lost (or an answer not back within `--policy.timeout_s`)
mid-episode loses the server's state of that episode (its chunk buffer): the connection is reopened
(`--policy.reconnects` times) and the episode ends with an `InfraError` (counted in no rate, run again);
if the server stays unreachable the run stops with `PolicyUnavailable`, and rerunning the command resumes.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from typing import Any

import numpy as np

from roboview.core.workers import worker_rank
from roboview.policies.base import AgentView, Episode, PolicyConfig, WebsocketServed, control_field
from roboview.policies.errors import InfraError, open_with_retries
from roboview.policies.serving.handshake import WrongProtocol, is_openpi_metadata, openpi_server
from roboview.policies.serving.vla_eval_specs import Negotiated, negotiate
from roboview.tasks import camera_names
from roboview.tasks.env import IMAGE_KEY
from roboview.tasks.world import native_render_size

log = logging.getLogger(__name__)

IMAGE_FORMATS = ("raw", "png", "jpeg")
DEFAULT_IMAGE_SIZE = 224


class ServerError(RuntimeError):
    """The server answered an ERROR frame (its model raised): that episode's failure."""


class _Lost(Exception):
    """The websocket closed or timed out (the server's state of the episode in flight is gone)."""


class ServerConnection:
    """One websocket to a vla-eval server, HELLO exchanged: `hello` is the server's answer."""

    def __init__(self, url: str, open_timeout_s: float, timeout_s: float, image_format: str) -> None:
        from vla_eval.protocol.messages import MessageType, make_hello_payload
        from vla_eval.protocol.numpy_codec import set_image_format
        from websockets.sync.client import connect

        set_image_format(image_format)  # vla-eval's codec reads it when it packs an image
        self.url, self.timeout_s, self.seq = url, timeout_s, 0
        self.ws = connect(
            url,
            compression=None,
            max_size=None,
            open_timeout=open_timeout_s,
            close_timeout=1,
            ping_interval=None,
            legacy=True,
        )
        try:
            self.send(MessageType.HELLO, make_hello_payload(benchmark="roboview"))
            frame = self.ws.recv(timeout=open_timeout_s)
            if is_openpi_metadata(frame):  # an openpi server greets every client with its metadata
                raise openpi_server(url)
            from vla_eval.protocol.messages import unpack_message

            reply = unpack_message(frame)
            if reply.type != MessageType.HELLO:
                raise ConnectionError(f"{url} answered HELLO with {reply.type.value}, not hello")
        except Exception:
            self.ws.close()
            raise
        self.hello: dict = reply.payload

    def send(self, kind, payload: dict) -> int:
        from vla_eval.protocol.messages import Message, pack_message

        self.seq += 1
        self.ws.send(pack_message(Message(type=kind, payload=payload, seq=self.seq)))
        return self.seq

    def _recv(self, timeout: float):
        from vla_eval.protocol.messages import unpack_message

        return unpack_message(self.ws.recv(timeout=timeout))

    def answer(self, seq: int) -> np.ndarray | ServerError:
        """The action answering observation `seq` (earlier frames read past: an ERROR of EPISODE_START
        becomes this answer's error), or the ServerError the server sent."""
        from vla_eval.protocol.messages import MessageType

        error: ServerError | None = None
        while True:
            msg = self._recv(self.timeout_s)
            if msg.type == MessageType.ERROR:
                error = error or ServerError(
                    f"vla-eval server error: {msg.payload.get('error', msg.payload)}"
                )
            if msg.seq != seq or msg.type not in (MessageType.ACTION, MessageType.ERROR):
                continue
            if error is not None:
                return error
            actions = msg.payload.get("actions", msg.payload.get("action"))
            if actions is None:
                return ServerError(f"vla-eval server answered without 'actions' (keys {sorted(msg.payload)})")
            actions = np.asarray(actions, np.float32)
            return actions[0] if actions.ndim == 2 else actions

    def close(self) -> None:
        self.ws.close()


class VlaEvalPolicy:
    """The client of `slots` envs: one connection each, opened at build (the server's HELLO checked again)."""

    def __init__(self, config: VlaEvalConfig, negotiated: Negotiated, slots: int = 1) -> None:
        self.config, self.agreed = config, negotiated
        self.url = config.url_list[worker_rank() % len(config.url_list)]
        self.name = f"vla_eval:{config.server_name(self.url)}"
        self.failure_reason = ""
        self.connections: list[ServerConnection | None] = [None] * slots
        self.episodes: list[Episode | None] = [None] * slots
        self.steps = [0] * slots
        for slot in range(slots):
            self._open(slot)

    def _open(self, slot: int, lost: str = "") -> None:
        """Open slot's connection (re-sending its episode's start), `reconnects` more tries; else the run stops."""
        from vla_eval.protocol.messages import MessageType

        cfg = self.config

        def connect() -> ServerConnection:
            connection = ServerConnection(self.url, cfg.open_timeout_s, cfg.timeout_s, cfg.image_format)
            if self.episodes[slot] is not None:
                connection.send(MessageType.EPISODE_START, start_payload(self.episodes[slot]))
            return connection

        self.connections[slot] = open_with_retries(
            connect, f"vla-eval server {self.url}", cfg.reconnects, cfg.reconnect_backoff_s, lost
        )

    def _lose(self, slot: int, why: str) -> InfraError:
        connection, self.connections[slot] = self.connections[slot], None
        if connection is not None:
            connection.close()
        self._open(slot, why)  # PolicyUnavailable (the run stops) if the server stays away
        return InfraError(
            f"lost the vla-eval server {self.url} mid-episode ({why}); reconnected, so only this episode is "
            "lost (it runs again)"
        )

    def _call(self, fn, *args):
        from websockets.exceptions import ConnectionClosed

        try:
            return fn(*args)
        except TimeoutError:
            raise _Lost(f"no answer within {self.config.timeout_s:g} s") from None
        except (ConnectionClosed, OSError) as exc:
            raise _Lost(f"the connection closed: {type(exc).__name__}: {exc}") from None

    def reset(self, episode: Episode, slot: int = 0) -> None:
        from vla_eval.protocol.messages import MessageType

        self.failure_reason = ""
        connection = self.connections[slot]
        try:
            if connection is None:
                raise _Lost("no connection")
            if self.episodes[slot] is not None:
                self._call(connection.send, MessageType.EPISODE_END, {"steps": self.steps[slot]})
            self.episodes[slot], self.steps[slot] = episode, 0
            self._call(connection.send, MessageType.EPISODE_START, start_payload(episode))
        except _Lost as exc:  # nothing of this episode was lost yet: reopen and start it there
            self.episodes[slot], self.steps[slot] = episode, 0
            self.connections[slot] = None
            self._open(slot, str(exc))

    def select_action(self, observation: dict) -> np.ndarray:
        return self.select_actions({0: observation})[0]

    def select_actions(self, observations: dict[int, dict]) -> dict[int, np.ndarray]:
        """Every slot's observation sent, then every answer read (a batching server sees them together)."""
        from vla_eval.protocol.messages import MessageType

        sent: dict[int, int] = {}
        answers: dict[int, Any] = {}
        for slot, obs in observations.items():
            connection = self.connections[slot]
            try:
                if connection is None:
                    raise _Lost("the connection was closed")
                sent[slot] = self._call(connection.send, MessageType.OBSERVATION, self.payload(slot, obs))
            except _Lost as exc:
                answers[slot] = exc
        for slot, seq in sent.items():
            try:
                answers[slot] = self._call(self.connections[slot].answer, seq)
            except _Lost as exc:
                answers[slot] = exc
        lost = [(slot, a) for slot, a in answers.items() if isinstance(a, _Lost)]
        if lost:
            raise [self._lose(slot, str(exc)) for slot, exc in lost][0]
        for answer in answers.values():
            if isinstance(answer, ServerError):
                self.failure_reason = str(answer)
                raise answer
        for slot in observations:
            self.steps[slot] += 1
        return {slot: self.agreed.env_action(answers[slot]) for slot in observations}

    def payload(self, slot: int, observation: dict) -> dict:
        """An OBSERVATION: images by the server's camera names, the instruction, the negotiated state."""
        payload: dict[str, Any] = {
            "task_description": self.episodes[slot].instruction if self.episodes[slot] else "",
        }
        # Images only on the steps that run the server's model (every step unless --policy.images_every says
        # the chunk size): the other steps are answered from its chunk buffer and their cameras never render.
        if self.steps[slot] % self.config.images_every == 0:
            payload["images"] = {
                wire: observation[IMAGE_KEY.format(cam)] for wire, cam in self.agreed.cameras
            }
        if self.agreed.state_key is not None:
            payload["states"] = payload["state"] = self.agreed.state(observation)
        return payload

    def episode_record(self) -> dict:
        return {}

    def close(self) -> None:
        from vla_eval.protocol.messages import MessageType

        for slot, connection in enumerate(self.connections):
            if connection is None:
                continue
            try:
                if self.episodes[slot] is not None:
                    connection.send(MessageType.EPISODE_END, {"steps": self.steps[slot]})
            except Exception:  # the server is gone: nothing to tell it
                pass
            connection.close()
            self.connections[slot] = None


def start_payload(episode: Episode) -> dict:
    """EPISODE_START: the task dict vla-eval's runners send (`name` is the instruction, as LIBERO's), with
    RoboView's task name and the episode seed."""
    return {
        "task": {
            "name": episode.instruction,
            "instruction": episode.instruction,
            "task": episode.task,
            "seed": episode.seed,
            "image_size": episode.image_size,
        }
    }


def _pairs(text: str, flag: str) -> dict[str, str]:
    out = {}
    for item in filter(None, (x.strip() for x in text.split(","))):
        key, sep, value = item.partition("=")
        if not sep or not key.strip() or value.strip() not in camera_names():
            raise ValueError(
                f"{flag} entry {item!r} must be SERVER_CAMERA=CAMERA with CAMERA one of {', '.join(camera_names())}"
            )
        out[key.strip()] = value.strip()
    return out


@PolicyConfig.register_subclass("vla_eval")
@dataclass
class VlaEvalConfig(PolicyConfig, WebsocketServed):
    """A policy behind a vla-eval model server (`vla_eval.model_servers`: LeRobot, π0, OpenVLA, GR00T, …)."""

    # ws://HOST:PORT of the server; a comma-separated list spreads workers over several (worker i → entry i mod n).
    url: str = ""
    # Cameras sent for a server that asks for a generic `image` (LeRobot's server), scene cameras first.
    cameras: str = "left_top,wrist"
    # The server's camera names mapped onto RoboView's, e.g. agentview=left_top,wrist=wrist (for servers that
    # declare named cameras RoboView does not have).
    camera_map: str = ""
    # Side of the square images sent (rendered at that size, not resized here; the server may resize). 0: 256 when a
    # LIBERO scene camera is sent (vla-eval's LIBERO benchmark renders 256²), else 224.
    image_size: int = 0
    # The env control for a server whose action spec is `raw` (LeRobot's server: the checkpoint decides): joint,
    # ee_delta or ee_abs; empty: joint. For other servers it must agree with their spec (empty: follow it).
    control: str = ""
    # How images travel: raw bytes, png (lossless, vla-eval's default) or jpeg (lossy).
    image_format: str = "png"
    # Send images on steps 0, N, 2N, … of an episode only. Set N to the server's chunk size (a LeRobot checkpoint's
    # n_action_steps) for a server without action ensembling: it answers the steps between model calls from its
    # chunk buffer without reading them, so those steps render no camera. 1: every step (a server that runs its
    # model on a step without images answers an error, which fails the episode with its message).
    images_every: int = 1

    doc = "any vla-eval model server (--policy.url=ws://HOST:PORT)"
    row_name = "vla_eval:*"  # vla_eval:<the model server's name, from its HELLO>
    reproducible = False  # the episode seed does not reach the server's randomness

    def __post_init__(self) -> None:
        self.check_url_and_cameras("the vla-eval model server")
        camera_map = _pairs(self.camera_map, "--policy.camera_map")
        control_field(self)
        if self.image_format not in IMAGE_FORMATS:
            raise ValueError(
                f"unknown --policy.image_format={self.image_format!r}; allowed: {', '.join(IMAGE_FORMATS)}"
            )
        if self.images_every < 1:
            raise ValueError(f"--policy.images_every={self.images_every} must be 1 or more (1: every step)")
        self.check_connection()
        if self.image_size < 0:
            raise ValueError(
                f"--policy.image_size={self.image_size} must be 0 (the world's own side: 256 for LIBERO, else 224) or positive"
            )
        # Every server is reached and negotiated here, before any rollout; all must agree.
        self._hello: dict[str, dict] = {}
        agreed = None
        for url in self.url_list:
            try:
                connection = ServerConnection(url, self.open_timeout_s, self.timeout_s, self.image_format)
            except WrongProtocol as exc:
                raise ValueError(f"--policy.url={url}: {exc}") from None
            except Exception as exc:
                raise ValueError(
                    f"cannot reach the vla-eval server at --policy.url={url} ({type(exc).__name__}: {exc}); "
                    "is it running, and is the port right?"
                ) from None
            connection.close()
            self._hello[url] = connection.hello
            mine = negotiate(connection.hello, self.camera_list, camera_map, self.control)
            if agreed is not None and mine != agreed:
                raise ValueError(
                    f"--policy.url: {url} declares other specs than {self.url_list[0]}: {mine} vs {agreed}"
                )
            agreed = mine
        self._agreed: Negotiated = agreed
        self._camera_map = camera_map
        super().__post_init__()

    def settle_control(self, controls: tuple[str, ...]) -> None:
        """A server whose action spec leaves the control open (`raw`: LeRobot's server) and no --policy.control:
        the world's only control (Meta-World's xyz_delta, LIBERO's ee_delta), renegotiated with it."""
        if self.control or self._agreed.gripper != "raw" or len(controls) != 1:
            return
        hello = self._hello[self.url_list[0]]
        self._agreed = negotiate(hello, self.camera_list, self._camera_map, controls[0])

    @property
    def negotiated(self) -> Negotiated:
        return self._agreed

    def declares_outputs(self) -> bool:
        return self._agreed.gripper != "raw"  # a `raw` action spec (LeRobot's server): the checkpoint decides

    def server_name(self, url: str) -> str:
        return str(self._hello.get(url, {}).get("model_server", "server"))

    def env_control(self) -> str:
        """The env control the server's actions are in (negotiated from its HELLO)."""
        return self._agreed.control

    def served_by(self) -> dict:
        return {
            "protocol": "vla_eval",
            "urls": self.url_list,
            "control": self._agreed.control,
            "cameras": dict(self._agreed.cameras),
            "state": self._agreed.state_key,
            "hello": json.loads(json.dumps(self._hello, default=str)),  # JSON-safe for provenance.json
        }

    def observed_cameras(self) -> tuple[str, ...]:
        return self._agreed.observed_cameras

    def input_image_size(self) -> int | None:
        if self.image_size:
            return self.image_size
        return native_render_size(self.observed_cameras()) or DEFAULT_IMAGE_SIZE

    def options(self) -> dict[str, Any]:
        # The URL is where the policy lives, not what it is: a resume may point at a restarted server.
        return {k: v for k, v in super().options().items() if k != "url"}

    def _check(self, view: AgentView | None) -> None:
        dims = view.action_space.shape[0] if view is not None else self._agreed.action_dims
        if dims != self._agreed.action_dims:
            raise ValueError(
                f"the vla-eval server acts in {self._agreed.control} control ({self._agreed.action_dims} values) but "
                f"the env takes {dims}: make the env with control={self._agreed.control!r}"
            )

    def build(self, view: AgentView) -> VlaEvalPolicy:
        self._check(view)
        return VlaEvalPolicy(self, self._agreed)

    def build_batched(self, view: AgentView, slots: int) -> VlaEvalPolicy:
        self._check(view)
        return VlaEvalPolicy(self, self._agreed, slots)
