"""LeRobot v3.0 → v2.1 export of a collected dataset, the library behind `roboview-export-dataset`.

Trainers that read datasets through a lerobot older than 0.4 (openpi pins one; dataset format v2.1) cannot open
v3.0, which packs many episodes into each parquet and MP4 file. The export writes one file per episode; videos
are cut without re-encoding (stream copy, every episode starting on a keyframe, checked), so decoded frames are
bit-identical to the source; values, timestamps, indices, tasks and per-episode statistics are copied unchanged.
`check_source` and `check_output` refuse what cannot be exported before anything is written; `export` writes.
"""

from __future__ import annotations

import json
import logging
import math
import shutil
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from tqdm import tqdm

log = logging.getLogger(__name__)

FORMATS = ("v2.1",)
SOURCE_VERSION = "v3.0"
# v2.1 path templates (lerobot before 0.4; lerobot 0.6 no longer defines them).
V21_DATA_PATH = "data/chunk-{episode_chunk:03d}/episode_{episode_index:06d}.parquet"
V21_VIDEO_PATH = "videos/chunk-{episode_chunk:03d}/{video_key}/episode_{episode_index:06d}.mp4"
# v3.0 templates, the ones in the source's info.json (lerobot.datasets.utils.DEFAULT_*_PATH).
V30_DATA_PATH = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
V30_VIDEO_PATH = "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
# v2.1 metadata files (lerobot.datasets.utils.LEGACY_*_PATH, which LeRobot's v2.1 -> v3.0 converter reads).
V21_TASKS_PATH = "meta/tasks.jsonl"
V21_EPISODES_PATH = "meta/episodes.jsonl"
V21_EPISODES_STATS_PATH = "meta/episodes_stats.jsonl"
# What roboview.pipelines.collect keeps beside lerobot's files (roboview.demos.dataset).
PROGRESS = Path("meta/roboview/progress.json")
PROVENANCE = Path("meta/roboview/episodes.parquet")


class ExportError(ValueError):
    """The source cannot be exported as asked (named value, what is allowed); nothing was left behind."""


@dataclass
class Source:
    """A validated v3.0 dataset: its info.json, task table and per-episode rows (meta/episodes)."""

    root: Path
    info: dict
    episodes: list[dict]
    tasks: list[tuple[int, str]]  # (task_index, task), by task_index
    video_keys: list[str] = field(default_factory=list)


def check_source(root: Path) -> tuple[Source, str | None]:
    """Everything an export needs from `root`, checked before any file is written; also the repo id the
    collection was made with (None for a dataset not written by roboview.pipelines.collect)."""
    import pyarrow.parquet as pq

    info = _read_info(root)
    video_keys = [key for key, ft in info["features"].items() if ft["dtype"] == "video"]
    for key, template in (("data_path", V30_DATA_PATH), ("video_path", V30_VIDEO_PATH)):
        if info.get(key) != template and (key == "data_path" or video_keys):
            raise ExportError(f"{root}: meta/info.json has {key}={info.get(key)!r}; allowed: {template!r}")
    repo_id = _collected_repo_id(root, info)
    episodes = _read_episodes(root, info)
    _check_files(root, episodes, video_keys)
    tasks = pq.read_table(root / "meta/tasks.parquet").to_pandas()
    task_list = sorted((int(index), str(task)) for task, index in zip(tasks.index, tasks["task_index"]))
    return Source(root, info, episodes, task_list, video_keys), repo_id


def _read_info(root: Path) -> dict:
    """meta/info.json of a LeRobot v3.0 dataset folder."""
    what = "give a LeRobot v3.0 dataset folder written by roboview.pipelines.collect"
    if not root.exists():
        raise ExportError(f"{root} does not exist; {what}")
    if not root.is_dir():
        raise ExportError(f"{root} is a file; {what}")
    info_path = root / "meta/info.json"
    if not info_path.is_file():
        raise ExportError(f"{root} is not a LeRobot dataset (meta/info.json missing); {what}")
    info = json.loads(info_path.read_text())
    version = info.get("codebase_version")
    if version != SOURCE_VERSION:
        raise ExportError(
            f"{root} is a LeRobot {version} dataset; allowed: {SOURCE_VERSION} "
            f"(this command exports {SOURCE_VERSION} to {', '.join(FORMATS)})"
        )
    return info


def _collected_repo_id(root: Path, info: dict) -> str | None:
    """The repo id roboview.pipelines.collect recorded (None for another writer's dataset); its checkpoint must
    match the metadata (an interrupted collection is refused)."""
    if not (root / PROGRESS).is_file():
        return None
    progress = json.loads((root / PROGRESS).read_text())
    if progress.get("episodes_saved") != info["total_episodes"]:
        raise ExportError(
            f"{root} holds an interrupted collection ({progress.get('episodes_saved')} episodes checkpointed, "
            f"meta/info.json lists {info['total_episodes']}); rerun roboview.pipelines.collect with the same "
            "settings to finish it, then export"
        )
    return progress.get("signature", {}).get("repo_id")


def _read_episodes(root: Path, info: dict) -> list[dict]:
    """meta/episodes' rows in episode order, checked against meta/info.json's counts."""
    import pyarrow.parquet as pq

    files = sorted((root / "meta/episodes").glob("chunk-*/file-*.parquet"))
    episodes = sorted(
        (row for f in files for row in pq.read_table(f).to_pylist()), key=lambda row: row["episode_index"]
    )
    indices = [row["episode_index"] for row in episodes]
    if indices != list(range(info["total_episodes"])):
        raise ExportError(
            f"{root}: meta/episodes lists episodes {indices[:5]}… ({len(indices)}), expected "
            f"0..{info['total_episodes'] - 1} as meta/info.json says"
        )
    if sum(row["length"] for row in episodes) != info["total_frames"]:
        raise ExportError(
            f"{root}: episode lengths add up to {sum(row['length'] for row in episodes)} frames, "
            f"meta/info.json says {info['total_frames']}"
        )
    if not episodes:
        raise ExportError(f"{root} holds no episodes; nothing to export")
    return episodes


def _check_files(root: Path, episodes: list[dict], video_keys: list[str]) -> None:
    """Every data and video file the episodes' metadata lists exists."""
    needed = {
        V30_DATA_PATH.format(chunk_index=row["data/chunk_index"], file_index=row["data/file_index"])
        for row in episodes
    }
    needed |= {
        V30_VIDEO_PATH.format(
            video_key=key,
            chunk_index=row[f"videos/{key}/chunk_index"],
            file_index=row[f"videos/{key}/file_index"],
        )
        for row in episodes
        for key in video_keys
    }
    missing = sorted(rel for rel in needed if not (root / rel).is_file())
    if missing:
        raise ExportError(
            f"{root} is incomplete: {len(missing)} file(s) its metadata lists are missing, e.g. {missing[0]}"
        )


def check_output(out: Path, root: Path) -> None:
    what = "give a new or empty folder"
    if out.exists() and not out.is_dir():
        raise ExportError(f"{out} is a file; {what}")
    if out.is_dir() and any(out.iterdir()):
        raise ExportError(f"{out} is not empty; {what} (an export never overwrites)")
    resolved, source = out.resolve(), root.resolve()
    if resolved == source or source in resolved.parents:
        raise ExportError(f"{out} lies inside --root={root}; {what} outside the source dataset")


def _datasets3_features(metadata: bytes) -> bytes:
    """The parquet's `huggingface` schema metadata with `datasets` 4's `List` written as `Sequence`:
    the older `datasets` (3.x) that lerobot before 0.4 runs on knows no `List` type and fails to load
    the file; `datasets` 4 still reads `Sequence` (as the same `List`)."""

    def rewrite(node):
        if isinstance(node, dict):
            node = {k: rewrite(v) for k, v in node.items()}
            if node.get("_type") == "List":
                node["_type"] = "Sequence"
            return node
        if isinstance(node, list):
            return [rewrite(v) for v in node]
        return node

    return json.dumps(rewrite(json.loads(metadata))).encode()


class _DataFiles:
    """Per-episode slices of the v3.0 data files, read one file at a time (episodes come in file order)."""

    def __init__(self, root: Path):
        self.root, self.key, self.table, self.first_index = root, None, None, 0

    def episode(self, row: dict):
        import numpy as np
        import pyarrow.parquet as pq

        key = (row["data/chunk_index"], row["data/file_index"])
        if key != self.key:
            self.key = key
            self.table = pq.read_table(
                self.root / V30_DATA_PATH.format(chunk_index=key[0], file_index=key[1])
            )
            self.first_index = int(self.table["index"][0].as_py())
        start = row["dataset_from_index"] - self.first_index
        part = self.table.slice(start, row["length"])
        ep = row["episode_index"]
        if (
            part.num_rows != row["length"]
            or not (part["episode_index"].to_numpy() == ep).all()
            or not np.array_equal(part["frame_index"].to_numpy(), np.arange(row["length"]))
        ):
            raise ExportError(
                f"{self.root}: the data rows of episode {ep} are not where meta/episodes puts them "
                f"(rows {row['dataset_from_index']}..{row['dataset_to_index']})"
            )
        metadata = dict(part.schema.metadata or {})
        if b"huggingface" in metadata:
            metadata[b"huggingface"] = _datasets3_features(metadata[b"huggingface"])
        return part.replace_schema_metadata(metadata)


class _VideoSegments:
    """Packets of one camera's v3.0 MP4 files, handed out episode by episode (stream copy, no decoding).

    Episodes follow each other in a file: an episode's packets are those whose presentation time lies in
    [from_timestamp, to_timestamp), the first one a keyframe (lerobot encodes every episode on its own and
    concatenates), one packet per frame."""

    def __init__(self, root: Path, video_key: str, fps: int):
        self.root, self.video_key, self.half_frame = root, video_key, 0.5 / fps
        self.key, self.container, self.stream, self.packets, self.pending = None, None, None, None, None

    def _open(self, key: tuple[int, int]) -> None:
        import av

        self.close()
        path = self.root / V30_VIDEO_PATH.format(
            video_key=self.video_key, chunk_index=key[0], file_index=key[1]
        )
        self.key, self.container = key, av.open(str(path))
        self.stream = self.container.streams.video[0]
        self.packets = (
            p for p in self.container.demux(self.stream) if p.dts is not None and p.pts is not None
        )
        self.pending = next(self.packets, None)

    def close(self) -> None:
        if self.container is not None:
            self.container.close()
            self.container = None

    def episode(self, row: dict) -> tuple[object, list]:
        """(the source stream, the episode's packets)."""
        vk, ep = self.video_key, row["episode_index"]
        key = (row[f"videos/{vk}/chunk_index"], row[f"videos/{vk}/file_index"])
        if key != self.key:
            self._open(key)
        start, stop = row[f"videos/{vk}/from_timestamp"], row[f"videos/{vk}/to_timestamp"]
        tb = self.stream.time_base
        packets = []
        while self.pending is not None and float(self.pending.pts * tb) < stop - self.half_frame:
            packets.append(self.pending)
            self.pending = next(self.packets, None)
        where = f"episode {ep} of {vk} (file {key}, {start:.3f}..{stop:.3f} s)"
        if not packets or abs(float(packets[0].pts * tb) - start) > self.half_frame:
            first = f"{float(packets[0].pts * tb):.3f} s" if packets else "nothing"
            raise ExportError(f"{where}: its video starts at {first}, not where meta/episodes says")
        if not packets[0].is_keyframe:
            raise ExportError(
                f"{where} does not start on a keyframe, so it cannot be cut out without "
                "re-encoding; this command only stream-copies"
            )
        if len(packets) != row["length"]:
            raise ExportError(
                f"{where} holds {len(packets)} video frames but {row['length']} data rows; "
                "the source dataset is inconsistent"
            )
        return self.stream, packets


def _write_video(stream, packets: list, path: Path) -> None:
    """One episode's packets into their own MP4, timestamps shifted to start at 0 (no re-encoding)."""
    import av

    path.parent.mkdir(parents=True, exist_ok=True)
    offset = packets[0].pts
    with av.open(str(path), mode="w", options={"movflags": "faststart"}) as out:
        target = out.add_stream_from_template(template=stream, opaque=True)
        target.time_base = stream.time_base
        for packet in packets:
            packet.pts -= offset
            packet.dts -= offset
            packet.stream = target
            out.mux(packet)


def _info_v21(info: dict, num_episodes: int, video_keys: list[str]) -> dict:
    """meta/info.json in v2.1 form: per-episode path templates, chunk and video counts, no file sizes."""
    features = {}
    for key, ft in info["features"].items():
        ft = dict(ft)
        if ft["dtype"] == "video":
            ft["info"] = {
                **ft.get("info", {}),
                "video.is_depth_map": bool(ft.get("info", {}).get("is_depth_map", False)),
            }
        else:
            ft.pop("fps", None)  # v2.1 keeps fps only in info.json's top level and the video info
        features[key] = ft
    chunks_size = info.get("chunks_size", 1000)
    return {
        "codebase_version": "v2.1",
        "robot_type": info.get("robot_type"),
        "total_episodes": num_episodes,
        "total_frames": info["total_frames"],
        "total_tasks": info["total_tasks"],
        "total_videos": num_episodes * len(video_keys),
        "total_chunks": math.ceil(num_episodes / chunks_size),
        "chunks_size": chunks_size,
        "fps": info["fps"],
        "splits": info.get("splits") or {"train": f"0:{num_episodes}"},
        "data_path": V21_DATA_PATH,
        "video_path": V21_VIDEO_PATH if video_keys else None,
        "features": features,
    }


def _episode_stats(row: dict) -> dict:
    """{feature: {stat: value}} from meta/episodes' `stats/<feature>/<stat>` columns (quantiles included)."""
    stats: dict[str, dict] = {}
    for column, value in row.items():
        if column.startswith("stats/") and value is not None:
            feature, stat = column[len("stats/") :].rsplit("/", 1)
            stats.setdefault(feature, {})[stat] = value
    return stats


def _write_jsonl(path: Path, rows: Iterator[dict]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w") as f:
        for row in rows:
            f.write(json.dumps(row) + "\n")


def export(source: Source, out: Path) -> int:
    """Write the v2.1 dataset into `out` (new or empty; check_output's), made if missing; returns how many videos
    were written. A failed or interrupted export leaves no half-written dataset: what it wrote is removed, and
    `out` itself if it made it."""
    created = not out.exists()
    out.mkdir(parents=True, exist_ok=True)
    try:
        return _write(source, out)
    except BaseException:
        if created:
            shutil.rmtree(out, ignore_errors=True)
        else:
            for child in out.iterdir():
                shutil.rmtree(child) if child.is_dir() else child.unlink()
        raise


def _write(source: Source, out: Path) -> int:
    """Write the v2.1 dataset into the existing, empty `out`; the videos written."""
    import pyarrow.parquet as pq

    info = source.info
    chunks_size = info.get("chunks_size", 1000)
    data = _DataFiles(source.root)
    videos = {key: _VideoSegments(source.root, key, info["fps"]) for key in source.video_keys}
    written = 0
    try:
        for row in tqdm(source.episodes, desc="export", unit="ep", dynamic_ncols=True):
            ep = row["episode_index"]
            chunk = ep // chunks_size
            path = out / V21_DATA_PATH.format(episode_chunk=chunk, episode_index=ep)
            path.parent.mkdir(parents=True, exist_ok=True)
            pq.write_table(data.episode(row), path)
            for key, segments in videos.items():
                stream, packets = segments.episode(row)
                _write_video(
                    stream,
                    packets,
                    out / V21_VIDEO_PATH.format(episode_chunk=chunk, video_key=key, episode_index=ep),
                )
                written += 1
    finally:
        for segments in videos.values():
            segments.close()

    _write_jsonl(out / V21_TASKS_PATH, ({"task_index": i, "task": task} for i, task in source.tasks))
    _write_jsonl(
        out / V21_EPISODES_PATH,
        (
            {"episode_index": row["episode_index"], "tasks": list(row["tasks"]), "length": row["length"]}
            for row in source.episodes
        ),
    )
    _write_jsonl(
        out / V21_EPISODES_STATS_PATH,
        ({"episode_index": row["episode_index"], "stats": _episode_stats(row)} for row in source.episodes),
    )
    (out / "meta/info.json").write_text(
        json.dumps(_info_v21(info, len(source.episodes), source.video_keys), indent=4, ensure_ascii=False)
    )
    if (source.root / PROVENANCE).is_file():
        (out / PROVENANCE).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(source.root / PROVENANCE, out / PROVENANCE)
    return written
