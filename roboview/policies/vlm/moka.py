"""`vlm_moka`: a MOKA-style agent — VLM plan, open-vocabulary grounding, marks, VLM mark choice.

1. **Plan**: the VLM reads the camera image and the instruction and describes, in words, the object
   to pick and the place to put it (`prompts.MOKA_PLAN`). The descriptions are recorded per episode
   (the paper's case study counts their colour and shape words).
2. **Grounding**: each description is found in the image by the grounding backend
   (`roboview.policies.vlm.grounding`: classic colour-driven, OWLv2 or Grounding DINO) and segmented (the blob,
   or SAM).
3. **Marks**: candidate keypoints — the mask's centroid and four points along its principal axes, for
   the object and for the target — are drawn as numbered marks on the image.
4. **Choice**: the VLM picks the grasp mark and the place mark (`prompts.MOKA_MARKS`).
5. **Motion**: the chosen marks are back-projected with depth and the camera calibration; the object's
   footprint around the grasp mark gives the grasp heading; the expert's motion planner moves.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from roboview.policies.base import AgentView, Episode, PolicyConfig
from roboview.policies.vlm.client import VLMClient
from roboview.policies.vlm.common import VLMConfig, object_from_point, world_point
from roboview.policies.vlm.grounding import (
    GROUNDING_BACKENDS,
    ClassicGrounder,
    Detection,
    Grounder,
    TransformersGrounder,
)
from roboview.policies.vlm.marks import draw_marks
from roboview.policies.vlm.prompts import MOKA_MARKS, MOKA_PLAN
from roboview.sim.motion import MotionPlanner
from roboview.tasks import load_task
from roboview.tasks.env import DEPTH_KEY, IMAGE_KEY, STATE_KEY

# Keypoints along each principal axis of a mask, as a fraction of its half-extent, and at least this
# many pixels from the centroid (so the drawn marks never merge; see roboview.policies.vlm.marks).
AXIS_FRACTION = 0.5
MIN_OFFSET_PX = 5.0


@PolicyConfig.register_subclass("vlm_moka")
@dataclass
class MokaConfig(VLMConfig):
    # Grounding backend: classic (colour-driven, offline), owlv2 or grounding_dino (transformers).
    grounding: str = "classic"
    # transformers model id of the owlv2 / grounding_dino detector (weights from your Hugging Face cache).
    detector_model: str = "google/owlv2-base-patch16-ensemble"
    # transformers model id of SAM, for masks of the detected boxes (e.g. facebook/sam-vit-base); empty: no masks.
    sam_model: str = ""
    # Detection score threshold of the transformers backends.
    detector_threshold: float = 0.1

    doc = "MOKA-style: VLM plan → grounding → numbered marks → VLM picks grasp/place (--policy.grounding=classic)"

    def __post_init__(self) -> None:
        if self.grounding not in GROUNDING_BACKENDS:
            raise ValueError(
                f"unknown grounding backend {self.grounding!r}; allowed: {', '.join(GROUNDING_BACKENDS)}"
            )
        super().__post_init__()

    def grounder(self) -> Grounder:
        if self.grounding == "classic":
            return ClassicGrounder()
        return TransformersGrounder.from_pretrained(
            self.grounding, self.detector_model, self.sam_model, self.detector_threshold
        )

    def build(self, view: AgentView) -> MokaAgent:
        return MokaAgent(view, self, self.grounder())


def keypoints(detection: Detection) -> list[tuple[float, float]]:
    """The mask's centroid and four points along its principal axes (the box's when there is no mask)."""
    if detection.mask is not None and detection.mask.sum() >= 3:
        ys, xs = np.nonzero(detection.mask)
        pts = np.column_stack([xs, ys]).astype(float)
    else:
        x0, y0, x1, y1 = detection.box
        pts = np.array([[x0, y0], [x1, y0], [x0, y1], [x1, y1]], dtype=float)
    center = pts.mean(axis=0)
    cov = np.cov((pts - center).T) if len(pts) > 2 else np.eye(2)
    values, vectors = np.linalg.eigh(cov)
    out = [tuple(center)]
    for value, vector in zip(values[::-1], vectors.T[::-1]):
        half = 2.0 * np.sqrt(max(value, 0.0))  # ~ half-extent of a uniform blob
        for sign in (1, -1):
            out.append(tuple(center + sign * max(AXIS_FRACTION * half, MIN_OFFSET_PX) * vector))
    return [(float(x), float(y)) for x, y in out]


class MokaAgent:
    name = "vlm_moka"

    def __init__(self, view: AgentView, config: MokaConfig, grounder: Grounder) -> None:
        self.camera = config.camera
        self.client = VLMClient(config.endpoint)
        self.grounder = grounder
        self.planner = MotionPlanner(view.kinematic_model())
        self.failure_reason = ""
        self._episode: Episode | None = None
        self._hold: np.ndarray | None = None
        self._planned = False
        self._record: dict = {}

    def reset(self, episode: Episode) -> None:
        self._episode = episode
        self.failure_reason = ""
        self._hold = None
        self._planned = False
        self._record = dict.fromkeys(
            (
                "moka_object_description",
                "moka_target_description",
                "moka_grounding_score",
                "moka_grasp_mark",
                "moka_place_mark",
            )
        )

    def select_action(self, observation: dict[str, np.ndarray]) -> np.ndarray:
        if not self._planned:
            self._plan(observation)
            self._planned = True
        return self._hold if self._hold is not None else self.planner.next_action()

    def _fail(self, reason: str, arm_q: np.ndarray) -> None:
        self.failure_reason = reason
        self._hold = np.append(arm_q, 0.0).astype(np.float32)

    def _plan(self, observation: dict[str, np.ndarray]) -> None:
        rgb = observation[IMAGE_KEY.format(self.camera)]
        depth = observation[DEPTH_KEY.format(self.camera)]
        arm_q = observation[STATE_KEY][:7].astype(np.float64)
        instruction = self._episode.instruction

        def check_plan(answer):
            if not isinstance(answer, dict):
                raise ValueError("expected a JSON object with object_description and target_description")
            obj, target = answer.get("object_description"), answer.get("target_description")
            if not (isinstance(obj, str) and obj.strip() and isinstance(target, str) and target.strip()):
                raise ValueError("object_description and target_description must be non-empty strings")
            return obj.strip(), target.strip()

        obj_desc, target_desc = self.client.ask_json(
            MOKA_PLAN.format(instruction=instruction), [rgb], check_plan
        )
        self._record |= {"moka_object_description": obj_desc, "moka_target_description": target_desc}
        objects, targets = self.grounder.detect(rgb, obj_desc), self.grounder.detect(rgb, target_desc)
        if not objects:
            return self._fail(f"grounding found no {obj_desc!r}", arm_q)
        if not targets:
            return self._fail(f"grounding found no {target_desc!r}", arm_q)
        self._record["moka_grounding_score"] = objects[0].score
        object_points, target_points = keypoints(objects[0]), keypoints(targets[0])
        points = object_points + target_points
        obj_marks = list(range(1, len(object_points) + 1))
        target_marks = list(range(len(object_points) + 1, len(points) + 1))
        marked = draw_marks(rgb, points)

        def check_marks(answer):
            if not isinstance(answer, dict):
                raise ValueError("expected a JSON object with grasp_mark and place_mark")
            grasp, place = answer.get("grasp_mark"), answer.get("place_mark")
            if grasp not in obj_marks:
                raise ValueError(f"grasp_mark must be one of {obj_marks}, got {grasp!r}")
            if place not in target_marks:
                raise ValueError(f"place_mark must be one of {target_marks}, got {place!r}")
            return grasp, place

        prompt = MOKA_MARKS.format(
            instruction=instruction,
            object_marks=_span(obj_marks),
            target_marks=_span(target_marks),
            object_description=obj_desc,
            target_description=target_desc,
        )
        grasp, place = self.client.ask_json(prompt, [marked], check_marks)
        self._record |= {"moka_grasp_mark": grasp, "moka_place_mark": place}
        h, w = rgb.shape[:2]
        grasp_px = _clip(points[grasp - 1], w, h)
        place_px = _clip(points[place - 1], w, h)
        calibration = self._episode.cameras[self.camera]
        solid = object_from_point(grasp_px, depth, calibration)
        if solid is None:
            return self._fail("grasp mark hits no graspable solid", arm_q)
        center, yaw, symmetry = solid
        box_xy = world_point(place_px, depth, calibration)[:2]
        # The task's own scripted solution through the points the VLM gave.
        load_task(self._episode.task).solve(self.planner, center, yaw, symmetry, box_xy, arm_q)

    def episode_record(self) -> dict:
        return {**self.client.take_stats(), **self._record}

    def close(self) -> None:
        pass


def _span(marks: list[int]) -> str:
    return f"{marks[0]}-{marks[-1]}" if len(marks) > 1 else str(marks[0])


def _clip(point: tuple[float, float], w: int, h: int) -> tuple[float, float]:
    return min(max(point[0], 0.0), w - 1.0), min(max(point[1], 0.0), h - 1.0)
