"""The policy protocol every evaluated agent implements, and the policy types (one config each).

`eval/` and `pipelines/` never import a concrete policy: a `PolicyConfig` subclass per type, chosen
with `--policy.type=NAME` (draccus.ChoiceRegistry, as lerobot's `PreTrainedConfig`), knows which
cameras its policy consumes (and whether it wants depth) so the evaluator renders only those, and
builds the policy once the env exists. To add a type, write one module like `policies/vision.py`
(config + policy) and list it in `roboview.policies.types.BUILTIN_MODULES`, or publish it from your own package
under the `roboview.policies` entry-point group.

**A policy sees only what a real agent would.** It is built from an `AgentView` (the env's action
and observation spaces, its cameras and image size, and the robot's kinematic model compiled at
defaults) and told about each episode through an `Episode`: the instruction, the episode seed and
the observed cameras' calibration. Never the `TaskInstance`, whose factor values name the object's
color and shape, and never the env, whose state holds the object's pose. Only a config that declares
`privileged = True` (the scripted `expert`) is built from the env itself.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, fields
from typing import Any, ClassVar, Protocol, runtime_checkable

import draccus
import gymnasium as gym
import mujoco
import numpy as np

from roboview.policies.errors import TransientPolicyError  # noqa: F401  (part of the policy API)
from roboview.sim.cameras import CameraPose
from roboview.sim.control import JointToEE, check_control
from roboview.sim.scene import Scene
from roboview.tasks.env import EE_STATE_KEY, TaskEnv
from roboview.tasks.world import all_controls


@dataclass(frozen=True)
class Episode:
    """What an agent is told when an episode starts: what a real robot's operator would tell it."""

    # The task's name (roboview.tasks) and its instruction in words.
    task: str
    instruction: str
    # The episode seed (common random numbers: shared by every value of one context and repeat);
    # a stochastic policy seeds its draws from it so reruns agree.
    seed: int
    # World pose and vertical field of view of every observed camera at t = 0 (extrinsics + intrinsics).
    cameras: dict[str, CameraPose]
    # Side of the square images (pixels).
    image_size: int

    @classmethod
    def of(cls, env: TaskEnv, seed: int) -> Episode:
        """The episode an env just reset into (reads its instruction and camera calibration only)."""
        return cls(
            env.instance.task,
            env.instruction,
            seed,
            {c: env.camera_pose(c) for c in env.cameras},
            env.image_size,
        )


@dataclass(frozen=True)
class AgentView:
    """What a non-privileged policy is built from: the env's interface, never its state."""

    task: str
    cameras: tuple[str, ...]
    image_size: int
    depth: bool
    fps: int
    action_space: gym.spaces.Box
    observation_space: gym.spaces.Dict
    # The env's control mode (roboview.sim.control.CONTROLS) and the joint-target action space, which
    # agents that plan joint targets plan in whatever the control (their plans are converted).
    control: str = "joint"
    joint_action_space: gym.spaces.Box | None = None

    @classmethod
    def of(cls, env: TaskEnv) -> AgentView:
        return cls(
            env.instance.task,
            env.cameras,
            env.image_size,
            env.depth,
            env.fps,
            env.action_space,
            env.observation_space,
            env.control,
            env.joint_action_space,
        )

    @classmethod
    def of_task(
        cls,
        task: str,
        cameras: tuple[str, ...],
        image_size: int,
        depth: bool = False,
        control: str = "joint",
    ) -> AgentView:
        """The view of `task`'s env with these cameras, for a policy built away from any worker's env (a
        policy server): the env is made for its interface and closed again."""
        from roboview.tasks import make_env

        env = make_env(task, cameras=cameras, image_size=image_size, depth=depth, control=control)
        try:
            return cls.of(env)
        finally:
            env.close()

    def kinematic_model(self) -> mujoco.MjModel:
        """The robot and static scene compiled at defaults (for inverse kinematics); no episode's state.

        Compiled once per process (≈ 1.3 s) and shared: planners only read it, each with its own MjData,
        so K envs per worker do not compile it K times."""
        return _kinematic_model()


@functools.cache
def _kinematic_model() -> mujoco.MjModel:
    return Scene().model


@runtime_checkable
class Policy(Protocol):
    name: str
    # Why the last episode failed, in the policy's own words ("" when it has nothing to add); the
    # evaluator records it as the episode's failure reason.
    failure_reason: str

    def reset(self, episode: Episode) -> None:
        """Called after every env reset, before the first action of an episode."""

    def select_action(self, observation: dict[str, np.ndarray]) -> np.ndarray:
        """Env action in the env's control: joint (8,) float32: 7 joint targets (rad) + gripper command (0 open …
        1 closed); ee_delta / ee_abs (7,) (roboview.sim.control)."""

    def close(self) -> None:
        """Release what the policy holds (models, sessions, connections); called once, at the end.

        Optionally, `episode_record() -> dict` adds the policy's own columns to the episode's row (the
        VLM agents' request and token counts, the SGL's refined instruction); same keys every episode.
        """


@runtime_checkable
class ChunkPredictor(Protocol):
    """A policy that predicts action chunks for many slots in one forward pass: what `--eval.policy_server` and
    `roboview.pipelines.serve_policy` batch across workers and connections (`PolicyConfig.build_batched` returns one for
    chunked LeRobot checkpoints)."""

    name: str
    # Actions of a chunk that run before the next prediction.
    n_action_steps: int

    def predict_chunks(
        self, observations: dict[int, dict], instructions: dict[int, str] | None = None
    ) -> dict[int, list[np.ndarray]]:
        """slot → its next `n_action_steps` actions, from one forward pass over every slot's observation."""


# The observed cameras of the paper's agents: VLM agents watch `front`, π0-style ones left_top + wrist.
DEFAULT_CAMERAS = ("front",)


@dataclass
class PolicyConfig(draccus.ChoiceRegistry):
    """One policy type's settings, chosen on the command line with `--policy.type=NAME`.

    A subclass registers itself with `@PolicyConfig.register_subclass("name")`, declares its own
    fields (they become `--policy.<field>` flags, validated in `__post_init__` before any work) and
    says what the evaluator must know: the cameras its policy watches, whether it wants depth, the
    image size it needs, and how to build the policy once the env exists.
    """

    # Name written in the results' `policy` column (e.g. act_ref vs act_campose for two checkpoints);
    # empty: the policy's own name (expert, vision, lerobot:act; "+sgl" appended with the SGL).
    name: str = ""

    # Whether the policy wants depth images too.
    depth: ClassVar[bool] = False
    # Whether `build` gets the env itself (ground-truth state): the scripted expert only.
    privileged: ClassVar[bool] = False
    # Whether the policy plans joint targets, converted to the EE action when `env_control()` is an EE mode
    # (`JointPlanInEE`, applied by roboview.policies.factory): the vision and VLM agents, the random floor.
    plans_joints: ClassVar[bool] = False
    # One line for listings and error messages.
    doc: ClassVar[str] = ""
    # The rows' `policy` column when --policy.name is not given: an fnmatch pattern formatted with `type` and the
    # type's recorded options (run.json's policy_options). roboview-verify holds a folder's rows to it.
    row_name: ClassVar[str] = "{type}"
    # Whether an episode re-run with its seed ends as it did: the policy's randomness, if any, is drawn from the
    # episode seed. False for a policy whose answers come from elsewhere (a server, a VLM endpoint): a replay that
    # disagrees then shows a stochastic policy, not a forged row.
    reproducible: ClassVar[bool] = True

    def __post_init__(self) -> None:
        """Subclasses validate their fields here (and call this first)."""

    @classmethod
    def default_choice_name(cls) -> str:
        """No default type: `--policy.<field>` without `--policy.type` is refused, naming the types."""
        raise ValueError(missing_policy_type())

    @property
    def type(self) -> str:
        return self.get_choice_name(type(self))

    @property
    def checkpoint(self) -> str | None:
        """Weights the policy loads (recorded in run.json as policy_path); None for weightless policies."""
        return None

    def worker_imports(self) -> tuple[str, ...]:
        """Modules an evaluation worker imports to run this policy: imported once by the process the workers start
        from (roboview.core.workers), not once per worker. Default: the module declaring the config."""
        return (type(self).__module__,)

    def declares_outputs(self) -> bool:
        """Whether what the policy answers (action width, control) is known before it runs: from its checkpoint, its
        code or its server's handshake. False (a server whose protocol declares nothing of it): the evaluation runs
        one step of the first instance before any episode counts, and stops, naming the cause, if that step fails."""
        return True

    def served_by(self) -> dict | None:
        """For a policy served elsewhere: where, and what its server said about itself on connecting
        (recorded in provenance.json; no secrets). None for a policy that runs in the worker."""
        return None

    def observed_cameras(self) -> tuple[str, ...]:
        """Cameras the policy observes (the env renders only these)."""
        return DEFAULT_CAMERAS

    def env_control(self) -> str:
        """The control mode the policy acts in (roboview.sim.control.CONTROLS); the evaluator makes its envs
        with it. Types that take `--policy.control` or read it from a model override this."""
        return "joint"

    def input_image_size(self) -> int | None:
        """Image side the policy was trained on (the env renders exactly that); None: any size works."""
        return None

    def settle_control(self, controls: tuple[str, ...]) -> None:
        """Called before any episode with the controls every env of the run takes: a type whose control can be
        left open (a checkpoint that does not say) takes it from them here; others need not override it."""

    def options(self) -> dict[str, Any]:
        """The type's own settings, recorded in run.json (a resume must match them); the control is recorded
        on its own (run.json's `control`)."""
        skip = {"name", "path", "control"}
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name not in skip}

    @classmethod
    def from_options(cls, settings: dict[str, Any]) -> PolicyConfig:
        """The config `options()` recorded (with `path`, `name` and `control` beside them where the type has them):
        what a replay rebuilds from run.json. Types whose options are not their fields as they are override it."""
        return cls(**settings)

    def build(self, view: AgentView) -> Policy:
        """The policy, from the agent's view of the env (privileged types: from the env itself)."""
        raise NotImplementedError(f"policy type {self.type!r} does not say how to build its policy")

    def batchable(self) -> bool:
        """Whether `build_batched` returns a policy (one model for many envs; what a policy server serves)."""
        return False

    def build_batched(self, view: AgentView, slots: int) -> Policy | None:
        """One policy that drives `slots` envs in lockstep (`reset(episode, slot)`, `select_actions({slot:
        obs})`) with one model, or None: the evaluator then builds one policy per env. Types whose cost is
        a model (checkpoints) override it; weightless ones need not."""
        return None


def control_field(config: PolicyConfig) -> None:
    """Check a config's `control` field (the `--policy.control` flag)."""
    if (
        config.control and config.control not in all_controls()
    ):  # empty: settled by the world (settle_control)
        raise ValueError(f"unknown --policy.control={config.control!r}; allowed: {', '.join(all_controls())}")


@dataclass
class ServedConnection:
    """The connection block every served policy type shares (openpi, vla_eval, lerobot_async): how long to wait for
    the server and how often to reach it again. Its fields are `--policy.<field>` flags of those types; the one
    retry loop that reads them is `roboview.policies.errors.open_with_retries`."""

    # Seconds to open a connection to the server and receive its greeting (metadata, HELLO, `Ready`).
    open_timeout_s: float = 10.0
    # Seconds to wait for one answer (an action chunk).
    timeout_s: float = 60.0
    # Further attempts to open a dropped connection (waiting reconnect_backoff_s, doubling) before the run stops.
    reconnects: int = 3
    # Seconds before the first reconnection attempt (doubling with each further one).
    reconnect_backoff_s: float = 0.5

    def check_connection(self) -> None:
        """One-line errors for a timeout that is not positive or a negative retry count or backoff."""
        for name in ("open_timeout_s", "timeout_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"--policy.{name}={getattr(self, name)} must be positive")
        for name in ("reconnects", "reconnect_backoff_s"):
            if getattr(self, name) < 0:
                raise ValueError(f"--policy.{name}={getattr(self, name)} must be ≥ 0")


class WebsocketServed(ServedConnection):
    """A served policy reached over websockets (openpi, vla_eval): its config's `url` (comma-separated ws:// or wss://
    addresses, one per worker in turn) and `cameras` (comma-separated camera names), read and checked here once."""

    url: str
    cameras: str

    @property
    def url_list(self) -> list[str]:
        return [u.strip() for u in self.url.split(",") if u.strip()]

    @property
    def camera_list(self) -> tuple[str, ...]:
        return tuple(c.strip() for c in self.cameras.split(",") if c.strip())

    def check_url_and_cameras(self, server: str) -> None:
        """One-line errors for a missing url, an entry that is not ws:// or wss://, and an unknown or empty camera
        list; `server` names the server the url is for ("the openpi server")."""
        from roboview.tasks import camera_names

        if not self.url_list:
            raise ValueError(
                f"--policy.url is required: ws://HOST:PORT of {server} (comma-separated for several)"
            )
        for url in self.url_list:
            if not url.startswith(("ws://", "wss://")):
                raise ValueError(
                    f"--policy.url entry {url!r} must start with ws:// or wss:// (e.g. ws://127.0.0.1:8000)"
                )
        cameras = camera_names()
        unknown = [c for c in self.camera_list if c not in cameras]
        if unknown or not self.camera_list:
            raise ValueError(
                f"--policy.cameras={self.cameras!r}: unknown camera(s) {unknown}; allowed: {', '.join(cameras)}"
            )


@dataclass
class ControlledConfig(PolicyConfig):
    """A policy type whose control mode is chosen with `--policy.control` (default: the world's only control, else
    joint)."""

    # Control mode the policy acts in: joint (7 joint targets + gripper), ee_delta or ee_abs (end effector:
    # position + axis-angle + gripper, LIBERO convention; docs/control.md) or xyz_delta (Meta-World's: hand position
    # delta + gripper). Empty: the world's only control where it takes one (LIBERO's ee_delta, Meta-World's
    # xyz_delta), else joint.
    control: str = ""

    def __post_init__(self) -> None:
        control_field(self)
        super().__post_init__()

    def settle_control(self, controls: tuple[str, ...]) -> None:
        if not self.control:
            self.control = controls[0] if len(controls) == 1 else "joint"

    def env_control(self) -> str:
        return self.control or "joint"


class JointPlanInEE:
    """A policy that plans joint targets, acting in an end-effector control: each of its joint actions becomes
    the EE action commanding the same pinch pose (`JointToEE`, from the observation's EE state)."""

    def __init__(self, policy: Policy, model: mujoco.MjModel, control: str) -> None:
        self.policy = policy
        self.name = policy.name
        self._to_ee = JointToEE(model, check_control(control))

    def __getattr__(self, name: str) -> Any:  # failure_reason, episode_record, … are the policy's own
        if name == "policy" or name.startswith("__"):
            raise AttributeError(name)
        return getattr(self.policy, name)

    def reset(self, episode: Episode) -> None:
        self.policy.reset(episode)

    def select_action(self, observation: dict[str, np.ndarray]) -> np.ndarray:
        return self._to_ee(self.policy.select_action(observation), observation[EE_STATE_KEY])

    def close(self) -> None:
        self.policy.close()


def registered_types() -> tuple[str, ...]:
    """The policy types registered so far (every one once `roboview.policies.types.load_policy_types` has run, as each
    command's does before it parses)."""
    return tuple(sorted(PolicyConfig.get_known_choices()))


def missing_policy_type() -> str:
    """The one-line error for a command run without `--policy.type` (there is no default policy)."""
    privileged = [name for name in registered_types() if PolicyConfig.get_choice_class(name).privileged]
    notes = [
        f"; `{name}` is the privileged scripted expert (it reads the simulator state, which no real "
        "policy sees)"
        if name == "expert"
        else f"; `{name}` is privileged (it reads the simulator state)"
        for name in privileged
    ]
    return f"--policy.type is required: one of {', '.join(registered_types())}{''.join(notes)}"


class PolicyBatch:
    """The policy side of `envs_per_worker` envs run in lockstep, slot i driving env i.

    Either one natively batched policy (one model; each step's acting slots go through one call, so a
    checkpoint's forward pass sees a batch of observations), or one policy per env called in turn.
    """

    def __init__(self, policies: list[Policy], batched: bool) -> None:
        self.policies = policies
        self.batched = batched
        self.name = policies[0].name

    def policy(self, slot: int) -> Policy:
        return self.policies[0 if self.batched else slot]

    def reset(self, slot: int, episode: Episode) -> None:
        if self.batched:
            self.policies[0].reset(episode, slot)
        else:
            self.policies[slot].reset(episode)

    def select_actions(self, observations: dict[int, dict]) -> dict[int, np.ndarray]:
        if self.batched:
            return self.policies[0].select_actions(observations)
        return {slot: self.policies[slot].select_action(obs) for slot, obs in observations.items()}

    def failure_reason(self, slot: int) -> str:
        return getattr(self.policy(slot), "failure_reason", "")

    def episode_record(self, slot: int) -> dict:
        record = getattr(self.policy(slot), "episode_record", None)
        return {} if record is None else record()

    def close(self) -> None:
        for policy in self.policies:
            close = getattr(policy, "close", None)
            if close is not None:
                close()
