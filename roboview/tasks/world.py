"""The world contract: what every simulated world declares, and the env interface every world's env implements.

A *world* is a simulator with its own scenes, robot and cameras: RoboView's own scene (`roboview.sim`, with the
`pick_place` and `push` tasks), LIBERO's scenes (`roboview.libero`), Meta-World's (`roboview.metaworld`). A world
lives in its own *wing* (a package, or RoboView's `sim` + task modules); it registers one `World` (its facts) and
its tasks, and its env subclasses `WorldEnv`, which holds the `World` (`env.world`). Everything outside the wing — the
policy clients, the fairness gate, the builder, collect, the recorder, the renderer — reads the facts from `env.world`
or `load_world(name)`, and never imports the wing (tests/project/test_imports.py enforces it). The recipe for a new
world is docs/extending.md.

    >>> load_world("roboview").observed_cameras
    ('front', 'left_top', 'wrist')
"""

from __future__ import annotations

import functools
import importlib
import importlib.util
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np

from roboview.core.registry import Registry
from roboview.sim.observation import LazyObservation

if TYPE_CHECKING:
    from roboview.sim.cameras import CameraPose
    from roboview.variation.instances import TaskInstance

# RoboView's observation keys, every world's (a LeRobot dataset's feature keys): each camera's image and depth map,
# the state a policy reads in its control, and the end-effector state.
IMAGE_KEY = "observation.images.{}"
DEPTH_KEY = "observation.depth.{}"
STATE_KEY = "observation.state"
EE_STATE_KEY = "observation.ee_state"
# An applier table's entry: "module:attr" (resolved when first used: only the wing imports the wing), or the callable.
Maker = str | Callable[..., Any]


def resolve(target: Maker) -> Any:
    """What a "module:attr" string names (`attr` may be dotted: a class's constructor `ObjectColor.skin`); a callable
    as it is."""
    if not isinstance(target, str):
        return target
    module, _, attr = target.partition(":")
    return functools.reduce(getattr, attr.split("."), importlib.import_module(module))


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
    # The module a world outside the core install needs, and the command that installs it ("": always there).
    requires: str = ""
    install: str = ""
    # The package the world lives in (its wing: env, task, factors, probe, expert), which nothing outside it imports;
    # "": RoboView's own scene, the shared base (`roboview.sim` and the task modules of `roboview.tasks`).
    wing: str = ""
    # Visual factor → its applier on the world's scenes: a `Maker`, called with the value's arguments
    # (`roboview.variation.model_edits.value_args`: color's sRGB, camera_pose's ring and step …), whose applier's
    # `apply(scene)` edits the compiled model after every reset. A tuple of factors takes one applier together
    # (LIBERO-plus's five view sub-factors: its pose arithmetic takes all five), its maker called with their
    # {factor: value}. None: the factor does not apply to the world's scenes; a factor the table does not name is one
    # the world lacks (`status`). An instance setting one it does not take away from its baseline is refused. The
    # appliers run in the table's order. None for the whole table: every visual factor's own applier (`Factor.bind`,
    # written for RoboView's scene; a factor with none, such as LIBERO-plus's `view_*`, is one the world lacks).
    appliers: Mapping[str | tuple[str, ...], Maker | None] | None = None
    # Whether a privileged policy (the scripted expert: it reads the simulator's state) watches the cameras it names
    # (RoboView's scene, which renders every policy's); False: the observed cameras, whatever it names (the videos of
    # LIBERO's and Meta-World's episodes show what every other policy sees).
    privileged_own_cameras: bool = False
    # Visual factor → the name of its baseline where the baseline is the world's own look, not the registered value
    # (LIBERO's and Meta-World's objects wear their own textures at the color baseline: {"color": "original"}, where
    # every CSS color, red included, is a re-skin). The wing registers them for each of its tasks
    # (`roboview.variation.factors.register_baseline_labels`); empty: the registered baselines (RoboView's red).
    baseline_labels: Mapping[str, str] = field(default_factory=dict)
    # What the fairness gate judges a value against: "thresholds" (RoboView's scene, drawn with the gate in mind) or
    # "no_change_view" (a world whose look is another benchmark's design, LIBERO's and Meta-World's: each value against
    # its own context's no-change view, what that world shows every policy; roboview.tasks.fairness.violations).
    gate_reference: str = "thresholds"

    @property
    def scene_cameras(self) -> tuple[str, ...]:
        """The observed cameras that are not on the hand."""
        return tuple(c for c in self.observed_cameras if c not in self.wrist_cameras)

    @property
    def default_control(self) -> str | None:
        """The control a policy given none acts in: the world's only one (None where it takes several)."""
        return self.controls[0] if len(self.controls) == 1 else None

    @property
    def privileged_cameras(self) -> tuple[str, ...]:
        """The cameras a privileged policy is given (empty: the ones it names)."""
        return () if self.privileged_own_cameras else self.observed_cameras

    def status(self, factor: str) -> str:
        """Whether the world "takes" visual factor `factor` (it has an applier), "refuses" it (declared not to apply to
        its scenes) or "lacks" it (its table does not name it: neither an applier nor a refusal is written for it; in
        RoboView's scene, which has no table, a factor that brings no applier for it, `Factor.bind`)."""
        if self.appliers is None:
            from roboview.variation.factors import load_factor

            return "takes" if load_factor(factor).bind is not None else "lacks"
        for key, maker in self.appliers.items():
            if factor == key or (isinstance(key, tuple) and factor in key):
                return "refuses" if maker is None else "takes"
        return "lacks"

    @property
    def not_applicable(self) -> tuple[str, ...]:
        """The registered visual factors the world takes no applier for (refused or lacked)."""
        from roboview.variation.factors import visual_factors

        return tuple(f for f in visual_factors() if self.status(f) != "takes")

    def make_appliers(
        self, values: Mapping[str, str], task: str | None = None, always: Collection[str] = ()
    ) -> list:
        """The appliers of an instance's visual factor `values` away from their baselines in `task`'s world
        (`baseline_of`: LIBERO's color `original` applies nothing, its `red` re-skins), in the table's order; those of
        the factors in `always` also at their baseline. A one-line ValueError names a factor the world does not
        take."""
        from roboview.variation.factors import FACTORS, baseline_of, visual_factors
        from roboview.variation.model_edits import value_args

        changed = {
            k
            for k, v in values.items()
            if k in FACTORS and FACTORS[k].kind != "context" and v != baseline_of(k, task)
        }
        refused = [k for k in values if k in changed and self.status(k) != "takes"]
        if refused:
            takes = [f for f in visual_factors() if self.status(f) == "takes"]
            raise ValueError(
                f"the {self.name} world cannot apply {', '.join(refused)}; its factors: {', '.join(takes)}"
            )
        out = []
        for key, maker in (self.appliers or {}).items():
            group = key if isinstance(key, tuple) else (key,)
            if maker is None or not any(f in changed or f in always for f in group):
                continue
            make = resolve(maker)
            out.append(
                make({f: values[f] for f in group if f in values})
                if isinstance(key, tuple)
                else make(*value_args(key, values[key]))
            )
        return out

    def installed(self) -> bool:
        """Whether the world's package imports here."""
        if not self.requires:
            return True
        return importlib.util.find_spec(self.requires) is not None

    def make_probe(self, env: WorldEnv) -> Any:
        """The world's fairness probe on `env`."""
        return resolve(self.probe)(env)


# Listed in the order of their wings (roboview.core.registry.rank): RoboView's own scene first.
WORLDS: Registry[World] = Registry("world", origin=lambda world: world.wing or __package__)
GATE_REFERENCES = ("thresholds", "no_change_view")


def register_world(world: World) -> World:
    from roboview.variation.factors import FACTORS

    factors = FACTORS.registered
    if world.name in WORLDS.registered:
        raise ValueError(f"world {world.name!r} is already registered")
    unknown = [c for c in (*world.observed_cameras, *world.recorded_cameras) if c not in world.cameras]
    if unknown or not set(world.judged_cameras) <= set(world.observed_cameras):
        raise ValueError(
            f"world {world.name!r}: cameras {unknown or world.judged_cameras} are not its cameras"
        )
    named = [f for key in world.appliers or () for f in (key if isinstance(key, tuple) else (key,))]
    strange = [f for f in named if f not in factors or factors[f].kind != "visual"]
    if strange:
        raise ValueError(
            f"world {world.name!r}: its appliers name {', '.join(strange)}, no registered visual factor"
        )
    if world.gate_reference not in GATE_REFERENCES:
        raise ValueError(
            f"world {world.name!r}: gate_reference {world.gate_reference!r}; allowed: {', '.join(GATE_REFERENCES)}"
        )
    return WORLDS.add(world.name, world)


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


def feature_key(camera: str) -> str:
    """The LeRobot feature key of `camera`'s images: a world's own (`World.image_features`), else
    `observation.images.<camera>`."""
    for world in WORLDS.values():
        if camera in world.image_features:
            return world.image_features[camera]
    return IMAGE_KEY.format(camera)


def camera_of_feature(key: str) -> str | None:
    """The camera a LeRobot image feature `key` holds (None: `key` is no image feature)."""
    prefix = IMAGE_KEY.format("")
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


def observation_space(
    cameras: Sequence[str], image_size: int, depth: bool, state_size: int, ee_state_size: int
) -> gym.spaces.Dict:
    """The observations' spaces: each camera's image (and depth map), the state and the EE state."""
    spaces = {
        IMAGE_KEY.format(c): gym.spaces.Box(0, 255, (image_size, image_size, 3), np.uint8) for c in cameras
    }
    if depth:
        spaces |= {
            DEPTH_KEY.format(c): gym.spaces.Box(0, np.inf, (image_size, image_size), np.float32)
            for c in cameras
        }
    spaces[STATE_KEY] = gym.spaces.Box(-np.inf, np.inf, (state_size,), np.float32)
    spaces[EE_STATE_KEY] = gym.spaces.Box(-np.inf, np.inf, (ee_state_size,), np.float32)
    return gym.spaces.Dict(spaces)


class WorldEnv(gym.Env):
    """The env interface of every world (a world's env subclasses it; RoboView's is `roboview.tasks.env.TaskEnv`).

    Beyond gymnasium's `reset(seed, options={"instance": TaskInstance})` and `step(action)`, everything outside a
    world reads only what is declared here: the class facts below (the world's own through `world`: its cameras,
    controls, observed cameras), the episode's `instruction`, `steps`, `max_steps` and `instance`, and the methods.
    Observations use RoboView's keys (IMAGE_KEY, STATE_KEY, EE_STATE_KEY, DEPTH_KEY). A world's env calls `setup`
    first, then writes what is its own: its scene, its reset, its raw observation, its step."""

    # The world this env runs in (its `World`, registered in WORLDS) and the task (its `Task` in roboview.tasks.TASKS).
    world: World
    task: str = ""
    # The context factor naming the instruction ("": the world's own instruction, per context).
    instruction_factor: str = ""
    # What besides the object a policy must find ("box", "zone"; None: nothing the gate judges).
    target: str | None = None
    # Whether the env renders depth maps (`depth=True`).
    renders_depth: bool = False
    # The robot, as a LeRobot dataset of this env names it (`robot_type`).
    robot_type: str = ""
    # The packages the scene's assets and code come from (the stack record names their versions).
    asset_packages: tuple[str, ...] = ()
    # The joint-target action (RoboView's scene: what its scripted planners plan in); None: the world has none.
    joint_action_space: gym.spaces.Box | None = None
    # The `{"motors": [...]}` names a LeRobot dataset of this env gives its state and its action (LIBERO's, Meta-World's
    # datasets name them so); empty: RoboView's own, per control (`feature_names`).
    state_feature_names: tuple[str, ...] = ()
    action_feature_names: tuple[str, ...] = ()
    # Observations made so far: a lazy one renders only while it is the latest (`observation`).
    observations_made: int = 0

    # The live episode, set by `reset`.
    instance: TaskInstance
    instruction: str
    steps: int
    max_steps: int
    image_size: int
    cameras: tuple[str, ...]

    def setup(
        self,
        cameras: Sequence[str],
        image_size: int,
        fps: int,
        depth: bool,
        control: str,
        render_mode: str | None,
    ) -> None:
        """Check `cameras`, `control` and `depth` against the world (a one-line ValueError naming what it takes) and
        keep the settings; `spaces` then builds the observation and action spaces."""
        world = self.world
        unknown = [c for c in cameras if c not in world.cameras]
        if unknown:
            raise ValueError(
                f"the {world.name} world has no camera {', '.join(map(repr, unknown))}; allowed: "
                f"{', '.join(world.cameras)}"
            )
        if control not in world.controls:
            raise ValueError(
                f"the {world.name} world's scenes take control={world.controls[0]!r} only, not {control!r}"
                if len(world.controls) == 1
                else f"unknown control {control!r}; allowed: {', '.join(world.controls)}"
            )
        if depth and not self.renders_depth:
            raise ValueError(f"the {world.name} world's scenes render no depth here (depth=False)")
        self.cameras, self.image_size, self.fps, self.depth = tuple(cameras), image_size, fps, depth
        self.control, self.render_mode = control, render_mode

    def spaces(self, action_space: gym.spaces.Box, state_size: int, ee_state_size: int | None = None) -> None:
        """`action_space`, and the observations' spaces of the cameras, image size and depth `setup` kept."""
        self.action_space = action_space
        self.observation_space = observation_space(
            self.cameras, self.image_size, self.depth, state_size, ee_state_size or state_size
        )

    @classmethod
    def feature_names(cls, control: str) -> tuple[list | dict, list | dict] | None:
        """The names a LeRobot dataset of this env gives `observation.state` and `action` in `control`; None:
        RoboView's own (the joints or the EE state, and the control's action names)."""
        if not cls.state_feature_names:
            return None
        return {"motors": list(cls.state_feature_names)}, {"motors": list(cls.action_feature_names)}

    def observation(
        self, eager: dict[str, Any], renders: dict[str, Callable[[], np.ndarray]]
    ) -> LazyObservation:
        """An observation of `eager` arrays and of images rendered when read (`renders`: key → render), readable
        until the env makes its next one (roboview.sim.observation)."""
        self.observations_made += 1
        count = self.observations_made
        return LazyObservation(eager, renders, lambda: self.observations_made == count)

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

    def text_card(self) -> Any:
        """The live scene's text card (the `scene_text` factor's): `glyph_heights(cameras, rgb)` and `hidden(cameras)`
        (and, where the goal is not the target, `hidden_goals(cameras)`) for the fairness gate, `geometry()` for the
        isolation certificate; None where the scene holds none."""
        return None

    def camera_ids(self) -> dict[str, int]:
        """The recorded cameras' ids in the compiled model, by RoboView's name."""
        raise NotImplementedError

    def image_filters(self) -> dict[str, str]:
        """The recorded cameras whose frames go through a corruption after rendering, and which (LIBERO-plus's
        sensor noise), as the isolation certificate records them; empty: every frame as rendered."""
        return {}

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
