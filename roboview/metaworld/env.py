"""One Meta-World task's env, built, seeded and observed exactly as LeRobot 0.6.1's `MetaworldEnv` builds it.

LeRobot (`lerobot/envs/metaworld.py`) makes a task's env from `metaworld.MT1(task, seed=42)`, sets its first train
task, moves the `corner2` camera to (0.75, 0.075, 0.7), resets once, then unfreezes the random vector and seeds it:
every `reset(seed=s)` draws the object's and the goal's positions from `env.seed(s)`. The observation is the
`corner2` render flipped on both axes (upright) and `agent_pos`, the first four entries of the 39-d state (hand
position and gripper opening); the action is 4-d (hand position delta, gripper) in [-1, 1]; success is Meta-World's
`info["success"]`; an episode lasts at most 500 steps (Meta-World's `max_path_length`, lerobot-eval's budget).
`MetaWorldScene` does the same, without LeRobot, with the render size given and the visual factors
(`roboview.metaworld.factors`) applied in place after every reset (the model is never recompiled).

Nothing here imports Meta-World at import time; it loads when a scene is first built.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

CAMERA = "corner2"
# LeRobot's position of corner2 (its orientation stays Meta-World's).
CORNER2_POS = (0.75, 0.075, 0.7)
NATIVE_SIZE = 480  # LeRobot renders corner2 at 480²
MAX_STEPS = 500  # Meta-World's max_path_length, the budget lerobot-eval runs
FPS = 80  # LeRobot's MetaworldEnv config
MT1_SEED = 42  # LeRobot's metaworld.MT1(task, seed=42)
PIP_INSTALL = "pip install metaworld==3.0.0"


class MetaWorldMissing(ImportError):
    """Meta-World is not installed; the message names the command that installs it."""


def import_metaworld():
    os.environ.setdefault("MUJOCO_GL", "egl")
    try:
        import metaworld
    except ImportError as err:
        raise MetaWorldMissing(
            f"Meta-World is not installed: run `make install-metaworld` (or `{PIP_INSTALL}`)"
        ) from err
    return metaworld


def task_names() -> tuple[str, ...]:
    """Every task Meta-World 3.0.0 ships (its MT50 names, `-v3`)."""
    from metaworld.env_dict import ALL_V3_ENVIRONMENTS

    return tuple(ALL_V3_ENVIRONMENTS)


def scripted_policy(task: str):
    """Meta-World's scripted policy for `task` (`metaworld.policies.Sawyer<Task>V3Policy`, as LeRobot maps them)."""
    import_metaworld()
    from metaworld import policies

    name = "Sawyer" + "".join(part.capitalize() for part in task.removesuffix("-v3").split("-")) + "V3Policy"
    return getattr(policies, name)()


class MetaWorldScene:
    """One Meta-World task's env (`self.inner`) as LeRobot builds it, rendered at `image_size`."""

    def __init__(self, task: str, image_size: int = NATIVE_SIZE, object_body: str = "obj") -> None:
        metaworld = import_metaworld()
        # `object_body`: the body of the task's object (what the `color` factor re-skins).
        self.task, self.image_size, self.object_body = task, image_size, object_body
        mt1 = metaworld.MT1(task, seed=MT1_SEED)
        env = mt1.train_classes[task](
            render_mode="rgb_array", camera_name=CAMERA, width=image_size, height=image_size
        )
        env.set_task(mt1.train_tasks[0])
        self.camera_id = env.model.camera(CAMERA).id
        env.model.cam_pos[self.camera_id] = CORNER2_POS
        env.reset()
        env._freeze_rand_vec = False  # LeRobot: otherwise no randomization
        env.seeded_rand_vec = True  # positions drawn from the seeded np_random
        self.inner = env
        self.model, self.data = env.model, env.data
        self.raw: np.ndarray | None = None  # the last 39-d state (what the scripted policies read)
        self.pristine = None  # the visual arrays before any factor (set on the first reset)
        self.factors: list = []

    @property
    def render_context(self):
        """The MjrContext of the offscreen renderer (made on the first render)."""
        viewer = self.inner.mujoco_renderer._get_viewer("rgb_array")
        return viewer.con

    def make_current(self) -> None:
        self.inner.mujoco_renderer._get_viewer("rgb_array").make_context_current()

    def reset(self, seed: int, factors: list | None = None) -> np.ndarray:
        """LeRobot's seeded reset (`env.seed(seed)`, `env.reset(seed=seed)`), then `factors` applied in place."""
        from roboview.metaworld.factors import restore_visuals, snapshot_visuals

        if self.pristine is None:
            self.render()  # the render context exists from here on: factors edit its texture tables too
            self.pristine = snapshot_visuals(self)
        else:
            restore_visuals(self, self.pristine)
        self.inner.seed(int(seed))
        raw, _ = self.inner.reset(seed=int(seed))
        self.factors = list(factors or [])
        for factor in self.factors:
            factor.apply(self)
        if (
            self.factors
        ):  # the reset's forward pass placed the cameras and lights before the factors moved them
            import mujoco

            mujoco.mj_kinematics(self.model, self.data)
            mujoco.mj_comPos(self.model, self.data)
            mujoco.mj_camlight(self.model, self.data)
        self.raw = raw
        return raw

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        raw, reward, done, truncated, info = self.inner.step(np.asarray(action))
        self.raw = raw
        return raw, float(reward), bool(done), bool(truncated), info

    def render(self) -> np.ndarray:
        """corner2 as LeRobot hands it: flipped on both axes (upright). Its GL context is made current first:
        gymnasium's renderer does not, so after another MuJoCo renderer in the process drew (LeRobot's MetaworldEnv
        on another task, a `mujoco.Renderer`) it read back that renderer's buffer — a frame frozen, or another scene's
        meshes."""
        self.make_current()
        return np.ascontiguousarray(np.flip(self.inner.render(), (0, 1)))

    def close(self) -> None:
        self.inner.close()
