"""Rerun recording of an evaluation, organised for browsing by factor and value.

Entity tree:
    /episodes/<split>/<factor>=<value>/<instance_id>/r<repeat>/
        camera/<name>      JPEG frames on the `step` timeline
        ee_path, object_path   3D trajectories (points per step + the whole path as a line strip)
        instance           factor values and seed (static text)
        outcome            success / failure text event at the episode's last step
    /summary/<split>/sr_by_value   bar chart of success rate per factor value (static; a split with two values
                                   or more)
    /summary/<split>/values        each value's success rate and episode count (static text)

A recording is never overwritten: the file opens when the first episode is logged (a resumed run with nothing
left to run writes none), and when `vision.rrd` already exists a run's episodes go to the next free
`vision-2.rrd`, `vision-3.rrd`, … `recordings(path)` lists them all (`rerun a.rrd b.rrd` opens them together).
"""

from __future__ import annotations

import re
from collections import defaultdict
from pathlib import Path

import numpy as np
import rerun as rr

from roboview.eval.running.rollout import EpisodeResult
from roboview.variation.factors import factor_names


def _safe(text: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "-_.=" else "_" for ch in text)


def _numbered(path: Path) -> dict[int, Path]:
    """The recordings of `path` that exist, by number: `path` itself is 1, `stem-N.rrd` is N (N ≥ 2)."""
    found = {1: path} if path.is_file() else {}
    pattern = re.compile(re.escape(path.stem) + r"-([0-9]+)" + re.escape(path.suffix))
    for other in path.parent.glob(f"{path.stem}-*{path.suffix}") if path.parent.is_dir() else ():
        match = pattern.fullmatch(other.name)
        if match and int(match[1]) >= 2 and other.is_file():
            found[int(match[1])] = other
    return found


def recordings(path: str | Path) -> list[Path]:
    """Every recording written for the `--eval.rerun` path `path`, oldest first (`path`, `stem-2.rrd`, …)."""
    found = _numbered(Path(path))
    return [found[n] for n in sorted(found)]


def next_recording(path: str | Path) -> Path:
    """Where a new recording for `path` goes: `path` when none exists yet, else the number after the last."""
    path = Path(path)
    found = _numbered(path)
    return path if not found else path.with_name(f"{path.stem}-{max(found) + 1}{path.suffix}")


class RerunLogger:
    """Records episodes to `path`, or to the next free `stem-N.rrd` when `path` exists; opened at the first
    episode, so a run that logs none writes no file and an earlier run's recording is never touched."""

    def __init__(self, path: Path, application_id: str = "roboview_eval") -> None:
        self.path = path  # the requested path; `written` is the file this run records to (None until it logs)
        self.application_id = application_id
        self.rec: rr.RecordingStream | None = None
        self.written: Path | None = None
        self._outcomes: dict[str, dict[str, list[bool]]] = defaultdict(lambda: defaultdict(list))

    def _open(self) -> rr.RecordingStream:
        if self.rec is None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.written = next_recording(self.path)
            self.rec = rr.RecordingStream(self.application_id)
            self.rec.save(str(self.written))
        return self.rec

    def log_episode(self, result: EpisodeResult) -> None:
        row = result.row
        base = (
            f"episodes/{_safe(row['split'])}/{_safe(row['factor'] + '=' + row['value'])}/"
            f"{row['instance_id']}/r{row['repeat']}"
        )
        rec = self._open()
        facts = "\n".join(f"{name}: {row[name]}" for name in factor_names())
        rec.log(
            f"{base}/instance",
            rr.TextDocument(f"{facts}\nepisode_seed: {row['episode_seed']}\npolicy: {row['policy']}"),
            static=True,
        )
        for step in range(len(result.ee_path)):
            rec.set_time("step", sequence=step)
            for cam, frames in result.frames.items():
                rec.log(
                    f"{base}/camera/{cam}", rr.EncodedImage(contents=frames[step], media_type="image/jpeg")
                )
            rec.log(
                f"{base}/ee", rr.Points3D(result.ee_path[step : step + 1], radii=0.01, colors=[40, 120, 255])
            )
            rec.log(
                f"{base}/object",
                rr.Points3D(
                    result.object_path[step : step + 1],
                    radii=0.012,
                    # The object's nominal color; a world's own look (`original`) has none: gray.
                    colors=[int(255 * c) for c in row.get("color_rgb") or (0.5, 0.5, 0.5)],
                ),
            )
        rec.log(f"{base}/ee_path", rr.LineStrips3D([result.ee_path], colors=[40, 120, 255]), static=True)
        rec.log(f"{base}/object_path", rr.LineStrips3D([result.object_path]), static=True)
        rec.set_time("step", sequence=max(len(result.ee_path) - 1, 0))
        outcome = "success" if row["success"] else f"failure: {row['failure_reason']}"
        rec.log(f"{base}/outcome", rr.TextLog(outcome, level="INFO" if row["success"] else "WARN"))
        self._outcomes[row["split"]][row["value"]].append(bool(row["success"]))

    def close(self) -> None:
        if self.rec is None:  # nothing logged: no file written
            return
        for split, by_value in self._outcomes.items():
            values = sorted(by_value)
            srs = np.array([np.mean(by_value[v]) for v in values])
            if len(values) > 1:  # one bar compares nothing, and rerun-sdk 0.33 warns that it is not 1-D
                self.rec.log(f"summary/{_safe(split)}/sr_by_value", rr.BarChart(srs), static=True)
            self.rec.log(
                f"summary/{_safe(split)}/values",
                rr.TextDocument(
                    "\n".join(
                        f"{i}: {v} — SR {sr:.2f} ({len(by_value[v])} episodes)"
                        for i, (v, sr) in enumerate(zip(values, srs))
                    )
                ),
                static=True,
            )
        self.rec.flush()
        rr.disconnect(recording=self.rec)
