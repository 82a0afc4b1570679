"""Perceptual-fairness gate, stage 1: measure, at t = 0 and from every observed camera, whether the
object and the receiver box are clearly visible — instead of asking a VLM.

This module holds the gate's thresholds, records and measures, shared by every world, and the probe of
RoboView's own scene (`FairnessProbe`); another world's probe lives in its wing and is named by its `World.probe`
(`roboview.tasks.world`).

For each observed camera we render segmentation twice: the scene as is, and the scene with every
geom but the target made invisible (alpha 0, material detached, restored right after — an
in-place edit). Visible fraction = visible pixels / pixels the target covers unoccluded. The
object's rendered color (mean sRGB over its visible pixels) is compared with its nominal color and
with the table's rendered color by CIEDE2000.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import mujoco
import numpy as np
from scipy import ndimage

from roboview.tasks.world import WorldEnv
from roboview.variation.colors import delta_e_2000, get_color, srgb_to_lab
from roboview.variation.factors import FACTORS, baseline_of


@dataclass(frozen=True)
class FairnessThresholds:
    """Pass criteria. "Box" is the task's target, whatever it is (pick_place's box, push's zone): the `box_*` names are
    those of the stored records and flags, kept so every benchmark already built still reads. The wrist view is local
    by design, so the target is not required in it."""

    # Minimum share of the object's unoccluded pixels that must be visible, per observed camera.
    min_object_visible: float = 0.6
    # Minimum share of the target's (box's, zone's) unoccluded pixels visible in the scene cameras (front, left_top).
    min_box_visible: float = 0.5
    # Minimum object area in pixels of a 224² frame (scaled by area for other image sizes).
    min_object_pixels: int = 25
    # Object must lie wholly inside the frame (no object pixel on the border when unoccluded).
    require_in_frame: bool = True
    # Minimum CIEDE2000 between the object's and the table's rendered colors.
    min_delta_e_table: float = 3.0
    # Maximum CIEDE2000 between the object's rendered and nominal colors (catches lighting failures).
    max_delta_e_nominal: float = 45.0
    # In a world judged against its context's no-change view (`World.gate_reference`), the share of that view's own
    # figure a value must keep where the view itself is under a threshold. Measured at 256² on the three LIBERO tasks
    # whose no-change view is (libero_object/8, libero_goal/0, libero_10/4): a camera turned ±6° or pulled back keeps
    # 0.88–1.0 of the view's figure when the same clutter or fixture edge merely shifts (libero_object/8's pudding 0.52–
    # 0.58 visible against 0.58), and 0.00–0.53 when the target swings out (libero_10/4 at yaw −6°: 0.00; libero_goal/0's
    # cabinet at yaw −6°: 0.47 in frame against 0.88). 0.85 lies between the two.
    min_share_of_view: float = 0.85

    def __post_init__(self) -> None:
        for name in ("min_object_visible", "min_box_visible"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name}={getattr(self, name)} must lie in [0, 1]")
        if not 0.0 < self.min_share_of_view <= 1.0:
            raise ValueError(f"min_share_of_view={self.min_share_of_view} must lie in (0, 1]")
        if self.min_object_pixels < 1 or self.min_delta_e_table < 0 or self.max_delta_e_nominal <= 0:
            raise ValueError("pixel and ΔE thresholds must be positive")


@dataclass(frozen=True)
class CameraFairness:
    """One camera's measures of an instance; `box_*` measure the task's target (the box, or push's zone)."""

    camera: str
    object_visible: float
    object_pixels: int
    object_in_frame: bool
    box_visible: float
    box_pixels: int
    box_in_frame: bool
    delta_e_nominal: float
    delta_e_table: float
    # The share of the object's unoccluded silhouette that falls inside the frame (1.0: wholly in frame), measured
    # where it is not wholly in frame (a fixture larger than the frame: LIBERO's cabinets) on a render widened 2×.
    object_frame_share: float = 1.0


@dataclass(frozen=True)
class FairnessReport:
    cameras: tuple[CameraFairness, ...]
    passed: bool
    reject_reason: str

    def to_record(self) -> dict:
        """The record a benchmark stores (format.py's `fairness` struct). The frame share is judged, not stored: it is
        measured only where the object is not wholly in frame, and a failing value's reason states it."""
        return {
            "cameras": [
                {k: v for k, v in asdict(c).items() if k != "object_frame_share"} for c in self.cameras
            ],
            "passed": self.passed,
            "reject_reason": self.reject_reason,
        }


class FairnessProbe:
    """Owns one segmentation renderer for an env; measures the env's current state."""

    def __init__(self, env: WorldEnv, cameras: tuple[str, ...] | None = None) -> None:
        """`cameras`: those measured (default: the world's observed cameras)."""
        self.env = env
        self.cameras = cameras or env.world.observed_cameras
        self._seg = env.new_renderer()
        self._seg.enable_segmentation_rendering()
        # The renderer of the scene the env last switched away from (`_renderer`).
        self._spare: mujoco.Renderer | None = None

    def _renderer(self) -> mujoco.Renderer:
        """The segmentation renderer of the env's live model. An env switching between its plain scene and one compiled
        with a factor's additions (scene_text's card) keeps both live, so the renderer of the one it left is kept
        too, and a switch back builds none; an older one (a LIBERO model replaced by a hard reset) is closed."""
        model = self.env.model
        if self._seg.model is not model:
            if self._spare is not None and self._spare.model is model:
                self._seg, self._spare = self._spare, self._seg
            else:
                if self._spare is not None:
                    self._spare.close()
                self._spare, self._seg = self._seg, self.env.new_renderer()
                self._seg.enable_segmentation_rendering()
        return self._seg

    def _segment(self, camera: str) -> np.ndarray:
        renderer = self._renderer()
        renderer.update_scene(self.env.data, camera=self.env.camera_ids()[camera])
        seg = renderer.render()
        return np.where(seg[..., 1] == mujoco.mjtObj.mjOBJ_GEOM, seg[..., 0], -1)

    def _segment_alone(self, camera: str, geoms: list[int]) -> np.ndarray:
        model = self.env.model
        rgba, matid = model.geom_rgba.copy(), model.geom_matid.copy()
        try:
            model.geom_rgba[:, 3] = 0.0
            model.geom_matid[:] = -1
            model.geom_rgba[geoms, 3] = 1.0
            return self._segment(camera)
        finally:
            model.geom_rgba[:] = rgba
            model.geom_matid[:] = matid

    def measure(self, rgb: dict[str, np.ndarray], thresholds: FairnessThresholds) -> FairnessReport:
        """Measure the current scene; `rgb` holds the already rendered RGB frame of each camera."""
        ids = self.env.scene.ids
        obj = ids.shape_geom[self.env.shape]
        # The task's target (pick_place's receiver box, push's marked zone); the record's box_* fields
        # measure it. A task without one has nothing there to hide.
        box = list(self.env.target_geoms())
        nominal_lab = np.asarray(get_color(self.env.instance.get("color")).lab)
        # Under a non-default light the rendered colour moves away from the nominal one by design: only
        # the object-table contrast (which a light that hides the object still fails) is judged.
        judge_nominal = all(
            FACTORS[name].keeps_nominal_color or value == baseline_of(name, self.env.instance.task)
            for name, value in self.env.instance.factors
        )
        results, reasons = [], []
        for cam in self.cameras:
            seg = self._segment(cam)
            obj_alone = self._segment_alone(cam, [obj]) == obj
            box_alone = np.isin(self._segment_alone(cam, box), box) if box else np.zeros_like(obj_alone)
            obj_mask, box_mask = seg == obj, np.isin(seg, box)
            obj_lab = mean_lab(rgb[cam], obj_mask)
            table_lab = mean_lab(rgb[cam], seg == ids.table_geom)
            result = CameraFairness(
                camera=cam,
                object_visible=fraction(obj_mask, obj_alone),
                object_pixels=int(obj_mask.sum()),
                object_in_frame=in_frame(obj_alone),
                box_visible=fraction(box_mask, box_alone) if box else 1.0,
                box_pixels=int(box_mask.sum()),
                box_in_frame=in_frame(box_alone) if box else True,
                delta_e_nominal=delta_e(obj_lab, nominal_lab),
                delta_e_table=delta_e(obj_lab, table_lab),
            )
            results.append(result)
            min_pixels = thresholds.min_object_pixels * (self.env.image_size / 224) ** 2
            reasons += violations(
                result, thresholds, min_pixels, scene_camera=cam != "wrist", judge_nominal=judge_nominal
            )
        reasons += factor_gates(self.env, rgb)
        return FairnessReport(tuple(results), not reasons, "; ".join(reasons))


def factor_gates(env: WorldEnv, rgb: dict[str, np.ndarray]) -> list[str]:
    """The reasons of the visual factors' own checks (`Factor.gate`: scene_text's legible text) that the instance
    sets away from their baselines; empty where they pass."""
    task = env.instance.task
    out = []
    for name, value in env.instance.factors:
        check = FACTORS[name].gate
        if check is not None and value != baseline_of(name, task):
            out += check(env, rgb)
    return out


def fraction(visible: np.ndarray, alone: np.ndarray) -> float:
    total = int(alone.sum())
    return float(min(visible.sum(), total) / total) if total else 0.0


def in_frame(mask: np.ndarray) -> bool:
    if not mask.any():
        return False
    return not (mask[0].any() or mask[-1].any() or mask[:, 0].any() or mask[:, -1].any())


def mean_lab(rgb: np.ndarray, mask: np.ndarray) -> np.ndarray | None:
    if not mask.any():
        return None
    return srgb_to_lab(rgb[mask].astype(np.float64).mean(0) / 255.0)


def delta_e(a: np.ndarray | None, b: np.ndarray | None) -> float:
    return float(delta_e_2000(a, b)) if a is not None and b is not None else float("nan")


def violations(
    r: CameraFairness,
    t: FairnessThresholds,
    min_pixels: float,
    scene_camera: bool,
    judge_nominal: bool = True,
    view: CameraFairness | None = None,
) -> list[str]:
    """Why one camera's measurements fail the thresholds, one reason each (empty when they pass); the box is
    judged only by a `scene_camera`, the object's colour shift only with `judge_nominal`.

    `view`: the same camera's measures of the context's no-change view, in a world whose look is another
    benchmark's design (`World.gate_reference`). A value is then asked to show the object no worse than that world
    shows it to every policy: each floor is the threshold or `min_share_of_view` of the no-change view's own figure,
    whichever is lower (a chocolate pudding 58 % visible among LIBERO's clutter may stay about that visible; a blue
    re-skin of a black bowl on a dark table may stand out from it about as little as the bowl itself does). An
    object the no-change view does not hold wholly in frame (a cabinet larger than the frame) is judged by the share
    of it in frame, not by being whole."""
    out = []

    def floor(threshold: float, own: float | None, digits: int = 2) -> tuple[float, str]:
        """The floor a measure is held to, and how the reason writes it: the threshold as written, or the share of
        the no-change view's figure, saying so."""
        if own is None or np.isnan(own) or t.min_share_of_view * own >= threshold:
            return threshold, f"{threshold}" if digits else f"{threshold:.0f}"
        least = t.min_share_of_view * own
        return least, f"{least:.{digits}f} ({t.min_share_of_view:.0%} of its no-change view's {own:.2f})"

    least, said = floor(t.min_object_visible, view and view.object_visible)
    if r.object_visible < least:
        out.append(f"{r.camera}: object visible {r.object_visible:.2f} < {said}")
    least, said = floor(min_pixels, view and float(view.object_pixels), 0)
    if r.object_pixels < least:
        out.append(f"{r.camera}: object area {r.object_pixels} px < {said}")
    if t.require_in_frame and not r.object_in_frame:
        if view is None or view.object_in_frame:
            out.append(f"{r.camera}: object not wholly in frame")
        else:  # the world's own view does not hold it whole either: judged by how much of it is in frame
            least, said = floor(t.min_object_visible, view.object_frame_share)
            if r.object_frame_share < least:
                out.append(f"{r.camera}: object {r.object_frame_share:.2f} in frame < {said}")
    if scene_camera:
        if r.box_visible < t.min_box_visible:
            out.append(f"{r.camera}: box visible {r.box_visible:.2f} < {t.min_box_visible}")
        if t.require_in_frame and not r.box_in_frame:
            out.append(f"{r.camera}: box not wholly in frame")
    least, said = floor(t.min_delta_e_table, view and view.delta_e_table, 1)
    if not np.isnan(r.delta_e_table) and r.delta_e_table < least:
        out.append(f"{r.camera}: object-table ΔE2000 {r.delta_e_table:.1f} < {said}")
    if judge_nominal and not np.isnan(r.delta_e_nominal) and r.delta_e_nominal > t.max_delta_e_nominal:
        out.append(f"{r.camera}: rendered-nominal ΔE2000 {r.delta_e_nominal:.1f} > {t.max_delta_e_nominal}")
    return out


def ring(mask: np.ndarray, width: int = 4) -> np.ndarray:
    """The pixels within `width` of `mask` (along a row or a column) but outside it: what the object is seen
    against."""
    cross = np.zeros((2 * width + 1, 2 * width + 1), bool)
    cross[width, :] = cross[:, width] = True
    return ndimage.binary_dilation(mask, structure=cross) & ~mask


class ObjectProbe:
    """The gate in a world whose task has one object to find (LIBERO's, Meta-World's): the object (`env.object_geoms()`)
    must be visible, whole and distinct from what surrounds it in the world's judged cameras; the others (a wrist
    camera that at t = 0 looks down past the gripper) are measured and recorded but not judged. There is no second
    target (box) to find. A world's wing subclasses it with the geom groups its renderer draws."""

    # The geom groups the world's renderer draws (robosuite: the visual geoms, group 1, not the collision geoms that
    # coincide with them).
    geom_groups: tuple[int, ...] = (0, 1, 2)
    # The axes along which the observations hand the world's frame flipped against what `mujoco.Renderer` draws
    # (top row first): Meta-World's corner2 is drawn top row first by gymnasium's renderer and flipped on both axes.
    # A wing whose renderer reads its frames otherwise declares its own (LIBERO's: robosuite reads them bottom row
    # first, so after its 180° turn they differ from mujoco.Renderer's by a left-right mirror alone). The
    # segmentation must land on the observed pixels: the colour measures read the frame under it.
    flip_axes: tuple[int, ...] = (0, 1)

    def __init__(self, env) -> None:
        self.env = env
        world = env.world
        self.cameras, self.judged, self.names = world.observed_cameras, world.judged_cameras, world.cameras
        self._seg: mujoco.Renderer | None = None

    def _segment(self, camera: str, alone: list[int] | None = None, widen: float = 1.0) -> np.ndarray:
        """Geom ids per pixel of `camera` as the observations hand the frame (`alone`: those geoms drawn alone;
        `widen`: the field of view's tangent scaled by it, so the frame is the central 1/widen of the render)."""
        model, data = self.env.model, self.env.data
        cam = model.camera(self.names[camera]).id
        fovy = float(model.cam_fovy[cam])
        if self._seg is None or self._seg.model is not model:  # a hard reset compiled a new model
            if self._seg is not None:
                self._seg.close()
            self._seg = mujoco.Renderer(model, self.env.image_size, self.env.image_size)
            self._seg.enable_segmentation_rendering()
            self._option = mujoco.MjvOption()
            self._option.geomgroup[:] = 0
            self._option.geomgroup[list(self.geom_groups)] = 1
        rgba = model.geom_rgba.copy()
        try:
            if alone is not None:
                model.geom_rgba[:, 3] = 0.0
                model.geom_rgba[alone, 3] = 1.0
            model.cam_fovy[cam] = np.degrees(2 * np.arctan(widen * np.tan(np.radians(fovy) / 2)))
            self._seg.update_scene(data, camera=cam, scene_option=self._option)
            seg = self._seg.render()
        finally:
            model.geom_rgba[:] = rgba
            model.cam_fovy[cam] = fovy
        ids = np.where(seg[..., 1] == mujoco.mjtObj.mjOBJ_GEOM, seg[..., 0], -1)
        return np.flip(ids, self.flip_axes) if self.flip_axes else ids  # as the observations hand the image

    def frame_share(self, camera: str, geoms: list[int], widen: float = 2.0) -> float:
        """The share of the geoms' unoccluded silhouette inside `camera`'s frame, from a render `widen`× wider (a
        silhouette that overflows even that counts only what it shows: an upper bound)."""
        wide = np.isin(self._segment(camera, geoms, widen), geoms)
        size = wide.shape[0]
        lo, hi = int(round(size * (1 - 1 / widen) / 2)), int(round(size * (1 + 1 / widen) / 2))
        total = int(wide.sum())
        return float(wide[lo:hi, lo:hi].sum() / total) if total else 0.0

    def measure(
        self, rgb: dict[str, np.ndarray], thresholds: FairnessThresholds, view: FairnessReport | None = None
    ) -> FairnessReport:
        """The gate's measures of the current scene and its verdict; `view`: the context's no-change view's report,
        which each value is judged against in a world whose look is another benchmark's (`violations`)."""
        geoms = list(self.env.object_geoms())
        color = self.env.instance.get("color")
        # At its baseline the object wears LIBERO's own texture, as LIBERO's scene shows it to every policy: there is
        # no nominal color to compare with, and its contrast with the surface is LIBERO's design (a black bowl on a
        # dark table), not the factor's doing. Both color checks judge the re-skinned object only.
        recolored = color != baseline_of("color", self.env.instance.task)
        judge_nominal = recolored and all(
            FACTORS[name].keeps_nominal_color or value == baseline_of(name, self.env.instance.task)
            for name, value in self.env.instance.factors
        )
        nominal = np.asarray(get_color(color).lab) if recolored else None  # `original`: no nominal color
        results, reasons = [], []
        for cam in self.cameras:
            obj_mask = np.isin(self._segment(cam), geoms)
            alone = np.isin(self._segment(cam, geoms), geoms)
            obj_lab = mean_lab(rgb[cam], obj_mask)
            whole = in_frame(alone)
            result = CameraFairness(
                camera=cam,
                object_visible=fraction(obj_mask, alone),
                object_pixels=int(obj_mask.sum()),
                object_in_frame=whole,
                box_visible=1.0,
                box_pixels=0,
                box_in_frame=True,
                delta_e_nominal=delta_e(obj_lab, nominal),
                # Measured at the baseline too: the contrast the world gives its own object is what a re-skin is
                # judged against where the gate takes the no-change view's figures.
                delta_e_table=delta_e(obj_lab, mean_lab(rgb[cam], ring(obj_mask))),
                object_frame_share=1.0 if whole or cam not in self.judged else self.frame_share(cam, geoms),
            )
            results.append(result)
            if cam in self.judged:
                min_pixels = thresholds.min_object_pixels * (self.env.image_size / 224) ** 2
                own = next((c for c in view.cameras if c.camera == cam), None) if view is not None else None
                judged = result if recolored else replace(result, delta_e_table=float("nan"))
                reasons += violations(judged, thresholds, min_pixels, False, judge_nominal, own)
        reasons += factor_gates(self.env, rgb)
        return FairnessReport(tuple(results), not reasons, "; ".join(reasons))

    def close(self) -> None:
        if self._seg is not None:
            self._seg.close()
