"""Turn a task instance into its benchmark record: camera extrinsics, fairness numbers, preview.

One `InstanceRenderer` per process (one compiled scene, one set of renderers); each instance is
applied in place by the env's reset — no recompiles.
"""

from __future__ import annotations

import io
from dataclasses import replace
from typing import Any

import numpy as np
from PIL import Image

from roboview.benchmark.screen import FAIRNESS_SCREEN, SCREEN_CAMERA, screen_image
from roboview.tasks import DEFAULT_TASK, load_task, make_env
from roboview.tasks.env import IMAGE_KEY
from roboview.tasks.fairness import FairnessThresholds
from roboview.variation.factors import baselines, visual_factors
from roboview.variation.instances import TaskInstance

PREVIEW_SIZE = 128  # pixels per camera tile in the stored preview


def no_change_view(instance: TaskInstance) -> TaskInstance:
    """`instance`'s context with every visual factor at its baseline (the task's label of it)."""
    visual = set(visual_factors())
    base = {name: value for name, value in baselines(instance.task).items() if name in visual}
    return replace(instance, factors={**dict(instance.factors), **base})


def preview_png(frames: list[np.ndarray], size: int = PREVIEW_SIZE) -> bytes:
    """Observed cameras side by side, PNG-encoded deterministically (no timestamps, fixed settings)."""
    tiles = [Image.fromarray(f).resize((size, size), Image.Resampling.BILINEAR) for f in frames]
    sheet = Image.new("RGB", (size * len(tiles), size))
    for i, tile in enumerate(tiles):
        sheet.paste(tile, (i * size, 0))
    buf = io.BytesIO()
    sheet.save(buf, format="PNG", optimize=False, compress_level=6)
    return buf.getvalue()


class InstanceRenderer:
    """One env (and fairness probe) per task, made on first use; every instance applied in place."""

    def __init__(
        self,
        image_size: int,
        thresholds: FairnessThresholds,
        task: str = DEFAULT_TASK,
        screen: tuple[Any, Any] | None = None,
    ) -> None:
        """`screen`: (client class, endpoint) of the stage-1b VLM fairness screen, built here in the worker."""
        self.image_size = image_size
        self.envs: dict[str, Any] = {}
        self.probes: dict[str, Any] = {}
        self.screen = screen[0](screen[1]) if screen is not None else None
        self.thresholds = thresholds
        self._views: dict[tuple, Any] = {}
        self._use(task)

    def _use(self, task: str) -> None:
        if task not in self.envs:
            world = load_task(task).env_class().world
            self.envs[task] = make_env(task, cameras=world.observed_cameras, image_size=self.image_size)
            self.probes[task] = world.make_probe(self.envs[task])
        self.env, self.probe = self.envs[task], self.probes[task]

    def record(self, instance: TaskInstance) -> dict:
        self._use(instance.task)
        view = self._no_change_view(instance)
        obs, _ = self.env.reset(seed=instance.seed, options={"instance": instance})
        cameras = self.probe.cameras
        rgb = {cam: obs[IMAGE_KEY.format(cam)] for cam in cameras}
        if view is None and self.env.world.gate_reference == "no_change_view":
            # The no-change view itself, judged against itself; kept for its context's variants (no second render).
            view = self.probe.measure(rgb, self.thresholds)
            self._keep_view((instance.task, instance.factors, instance.seed), view)
        fairness = self.probe.measure(rgb, self.thresholds, *([view] if view else [])).to_record()
        vlm = (
            screen_image(self.screen, FAIRNESS_SCREEN, rgb[SCREEN_CAMERA]) if self.screen is not None else {}
        )
        fairness |= {"vlm_answer": vlm.get("answer", ""), "vlm_analysis": vlm.get("analysis", "")}
        return {
            **instance.to_record(),
            "cameras": [self.env.camera_pose(cam).to_record() for cam in self._recorded_cameras()],
            "fairness": fairness,
            "preview": {"bytes": preview_png([rgb[c] for c in cameras]), "path": None},
        }

    def _no_change_view(self, instance: TaskInstance):
        """The gate's report of `instance`'s context at every visual factor's baseline (on the same seed), where the
        world judges against it (`World.gate_reference`); None where it does not, or `instance` is that view."""
        if self.env.world.gate_reference != "no_change_view":
            return None
        base = no_change_view(instance)
        if base.factors == instance.factors:
            return None
        key = (base.task, base.factors, instance.seed)
        if key not in self._views:
            obs, _ = self.env.reset(seed=instance.seed, options={"instance": base})
            rgb = {cam: obs[IMAGE_KEY.format(cam)] for cam in self.probe.cameras}
            self._keep_view(key, self.probe.measure(rgb, self.thresholds))
        return self._views[key]

    def _keep_view(self, key: tuple, view: Any) -> None:
        if len(self._views) >= 256:  # a batch holds one world's instances: a few contexts at a time
            self._views.clear()
        self._views[key] = view

    def records(self, instances: list[TaskInstance]) -> list[dict]:
        """`record` of each of `instances` (one world's, in one call: its model is compiled once)."""
        return [self.record(instance) for instance in instances]

    def _recorded_cameras(self) -> tuple[str, ...]:
        """The cameras whose calibration the world records (RoboView's scene: all four; LIBERO's: its two)."""
        return self.env.world.recorded_cameras

    def close(self) -> None:
        for env in self.envs.values():
            env.close()
