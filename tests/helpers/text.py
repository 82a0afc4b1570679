"""Whether a word on a card reads upright in a rendered frame: the ink the word adds to the frame (against the same
frame with the card blank) matches the word's own drawing better upright than flipped or turned."""

from __future__ import annotations

import numpy as np
from PIL import Image

from roboview.variation.factors.scene_text import card_image


def _bbox(mask: np.ndarray) -> np.ndarray:
    rows, cols = np.nonzero(mask)
    return mask[rows.min() : rows.max() + 1, cols.min() : cols.max() + 1]


def reading(frame: np.ndarray, blank: np.ndarray, word: str) -> str:
    """How `word` reads in `frame`: "upright", "flipped" (top to bottom), "mirrored" or "turned" (180°)."""
    ink = _bbox((blank.astype(int) - frame.astype(int)).max(axis=-1) > 40)
    drawn = _bbox(card_image(word).min(axis=-1) < 128)
    size = (ink.shape[1], ink.shape[0])
    variants = {
        "upright": drawn,
        "flipped": drawn[::-1],
        "mirrored": drawn[:, ::-1],
        "turned": drawn[::-1, ::-1],
    }
    scores = {
        name: float((np.asarray(Image.fromarray(v).resize(size)) == ink).mean())
        for name, v in variants.items()
    }
    return max(scores, key=scores.get)
