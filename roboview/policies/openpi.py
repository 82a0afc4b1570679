"""A policy served over openpi's websocket protocol: π0 / π0.5 / π0-FAST in openpi, or any server that speaks it.

    roboview-evaluate --benchmark.path=outputs/benchmark --policy.type=openpi \\
        --policy.url=ws://gpu-host:8000 --policy.obs_format=droid --policy.cameras=left_top,wrist \\
        --policy.image_size=224 --output_dir=outputs/eval/pi05

The protocol (openpi's `WebsocketPolicyServer` / `WebsocketClientPolicy`): on connect the server sends one
msgpack frame of metadata; each request is one observation dict (msgpack, arrays as openpi-client's
`msgpack_numpy` encodes them), each answer `{"actions": (H, D), ...}`; a server error is a text frame with
the traceback, then close code 1011. There is no reset message: a new episode is a new instruction.

The wire codec is openpi-client's own (`openpi_client.msgpack_numpy`); the connection is the same
`websockets` call its `WebsocketClientPolicy` makes, with what that class lacks for a benchmark run: an
open and a receive timeout, and bounded reconnects.

**Observation layouts** (`--policy.obs_format`), RoboView's robot being DROID's (Franka Panda + Robotiq
2F-85, joint positions):

    droid   observation/exterior_image_1_left (first scene camera), observation/exterior_image_2_left
            (second, if any), observation/wrist_image_left (wrist), observation/joint_position (7),
            observation/gripper_position (1; 0 open … 1 closed), prompt
    libero  observation/image, observation/wrist_image, observation/state (8), prompt — on LIBERO's scenes what
            openpi's LIBERO example sends a `pi05_libero` server: agentview and the wrist camera rendered at 256,
            flipped upright, brought to --policy.image_size by openpi-client's resize_with_pad, and LIBERO's 8-d
            EEF state; on RoboView's scene the joints + gripper
    aloha   images: {cam_high, cam_low, cam_left_wrist} (3×H×W), state (8), prompt
    custom  --policy.key_map='wire_key=SOURCE,…' with SOURCE one of camera:NAME (H×W×3 uint8),
            camera_chw:NAME (3×H×W), depth:NAME (H×W float32, metres), state[i:j] (float32),
            instruction

Images are rendered at `--policy.image_size` unless `--policy.render_size` names another side, in which case
openpi-client's `resize_with_pad` brings them to `--policy.image_size` (LIBERO's cameras default to 256, as openpi's
LIBERO example renders them). On RoboView's scene the LIBERO and ALOHA layouts are for servers fine-tuned on
RoboView data with those keys (RoboView's robot is neither LIBERO's nor ALOHA's). **A served policy's randomness lives on the server**: the episode seed does not
reach it, so a stochastic server policy is not reproducible from RoboView's seeds.

Failures: a server that is down fails before any rollout, naming the URL. During a run, an error frame
or a chunk of the wrong shape fails that episode with the reason (the policy's failure); a connection that
drops is reopened (`--policy.reconnects` times) and the episode in flight ends with an `InfraError` (recorded
as `infra_error`, counted in no rate, and re-run: the restarted server holds none of that episode's state); if
the server stays unreachable the run stops with `PolicyUnavailable` and rerunning the same command resumes it
(no episode is counted against the policy for it). An answer that does not come within `--policy.timeout_s`
is retried by the evaluator; one still missing after its retries is an infrastructure error too.
"""

from __future__ import annotations

import collections
import logging
import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from roboview.core.workers import worker_rank
from roboview.policies.base import (
    AgentView,
    ControlledConfig,
    Episode,
    PolicyConfig,
    WebsocketServed,
    control_field,
)
from roboview.policies.errors import InfraError, open_with_retries
from roboview.policies.serving.handshake import (
    PROBE_S,
    WrongProtocol,
    hello_frame,
    is_vla_eval,
    vla_eval_server,
)
from roboview.policies.serving.openpi_wire import (
    ACTION_SPACES,
    EPISODE_KEY,
    GRIPPER_MODES,
    ROBOVIEW_KEY,
    ProtocolError,
    WireFormat,
    episode_message,
    wire_format,
)
from roboview.tasks.env import EE_STATE_KEY, STATE_KEY
from roboview.tasks.world import native_render_size

log = logging.getLogger(__name__)

# The connection


def _plain(value):
    """Metadata made JSON-safe for provenance.json (arrays as lists, bytes as their length)."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, bytes):
        return f"<{len(value)} bytes>"
    return value


class Connection:
    """One websocket to an openpi server: handshake metadata, request → answer, with timeouts."""

    def __init__(self, url: str, api_key: str | None, open_timeout_s: float, timeout_s: float) -> None:
        from openpi_client import msgpack_numpy
        from websockets.sync.client import connect

        self.url, self.timeout_s = url, timeout_s
        self._codec = msgpack_numpy
        self._packer = msgpack_numpy.Packer()
        headers = {"Authorization": f"Api-Key {api_key}"} if api_key else None

        def open_ws():
            return connect(
                url,
                compression=None,
                max_size=None,
                additional_headers=headers,
                open_timeout=open_timeout_s,
                close_timeout=1,
                legacy=True,
            )

        self.ws = open_ws()
        try:
            try:
                first = self.ws.recv(timeout=min(PROBE_S, open_timeout_s))
            except (
                TimeoutError
            ):  # no metadata yet: a slow openpi server, or a vla-eval one waiting for a HELLO
                self.ws.send(hello_frame())
                first = self.ws.recv(timeout=open_timeout_s)
                if is_vla_eval(first):
                    raise vla_eval_server(url) from None
                self.ws.close()  # metadata came late, and our HELLO went to the server: start afresh
                self.ws = open_ws()
                first = self.ws.recv(timeout=open_timeout_s)
            self.metadata = msgpack_numpy.unpackb(first)
        except Exception:
            self.ws.close()
            raise

    def infer(self, request: dict) -> dict:
        self.ws.send(self._packer.pack(request))
        answer = self.ws.recv(timeout=self.timeout_s)
        if isinstance(answer, str):  # openpi's servers send the traceback as text, then close (1011)
            last = [line for line in answer.strip().splitlines() if line.strip()]
            raise ProtocolError(f"server error: {last[-1] if last else answer}")
        return self._codec.unpackb(answer)

    def close(self) -> None:
        self.ws.close()


def connect(url: str, api_key_env: str, open_timeout_s: float, timeout_s: float) -> Connection:
    return Connection(url, os.environ.get(api_key_env) or None, open_timeout_s, timeout_s)


class Resized:
    """An observation whose images read resized to `side`² by openpi-client's `resize_with_pad` (what openpi's
    LIBERO example sends); everything else reads unchanged."""

    def __init__(self, observation, side: int) -> None:
        self.observation, self.side = observation, side

    def __getitem__(self, key: str):
        value = self.observation[key]
        if not key.startswith("observation.images."):
            return value
        from openpi_client.image_tools import resize_with_pad

        return resize_with_pad(np.asarray(value, np.uint8), self.side, self.side)


# ---------------------------------------------------------------------------------------------------------------
# The policy


class OpenPIPolicy:
    """One worker's client: it keeps the action chunk, and asks the server when `replan_steps` are used."""

    def __init__(self, config: OpenPIConfig, view: AgentView) -> None:
        self.config = config
        urls = config.url_list
        self.url = urls[worker_rank() % len(urls)]
        self.format = config.wire_format()
        # Rendered at another side than the wire's: resized as openpi's LIBERO example does.
        self.resize = config.image_size if config.render_side != config.image_size else 0
        self.dt = 1.0 / view.fps
        self.joint = config.env_control() == "joint"
        # What the model reads as its state and answers: joints, or (end-effector control) the EE state and pose.
        self.state_key = STATE_KEY if self.joint else EE_STATE_KEY
        self.action_dims = int(view.action_space.shape[0])  # the env's action: 8 joint, 7 EE, 4 Meta-World
        self.name = f"openpi:{config.obs_format}"
        self.failure_reason = ""
        self.queue: collections.deque = collections.deque()
        self.instruction = ""
        self.pending_episode: dict | None = None
        self.requests = 0
        self.conn: Connection | None = None
        self._connect()

    def _connect(self) -> None:
        """Open the connection, trying `reconnects` more times; if it cannot be opened the server is down."""
        cfg = self.config
        self.conn = open_with_retries(
            lambda: connect(self.url, cfg.api_key_env, cfg.open_timeout_s, cfg.timeout_s),
            f"openpi server {self.url}",
            cfg.reconnects,
            cfg.reconnect_backoff_s,
        )

    def reset(self, episode: Episode) -> None:
        self.queue.clear()
        self.instruction = episode.instruction
        self.failure_reason = ""
        if self.conn is not None and ROBOVIEW_KEY in self.conn.metadata:
            self.pending_episode = episode_message(episode)

    def _request(self, observation: dict) -> np.ndarray:
        from websockets.exceptions import ConnectionClosed

        if self.conn is None:
            self._connect()
        if self.resize:
            observation = Resized(observation, self.resize)
        request = self.format.encode(observation, self.instruction, self.state_key)
        if self.pending_episode is not None:
            request[EPISODE_KEY] = self.pending_episode
        try:
            answer = self.conn.infer(request)
        except ProtocolError:
            self.conn.close()  # the server closes after an error frame; the next request reconnects
            self.conn = None
            raise
        except TimeoutError as exc:  # an answer may still come: a fresh connection keeps requests in order
            self.conn.close()
            self.conn = None
            raise TimeoutError(
                f"openpi server {self.url} did not answer within {self.config.timeout_s:g} s"
            ) from exc
        except (ConnectionClosed, OSError) as exc:
            self.conn = None
            self.queue.clear()
            self._connect()  # PolicyUnavailable (the run stops) if the server stays away
            raise InfraError(
                f"lost the openpi server {self.url} mid-episode: it closed the connection ({exc}); "
                "reconnected, so only this episode is lost (it runs again)"
            ) from None
        self.pending_episode = None
        self.requests += 1
        return self._chunk(answer)

    def _chunk(self, answer) -> np.ndarray:
        actions = answer.get("actions") if isinstance(answer, dict) else None
        if actions is None:
            keys = sorted(answer) if isinstance(answer, dict) else type(answer).__name__
            raise ProtocolError(f"openpi server {self.url} answered without 'actions' (got {keys})")
        chunk = np.asarray(actions, np.float32)
        if chunk.ndim == 1:
            chunk = chunk[None]
        if (
            chunk.ndim != 2
            or chunk.shape[0] < 1
            or chunk.shape[1] != self.action_dims
            or not np.isfinite(chunk).all()
        ):
            meaning = (
                f"7 joint {self.config.action_space}s + gripper"
                if self.joint
                else f"{self.config.env_control()} end-effector pose + gripper"
            )
            raise ProtocolError(
                f"openpi server {self.url} answered actions of shape {np.shape(actions)}; RoboView "
                f"takes (H, {self.action_dims}) finite values: {meaning}"
            )
        steps = self.config.replan_steps or len(chunk)
        return chunk[:steps]

    def select_action(self, observation: dict) -> np.ndarray:
        if not self.queue:
            self.queue.extend(self._request(observation))
        action = self.queue.popleft().copy()
        if self.config.action_space == "joint_velocity":  # rad/s, integrated over one control period
            action[:7] = np.asarray(observation[STATE_KEY], np.float32)[:7] + action[:7] * self.dt
        if self.config.gripper == "binary":  # joint: 0 open … 1 closed; EE: −1 open … +1 close
            if self.joint:
                action[7] = 1.0 if action[7] > 0.5 else 0.0
            else:
                action[6] = 1.0 if action[6] > 0.0 else -1.0
        return action

    def episode_record(self) -> dict:
        return {}

    def close(self) -> None:
        if self.conn is not None:
            self.conn.close()
            self.conn = None


@PolicyConfig.register_subclass("openpi")
@dataclass
class OpenPIConfig(ControlledConfig, WebsocketServed):
    """A policy behind openpi's websocket protocol (openpi's serve_policy.py, roboview.pipelines.serve_policy, …)."""

    # ws://HOST:PORT of the server; a comma-separated list spreads workers over several (worker i → entry i mod n).
    url: str = ""
    # Observation layout on the wire: droid, libero, aloha, or custom (with --policy.key_map).
    obs_format: str = "droid"
    # custom layout: comma-separated wire_key=SOURCE, SOURCE = camera:NAME, camera_chw:NAME, depth:NAME,
    # state, state[i:j] or instruction.
    key_map: str = ""
    # Cameras to render and send, scene cameras first (front, left_top, right_top; wrist).
    cameras: str = "left_top,wrist"
    # Side of the square images sent.
    image_size: int = 224
    # Side the cameras render at, when it is not image_size: the images are brought to image_size by openpi-client's
    # resize_with_pad. 0: image_size, except LIBERO's cameras (agentview, image, wrist with them), which render at
    # 256 as openpi's LIBERO example renders them.
    render_size: int = 0
    # Also send each camera's depth (roboview/depth/<camera>, metres; for servers of RoboView's depth policies).
    send_depth: bool = False
    # Actions used from each chunk before asking again; 0: the whole chunk (openpi's LIBERO example uses 5, DROID 8).
    replan_steps: int = 0
    # What the server's actions are with --policy.control=joint: joint_position (targets, RoboView's action) or
    # joint_velocity (rad/s, integrated at the control rate from the observed joints). With an end-effector
    # control the model reads the EE state as its state and answers 7-d EE actions.
    action_space: str = "joint_position"
    # Gripper action: continuous (as sent; the env clips it to 0 open … 1 closed, or −1 … +1 in EE controls) or
    # binary (closed above 0.5; in EE controls above 0).
    gripper: str = "continuous"
    # Name of the environment variable holding the API key (sent as `Authorization: Api-Key …`; never recorded).
    api_key_env: str = "OPENPI_API_KEY"

    doc = "a policy served over openpi's websocket protocol (--policy.url=ws://HOST:PORT)"
    row_name = "openpi:{obs_format}"
    reproducible = False  # the episode seed does not reach the server's randomness

    def __post_init__(self) -> None:
        control_field(self)
        self.check_url_and_cameras("the openpi server")
        for name, value, allowed in (
            ("action_space", self.action_space, ACTION_SPACES),
            ("gripper", self.gripper, GRIPPER_MODES),
        ):
            if value not in allowed:
                raise ValueError(f"unknown --policy.{name}={value!r}; allowed: {', '.join(allowed)}")
        if self.control not in ("", "joint") and self.action_space != "joint_position":
            raise ValueError(
                f"--policy.action_space={self.action_space!r} is a joint action; with --policy.control="
                f"{self.control} the server answers end-effector actions (leave --policy.action_space unset)"
            )
        self.check_connection()
        for name in ("image_size", "render_size"):
            if getattr(self, name) < (name == "image_size"):
                raise ValueError(f"--policy.{name}={getattr(self, name)} must be positive")
        for name in ("replan_steps",):
            if getattr(self, name) < 0:
                raise ValueError(f"--policy.{name}={getattr(self, name)} must be ≥ 0")
        fmt = self.wire_format()  # validates obs_format / key_map against the cameras
        missing = [c for c in fmt.cameras if c not in self.camera_list]
        if missing:
            raise ValueError(
                f"--policy.key_map reads camera(s) {missing} not in --policy.cameras={self.cameras}"
            )
        # A server that is down fails here, before any rollout; its metadata goes into provenance.json.
        self._metadata = {}
        for url in self.url_list:
            try:
                conn = connect(url, self.api_key_env, self.open_timeout_s, self.timeout_s)
            except WrongProtocol as exc:
                raise ValueError(f"--policy.url={url}: {exc}") from None
            except Exception as exc:
                raise ValueError(
                    f"cannot reach the openpi server at --policy.url={url} ({type(exc).__name__}: "
                    f"{exc}); is it running, and is the port right?"
                ) from None
            self._metadata[url] = _plain(conn.metadata)
            conn.close()
        super().__post_init__()

    def declares_outputs(self) -> bool:
        return False  # openpi's metadata is free-form: the action chunk's width shows at the first answer

    @property
    def depth(self) -> bool:  # type: ignore[override]
        return self.send_depth

    def wire_format(self) -> WireFormat:
        return wire_format(self.obs_format, self.camera_list, self.key_map, self.send_depth)

    def served_by(self) -> dict:
        return {
            "protocol": "openpi",
            "urls": self.url_list,
            "obs_format": self.obs_format,
            "metadata": getattr(self, "_metadata", {}),
        }

    def observed_cameras(self) -> tuple[str, ...]:
        return self.camera_list

    @property
    def render_side(self) -> int:
        """The side the env renders the cameras at (then resized to image_size when it differs)."""
        if self.render_size:
            return self.render_size
        # A world's own cameras in the openpi layout of that world render at its harnesses' side (LIBERO's 256).
        native = native_render_size(self.camera_list) if self.obs_format == "libero" else 0
        return native or self.image_size

    def input_image_size(self) -> int | None:
        return self.render_side

    def options(self) -> dict[str, Any]:
        # The URL is where the policy lives, not what it is: a resume may point at a restarted server.
        return {k: v for k, v in super().options().items() if k != "url"}

    def build(self, view: AgentView) -> OpenPIPolicy:
        return OpenPIPolicy(self, view)
