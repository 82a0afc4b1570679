"""roboview.pipelines.export_dataset: a collected LeRobot v3.0 dataset, exported to v2.1 and turned back into v3.0 by
LeRobot's own converter (convert_dataset_v21_to_v30), equals the collection frame for frame: values, indices,
timestamps, tasks, and decoded images bit for bit (videos are stream-copied, never re-encoded)."""

import json
import shutil
from pathlib import Path

import pyarrow.parquet as pq
import pytest
import torch

pytestmark = pytest.mark.slow

REPO_ID = "t/demos"
CAMERAS = ["left_top", "wrist"]


@pytest.fixture(scope="module")
def collected(tmp_path_factory) -> Path:
    from roboview.pipelines.collect import CollectConfig, DatasetConfig
    from roboview.pipelines.collect import run as collect

    root = tmp_path_factory.mktemp("export") / "ds"
    collect(
        CollectConfig(
            DatasetConfig(repo_id=REPO_ID, root=str(root), num_episodes=2, image_size=64, cameras=CAMERAS),
            num_workers=1,
        )
    )
    return root


def test_export_round_trips_through_lerobots_v21_converter(collected, tmp_path):
    from lerobot.datasets import utils as lerobot_utils
    from lerobot.datasets.lerobot_dataset import LeRobotDataset
    from lerobot.datasets.video_utils import decode_video_frames
    from lerobot.scripts.convert_dataset_v21_to_v30 import convert_dataset

    from roboview.demos import export_v21
    from roboview.pipelines import export_dataset as export

    out = tmp_path / "t" / "demos"  # the converter works in place, with siblings demos_old / demos_v30
    result = export.run(export.ExportConfig(root=str(collected), output_dir=str(out)))
    native = LeRobotDataset(REPO_ID, root=collected)
    assert (result.episodes, result.frames, result.videos, result.repo_id) == (
        2,
        native.num_frames,
        4,
        REPO_ID,
    )

    # The v2.1 layout, with the metadata file names LeRobot's converter reads.
    assert (export_v21.V21_TASKS_PATH, export_v21.V21_EPISODES_PATH, export_v21.V21_EPISODES_STATS_PATH) == (
        lerobot_utils.LEGACY_TASKS_PATH,
        lerobot_utils.LEGACY_EPISODES_PATH,
        lerobot_utils.LEGACY_EPISODES_STATS_PATH,
    )
    info = json.loads((out / "meta/info.json").read_text())
    assert info["codebase_version"] == "v2.1" and info["data_path"] == export_v21.V21_DATA_PATH
    assert (info["total_episodes"], info["total_frames"], info["total_videos"], info["total_chunks"]) == (
        2,
        native.num_frames,
        4,
        1,
    )
    assert "data_files_size_in_mb" not in info and info["splits"] == {"train": "0:2"}
    lengths = [json.loads(line)["length"] for line in (out / "meta/episodes.jsonl").read_text().splitlines()]
    assert lengths == [int(n) for n in native.meta.episodes["length"]]
    items = [native[i] for i in range(native.num_frames)]
    images = [f"observation.images.{cam}" for cam in CAMERAS]
    for ep in range(2):
        table = pq.read_table(out / f"data/chunk-000/episode_{ep:06d}.parquet")
        assert table.num_rows == lengths[ep] and set(table["episode_index"].to_pylist()) == {ep}
        # datasets 3.x (what a v2.1 lerobot runs on) knows `Sequence`, not datasets 4's `List`.
        features = json.loads(table.schema.metadata[b"huggingface"])["info"]["features"]
        assert features["action"]["_type"] == "Sequence" and features["action"]["length"] == 8
        # Read as a v2.1 reader does: the frame's parquet timestamp into the episode's own MP4 (which must
        # start at 0), at lerobot's default tolerance.
        rows = [item for item in items if int(item["episode_index"]) == ep]
        timestamps = table["timestamp"].to_pylist()
        assert timestamps == [float(item["timestamp"]) for item in rows]
        for key in images:
            frames = decode_video_frames(
                out / f"videos/chunk-000/{key}/episode_{ep:06d}.mp4",
                timestamps,
                tolerance_s=1e-4,
                backend="pyav",
            )
            assert torch.equal(frames, torch.stack([item[key] for item in rows])), (ep, key)
    stats = [json.loads(line) for line in (out / "meta/episodes_stats.jsonl").read_text().splitlines()]
    assert [s["episode_index"] for s in stats] == [0, 1]
    assert stats[1]["stats"]["action"]["count"] == [lengths[1]]
    assert (out / "meta/roboview/episodes.parquet").is_file()  # RoboView's provenance comes along

    # Back to v3.0 with LeRobot's own converter (local root: no hub), then compare frame by frame.
    convert_dataset(REPO_ID, root=out, push_to_hub=False)
    back = LeRobotDataset(REPO_ID, root=out)
    assert back.meta.info.codebase_version == "v3.0"
    assert (
        (back.num_episodes, back.num_frames) == (native.num_episodes, native.num_frames) == (2, sum(lengths))
    )
    assert list(back.meta.tasks.index) == list(native.meta.tasks.index)
    for i, a in enumerate(items):
        b = back[i]
        for key in (
            "action",
            "observation.state",
            "timestamp",
            "episode_index",
            "frame_index",
            "index",
            "task_index",
            *images,
        ):
            assert torch.equal(a[key], b[key]), (i, key)  # images: identical decoded pixels, not close
        assert a["task"] == b["task"]
    # Per-episode statistics (quantiles included) survive the trip: the aggregate is the collection's.
    for key in ("action", "observation.state"):
        for stat in ("mean", "std", "min", "max", "q01", "q99"):
            assert torch.allclose(
                torch.as_tensor(back.meta.stats[key][stat]),
                torch.as_tensor(native.meta.stats[key][stat]),
                atol=1e-6,
            ), (key, stat)


def _fails(capsys, args: list[str]) -> str:
    from roboview.pipelines.export_dataset import main

    with pytest.raises(SystemExit) as exc:
        main(args)
    assert exc.value.code == 2
    return capsys.readouterr().err


def test_bad_input_fails_before_any_work(collected, tmp_path, capsys):
    out = tmp_path / "out"
    err = _fails(capsys, [f"--root={tmp_path / 'missing'}", f"--output_dir={out}"])
    assert f"--root: {tmp_path / 'missing'} does not exist" in err and "v3.0" in err

    old = tmp_path / "old"
    (old / "meta").mkdir(parents=True)
    (old / "meta/info.json").write_text(json.dumps({"codebase_version": "v2.1"}))
    err = _fails(capsys, [f"--root={old}", f"--output_dir={out}"])
    assert f"{old} is a LeRobot v2.1 dataset; allowed: v3.0" in err

    err = _fails(capsys, [f"--root={collected}", f"--output_dir={out}", "--format=v2.0"])
    assert "--format='v2.0' unknown; allowed: v2.1" in err

    busy = tmp_path / "busy"
    busy.mkdir()
    (busy / "keep.txt").write_text("mine")
    err = _fails(capsys, [f"--root={collected}", f"--output_dir={busy}"])
    assert f"--output_dir: {busy} is not empty" in err and [p.name for p in busy.iterdir()] == ["keep.txt"]

    interrupted = tmp_path / "interrupted"
    shutil.copytree(collected, interrupted)
    progress = json.loads((interrupted / "meta/roboview/progress.json").read_text())
    (interrupted / "meta/roboview/progress.json").write_text(json.dumps({**progress, "episodes_saved": 1}))
    err = _fails(capsys, [f"--root={interrupted}", f"--output_dir={out}"])
    assert "interrupted collection (1 episodes checkpointed, meta/info.json lists 2)" in err
    assert not out.exists()  # no case wrote anything


def test_a_failed_export_removes_what_it_wrote(collected, tmp_path):
    import pyarrow as pa

    from roboview.pipelines.export_dataset import ExportConfig, ExportError, run

    # Episode 1's wrist video said to start one frame late: found while cutting it, after episode 0 was written.
    broken = tmp_path / "broken"
    shutil.copytree(collected, broken)
    path = broken / "meta/episodes/chunk-000/file-000.parquet"
    table = pq.read_table(path)
    column = "videos/observation.images.wrist/from_timestamp"
    starts = table[column].to_pylist()
    table = table.set_column(
        table.schema.get_field_index(column), column, pa.array([starts[0], starts[1] + 0.1], pa.float64())
    )
    pq.write_table(table, path)
    out = tmp_path / "out"
    with pytest.raises(ExportError, match=r"episode 1 of observation.images.wrist .* its video starts at"):
        run(ExportConfig(root=str(broken), output_dir=str(out)))
    assert not out.exists()
