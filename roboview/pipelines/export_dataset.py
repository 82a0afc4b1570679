"""Export a LeRobot v3.0 dataset (as written by roboview.pipelines.collect) to LeRobot's v2.1 layout.

    roboview-export-dataset --root=outputs/demos --output_dir=outputs/demos_v21 \
        [--repo_id=roboview/demos] [--format=v2.1]

Trainers that read datasets through a lerobot older than 0.4 (openpi pins one; dataset format v2.1)
cannot open v3.0, which packs many episodes into each parquet and MP4 file. The export holds the
same episodes with one file per episode:

    data/chunk-000/episode_000000.parquet              the episode's frames (state, action, indices, task)
    videos/chunk-000/<video_key>/episode_000000.mp4    one MP4 per episode and camera, timestamps from 0
    meta/info.json                                     codebase_version "v2.1", path templates, counts
    meta/episodes.jsonl, meta/tasks.jsonl, meta/episodes_stats.jsonl

Videos are cut out of the v3.0 files without re-encoding (stream copy; every episode lerobot writes
starts on a keyframe, which is checked), so decoded frames are bit-identical to the source. Values,
timestamps, indices, tasks and per-episode statistics are copied unchanged; parquet files carry
`datasets` feature metadata in the `Sequence` form that `datasets` 3.x (the older lerobot's) reads.
RoboView's per-episode provenance (meta/roboview/episodes.parquet) comes along. LeRobot's own
`convert_dataset_v21_to_v30.py` turns an export back into the source dataset.

Without --output_dir the export goes to `$HF_LEROBOT_HOME/<repo_id>`, where a v2.x lerobot (and
openpi's `repo_id=`) looks for it; --repo_id defaults to the id the collection was made with. The
output folder must be new or empty; a failed export removes what it wrote. See docs/openpi.md.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from roboview.core.cli_errors import flag_errors
from roboview.demos.export_v21 import FORMATS, ExportError, check_output, check_source, export
from roboview.pipelines._cli import cli_main


@dataclass
class ExportConfig:
    # LeRobot v3.0 dataset folder to export (as written by roboview.pipelines.collect).
    root: str = ""
    # New or empty folder for the export. Default: $HF_LEROBOT_HOME/<repo_id>, where a v2.x lerobot
    # (and openpi's repo_id) looks for the dataset.
    output_dir: str = ""
    # Dataset id (ORG/NAME) readers open the export by. Default: the id the collection was made with.
    repo_id: str = ""
    # Layout to write: v2.1 (one parquet and one MP4 per camera per episode; lerobot before 0.4, openpi).
    format: str = "v2.1"

    def __post_init__(self) -> None:
        if not self.root:
            raise ExportError(
                "--root is required: a LeRobot v3.0 dataset folder written by roboview.pipelines.collect"
            )
        if self.format not in FORMATS:
            raise ExportError(f"--format={self.format!r} unknown; allowed: {', '.join(FORMATS)}")
        if self.repo_id and (self.repo_id.count("/") != 1 or not all(self.repo_id.split("/"))):
            raise ExportError(f"--repo_id={self.repo_id!r} must look like ORG/NAME")


@dataclass(frozen=True)
class ExportResult:
    output_dir: Path
    repo_id: str
    episodes: int
    frames: int
    videos: int
    elapsed_s: float
    in_lerobot_home: bool = False  # written to $HF_LEROBOT_HOME/<repo_id>, where v2.x readers look


def run(cfg: ExportConfig) -> ExportResult:
    root = Path(cfg.root)
    with flag_errors("--root"):
        source, collected_as = check_source(root)
    repo_id = cfg.repo_id or collected_as
    if cfg.output_dir:
        out = Path(cfg.output_dir)
    elif repo_id:
        from lerobot.utils.constants import HF_LEROBOT_HOME

        out = HF_LEROBOT_HOME / repo_id
    else:
        raise ExportError(
            f"--root={root} was not written by roboview.pipelines.collect, so it names no repo id: "
            "give --output_dir, or --repo_id to export to $HF_LEROBOT_HOME/<repo_id>"
        )
    with flag_errors("--output_dir"):
        check_output(out, root)

    t0 = time.perf_counter()
    videos = export(source, out)
    return ExportResult(
        out,
        repo_id or "",
        len(source.episodes),
        source.info["total_frames"],
        videos,
        time.perf_counter() - t0,
        in_lerobot_home=not cfg.output_dir,
    )


def _summary(cfg: ExportConfig, result: ExportResult) -> None:
    print(
        f"[export_dataset] {result.episodes} episodes, {result.frames:,} frames, {result.videos} videos "
        f"(stream copy) → {result.output_dir} as LeRobot {cfg.format} in {result.elapsed_s:.2f} s"
    )
    if result.in_lerobot_home:
        print(f"  a v2.x lerobot (openpi: repo_id={result.repo_id!r}) finds it there")
    elif result.repo_id:
        print(
            f"  a v2.x lerobot (openpi: repo_id={result.repo_id!r}) reads it from "
            f"$HF_LEROBOT_HOME/{result.repo_id}: copy or link it there"
        )


def main(args: list[str] | None = None) -> ExportResult:
    return cli_main(ExportConfig, run, _summary, (ValueError,), args)


if __name__ == "__main__":
    main()
