"""The env every task builds on (`TaskEnv`), and the scripted expert that plans a task from ground truth.

`TaskEnv` is the shared world as a gymnasium env: the robot, the cameras, rendering, the visual factors applied at
every reset, stepping. A task subclasses it (`roboview.tasks.pick_place`, `roboview.tasks.push`) with what is its
own: what it adds to the scene (`add_target`), where its context puts things (`place_context`), its success test
(`is_success`), its target for the fairness gate and for perception (`target`, `target_geoms`, `target_xy`) and its
scripted solution (`plan`), which the privileged `ScriptedExpert` drives from the true object pose and the `vision`
policy from a perceived one.
"""

from __future__ import annotations

import atexit
import functools
import logging
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np

from roboview.core.errors import RenderError
from roboview.sim.cameras import ALL_CAMERAS, BASE_CAMERAS, check_image_size
from roboview.sim.control import (
    CONTROLS as CONTROLS,  # re-exported: the control modes a TaskEnv takes
)
from roboview.sim.control import (
    EE_ACTION_NAMES,
    EE_CONTROLS,
    EE_STATE_NAMES,
    EEController,
    EndEffector,
    check_control,
    ee_action_space_bounds,
)
from roboview.sim.motion import MotionPlanner
from roboview.sim.observation import LazyObservation
from roboview.sim.scene import (
    GRIPPER_DRIVER_CLOSED,
    HOME_QPOS,
    RenderQuality,
    Scene,
)
from roboview.tasks.scenes import LiveScenes, variant_key
from roboview.tasks.world import (  # the observation keys too, which every policy imports from here
    DEPTH_KEY,
    EE_STATE_KEY,
    IMAGE_KEY,
    STATE_KEY,
    WORLDS,
    World,
    WorldEnv,
    register_world,
)
from roboview.variation.factors import (
    DEFAULT_TASK,
    SceneApplier,
    baselines,
    load_factor,
    visual_factors,
)
from roboview.variation.instances import TaskInstance

log = logging.getLogger(__name__)

DEFAULT_MAX_STEPS = 120
# The object's extent across the gripper (along a push) a non-privileged agent assumes, not knowing the
# shape: a 4 cm solid.
ASSUMED_REACH_M = 0.04
STATE_NAMES = tuple(f"joint{i}" for i in range(1, 8)) + ("gripper",)
ACTION_NAMES = tuple(f"joint{i}_target" for i in range(1, 8)) + ("gripper_close",)

# Per-episode jitter drawn from the episode seed (kept small so the named position stays meaningful).
POSITION_JITTER_M = 0.01
YAW_JITTER_RAD = 0.35
# Success: the object is this still (m/s) and the gripper this open (0 open … 1 closed).
REST_SPEED = 0.05
UNSTABLE_REASON = "simulation unstable"
RELEASED_GRIPPER = 0.25


def state_names(control: str) -> tuple[str, ...]:
    """The names of the `observation.state` entries a policy in `control` reads: the joints, or the EE state."""
    return STATE_NAMES if check_control(control) == "joint" else EE_STATE_NAMES


def action_names(control: str) -> tuple[str, ...]:
    """The names of a control mode's action entries (a dataset's `action` feature names)."""
    return ACTION_NAMES if check_control(control) == "joint" else EE_ACTION_NAMES[control]


def _joint_action_space(arm_range: np.ndarray) -> gym.spaces.Box:
    """The joint-target action's space: each arm joint within its limits (`arm_range`, (7, 2) rad), the gripper
    command in [0, 1]."""
    low = np.append(arm_range[:, 0], 0.0).astype(np.float32)
    high = np.append(arm_range[:, 1], 1.0).astype(np.float32)
    return gym.spaces.Box(low, high, dtype=np.float32)


# RoboView's own world: the shared scene of `roboview.sim`, which the built-in tasks (pick_place, push) build on.
WORLD = register_world(
    World(
        name="roboview",
        title="RoboView's scene: Franka Panda + Robotiq 2F-85, one small object, four cameras",
        cameras={c: c for c in ALL_CAMERAS},
        # VLM agents watch `front`; π0-style policies `left_top` + `wrist`.
        observed_cameras=("front", "left_top", "wrist"),
        judged_cameras=("front", "left_top", "wrist"),
        recorded_cameras=ALL_CAMERAS,
        wrist_cameras=("wrist",),
        controls=CONTROLS,
        probe="roboview.tasks.fairness:FairnessProbe",
        episode_visuals=True,
        privileged_own_cameras=True,
    )
)


class Lacked:
    """RoboView's scene's applier of a visual factor that brings none for it (`Factor.bind` None: LIBERO-plus's
    `view_*`): the baseline applies nothing, another value is refused."""

    def __init__(self, factor: str) -> None:
        self.factor, self.baseline = factor, load_factor(factor).baseline

    def apply(self, value: str, rng: np.random.Generator) -> None:
        if value != self.baseline:
            takes = [name for name, world in WORLDS.items() if world.status(self.factor) == "takes"]
            raise ValueError(
                f"the roboview world cannot apply {self.factor}={value!r}: the factor brings no applier for RoboView's "
                f"scene; the worlds that take it: {', '.join(takes) or 'none'}"
            )


def baseline_instance(task: str = DEFAULT_TASK) -> TaskInstance:
    """Every factor at its baseline: the scene the expert demos are rendered in."""
    return TaskInstance(
        split="baseline", varied=("color",), factors=baselines(task), context_subspace="base", task=task
    )


class TaskEnv(WorldEnv):
    """Franka Panda + Robotiq 2F-85 and one small object on a table, seen by four cameras; a task subclasses it.

    **Observations** (keys are the LeRobot dataset's feature keys): ``observation.images.<camera>``
    uint8 H×W×3 for each requested camera (``front``, ``left_top``, ``right_top``, ``wrist``),
    optionally ``observation.depth.<camera>`` float32 H×W metres, ``observation.state`` float32
    (8,) = 7 arm joint positions (rad) + gripper closure (0 open … 1 closed), and
    ``observation.ee_state`` float32 (8,) = pinch-point position (m) + orientation axis-angle (rad), both
    in the robot base frame, + the two finger openings (m) (`roboview.sim.control`).

    **Actions** (`control`): ``joint`` float32 (8,): absolute target positions (rad) of the 7 arm joints,
    tracked by joint position servos, and the gripper command (0 open … 1 closed), held for one control
    period (1/fps s). ``ee_delta`` float32 (7,) in [-1, 1]: pinch-point position delta × 0.05 m and
    axis-angle rotation delta × 0.5 rad (base frame, from the current pose), gripper +1 close / −1 open;
    ``ee_abs`` float32 (7,): target pinch position (m) and axis-angle (rad), base frame, and the gripper.
    Both end-effector modes become joint targets through inverse kinematics (`EEController`). Should
    MuJoCo find the simulation unstable (NaN/Inf accelerations, after which it resets the state on its
    own), the step truncates the episode with ``info["failure_reason"] == "simulation unstable"``.

    **Randomizations** — the instance fixes every factor (the visual ones: object color, camera
    pose / Euler perturbation / distance, …; the task's context: where the object starts, its
    shape, the instruction). The episode seed adds only what the task's `place_context` draws (a
    small jitter: object xy ± 1 cm and heading ± 0.35 rad for the built-in tasks) from a
    `numpy.random.Generator` seeded by `reset(seed=...)` (default: the instance's seed).
    Training-time domain randomization overrides the instance's visuals through reset options:
    ``object_rgb`` (sRGB in [0, 1]) and ``cameras`` (scene camera name -> `CameraPose`).

    **Success conditions** — the task's (`is_success`). The episode terminates on success and
    truncates after `max_steps`.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}
    # The task this env runs (its name in roboview.tasks) and the context factor naming its instruction.
    task: str = ""
    instruction_factor: str = ""
    # What the task adds for a policy to find besides the object ("box", "zone"; None: nothing). The
    # fairness gate measures `target_geoms()` under the record's box_* fields; the `vision` policy's
    # perception looks for it by this name.
    target: str | None = None
    # The simulated world the task runs in: its cameras, controls and probe (RoboView's scene).
    world = WORLD
    renders_depth = True
    # The robot, as a LeRobot dataset of this env names it (`robot_type`).
    robot_type: str = "franka_panda_robotiq_2f85"

    # -- what a task declares ----------------------------------------------------------------
    @staticmethod
    def add_target(spec: mujoco.MjSpec) -> None:
        """Add the task's own bodies/geoms to the scene spec (made once, before it is compiled)."""

    def bind_target(self) -> None:
        """Look up, once after compiling, the ids of what `add_target` added."""

    def place_context(self, values: dict[str, str], rng: np.random.Generator) -> None:
        """Put the object (`self.scene.place_object`) and the target where the instance's context says."""
        raise NotImplementedError(f"{type(self).__name__} must define place_context")

    def is_success(self) -> bool:
        raise NotImplementedError(f"{type(self).__name__} must define is_success")

    def target_geoms(self) -> tuple[int, ...]:
        """Geom ids of the target the fairness gate requires visible (empty: none)."""
        return ()

    def target_xy(self) -> np.ndarray | None:
        """Privileged: the target's world xy now (None when the task has no target)."""
        return None

    @staticmethod
    def plan(
        planner: MotionPlanner,
        obj_pos: np.ndarray,
        obj_yaw: float,
        symmetry: float,
        reach: float,
        target_xy: np.ndarray | None,
        arm_qpos: np.ndarray,
        ee_pos: np.ndarray | None = None,
    ) -> None:
        """Lay out the task's scripted solution on `planner` from an object pose and the target's xy.

        `reach` is the object's extent across the gripper (m); `ee_pos` the pinch point now (computed
        from `arm_qpos` when None). The expert passes the true values, the `vision` policy perceived ones.
        """
        raise NotImplementedError("this task has no scripted solution")

    def __init__(
        self,
        cameras: Sequence[str] = ALL_CAMERAS,
        image_size: int = 224,
        fps: int = 10,
        max_steps: int = DEFAULT_MAX_STEPS,
        depth: bool = False,
        quality: RenderQuality = "fast",
        render_mode: str | None = "rgb_array",
        lazy: bool = False,
        control: str = "joint",
    ) -> None:
        self.setup(cameras, image_size, fps, depth, control, render_mode)
        self._check_settings(render_mode, cameras, image_size, fps, max_steps)
        self.max_steps = max_steps
        # Lazy: observations render their cameras when read (roboview.sim.observation), so steps
        # whose images no one reads cost physics only; the pixels are those eager rendering gives.
        self.lazy = lazy
        self._generation = 0  # bumped on every reset/step: a lazy observation is readable only at its own
        self._renderer: mujoco.Renderer | None = None
        self._depth_renderer: mujoco.Renderer | None = None
        self._open_renderers: list[mujoco.Renderer] = []
        self._appliers: dict[str, SceneApplier] = {}
        self._scenes = LiveScenes(quality, type(self).add_target, self.task)  # the plain one live first
        self.bind_scene(self._scenes.compile(()))
        self.n_substeps = round(1.0 / (fps * self.model.opt.timestep))
        self.instance = baseline_instance(self.task)
        self.instruction = self.instance.get(self.instruction_factor)
        self.steps = 0

        # The joint-target action (what the scripted planners plan in, whatever the control).
        self.joint_action_space = _joint_action_space(self.scene.ids.arm_range)
        if control == "joint":
            action_space = self.joint_action_space
        else:
            action_space = gym.spaces.Box(*ee_action_space_bounds(control), dtype=np.float32)
        self.spaces(action_space, len(STATE_NAMES), len(EE_STATE_NAMES))

    def bind_scene(self, scene: Scene) -> None:
        """Make `scene` the live one: the model, data and what is bound to them."""
        self.scene, self.model, self.data = scene, scene.model, scene.data
        self.bind_target()
        self.end_effector = EndEffector(self.model)
        ee = self.control in EE_CONTROLS
        self.controller = EEController(self.model, self.control, self.end_effector) if ee else None

    def text_card(self) -> Any:
        return self._scenes.card(self)

    @classmethod
    def _check_settings(
        cls, render_mode: str | None, cameras: Sequence[str], image_size: int, fps: int, max_steps: int
    ) -> None:
        """ValueError for a render mode, no camera, an image size, control rate or step budget the env cannot take."""
        if render_mode not in (None, *cls.metadata["render_modes"]):
            raise ValueError(
                f"render_mode={render_mode!r} unsupported; allowed: None, "
                f"{', '.join(map(repr, cls.metadata['render_modes']))}"
            )
        if not cameras:
            raise ValueError(f"no camera given; allowed: {', '.join(ALL_CAMERAS)}")
        check_image_size(image_size)
        if fps <= 0 or 500 % fps:
            raise ValueError(f"fps={fps} must divide the 500 Hz physics rate (e.g. 5, 10, 20, 25, 50)")
        if max_steps <= 0:
            raise ValueError(f"max_steps={max_steps} must be positive")

    # -- rendering ---------------------------------------------------------------------------
    def new_renderer(self) -> mujoco.Renderer:
        """A renderer at the env's image size, closed with the env (or at exit, while EGL is up)."""
        return self._track(mujoco.Renderer(self.model, self.image_size, self.image_size))

    def _track(self, renderer: mujoco.Renderer) -> mujoco.Renderer:
        # GL contexts must be freed before interpreter teardown, not by __del__ during it; the
        # hook is registered after mujoco.egl's own (made with the first context), so it runs first.
        if not self._open_renderers:
            atexit.register(TaskEnv._close_renderers, self._open_renderers)
        self._open_renderers.append(renderer)
        return renderer

    @property
    def renderer(self) -> mujoco.Renderer:
        # Created lazily and reused: a Renderer costs ~0.7 s and must live in the process using it.
        if self._renderer is None:
            self._renderer = self.new_renderer()
        return self._renderer

    def render_camera(self, camera: str, depth: bool = False) -> np.ndarray:
        """One camera's image (or depth map) now. A renderer that fails (a lost GL context, out of GPU memory)
        raises `RenderError`: the evaluator records that episode as ended by infrastructure."""
        # an unknown camera is the caller's error, not a render failure
        camera_id = self.scene.ids.cameras[camera]
        try:
            if depth:
                if self._depth_renderer is None:
                    self._depth_renderer = self.new_renderer()
                    self._depth_renderer.enable_depth_rendering()
                renderer = self._depth_renderer
            else:
                renderer = self.renderer
            renderer.update_scene(self.data, camera=camera_id)
            return renderer.render()
        except Exception as exc:
            raise RenderError(
                f"rendering camera {camera!r}{' (depth)' if depth else ''} failed: "
                f"{type(exc).__name__}: {exc}"
            ) from exc

    def render(self) -> np.ndarray:
        return self.render_camera(self.cameras[0])

    # -- gym API -----------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        options = options or {}
        instance = options.get("instance", self.instance)
        if not isinstance(instance, TaskInstance):
            raise TypeError(f"options['instance'] must be a TaskInstance, got {type(instance).__name__}")
        episode_seed = instance.seed if seed is None else seed
        super().reset(seed=episode_seed)
        rng = np.random.default_rng(episode_seed)
        if instance.task != self.task:
            raise ValueError(
                f"instance {instance.instance_id} is a {instance.task!r} instance; this env runs "
                f"{self.task!r} (make the env with make_env({instance.task!r}))"
            )
        self.instance = instance
        self.instruction = instance.get(self.instruction_factor)
        self.steps = 0

        cameras = options.get("cameras", {})
        for name, pose in cameras.items():
            if name not in BASE_CAMERAS or pose.name != name:
                raise ValueError(
                    f"options['cameras'][{name!r}]: only the scene cameras {sorted(BASE_CAMERAS)} can "
                    f"be posed (pose named {pose.name!r})"
                )
        rgb = np.asarray(options.get("object_rgb", (0.0, 0.0, 0.0)), dtype=float)
        if rgb.shape != (3,) or not np.all((rgb >= 0) & (rgb <= 1)):
            raise ValueError(
                f"options['object_rgb']={options['object_rgb']!r} must be 3 sRGB values in [0, 1]"
            )

        values = instance.factor_values
        self._scenes.switch(self, variant_key(values, self.task))
        mujoco.mj_resetData(self.model, self.data)
        # Context (the task's own): where the object starts, with the episode's jitter, and the rest.
        self.place_context(values, rng)
        # Visual factors: every registered one writes its value into the compiled model, in order.
        for pose in BASE_CAMERAS.values():
            self.scene.set_camera(pose)
        for name in visual_factors():
            self.applier(name).apply(values[name], rng)
        # Training-time domain randomization overrides the instance's visuals.
        for pose in cameras.values():
            self.scene.set_camera(pose)
        if "object_rgb" in options:
            self.model.geom_rgba[self.scene.active_geom] = [*rgb, 1.0]
        self.scene.reset_robot(HOME_QPOS)
        mujoco.mj_forward(self.model, self.data)
        self._generation += 1
        return self._observation(), self._info()

    def step(self, action: np.ndarray) -> tuple[dict, float, bool, bool, dict]:
        action = np.asarray(action, dtype=np.float64)
        if action.shape != self.action_space.shape or not np.all(np.isfinite(action)):
            raise ValueError(f"action must be {self.action_space.shape} finite values, got {action!r}")
        action = np.clip(action, self.action_space.low, self.action_space.high)
        if self.controller is not None:
            action = self.controller.joint_action(self.data.qpos, action)
        self.data.ctrl[self.scene.ids.arm_actuators] = action[:7]
        self.data.ctrl[self.scene.ids.gripper_actuator] = 255.0 * action[7]
        self._generation += 1  # before the state changes: any lazy observation still unread is now stale
        mujoco.mj_step(self.model, self.data, nstep=self.n_substeps)
        self.steps += 1
        if self.unstable:
            # MuJoCo found NaN/Inf accelerations and silently reset the state to the model's defaults:
            # what follows is no longer this episode, so it ends here as a failure.
            info = self._info() | {"failure_reason": UNSTABLE_REASON}
            return self._observation(), 0.0, False, True, info
        success = self.is_success()
        truncated = self.steps >= self.max_steps and not success
        return self._observation(), float(success), success, truncated, self._info(success)

    def applier(self, factor: str) -> SceneApplier:
        """The factor's applier bound to this env's scene (bound on first use, then reused; `Lacked` for a factor that
        brings none for it)."""
        if factor not in self._appliers:
            bind = load_factor(factor).bind
            self._appliers[factor] = Lacked(factor) if bind is None else bind(self.scene)
        return self._appliers[factor]

    @property
    def unstable(self) -> bool:
        """True once MuJoCo reported an unstable simulation (bad accelerations) this episode."""
        return self.data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number > 0

    # -- state -------------------------------------------------------------------------------
    @property
    def shape(self) -> str:
        return self.scene.active_shape

    def gripper_closure(self) -> float:
        return float(np.clip(self.data.qpos[self.scene.ids.gripper_qpos] / GRIPPER_DRIVER_CLOSED, 0.0, 1.0))

    def state(self) -> np.ndarray:
        q = self.data.qpos[self.scene.ids.arm_qpos]
        return np.append(q, self.gripper_closure()).astype(np.float32)

    def object_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Privileged: world position and quaternion [w,x,y,z] of the active object."""
        body = self.scene.ids.shape_body[self.shape]
        return self.data.xpos[body].copy(), self.data.xquat[body].copy()

    def ee_state(self) -> np.ndarray:
        """float32 (8): pinch position + orientation axis-angle (base frame) + finger openings (EE_STATE_NAMES)."""
        return self.end_effector.state(self.data.qpos)

    def ee_position(self) -> np.ndarray:
        return self.data.site_xpos[self.scene.ids.pinch_site].copy()

    def object_touches_robot(self) -> bool:
        geom = self.scene.ids.shape_geom[self.shape]
        robot = self.scene.ids.robot_geoms
        for c in self.data.contact[: self.data.ncon]:
            if (c.geom1 == geom and c.geom2 in robot) or (c.geom2 == geom and c.geom1 in robot):
                return True
        return False

    def object_speed(self) -> float:
        """Privileged: the active object's linear speed (m/s)."""
        dof = self.scene.ids.shape_dof[self.shape]
        return float(np.linalg.norm(self.data.qvel[dof : dof + 3]))

    def camera_ids(self) -> dict[str, int]:
        return dict(self.scene.ids.cameras)

    def camera_pose(self, name: str):
        return self.scene.camera_pose(name)

    def scene_xml(self) -> str:
        """The plain scene's MJCF (a scene compiled with a factor's additions holds pixel buffers MJCF cannot)."""
        return self._scenes.plain(self).spec.to_xml()

    def _observation(self) -> dict[str, np.ndarray]:
        renders = {IMAGE_KEY.format(c): functools.partial(self.render_camera, c) for c in self.cameras}
        if self.depth:
            renders |= {DEPTH_KEY.format(c): functools.partial(self._render_depth, c) for c in self.cameras}
        state = {STATE_KEY: self.state(), EE_STATE_KEY: self.ee_state()}
        if self.lazy:
            generation = self._generation
            return LazyObservation(state, renders, lambda: self._generation == generation)
        return {key: render() for key, render in renders.items()} | state

    def _render_depth(self, camera: str) -> np.ndarray:
        return self.render_camera(camera, depth=True).astype(np.float32)

    def _info(self, success: bool = False) -> dict:
        return {
            "is_success": success,
            "instance_id": self.instance.instance_id,
            "task": self.instruction,
            "steps": self.steps,
        }

    @staticmethod
    def _close_renderers(renderers: list[mujoco.Renderer]) -> None:
        while renderers:
            renderers.pop().close()

    def close(self) -> None:
        self._close_renderers(self._open_renderers)
        self._renderer = self._depth_renderer = None
