"""A LeRobot checkpoint served by LeRobot's own async inference server (`--policy.type=lerobot_async`).

    python -m lerobot.async_inference.policy_server --host=0.0.0.0 --port=8080 --fps=10 \
        --inference_latency=0 --obs_queue_timeout=2                       # on the GPU machine
    roboview-evaluate --policy.type=lerobot_async --policy.server=gpu-box:8080 \
        --policy.path=outputs/train/checkpoints/last/pretrained_model --policy.device=cuda ...

The client speaks LeRobot's protocol with LeRobot's own pieces (the gRPC stubs of
`lerobot.transport`, `RemotePolicyConfig` / `TimedObservation` / `TimedAction` of
`lerobot.async_inference.helpers`, `send_bytes_in_chunks`), never a reimplementation of it:
`Ready`, then `SendPolicyInstructions` (the server loads the checkpoint), then per chunk one
`SendObservations` (the observation, `must_go=True`: without it the server drops observations whose
joint state moved less than 1 in L2, LeRobot issue #1500) and one `GetActions` (the chunk, waited for
with `--policy.timeout_s`). The action queue is kept here: a chunk is asked for only when the queue
is empty, then popped one action per step; that is what the in-process `lerobot` type does for a
chunked checkpoint, and the observation is mapped so that the model sees the same tensors: the
raw observation is `{joint name: value, camera: HxWx3 uint8, "task": instruction}`, which the server
turns (`raw_observation_to_observation`) into the same `observation.state` / `observation.images.<cam>`
batch keys as `roboview.policies.lerobot_policy` builds (uint8 → float32 / 255, channels first; its bilinear
resize is the identity, since the env renders the checkpoint's own image size). Actions come back
post-processed (unnormalized) by the checkpoint's own post-processor, as in-process.

Resetting the server's policy state between episodes — what was found (LeRobot 0.6.1):
  * The protocol has no reset message, and the server never calls `policy.reset()`. `Ready` only
    flushes the server's observation queue. Re-sending `SendPolicyInstructions` re-creates the policy,
    but that is a full `from_pretrained` plus pre/post-processors (measured on loopback, CPU, with `Ready`:
    0.17–0.43 s, median ≈ 0.2 s, for the 62 MB ACT test checkpoint, i.e. 6–7 chunk round trips; seconds to
    minutes for a multi-GB VLA) — too dear per episode, and it would not reseed the server's random
    generator either.
  * It is not needed: the server only ever calls `predict_action_chunk`, never `select_action`, so none
    of lerobot's per-episode queues (action queue, observation history, temporal ensembler) is used.
    For the chunked types served here (act, pi0, pi05, smolvla without temporal ensembling: the
    in-process type's CHUNKED_TYPES that the server supports) `predict_action_chunk` is a function
    of the observation alone (smolvla appends to an observation queue it never reads back), so each
    chunk is independent of earlier episodes. `reset` therefore clears only the client-side queue.
    Other types are refused: their in-process evaluation reads per-step state (diffusion's observation
    history, ACT's temporal ensembling) that the served `predict_action_chunk` never sees.
  * Randomness: the server's torch generator is not seeded per episode (the in-process type seeds it
    with the episode seed). ACT draws nothing at inference, so its rows are reproducible and equal to
    the in-process type's; flow-matching VLAs (pi0, pi05, smolvla) draw their noise from the server's
    unseeded generator: their rows vary between runs.

One client per server (the server keeps one observation queue): with `--policy.server=A,B,…` worker i
talks to entry `i mod n`, so give at least `--eval.num_workers` servers. Envs stepped in lockstep
(`--eval.envs_per_worker`) share their worker's connection, one round trip per slot whose queue ran dry.
A server found shared (a chunk answering another client's observation) stops the run.

Failures: the server must answer `Ready` when the config is built (before any rollout), else the
error names HOST:PORT. A connection lost mid-episode is retried up to `--policy.reconnects`
times (`Ready` + `SendPolicyInstructions`, each attempt on a fresh channel); if that works the episode in
flight ends with an `InfraError` (recorded as `infra_error`, counted in no rate, and re-run), if not
`PolicyUnavailable` stops the run (that episode is not written) and says to rerun the same command to resume.
A server that answers with no chunk (a restarted server without a policy, an inference error: the server
logs it and answers empty) gets the policy instructions and the observation once more, then the episode
fails (the policy's failure).

LeRobot's messages are pickles both ways: point the client only at a server you trust.
"""

from __future__ import annotations

import collections
import logging
import pickle  # nosec: LeRobot's protocol pickles its messages; we only talk to a server we were pointed at
import random
import re
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from roboview.core.cli_errors import flag_errors
from roboview.core.workers import worker_rank
from roboview.policies.base import (
    DEFAULT_CAMERAS,
    AgentView,
    ControlledConfig,
    Episode,
    PolicyConfig,
    ServedConnection,
    control_field,
)
from roboview.policies.errors import InfraError, PolicyUnavailable, open_with_retries
from roboview.policies.lerobot_async_checkpoint import ServedCheckpoint, resolve_checkpoint
from roboview.policies.lerobot_async_connection import (
    ConnectionLost,
    check_reachable,
    chunk_error,
    open_channel,
    parse_servers,
    rpc_reason,
    start_server_hint,
)
from roboview.tasks.env import EE_STATE_KEY, EE_STATE_NAMES, IMAGE_KEY, STATE_KEY, STATE_NAMES

log = logging.getLogger(__name__)

SERVER_DEVICE = re.compile(r"^(cpu|mps|cuda(:\d+)?)$")


@dataclass(frozen=True)
class _Spec:
    """What a client sends and needs, resolved from the config (picklable: it travels to workers)."""

    address: str
    policy_type: str
    path: str  # as sent to the server
    device: str
    actions_per_chunk: int
    cameras: tuple[str, ...]
    image_size: int
    open_timeout_s: float
    timeout_s: float
    load_timeout_s: float
    reconnects: int
    reconnect_backoff_s: float
    control: str = "joint"

    @property
    def state(self) -> tuple[str, tuple[str, ...]]:
        """The observation key the state is read from and its entries' names (joint, or the EE state)."""
        return (STATE_KEY, STATE_NAMES) if self.control == "joint" else (EE_STATE_KEY, EE_STATE_NAMES)


class LeRobotAsyncPolicy:
    """A client of one LeRobot policy server, driving one env or `slots` envs in lockstep.

    Each slot keeps its own instruction and action queue; a slot whose queue is empty gets its chunk
    through one SendObservations + GetActions round trip (slots one after the other: the server answers
    one observation at a time).
    """

    failure_reason = ""

    def __init__(self, spec: _Spec, slots: int = 1) -> None:
        from lerobot.utils.feature_utils import hw_to_dataset_features

        self.spec = spec
        self.name = f"lerobot:{spec.policy_type}"
        self.slots = slots
        self.tasks = [""] * slots
        self.queues: list[collections.deque] = [collections.deque() for _ in range(slots)]
        # The raw observation's features, as a LeRobot robot client describes its robot: one float per
        # joint (→ observation.state in STATE_NAMES order; EE_STATE_NAMES in an end-effector control) and one
        # HxWx3 image per camera.
        side = spec.image_size
        hw = {name: float for name in spec.state[1]} | {cam: (side, side, 3) for cam in spec.cameras}
        self.features = hw_to_dataset_features(hw, "observation", use_video=False)
        self.round_trips = 0  # chunks asked for (observations sent)
        self.round_trip_s = 0.0
        # Timesteps this client stamps on its observations: a random base, so a chunk answering another
        # client's observation (a shared server) is recognised.
        self._timestep = random.SystemRandom().randrange(1 << 40) * 1000
        self._channel = self._stub = None
        self.connected = False

    # -- connection ---------------------------------------------------------------------------------
    def _load(self) -> None:
        """Ready + SendPolicyInstructions; ConnectionLost if unreachable, PolicyUnavailable if the server
        cannot load the policy."""
        import grpc
        from lerobot.async_inference.helpers import RemotePolicyConfig
        from lerobot.transport import services_pb2

        s = self.spec
        if self._channel is None:
            self._channel, self._stub = open_channel(s.address)
        instructions = RemotePolicyConfig(
            policy_type=s.policy_type,
            pretrained_name_or_path=s.path,
            lerobot_features=self.features,
            actions_per_chunk=s.actions_per_chunk,
            device=s.device,
        )
        try:
            self._stub.Ready(services_pb2.Empty(), timeout=s.open_timeout_s)
            start = time.perf_counter()
            self._stub.SendPolicyInstructions(
                services_pb2.PolicySetup(data=pickle.dumps(instructions)), timeout=s.load_timeout_s
            )
        except grpc.RpcError as exc:
            if exc.code() in (
                grpc.StatusCode.UNAVAILABLE,
                grpc.StatusCode.CANCELLED,
                grpc.StatusCode.DEADLINE_EXCEEDED,
            ):
                raise ConnectionLost(rpc_reason(exc)) from exc
            raise PolicyUnavailable(
                f"the LeRobot policy server at {s.address} could not load {s.policy_type} checkpoint {s.path!r} on "
                f"{s.device} ({rpc_reason(exc)}; its log has the traceback); fix that and rerun the same command "
                "to resume (finished episodes are kept)"
            ) from None
        log.info("policy server %s loaded %s in %.2f s", s.address, s.path, time.perf_counter() - start)
        self.connected = True

    def _connect(self, lost: str = "") -> None:
        """(Re)connect with up to `reconnects` retries, each on a fresh channel; PolicyUnavailable if the server
        stays away (open_with_retries, the served policies' one retry loop)."""
        attempts = []

        def load() -> None:
            if attempts:
                self._drop_channel()
            attempts.append(1)
            self._load()

        try:
            open_with_retries(
                load,
                f"the LeRobot policy server at {self.spec.address}",
                self.spec.reconnects,
                self.spec.reconnect_backoff_s,
                lost,
                retry_on=(ConnectionLost,),
                flag="--policy.server",
            )
        except PolicyUnavailable as exc:
            self.connected = False
            raise PolicyUnavailable(f"{exc}; {start_server_hint(self.spec.address)}") from None

    # -- the policy protocol ------------------------------------------------------------------------
    def reset(self, episode: Episode, slot: int = 0) -> None:
        # No server-side reset exists or is needed (module docstring): the chunk queue is ours.
        self.queues[slot].clear()
        self.tasks[slot] = episode.instruction
        if not self.connected:
            self._connect()

    def select_action(self, observation: dict) -> np.ndarray:
        return self.select_actions({0: observation})[0]

    def select_actions(self, observations: dict[int, dict]) -> dict[int, np.ndarray]:
        if not self.connected:
            self._connect()
        for slot, observation in observations.items():
            if not self.queues[slot]:
                try:
                    self.queues[slot].extend(self._chunk(observation, self.tasks[slot]))
                except ConnectionLost as exc:
                    self.connected = False
                    self._drop_channel()
                    self._connect(str(exc))  # PolicyUnavailable (the run stops) if the server stays away
                    raise InfraError(
                        f"lost the LeRobot policy server at {self.spec.address} mid-episode ({exc}); "
                        "reconnected, so only this episode is lost (it runs again)"
                    ) from None
        return {slot: self.queues[slot].popleft() for slot in observations}

    def raw_observation(self, observation: dict, task: str) -> dict[str, Any]:
        """What a LeRobot robot client sends: joint (or EE state) values by name, images by camera name, the task."""
        key, names = self.spec.state
        state = observation[key]
        raw: dict[str, Any] = {name: float(state[i]) for i, name in enumerate(names)}
        raw |= {cam: np.ascontiguousarray(observation[IMAGE_KEY.format(cam)]) for cam in self.spec.cameras}
        raw["task"] = task
        return raw

    def _chunk(self, observation: dict, task: str) -> list[np.ndarray]:
        """One chunk for `observation`: SendObservations (must_go) then GetActions, the latter waited for."""
        import grpc
        from lerobot.async_inference.helpers import TimedObservation
        from lerobot.transport import services_pb2
        from lerobot.transport.utils import send_bytes_in_chunks

        s = self.spec
        start = time.perf_counter()
        raw = self.raw_observation(observation, task)
        for attempt in range(2):
            self._timestep += 1
            sent = TimedObservation(
                timestamp=time.time(), timestep=self._timestep, observation=raw, must_go=True
            )
            deadline = time.monotonic() + s.timeout_s
            try:
                self._stub.SendObservations(
                    send_bytes_in_chunks(pickle.dumps(sent), services_pb2.Observation), timeout=s.timeout_s
                )
                reply = self._stub.GetActions(
                    services_pb2.Empty(), timeout=max(0.1, deadline - time.monotonic())
                )
            except grpc.RpcError as exc:
                error = chunk_error(exc, s.address, s.timeout_s)
                raise error from (exc if isinstance(error, ConnectionLost) else None)
            if reply.data:
                break
            if attempt == 0:  # a restarted server has no policy; an inference error also answers empty
                log.warning(
                    "policy server %s sent no actions for observation #%d; sending the policy and the "
                    "observation once more",
                    s.address,
                    sent.timestep,
                )
                self._load()
        else:
            raise RuntimeError(
                f"the LeRobot policy server at {s.address} sent no actions for the observation twice "
                "(an inference error: its log says which)"
            )
        actions = pickle.loads(reply.data)  # nosec: list[TimedAction] from the server we were pointed at
        if not actions or actions[0].get_timestep() != sent.timestep:
            got = actions[0].get_timestep() if actions else None
            raise PolicyUnavailable(
                f"the LeRobot policy server at {s.address} answered another client's observation (#{got}, ours "
                f"#{sent.timestep}): it serves one client at a time. Give every worker its own server "
                "(--policy.server=HOST:PORT,HOST:PORT,… with at least --eval.num_workers entries; envs_per_worker "
                "share their worker's) and rerun the same command to resume"
            )
        self.round_trips += 1
        self.round_trip_s += time.perf_counter() - start
        return [np.asarray(a.get_action().numpy(), dtype=np.float32) for a in actions]

    def _drop_channel(self) -> None:
        """Close the channel; the next call opens a fresh one (a channel whose server went away would first wait
        out its own reconnect backoff, seconds after the server is back)."""
        if self._channel is not None:
            self._channel.close()
            self._channel = self._stub = None

    def close(self) -> None:
        self._drop_channel()
        self.connected = False


@PolicyConfig.register_subclass("lerobot_async")
@dataclass
class LeRobotAsyncConfig(ControlledConfig, ServedConnection):
    """A LeRobot checkpoint served by `python -m lerobot.async_inference.policy_server` (gRPC)."""

    # The server: HOST:PORT, or a comma-separated list (worker i talks to entry i mod n; one client per server).
    server: str = "127.0.0.1:8080"
    # The checkpoint as the server loads it (a folder on the server's machine or a hub id ORG/NAME). When it is
    # also a folder here, its cameras, image size, type and chunk length are read from it (and its absolute
    # path is sent); otherwise give cameras, image_size, policy_type and actions_per_chunk.
    path: str | None = None
    # The server's device: cpu, cuda (cuda:N) or mps.
    device: str = "cpu"
    # Actions the server returns per chunk (all of them are played); 0: the checkpoint's n_action_steps.
    actions_per_chunk: int = 0
    # For a checkpoint not readable here: its policy type (act, pi0, pi05, smolvla); empty: read from the checkpoint.
    policy_type: str = ""
    # For a checkpoint not readable here: its cameras, comma-separated (e.g. left_top,wrist); empty: read from the
    # checkpoint.
    cameras: str = ""
    # For a checkpoint not readable here: its image side (pixels); 0: read from the checkpoint.
    image_size: int = 0
    # Seconds the server may take to load the checkpoint (SendPolicyInstructions).
    load_timeout_s: float = 600.0

    doc = "a LeRobot checkpoint served by lerobot.async_inference.policy_server (--policy.server=HOST:PORT)"
    row_name = "lerobot:*"  # lerobot:<the checkpoint's policy type>
    reproducible = False  # the episode seed does not reach the server's randomness

    def __post_init__(self) -> None:
        control_field(self)
        with flag_errors(f"--policy.server={self.server!r}"):
            servers = parse_servers(self.server)
        with flag_errors(f"--policy.device={self.device!r}"):
            if not SERVER_DEVICE.match(self.device):
                raise ValueError("the server's device must be cpu, cuda, cuda:N or mps")
        self.check_connection()
        for name in ("load_timeout_s",):
            if not getattr(self, name) > 0:
                raise ValueError(f"--policy.{name}={getattr(self, name)} must be positive")
        for name in ("actions_per_chunk", "image_size"):
            if getattr(self, name) < 0:
                raise ValueError(f"--policy.{name}={getattr(self, name)} must be ≥ 0")
        self._resolve()  # the checkpoint's facts, before any connection
        if self.local:
            self._check_control()
        for server in servers:  # reachable before any rollout
            with flag_errors("--policy.server"):
                check_reachable(server, self.open_timeout_s)
        super().__post_init__()

    def _check_control(self) -> None:
        """A checkpoint readable here acts in the control --policy.control names (its action width and its
        dataset's action names), else the run stops naming the flag: the served action would not fit the env."""
        from roboview.policies.lerobot_policy import checkpoint_control, refuse_control

        with flag_errors("--policy.path"):
            found = checkpoint_control(self.path)
        if not self.control and found:  # no control given: the checkpoint's own
            self.control = found
            return
        fix = (
            f"pass --policy.control={found}"
            if found
            else "pass --policy.control=ee_delta or --policy.control=ee_abs"
        )
        refuse_control(self.path, self.control, found, fix)

    def declares_outputs(self) -> bool:
        return self.local  # a checkpoint not readable here: its action width shows at the pre-flight step

    # -- the checkpoint: read here when it is a folder here, else from the flags --------------------
    @property
    def local(self) -> bool:
        return bool(self.path) and Path(self.path).exists()

    def _resolve(self) -> ServedCheckpoint:
        """The checkpoint the server loads and what the client needs of it; ValueError naming the flag."""
        return resolve_checkpoint(
            self.path, self.policy_type, self.cameras, self.image_size, self.actions_per_chunk
        )

    def spec(self, rank: int | None = None) -> _Spec:
        servers = parse_servers(self.server)
        checkpoint = self._resolve()
        address = servers[(worker_rank() if rank is None else rank) % len(servers)]
        return _Spec(
            address,
            checkpoint.policy_type,
            checkpoint.path,
            self.device,
            checkpoint.actions_per_chunk,
            checkpoint.cameras,
            checkpoint.image_size,
            self.open_timeout_s,
            self.timeout_s,
            self.load_timeout_s,
            self.reconnects,
            self.reconnect_backoff_s,
            str(self.control),
        )

    @property
    def checkpoint(self) -> str | None:
        # Only a checkpoint readable here is hashed into provenance; a remote one is named by served_by().
        return self.path if self.local else None

    def observed_cameras(self) -> tuple[str, ...]:
        return self._resolve().cameras or DEFAULT_CAMERAS

    def input_image_size(self) -> int | None:
        return self._resolve().image_size or None

    def served_by(self) -> dict:
        checkpoint = self._resolve()
        return {
            "protocol": "lerobot_async",
            "servers": list(parse_servers(self.server)),
            "policy_type": checkpoint.policy_type,
            "pretrained_name_or_path": checkpoint.path,
            "device": self.device,
            "actions_per_chunk": checkpoint.actions_per_chunk,
        }

    def options(self) -> dict[str, Any]:
        # What decides the actions; not where the server runs nor how long to wait for it.
        skip = ("server", "timeout_s", "load_timeout_s", "reconnects", "reconnect_backoff_s")
        options = {k: v for k, v in super().options().items() if k not in skip}
        if not self.local:
            options["path"] = self.path  # a remote checkpoint has no policy_path (nothing here to hash)
        return options

    def build(self, view: AgentView) -> LeRobotAsyncPolicy:
        return LeRobotAsyncPolicy(self.spec())

    def build_batched(self, view: AgentView, slots: int) -> LeRobotAsyncPolicy:
        # One connection per worker (one client per server), whatever the envs per worker.
        return LeRobotAsyncPolicy(self.spec(), slots)
