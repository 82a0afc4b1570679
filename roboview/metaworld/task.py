"""The `metaworld` world and task: Meta-World's tasks as RoboView contexts (``RoboView/MetaWorld-v0``), so a policy
trained on Meta-World (LeRobot's `--env.type=metaworld`, SmolVLA's second benchmark) gets a factor-isolated
visual-bias profile (docs/metaworld.md).

**Contexts.** `metaworld_task` names one of Meta-World's tasks (its MT50 name, `push-v3`); the episode seed draws
the object's and the goal's positions, as LeRobot's `MetaworldEnv` draws them from `reset(seed=...)`. Every value
of a (context, repeat) runs the same seed, so the positions are paired across values; a repeat runs another seed.

**Observations** (RoboView's keys): `observation.images.corner2` (alias `top`, LeRobot's name), uint8 H×W×3, flipped
on both axes as LeRobot flips it (upright); `observation.state` and `observation.ee_state`, float32 (4,): LeRobot's
`agent_pos` (hand position, gripper opening); `metaworld.state`, float64 (39,): Meta-World's full state (what its
scripted policies read).

**Action** (`xyz_delta`): float32 (4,) in [-1, 1]: hand position delta (× 1/100 m through the mocap) and gripper
effort (+1 closes). **Success**: Meta-World's `info["success"]`, after every step. An episode lasts 500 steps
(Meta-World's `max_path_length`; lerobot-eval's budget).

**Visual factors** (`roboview.metaworld.factors` says how), every baseline being Meta-World's scene unchanged:
`color` (the task's object, `OBJECTS`, re-skinned a CSS color, red included; its baseline, the object's own look, is
named `original`), `camera_pose`, `camera_euler`, `dist_scale` (corner2), `lighting`, `table_texture` (the world's
applier table, `APPLIERS`). `distractors` and `object_size` do not apply: an instance setting them is refused.

**Expert.** Meta-World's own scripted policy for the task (`metaworld.policies`, as LeRobot maps them), reading the
39-d state.
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np

from roboview.metaworld.env import CAMERA, FPS, MAX_STEPS, NATIVE_SIZE
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

TASK = "metaworld"
# RoboView's name of Meta-World's camera → Meta-World's; `top` is LeRobot's name of the same view (its `pixels/top`
# env feature, stored and read as `observation.image`), so a LeRobot Meta-World checkpoint finds its camera.
CAMERAS = {"corner2": CAMERA, "top": CAMERA}
OBSERVED_CAMERAS = ("corner2",)
RAW_STATE_KEY = "metaworld.state"
CONTROL = "xyz_delta"
# The `{"motors": [...]}` names of the 4-d state and action (LeRobot's Meta-World datasets name them so).
STATE_NAMES = ("x", "y", "z", "gripper")
ACTION_NAMES = ("dx", "dy", "dz", "gripper")
# Each visual factor's applier on Meta-World's scenes (`roboview.metaworld.factors`), in the order they run; its scenes
# take no distractors and no object size.
APPLIERS = {
    "color": "roboview.metaworld.factors:ObjectColor",
    "camera_pose": "roboview.metaworld.factors:OrbitalPose",
    "camera_euler": "roboview.metaworld.factors:CameraEuler",
    "dist_scale": "roboview.metaworld.factors:PullBack",
    "lighting": "roboview.variation.model_edits:Lighting",
    "table_texture": "roboview.metaworld.factors:TableTexture",
    "distractors": None,
    "object_size": None,
}
# The baselines that are Meta-World's own look, by name: the object's own material is `original`, not red.
BASELINE_LABELS = {"color": "original"}
# The registered tasks and the body of each one's object (what `color` re-skins and the fairness gate judges): the
# tasks whose object is one body a policy must find, which Meta-World's scripted policy solves at baseline and which
# corner2 shows (bin-picking-v3's puck sits in a bin that hides 62 % of it from corner2 at baseline: the gate
# rejected 185 of its 197 instances).
OBJECTS = {
    "push-v3": "obj",
    "pick-place-v3": "obj",
    "push-back-v3": "obj",
    "sweep-v3": "obj",
    "sweep-into-v3": "obj",
    "hand-insert-v3": "obj",
    "pick-out-of-hole-v3": "obj",
    "shelf-place-v3": "obj",
    "coffee-push-v3": "obj",
    "basketball-v3": "bsktball",
    "soccer-v3": "soccer_ball",
}
# LeRobot's instructions (`lerobot/envs/metaworld_config.json`, TASK_DESCRIPTIONS) and scripted policies
# (TASK_POLICY_MAPPING) for the registered tasks.
INSTRUCTIONS = {
    "push-v3": "Push the puck to a goal",
    "pick-place-v3": "Pick and place a puck to a goal",
    "push-back-v3": "Push the puck to a goal",
    "sweep-v3": "Sweep a puck off the table",
    "sweep-into-v3": "Sweep a puck into a hole",
    "hand-insert-v3": "Insert the gripper into a hole",
    "pick-out-of-hole-v3": "Pick up a puck from a hole",
    "shelf-place-v3": "Pick and place a puck onto a shelf",
    "coffee-push-v3": "Push a mug under a coffee machine",
    "basketball-v3": "Dunk the basketball into the basket",
    "soccer-v3": "Kick a soccer into the goal",
}

WORLD = register_world(
    World(
        name="metaworld",
        title="Meta-World's tasks (MT50), built, seeded and observed as LeRobot's MetaworldEnv",
        cameras=CAMERAS,
        observed_cameras=OBSERVED_CAMERAS,
        judged_cameras=OBSERVED_CAMERAS,
        recorded_cameras=OBSERVED_CAMERAS,
        wrist_cameras=(),
        image_features={"top": "observation.image"},
        controls=(CONTROL,),
        probe="roboview.metaworld.probe:MetaWorldFairnessProbe",
        # Meta-World's scenes are its designers': the gate judges each value against its context's no-change view.
        gate_reference="no_change_view",
        render_size=NATIVE_SIZE,
        fps=FPS,
        requires="metaworld",
        install="make install-metaworld",
        wing=__package__,  # roboview.metaworld
        appliers=APPLIERS,
        baseline_labels=BASELINE_LABELS,
    )
)
register_baseline_labels(TASK, BASELINE_LABELS)

METAWORLD_TASK = register_factor(
    Factor(
        name="metaworld_task",
        kind="context",
        task=TASK,
        values=tuple(OBJECTS),
        baseline="push-v3",
        doc="One Meta-World task (its MT50 name); the episode seed draws its object's and goal's positions.",
        title="Meta-World task",
    )
)


def baseline_metaworld_instance(metaworld_task: str = METAWORLD_TASK.baseline) -> TaskInstance:
    """Every visual factor at its baseline: Meta-World's own scene of `metaworld_task`."""
    from roboview.variation.factors import baselines
    from roboview.variation.instances import TaskInstance

    values = baselines(TASK) | {"metaworld_task": metaworld_task}
    return TaskInstance(
        split="baseline", varied=("color",), factors=values, context_subspace="base", task=TASK
    )


class MetaWorldTaskEnv(WorldEnv):
    """The gym env of the `metaworld` task: one `MetaWorldScene` at a time (rebuilt when the instance names another
    task), the instance's visual factors applied in place, RoboView's observation keys."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": FPS}
    task = TASK
    world = WORLD
    asset_packages = ("metaworld",)
    target = None
    robot_type = "sawyer"
    state_feature_names, action_feature_names = STATE_NAMES, ACTION_NAMES

    def __init__(
        self,
        cameras=OBSERVED_CAMERAS,
        image_size: int = NATIVE_SIZE,
        fps: int = FPS,
        max_steps: int | None = None,
        depth: bool = False,
        quality: str = "fast",
        render_mode: str | None = "rgb_array",
        lazy: bool = True,
        control: str = CONTROL,
    ) -> None:
        self.setup(cameras, image_size, fps, depth, control, render_mode)
        # The hand xyz delta and the gripper in [-1, 1]; LeRobot's `agent_pos` state.
        self.spaces(gym.spaces.Box(-1.0, 1.0, (len(ACTION_NAMES),), np.float32), len(STATE_NAMES))
        self.max_steps = max_steps or MAX_STEPS
        self.scene = None
        self.instance = baseline_metaworld_instance()
        self.instruction = INSTRUCTIONS[self.instance.get("metaworld_task")]
        self.steps, self._success = 0, False
        self._scene(self.instance.get("metaworld_task"))

    # ---- episodes -------------------------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        instance = (options or {}).get("instance") or baseline_metaworld_instance()
        if instance.task != TASK:
            raise ValueError(f"instance of task {instance.task!r} given to the {TASK!r} env")
        name = METAWORLD_TASK.validate(instance.get("metaworld_task"))
        scene = self._scene(name)
        raw = scene.reset(
            seed=instance.seed if seed is None else int(seed),
            factors=self.world.make_appliers(dict(instance.factors), TASK),
        )
        self.instance, self.instruction, self.steps, self._success = instance, INSTRUCTIONS[name], 0, False
        return self._observation(raw), {"task": name}

    def step(self, action):
        raw, reward, done, truncated, info = self.scene.step(np.asarray(action, dtype=np.float32))
        self.steps += 1
        success = self._success = bool(info.get("success", 0))
        info = dict(info, is_success=success)
        return (
            self._observation(raw),
            reward,
            success or done,
            truncated or self.steps >= self.max_steps,
            info,
        )

    def is_success(self) -> bool:
        """Meta-World's success after the last step."""
        return self._success

    def _scene(self, name: str):
        from roboview.metaworld.env import MetaWorldScene

        if self.scene is None or self.scene.task != name:
            if self.scene is not None:
                self.scene.close()
            self.scene = MetaWorldScene(name, image_size=self.image_size, object_body=OBJECTS[name])
        return self.scene

    def _observation(self, raw: np.ndarray) -> dict:
        state = np.asarray(raw[:4], np.float32)
        eager = {STATE_KEY: state, EE_STATE_KEY: state.copy(), RAW_STATE_KEY: np.asarray(raw, np.float64)}
        # corner2 and top are one view: rendered once per observation, whichever key is read first.
        lazy = dict.fromkeys((IMAGE_KEY.format(c) for c in self.cameras), functools.cache(self.scene.render))
        return self.observation(eager, lazy)

    # ---- what the evaluator, the builder and the certificate read --------------------------------------------
    @property
    def model(self):
        return self.scene.model

    @property
    def data(self):
        return self.scene.data

    def object_body(self) -> str:
        return OBJECTS[self.scene.task]

    def object_pose(self) -> tuple[np.ndarray, np.ndarray]:
        body = self.model.body(self.object_body()).id
        return self.data.xpos[body].copy(), self.data.xquat[body].copy()

    def state(self) -> np.ndarray:
        """The hand position and the two gripper finger joints."""
        return np.asarray(self.scene.raw[:4], float).copy()

    def ee_position(self) -> np.ndarray:
        return np.asarray(self.scene.raw[:3], float).copy()

    def object_geoms(self) -> tuple[int, ...]:
        from roboview.metaworld.factors import object_geoms

        return tuple(object_geoms(self.model, self.object_body()))

    def render(self):
        return self.scene.render()

    def render_camera(self, camera: str) -> np.ndarray:
        return self.scene.render()

    def camera_ids(self) -> dict[str, int]:
        return {name: self.scene.camera_id for name in self.world.recorded_cameras}

    def camera_pose(self, name: str) -> CameraPose:
        return camera_pose_of(self.model, self.data, self.scene.camera_id, name)

    def scene_xml(self) -> str:
        """Meta-World's MJCF of the task, includes expanded (MuJoCo's `MjSpec`)."""
        import mujoco

        return mujoco.MjSpec.from_file(self.scene.inner.fullpath).to_xml()

    def close(self) -> None:
        if self.scene is not None:
            self.scene.close()
            self.scene = None


class MetaWorldExpert(WorldExpert):
    """Meta-World's scripted policy for the env's current task (`metaworld.policies`), from the 39-d state."""

    def __init__(self, env: MetaWorldTaskEnv) -> None:
        super().__init__(env)
        self._policy = None
        self._task = None

    def reset(self) -> None:
        from roboview.metaworld.env import scripted_policy

        if self._task != self.env.scene.task:
            self._policy, self._task = scripted_policy(self.env.scene.task), self.env.scene.task

    def select_action(self, observation=None) -> np.ndarray:
        return np.clip(self._policy.get_action(self.env.scene.raw), -1.0, 1.0).astype(np.float32)


register_task(
    Task(
        name=TASK,
        gym_id="RoboView/MetaWorld-v0",
        env="roboview.metaworld.task:MetaWorldTaskEnv",
        success="Meta-World's own success test for the task (info['success']) holds",
        timeout_reason="Meta-World's goal not reached",
        expert="roboview.metaworld.task:MetaWorldExpert",
        small_contexts=(("metaworld_task", ("push-v3",)),),
        max_episode_steps=MAX_STEPS,
        seed_randomizes="the object's and the goal's positions (Meta-World's random vector, seeded)",
        world_factor="metaworld_task",
    )
)

# The wing's presets (roboview.metaworld.presets), registered with its task.
import roboview.metaworld.presets  # noqa: E402, F401
