"""Episode videos: which episodes get one (`--eval.videos=N|failures|all`) and the MP4 writer.

One H.264 MP4 per episode and observed camera, the frames the policy was shown at the env's control
rate, written with PyAV (its wheels bundle FFmpeg and libx264: no system FFmpeg needed). Files are
named by instance, value and repeat so the report can link them from its per-value tables:
`videos/<split>/<value>/<instance_id>_r<repeat>_<camera>.mp4`.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

MODES = ("failures", "all")


def parse(spec: str) -> str | int:
    """'' (none), 'failures', 'all', or N ≥ 1 (the first N episodes run) — anything else is an error."""
    spec = spec.strip()
    if not spec or spec in MODES:
        return spec
    if spec.isdigit() and int(spec) > 0:
        return int(spec)
    raise ValueError(
        f"videos={spec!r} is not allowed; allowed: a count N ≥ 1 (the first N episodes), "
        f"{' or '.join(MODES)}, or empty for none"
    )


def _safe(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", str(text))


def relative_path(row: dict, camera: str) -> str:
    """Where an episode's video of `camera` goes, relative to the results folder."""
    return (
        f"videos/{_safe(row['split'])}/{_safe(row['value'])}/"
        f"{_safe(row['instance_id'])}_r{row['repeat']}_{_safe(camera)}.mp4"
    )


def camera_of(path: str) -> str:
    """The camera of a video written at `relative_path` (instance ids and the repeat tag hold no "_")."""
    return Path(path).stem.split("_", 2)[-1]


def write_mp4(path: Path, frames: np.ndarray, fps: int) -> Path:
    """(T, H, W, 3) uint8 → H.264 MP4 (yuv420p; odd sides padded by one black pixel)."""
    import av

    frames = np.asarray(frames, dtype=np.uint8)
    pad_h, pad_w = frames.shape[1] % 2, frames.shape[2] % 2
    if pad_h or pad_w:
        frames = np.pad(frames, ((0, 0), (0, pad_h), (0, pad_w), (0, 0)))
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.mp4")
    with av.open(str(tmp), mode="w") as container:
        stream = container.add_stream("libx264", rate=fps)
        stream.width, stream.height = frames.shape[2], frames.shape[1]
        stream.pix_fmt = "yuv420p"
        stream.thread_count = 1  # rendering workers own the cores
        stream.options = {"crf": "23", "preset": "veryfast"}
        for frame in frames:
            for packet in stream.encode(av.VideoFrame.from_ndarray(frame, format="rgb24")):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)
    tmp.replace(path)
    return path


def filmed(mode: str | int, index: int) -> bool:
    """Whether the `index`-th episode still to run records frames (`failures` records every episode: a failure
    is known only at its end, when the worker drops the frames of a success)."""
    return mode in MODES or (bool(mode) and index < int(mode))
