"""One LIBERO task as a RoboView world: LeRobot's exact env, lazily rendered, with visual factors applied in place.

`LiberoWorld(suite, task_id, init_state_id)` builds LIBERO's `OffScreenRenderEnv` exactly as LeRobot 0.6.1's
`lerobot.envs.libero.LiberoEnv` does (cameras `agentview` + `robot0_eye_in_hand` at 256², `control_freq` 20,
`hard_reset=True`, OSC_POSE delta control) and resets it the same way: `env.seed(seed)` (LIBERO seeds the global
`np.random`) → `env.reset()` → `set_init_state(init_states[init_state_id])` → 10 settle steps of `[0,0,0,0,0,0,-1]`.
Seeding before *every* reset matters: each reset re-samples fixture placement (cabinets, stoves…) from the global
`np.random`, and the init state does not fix it.

Why lazy rendering, and why it stays exact: robosuite samples every observable (images included) at one sim substep
of each control step — not necessarily the last one — and renders both cameras there. Rendering is ~95 % of a step's
cost on a CPU, and most policies read far fewer frames than the env steps. Here the two camera sensors are replaced by
sensors that copy `MjData` at that very substep (≈ 0.1 ms); an image is rendered from that copy only when it is read
(`LazyObservation`), with robosuite's own camera sensor, so the pixels are those eager rendering would have produced.

Visual factors (`roboview.libero.factors`) edit the compiled model in place. A hard reset compiles a *new* `MjModel`
and render context, so the world re-applies them after every reset, before the init state is loaded; with
`hard_reset=False` it first restores the visual arrays it snapshotted from the pristine model. A factor that swaps
LIBERO's scene file for another (`arena()`: LIBERO-plus's light and background scenes) makes the reset that changes
the scene a hard one, whose arena LIBERO's problem class builds from that file.

LeRobot's processed view of an observation (`lerobot_view`): both images flipped 180° (`[::-1, ::-1]`) and the 8-D
state eef pos (3) + axis-angle of the xyzw eef quat (3) + gripper qpos (2), computed with the same torch float32
operations as `lerobot.processor.env_processor.LiberoProcessorStep`, so the numbers are bit-identical.
"""

from __future__ import annotations

import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import Any

import mujoco
import numpy as np

from roboview.libero.bootstrap import ensure_libero
from roboview.libero.suites import LiberoTask, get_task, init_state
from roboview.sim.observation import LazyObservation

CAMERAS = ("agentview", "robot0_eye_in_hand")
# LeRobot's names for the two cameras (LiberoEnv's camera_name_mapping).
LEROBOT_IMAGE_KEYS = {
    "agentview": "observation.images.image",
    "robot0_eye_in_hand": "observation.images.image2",
}
IMAGE_SIZE = 256
CONTROL_FREQ = 20
SETTLE_STEPS = 10
DUMMY_ACTION = (0, 0, 0, 0, 0, 0, -1)  # lerobot.envs.libero.get_libero_dummy_action()


def image_key(camera: str) -> str:
    """robosuite's observation key of `camera`'s RGB image."""
    return f"{camera}_image"


class _FrameStore:
    """MjData copies taken when robosuite samples the cameras, and rendering from them on demand."""

    def __init__(self) -> None:
        self.snapshot: mujoco.MjData | None = None
        self._spare: mujoco.MjData | None = None
        self._model: mujoco.MjModel | None = None
        self.renderers: dict[str, Any] = {}  # camera -> robosuite's own camera sensor
        self.version = 0  # bumped on every snapshot

    def capture(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        if self._model is not model:  # a hard reset compiled a new model: new buffers
            self._model, self.snapshot, self._spare = model, mujoco.MjData(model), mujoco.MjData(model)
        mujoco.mj_copyData(self.snapshot, model, data)
        self.version += 1

    def render(self, data: mujoco.MjData, cameras: Sequence[str]) -> dict[str, np.ndarray]:
        """Render `cameras` from the last snapshot (swapped into the live `data`, then swapped back)."""
        if self.snapshot is None:
            raise RuntimeError("no camera sample yet: reset the world first")
        model = self._model
        mujoco.mj_copyData(self._spare, model, data)
        mujoco.mj_copyData(data, model, self.snapshot)
        try:
            return {cam: np.array(self.renderers[cam]({})) for cam in cameras}
        finally:
            mujoco.mj_copyData(data, model, self._spare)


class LiberoWorld:
    """LIBERO task `task_id` of `suite`, started from init state `init_state_id`, as LeRobot runs it.

    `factors` are visual-factor appliers (objects with `apply(world)`, see roboview.libero.factors), applied after
    every reset. Observations are `LazyObservation`s keyed as robosuite's (raw, unflipped images); read images
    before the next `step`/`reset`.
    """

    def __init__(
        self,
        suite: str,
        task_id: int,
        init_state_id: int = 0,
        *,
        factors: Sequence[Any] = (),
        image_size: int = IMAGE_SIZE,
        control_freq: int = CONTROL_FREQ,
        hard_reset: bool = True,
        settle_steps: int = SETTLE_STEPS,
    ) -> None:
        self.task: LiberoTask = get_task(suite, task_id)
        self.init_state_id = init_state_id
        self._init_state = init_state(suite, task_id, init_state_id)  # validates init_state_id
        self.factors = tuple(factors)
        self.settle_steps = settle_steps
        self.hard_reset = hard_reset
        self._frames = _FrameStore()
        self._step_count = 0
        self._visual_snapshot: dict[str, np.ndarray] | None = None
        # Camera → the corruption its frames go through (`image(frame, seed, step)`), set by the factors at each reset
        # (LIBERO-plus's sensor noise, roboview.libero.noise); none: the frames as rendered.
        self.image_filters: dict[str, Any] = {}
        # The last factors left an edit a soft reset cannot undo: the next reset compiles a new model.
        self._dirty = False
        # The live model was compiled with a factor's MJCF additions (`edit_xml`).
        self._edited = False
        self.hard_resets = 0
        self.timings: dict[str, float] = {}
        ensure_libero()
        from libero.libero.envs import OffScreenRenderEnv

        start = time.perf_counter()
        self.env = OffScreenRenderEnv(
            bddl_file_name=str(self.task.bddl_file),
            camera_heights=image_size,
            camera_widths=image_size,
            control_freq=control_freq,
            hard_reset=hard_reset,
        )
        self.timings["create_s"] = time.perf_counter() - start
        # The scene file LIBERO's problem class builds its arena from, and the arena's properties (styles): LIBERO's
        # own, or a factor's (`arena()`); `arena` is the live model's.
        self._own_arena = (self.inner._arena_xml, tuple(sorted(self.inner._arena_properties.items())))
        self.arena = self._own_arena
        self._install_lazy_cameras()

    # ---- the robosuite objects -------------------------------------------------------------------------------
    @property
    def inner(self):
        """LIBERO's robosuite env (the `BDDLBaseDomain` subclass)."""
        return self.env.env

    @property
    def model(self) -> mujoco.MjModel:
        return self.inner.sim.model._model

    @property
    def data(self) -> mujoco.MjData:
        return self.inner.sim.data._data

    @property
    def render_context(self):
        """robosuite's offscreen render context (`.con` is the `mujoco.MjrContext`); rebuilt by every hard reset."""
        return self.inner.sim._render_context_offscreen

    def _install_lazy_cameras(self) -> None:
        """Make robosuite's observable setup (run again by every hard reset) swap in snapshotting camera sensors."""
        inner, frames = self.inner, self._frames
        original_setup = type(inner)._setup_observables

        def setup_observables():
            observables = original_setup(inner)
            for cam in CAMERAS:
                observable = observables[image_key(cam)]
                frames.renderers[cam] = observable._sensor
                observable._sensor = self._snapshot_sensor(observable._sensor.__modality__)
            return observables

        inner._setup_observables = setup_observables
        for name, observable in setup_observables().items():  # the env built before the patch
            inner.modify_observable(observable_name=name, attribute="sensor", modifier=observable._sensor)

    def _snapshot_sensor(self, modality: str):
        from robosuite.utils.observables import sensor

        @sensor(modality=modality)
        def snapshot(obs_cache):
            self._frames.capture(self.model, self.data)
            return np.zeros(1, np.uint8)  # placeholder; images come from `render`

        return snapshot

    # ---- episode -------------------------------------------------------------------------------------------
    def reset(self, seed: int = 0) -> LazyObservation:
        """LeRobot's reset: seed → reset → factors → init state → settle steps; same seed, same frames.

        With `hard_reset=False` the model is compiled once and reused: the visual arrays are restored in place and
        the state robosuite keeps outside `MjData` is reset as a fresh model has it, so the episode is bit-identical
        to LeRobot's hard-reset one. After a factor whose edit cannot be undone in place (`in_place = False`: a
        texture uploaded to the render context) the next reset is a hard one."""
        with self.own_gl():
            return self._reset(seed)

    def _reset(self, seed: int) -> LazyObservation:
        start = time.perf_counter()
        # A factor adding to LIBERO's MJCF (scene_text's card) compiles a model of its own; one without compiles
        # LIBERO's own MJCF again: robosuite's XML processor, None as LIBERO leaves it unless such a factor is set.
        edits = [factor.edit_xml for factor in self.factors if hasattr(factor, "edit_xml")]
        arena = self._arena_of(self.factors)
        hard = self.hard_reset or self._dirty or bool(edits) != self._edited or arena != self.arena
        self.inner._xml_processor = _chain(edits) if edits else None
        self._edited = bool(edits)
        self.inner._arena_xml, self.inner._arena_properties = arena[0], dict(arena[1])
        self.arena = arena
        self.inner.hard_reset = hard
        if hard:
            self._visual_snapshot = None  # a new model: snapshot its pristine visuals again
        else:
            for (
                robot
            ) in self.env.robots:  # a hard reset rebuilds the gripper model, whose action ramp starts at 0
                robot.gripper.current_action = np.zeros(robot.gripper.dof)
        self.env.seed(seed)  # LIBERO: np.random.seed(seed); fixture placement draws from it
        self.env.reset()
        self.timings["inner_reset_s"] = time.perf_counter() - start
        self.timings["hard"] = float(hard)
        self.hard_resets += int(hard)
        self._apply_factors()
        raw = self.env.set_init_state(self._init_state)
        for _ in range(self.settle_steps):
            raw, _, _, _ = self.env.step(list(DUMMY_ACTION))
        for robot in self.env.robots:
            robot.controller.use_delta = True  # LeRobot's control_mode="relative"
        self.timings["reset_s"] = time.perf_counter() - start
        return self._observation(raw)

    def _arena_of(self, factors: Sequence[Any]) -> tuple[str, tuple[tuple[str, Any], ...]]:
        """The arena `factors` load: LIBERO's own, or the one factor's that swaps it (two are refused)."""
        arenas = [factor.arena() for factor in factors if hasattr(factor, "arena")]
        if len(arenas) > 1:
            raise ValueError(
                f"{len(arenas)} factors swap LIBERO's scene file ({arenas}); one scene at a time"
            )
        return arenas[0] if arenas else self._own_arena

    def step(self, action: np.ndarray) -> tuple[LazyObservation, float, bool, bool, dict[str, Any]]:
        """One control step (OSC_POSE delta, 7-D in [-1, 1]); `terminated` when LIBERO says done or success."""
        action = np.asarray(action)
        if action.shape != (7,):
            raise ValueError(f"action shape {action.shape} invalid; allowed: (7,)")
        raw, reward, done, info = self.env.step(action)
        success = self.check_success()
        info.update(
            {"task": self.task.name, "task_id": self.task.task_id, "done": done, "is_success": success}
        )
        return self._observation(raw), reward, bool(done or success), False, info

    def check_success(self) -> bool:
        """LIBERO's own goal predicate for the task (what LeRobot reports as `is_success`)."""
        return bool(self.env.check_success())

    def _observation(self, raw: dict[str, Any]) -> LazyObservation:
        self._step_count += 1
        count, version = self._step_count, self._frames.version
        eager = {k: v for k, v in raw.items() if k not in {image_key(c) for c in CAMERAS}}
        cache: dict[str, np.ndarray] = {}

        def render(cam: str):
            def lazy() -> np.ndarray:
                if cam not in cache:  # both cameras in one swap of the snapshot
                    with self.own_gl():
                        cache.update(self._frames.render(self.data, CAMERAS))
                return cache[cam]

            return lazy

        return LazyObservation(
            eager,
            {image_key(c): render(c) for c in CAMERAS},
            lambda: self._step_count == count and self._frames.version == version,
        )

    # ---- rendering and factors ------------------------------------------------------------------------------
    def render(self, camera: str = "agentview") -> np.ndarray:
        """`camera` rendered from the live state now (raw robosuite orientation), e.g. after changing a factor."""
        if camera not in CAMERAS:
            raise ValueError(f"unknown camera {camera!r}; allowed: {', '.join(CAMERAS)}")
        with self.own_gl():
            return np.array(self._frames.renderers[camera]({}))

    def _live_context(self):
        """The render context, or None once the env is closed (robosuite drops its sim on close)."""
        env = getattr(self, "env", None)
        inner = getattr(env, "env", None)
        return None if inner is None else inner.sim._render_context_offscreen

    @contextmanager
    def own_gl(self) -> Iterator[None]:
        """This world's GL context current for the block, the one current before restored after it.

        robosuite draws, uploads and frees GL objects in whatever context is current, and makes its own current
        only when it builds it. Two worlds in one process (a worker with several envs; LeRobot's own LiberoEnv beside
        ours in a fidelity check) would otherwise draw into, or free the textures of, each other's context; a world
        that compiles its model once keeps its context for its whole life, so it must take it for each use."""
        ctx = self._live_context()
        if ctx is None:  # no context (before the first reset, after close): nothing to guard
            yield
            return
        egl = _egl() if hasattr(ctx.gl_ctx, "_context") else None
        previous = egl.eglGetCurrentContext() if egl is not None else None
        entry = _address(ctx.gl_ctx)
        ctx.gl_ctx.make_current()
        # No reference may outlive a hard reset in the block: the old context must be freed then, while current,
        # not later in the new one (freeing deletes GL objects by id in whatever context is current).
        del ctx
        try:
            yield
        finally:  # a hard reset in the block built a new context: neither it nor the freed one is "previous"
            exit_ = _address(self._live_context().gl_ctx) if self._live_context() is not None else None
            if egl is not None and previous and previous.address not in (entry, exit_):
                from robosuite.renderers.context import egl_context

                egl.eglMakeCurrent(egl_context.EGL_DISPLAY, egl.EGL_NO_SURFACE, egl.EGL_NO_SURFACE, previous)

    def set_init_state(self, init_state_id: int) -> None:
        """Start from LIBERO's init state `init_state_id` of this task from the next reset on."""
        self._init_state = init_state(self.task.suite, self.task.task_id, init_state_id)
        self.init_state_id = init_state_id

    def set_factors(self, factors: Sequence[Any]) -> None:
        """Appliers used from the next reset on (a reset rebuilds the model, so they apply there)."""
        self.factors = tuple(factors)

    def _apply_factors(self) -> None:
        from roboview.libero.factors import restore_visuals, snapshot_visuals

        if not self.hard_reset:  # a hard reset compiled a pristine model; a soft one kept the last edits
            if self._visual_snapshot is None:
                self._visual_snapshot = snapshot_visuals(self)
            else:
                restore_visuals(self, self._visual_snapshot)
        self.image_filters = {}
        for factor in self.factors:
            factor.apply(self)
        self._dirty = any(not getattr(factor, "in_place", True) for factor in self.factors)

    def close(self) -> None:
        if getattr(self, "env", None) is not None:
            with self.own_gl():  # its GL objects are freed in the current context: make it this world's
                self.env.close()
            self.env = None

    def __enter__(self) -> LiberoWorld:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _chain(edits: Sequence[Any]):
    """One XML processor applying `edits` (each MJCF text → MJCF text) in order."""

    def process(xml: str) -> str:
        for edit in edits:
            xml = edit(xml)
        return xml

    return process


def _address(gl) -> int | None:
    """The address of an EGL context object's handle (None: freed, or not an EGL context)."""
    handle = getattr(gl, "_context", None)
    return handle.address if handle else None


def _egl():
    """PyOpenGL's EGL binding, which robosuite's EGL contexts use."""
    from OpenGL import EGL

    return EGL


def quat2axisangle(quat: np.ndarray) -> np.ndarray:
    """xyzw quaternion(s) → axis-angle, float32: LeRobot's `LiberoProcessorStep._quat2axisangle`, op for op."""
    import torch

    q = torch.as_tensor(np.atleast_2d(quat)).to(dtype=torch.float32)
    w = q[:, 3].clamp(-1.0, 1.0)
    den = torch.sqrt(torch.clamp(1.0 - w * w, min=0.0))
    result = torch.zeros((q.shape[0], 3))
    mask = den > 1e-10
    if mask.any():
        angle = 2.0 * torch.acos(w[mask])
        axis = q[mask, :3] / den[mask].unsqueeze(1)
        result[mask] = axis * angle.unsqueeze(1)
    return result.numpy()


def lerobot_state(obs: dict[str, Any]) -> np.ndarray:
    """LeRobot's 8-D `observation.state` (float32): eef pos, axis-angle of the eef quat, gripper qpos."""
    import torch

    pos = torch.as_tensor(np.atleast_2d(obs["robot0_eef_pos"]))
    aa = torch.as_tensor(quat2axisangle(obs["robot0_eef_quat"]))
    grip = torch.as_tensor(np.atleast_2d(obs["robot0_gripper_qpos"]))
    return torch.cat((pos, aa, grip), dim=-1).float().numpy()[0]


def lerobot_view(obs: dict[str, Any]) -> dict[str, np.ndarray]:
    """The observation as LeRobot's LIBERO processor hands it to a policy, in numpy: images flipped 180° (uint8 HWC;
    LeRobot then scales to float CHW /255) under LeRobot's keys, and the 8-D float32 state."""
    view = {
        key: np.ascontiguousarray(obs[image_key(cam)][::-1, ::-1]) for cam, key in LEROBOT_IMAGE_KEYS.items()
    }
    view["observation.state"] = lerobot_state(obs)
    return view
