"""The world contract: what every simulated world declares, and the env interface every world's env implements.

A *world* is a simulator with its own scenes, robot and cameras: RoboView's own scene (`roboview.sim`, with the
`pick_place` and `push` tasks), LIBERO's scenes (`roboview.libero`), Meta-World's (`roboview.metaworld`). A world
lives in its own *wing* (a package, or RoboView's `sim` + task modules); it registers one `World` (its facts) and
its tasks, and its env subclasses `WorldEnv`. Everything outside the wing — the policy clients, the fairness gate,
the builder, collect, the recorder, the renderer — reads the facts from `load_world(env.world)` or from the env,
and never imports the wing (tests/project/test_imports.py enforces it). The recipe for a new world is docs/extending.md.

    >>> load_world("roboview").observed_cameras
    ('front', 'left_top', 'wrist')
"""

from __future__ import annotations

import importlib
import importlib.util
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np

if TYPE_CHECKING:
    from roboview.sim.cameras import CameraPose
    from roboview.variation.instances import TaskInstance


@dataclass(frozen=True)
class World:
    """The facts of one simulated world, read by everything outside its wing."""

    name: str
    # One line for --help and the docs.
    title: str
    # Every camera name the world's envs render → the world's own name of that camera (an alias maps to the
    # same camera: LeRobot's `image`/`image2` for LIBERO's `agentview`/wrist camera).
    cameras: Mapping[str, str]
    # The cameras a policy observes and the fairness gate measures, in that order.
    observed_cameras: tuple[str, ...]
    # The observed cameras whose measurements the gate judges (the wrist view may be measured and not judged).
    judged_cameras: tuple[str, ...]
    # The cameras whose calibration a build records with every instance.
    recorded_cameras: tuple[str, ...]
    # The camera names (aliases too) on the robot's hand: never perturbed, sent as the wrist image on the wire.
    wrist_cameras: tuple[str, ...]
    # The control modes its envs take; a policy given none takes the only one, where there is one.
    controls: tuple[str, ...]
    # "module:Class" of its fairness probe: `Probe(env)`, `.cameras`, `.measure(rgb, thresholds)`, `.close()`.
    probe: str
    # The control rate its episodes run at, and its datasets record (Meta-World's 80 Hz); 0: a collection chooses
    # (`--dataset.fps`, RoboView's scene steps its 500 Hz physics at any divisor).
    fps: int = 0
    # The side its own harnesses render at (LIBERO's 256, Meta-World's 480); 0: none, the env renders any size.
    render_size: int = 0
    # Cameras whose LeRobot dataset / checkpoint feature key is not `observation.images.<camera>`: camera → key
    # (Meta-World's `top` is LeRobot's `observation.image`, its one camera).
    image_features: Mapping[str, str] = field(default_factory=dict)
    # An observation key holding the world's raw proprioception, for a client that builds another harness's state
    # convention from it ("": none).
    proprio_key: str = ""
    # Whether demos draw per-episode visual randomization (object color, camera jitter) on top of the instance.
    episode_visuals: bool = False
    # Where an episode's instruction and success come from (one line each, for the docs and the task card).
    instruction: str = ""
    success: str = ""
    # The module a world outside the core install needs, and the command that installs it ("": always there).
    requires: str = ""
    install: str = ""
    # The package the world lives in (its wing: env, task, factors, probe, expert), which nothing outside it imports;
    # "": RoboView's own scene, the shared base (`roboview.sim` and the task modules of `roboview.tasks`).
    wing: str = ""
    # The factors its scenes cannot take (an instance setting one away from its baseline is refused).
    not_applicable: tuple[str, ...] = ()
    # Visual factor → the name of its baseline where the baseline is the world's own look, not the registered value
    # (LIBERO's and Meta-World's objects wear their own textures at the color baseline: {"color": "original"}, where
    # every CSS color, red included, is a re-skin). The wing registers them for each of its tasks
    # (`roboview.variation.factors.register_baseline_labels`); empty: the registered baselines (RoboView's red).
    baseline_labels: Mapping[str, str] = field(default_factory=dict)
    # What the fairness gate judges a value against: "thresholds" (RoboView's scene, drawn with the gate in mind) or
    # "no_change_view" (a world whose look is another benchmark's design, LIBERO's and Meta-World's: each value against
    # its own context's no-change view, what that world shows every policy; roboview.tasks.fairness.violations).
    gate_reference: str = "thresholds"
    extra: Mapping[str, Any] = field(default_factory=dict)

    @property
    def scene_cameras(self) -> tuple[str, ...]:
        """The observed cameras that are not on the hand."""
        return tuple(c for c in self.observed_cameras if c not in self.wrist_cameras)

    @property
    def default_control(self) -> str | None:
        """The control a policy given none acts in: the world's only one (None where it takes several)."""
        return self.controls[0] if len(self.controls) == 1 else None

    def installed(self) -> bool:
        """Whether the world's package imports here."""
        if not self.requires:
            return True
        return importlib.util.find_spec(self.requires) is not None

    def make_probe(self, env: WorldEnv) -> Any:
        """The world's fairness probe on `env`."""
        module, _, attr = self.probe.partition(":")
        return getattr(importlib.import_module(module), attr)(env)


WORLDS: dict[str, World] = {}
GATE_REFERENCES = ("thresholds", "no_change_view")


def register_world(world: World) -> World:
    if world.name in WORLDS:
        raise ValueError(f"world {world.name!r} is already registered")
    unknown = [c for c in (*world.observed_cameras, *world.recorded_cameras) if c not in world.cameras]
    if unknown or not set(world.judged_cameras) <= set(world.observed_cameras):
        raise ValueError(
            f"world {world.name!r}: cameras {unknown or world.judged_cameras} are not its cameras"
        )
    if world.gate_reference not in GATE_REFERENCES:
        raise ValueError(
            f"world {world.name!r}: gate_reference {world.gate_reference!r}; allowed: {', '.join(GATE_REFERENCES)}"
        )
    WORLDS[world.name] = world
    return world


def load_world(name: str) -> World:
    try:
        return WORLDS[name]
    except KeyError:
        raise ValueError(f"unknown world {name!r}; registered: {', '.join(WORLDS)}") from None


def world_of_cameras(cameras: Sequence[str]) -> World | None:
    """The world whose *own* camera names (not RoboView's shared `wrist`) `cameras` include, if one does: how a policy
    configured before any env is made knows what world it will watch (LIBERO's `agentview`, Meta-World's
    `corner2`)."""
    for world in WORLDS.values():
        own = set(world.cameras) - {c for w in WORLDS.values() if w is not world for c in w.cameras}
        if own & set(cameras):
            return world
    return None


def native_render_size(cameras: Sequence[str]) -> int:
    """The side the world watched through `cameras` renders at in its own harnesses (0: no such world)."""
    world = world_of_cameras(cameras)
    return world.render_size if world is not None else 0


IMAGE_FEATURE = "observation.images.{}"


def feature_key(camera: str) -> str:
    """The LeRobot feature key of `camera`'s images: a world's own (`World.image_features`), else
    `observation.images.<camera>`."""
    for world in WORLDS.values():
        if camera in world.image_features:
            return world.image_features[camera]
    return IMAGE_FEATURE.format(camera)


def camera_of_feature(key: str) -> str | None:
    """The camera a LeRobot image feature `key` holds (None: `key` is no image feature)."""
    prefix = IMAGE_FEATURE.format("")
    if key.startswith(prefix):
        return key.removeprefix(prefix)
    return next((c for w in WORLDS.values() for c, k in w.image_features.items() if k == key), None)


def all_controls() -> tuple[str, ...]:
    """Every control some registered world takes."""
    return tuple(dict.fromkeys(c for w in WORLDS.values() for c in w.controls))


def wrist_camera_names() -> tuple[str, ...]:
    """Every registered world's wrist camera names."""
    return tuple(dict.fromkeys(c for w in WORLDS.values() for c in w.wrist_cameras))


def proprio_of(observation: Mapping[str, Any]) -> np.ndarray | None:
    """The raw proprioception a world puts in its observations (`World.proprio_key`), or None."""
    for world in WORLDS.values():
        if world.proprio_key and world.proprio_key in observation:
            return np.asarray(observation[world.proprio_key], np.float64)
    return None


class WorldEnv(gym.Env):
    """The env interface of every world (a world's env subclasses it; RoboView's is `roboview.tasks.env.TaskEnv`).

    Beyond gymnasium's `reset(seed, options={"instance": TaskInstance})` and `step(action)`, everything outside a
    world reads only what is declared here: the class facts below, the episode's `instruction`, `steps`,
    `max_steps` and `instance`, and the methods. Observations use RoboView's keys (`observation.images.<camera>`,
    `observation.state`, `observation.ee_state`)."""

    # The world (its `World` in WORLDS) and the task (its `Task` in roboview.tasks.TASKS) this env runs.
    world: str = ""
    task: str = ""
    # The context factor naming the instruction ("": the world's own instruction, per context).
    instruction_factor: str = ""
    # What besides the object a policy must find ("box", "zone"; None: nothing the gate judges).
    target: str | None = None
    # The cameras a privileged policy (which reads the simulator's state) is given; empty: the policy's own choice.
    observed_cameras: tuple[str, ...] = ()
    # Every camera the env renders by name and every control it takes (checked before any episode).
    camera_names: tuple[str, ...] = ()
    controls: tuple[str, ...] = ()
    # The robot, as a LeRobot dataset of this env names it (`robot_type`).
    robot_type: str = ""
    # The packages the scene's assets and code come from (the stack record names their versions).
    asset_packages: tuple[str, ...] = ()

    # The live episode, set by `reset`.
    instance: TaskInstance
    instruction: str
    steps: int
    max_steps: int
    image_size: int
    cameras: tuple[str, ...]

    @classmethod
    def feature_names(cls, control: str) -> tuple[list | dict, list | dict] | None:
        """The names a LeRobot dataset of this env gives `observation.state` and `action` in `control`; None:
        RoboView's own (the joints or the EE state, and the control's action names)."""
        return None

    def is_success(self) -> bool:
        raise NotImplementedError

    def state(self) -> np.ndarray:
        """Privileged: the robot's joint positions."""
        raise NotImplementedError

    def object_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Privileged: the task object's world position and quaternion [w, x, y, z]."""
        raise NotImplementedError

    def ee_position(self) -> np.ndarray:
        raise NotImplementedError

    def object_geoms(self) -> tuple[int, ...]:
        """The task object's visual geoms (what the fairness gate requires visible)."""
        raise NotImplementedError

    def target_geoms(self) -> tuple[int, ...]:
        """Geom ids of the target the fairness gate requires visible (empty: none)."""
        return ()

    def render_camera(self, camera: str) -> np.ndarray:
        """`camera` rendered from the live state now, as observations hand it."""
        raise NotImplementedError

    def camera_ids(self) -> dict[str, int]:
        """The recorded cameras' ids in the compiled model, by RoboView's name."""
        raise NotImplementedError

    def camera_pose(self, name: str) -> CameraPose:
        """Camera `name`'s calibration now (position, orientation, fovy), as records and certificates store it."""
        raise NotImplementedError

    def scene_xml(self) -> str:
        """The compiled scene's MJCF (the stack record hashes it)."""
        raise NotImplementedError


class WorldExpert:
    """The privileged scripted expert every task names (`Task.expert`): `Expert(env)`, `reset()` after each env
    reset, `select_action(observation)` in the env's control."""

    name = "expert"

    def __init__(self, env: WorldEnv) -> None:
        self.env = env

    @staticmethod
    def scripts(instance: TaskInstance) -> bool:
        """Whether the expert can solve `instance`'s context (LIBERO's scripts two of its four suites)."""
        return True

    def reset(self) -> None:
        raise NotImplementedError

    def select_action(self, observation: Any = None) -> np.ndarray:
        raise NotImplementedError
