"""Open-vocabulary grounding and segmentation for the MOKA agent: description → box → mask.

Backends (`--policy.grounding=`):

- ``classic`` (default; runs offline): colour-driven. A description naming a box or container
  grounds to the largest yellow blob; anything else to the candidate object blobs
  (`roboview.policies.vlm.blobs`), scored by how close each blob's rendered CIELAB colour is to the colour the
  description names (any of the 141 names or the 11 basic categories; ΔE2000), or by saliency when
  it names none. Masks: the blob itself.
- ``owlv2`` / ``grounding_dino``: `transformers`' zero-shot object detection (model ids in the
  config, weights from the user's Hugging Face cache), masks from SAM (`--policy.sam_model`) when
  given, else the box. These need the weights on disk: this machine has none, so they are exercised
  on tiny randomly initialised models in the tests.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from roboview.policies.vlm.blobs import find_box, find_objects
from roboview.variation.colors import CATEGORIES, COLORS, delta_e_2000, srgb_to_lab

TARGET_WORDS = ("box", "container", "bin", "basket", "tray")
# ΔE2000 at which a blob's colour match score halves.
COLOR_SCALE = 20.0
GROUNDING_BACKENDS = ("classic", "owlv2", "grounding_dino")


@dataclass(frozen=True)
class Detection:
    box: tuple[float, float, float, float]  # x0, y0, x1, y1 (pixels)
    score: float  # grounding confidence in [0, 1]
    mask: np.ndarray | None = None  # H×W bool

    @property
    def center(self) -> tuple[float, float]:
        if self.mask is not None and self.mask.any():
            ys, xs = np.nonzero(self.mask)
            return float(xs.mean()), float(ys.mean())
        x0, y0, x1, y1 = self.box
        return (x0 + x1) / 2, (y0 + y1) / 2


class Grounder(Protocol):
    def detect(self, rgb: np.ndarray, description: str) -> list[Detection]:
        """Detections of `description`, best first (empty: not found)."""


def named_color(description: str) -> tuple[str, np.ndarray] | None:
    """The colour a description names and its CIELAB: a CSS name ("dark red" → darkred, "gold"), else a
    basic category ("purple": the mean of its members); None when it names no colour."""
    words = re.findall(r"[a-z]+", description.lower().replace("grey", "gray"))
    for a, b in zip(words, words[1:]):
        if a + b in COLORS:
            return a + b, np.asarray(COLORS[a + b].lab)
    for word in words:
        if word in COLORS:
            return word, np.asarray(COLORS[word].lab)
        if word in CATEGORIES:
            return word, np.mean([np.asarray(c.lab) for c in COLORS.values() if c.category == word], axis=0)
    return None


class ClassicGrounder:
    """Colour-driven grounding on one RGB image (see the module docstring)."""

    def detect(self, rgb: np.ndarray, description: str) -> list[Detection]:
        words = description.lower()
        if any(re.search(rf"\b{w}\b", words) for w in TARGET_WORDS):
            box = find_box(rgb)
            if box is None:
                return []
            x, y, w, h = box.bbox
            return [Detection((x, y, x + w, y + h), 1.0, box.mask)]
        blobs = find_objects(rgb)
        if not blobs:
            return []
        named = named_color(description)
        detections = []
        for rank, blob in enumerate(blobs):
            if named is not None:
                lab = srgb_to_lab(np.asarray(blob.rgb))
                score = float(np.exp(-float(delta_e_2000(lab, named[1])) / COLOR_SCALE * np.log(2)))
            else:
                score = 1.0 / (1 + rank)  # saliency order
            x, y, w, h = blob.bbox
            detections.append(Detection((x, y, x + w, y + h), round(score, 4), blob.mask))
        return sorted(detections, key=lambda d: -d.score)


class TransformersGrounder:
    """OWLv2 or Grounding DINO through `transformers`, optionally SAM masks, on a loaded model."""

    def __init__(
        self, kind: str, model, processor, sam_model=None, sam_processor=None, threshold: float = 0.1
    ) -> None:
        if kind not in ("owlv2", "grounding_dino"):
            raise ValueError(f"unknown grounding backend {kind!r}; allowed: owlv2, grounding_dino")
        self.kind, self.model, self.processor = kind, model, processor
        self.sam_model, self.sam_processor = sam_model, sam_processor
        self.threshold = threshold

    @classmethod
    def from_pretrained(
        cls, kind: str, model_id: str, sam_id: str = "", threshold: float = 0.1
    ) -> TransformersGrounder:
        from transformers import (
            AutoModelForZeroShotObjectDetection,
            AutoProcessor,
            SamModel,
            SamProcessor,
        )

        model = AutoModelForZeroShotObjectDetection.from_pretrained(model_id).eval()
        processor = AutoProcessor.from_pretrained(model_id)
        sam = (
            (SamModel.from_pretrained(sam_id).eval(), SamProcessor.from_pretrained(sam_id))
            if sam_id
            else (None, None)
        )
        return cls(kind, model, processor, *sam, threshold=threshold)

    def detect(self, rgb: np.ndarray, description: str) -> list[Detection]:
        import torch

        h, w = rgb.shape[:2]
        if self.kind == "owlv2":
            inputs = self.processor(text=[[description]], images=rgb, return_tensors="pt")
            with torch.inference_mode():
                outputs = self.model(**inputs)
            # OWLv2 pads images to a square: boxes are relative to the padded side.
            side = max(h, w)
            result = self.processor.post_process_grounded_object_detection(
                outputs, threshold=self.threshold, target_sizes=torch.tensor([[side, side]])
            )[0]
        else:
            inputs = self.processor(
                images=rgb, text=description.lower().rstrip(".") + ".", return_tensors="pt"
            )
            with torch.inference_mode():
                outputs = self.model(**inputs)
            result = self.processor.post_process_grounded_object_detection(
                outputs,
                inputs["input_ids"],
                threshold=self.threshold,
                text_threshold=self.threshold,
                target_sizes=[(h, w)],
            )[0]
        # Clip to the image; a box wholly inside OWLv2's padding holds nothing of the image: dropped.
        kept = [
            ((max(0.0, x0), max(0.0, y0), min(float(w), x1), min(float(h), y1)), float(s))
            for (x0, y0, x1, y1), s in zip(result["boxes"].tolist(), result["scores"].tolist())
            if min(float(w), x1) > max(0.0, x0) and min(float(h), y1) > max(0.0, y0)
        ]
        boxes, scores = [b for b, _ in kept], [s for _, s in kept]
        masks = self._segment(rgb, boxes) if boxes else []
        detections = [Detection(b, s, m) for b, s, m in zip(boxes, scores, masks or [None] * len(boxes))]
        return sorted(detections, key=lambda d: -d.score)

    def _segment(self, rgb: np.ndarray, boxes: list[tuple[float, ...]]) -> list[np.ndarray] | None:
        if self.sam_model is None:
            return None
        import torch

        inputs = self.sam_processor(images=rgb, input_boxes=[[list(b) for b in boxes]], return_tensors="pt")
        with torch.inference_mode():
            outputs = self.sam_model(**inputs, multimask_output=False)
        masks = self.sam_processor.image_processor.post_process_masks(
            outputs.pred_masks, inputs["original_sizes"], inputs["reshaped_input_sizes"]
        )[0]
        return [m[0].numpy().astype(bool) for m in masks]
