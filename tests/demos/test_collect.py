"""collect → load → lerobot-train round trip, kill-and-resume, and bad input, on tiny sizes."""

import json
import os
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from roboview.pipelines.collect import CollectConfig, DatasetConfig, run
from tests.helpers import cli

pytestmark = pytest.mark.slow

REPO_ID = "roboview_test/demos"
SMALL = ["--dataset.image_size=64", "--dataset.fps=10", "--max_steps=100"]


def small_cfg(root: Path, n: int, workers: int, checkpoint_every: int = 2) -> CollectConfig:
    return CollectConfig(
        dataset=DatasetConfig(repo_id=REPO_ID, root=str(root), num_episodes=n, image_size=64),
        num_workers=workers,
        max_steps=100,
        checkpoint_every=checkpoint_every,
    )


def frames_table(root: Path) -> pd.DataFrame:
    files = sorted((root / "data").rglob("*.parquet"))
    return pd.concat([pd.read_parquet(f) for f in files]).sort_values("index").reset_index(drop=True)


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> Path:
    """An uninterrupted 4-episode collection with two spawned workers."""
    root = tmp_path_factory.mktemp("ref") / "ds"
    result = run(small_cfg(root, 4, workers=2))
    assert result.episodes == 4 and result.new_episodes == 4
    assert result.attempts >= 4 and result.failures == result.attempts - 4
    return root


def test_dataset_loads_with_lerobot_and_matches_the_features(reference):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    ds = LeRobotDataset(REPO_ID, root=reference)
    assert ds.num_episodes == 4
    assert set(ds.meta.video_keys) == {
        f"observation.images.{c}" for c in ("front", "left_top", "right_top", "wrist")
    }
    assert ds.meta.features["observation.state"]["shape"] == (8,)
    assert ds.meta.features["action"]["names"][-1] == "gripper_close"
    item = ds[0]
    assert tuple(item["observation.images.front"].shape) == (3, 64, 64)
    assert float(item["observation.images.front"].std()) > 0.02  # a decoded, non-blank frame
    assert item["task"] in {
        "put the small object into the yellow box",
        "pick up the small object and place it in the yellow box",
        "move the small object into the yellow box",
    }
    # Provenance: one row per saved episode with its context and seed.
    prov = pd.read_parquet(reference / "meta/roboview/episodes.parquet")
    assert list(prov["episode_index"]) == [0, 1, 2, 3]
    assert prov["attempt"].is_unique and set(prov["shape"]) <= {"cube", "cylinder", "hex_prism", "cuboid"}
    lengths = list(ds.meta.episodes["length"])
    assert lengths == list(prov["steps"])
    # The gripper closes and opens again in every episode (grasp, then release).
    frames = frames_table(reference)
    for _, ep in frames.groupby("episode_index"):
        grip = np.stack(ep["action"])[:, 7]
        assert grip.max() == 1.0 and grip[-1] == 0.0


def test_lerobots_trainer_trains_on_a_collected_dataset(tiny_checkpoint):
    # The shared checkpoint: lerobot-train (through roboview.pipelines.train's recipe) on 2 demos collect wrote.
    config = json.loads((tiny_checkpoint / "config.json").read_text())
    assert config["type"] == "act"
    assert {"observation.images.left_top", "observation.images.wrist"} <= set(config["input_features"])
    assert (tiny_checkpoint / "model.safetensors").stat().st_size > 1_000_000


def test_every_collected_dataset_has_a_dataset_card(reference):
    from huggingface_hub import DatasetCard

    card = DatasetCard.load(reference / "README.md")
    assert {"LeRobot", "roboview", "pick_place"} <= set(card.data.tags) and card.data.license == "apache-2.0"
    assert card.data.task_categories == ["robotics"]
    assert "Episodes: 4 (" in card.text and "front, left_top, right_top, wrist (64 px square)" in card.text
    assert '"total_episodes": 4' in card.text  # LeRobot's own structure block, from meta/info.json


def test_killed_run_resumes_without_loss_or_duplicates(reference, tmp_path):
    root = tmp_path / "ds"
    proc = cli.start(
        "roboview.pipelines.collect",
        f"--dataset.repo_id={REPO_ID}",
        f"--dataset.root={root}",
        "--dataset.num_episodes=4",
        "--num_workers=1",
        "--checkpoint_every=1",
        *SMALL,
        new_session=True,
    )
    progress = root / "meta/roboview/progress.json"
    deadline = time.time() + 300
    while time.time() < deadline:
        if progress.exists() and json.loads(progress.read_text())["episodes_saved"] >= 2:
            break
        time.sleep(0.2)
    time.sleep(1.0)  # let it get into the middle of the next episode
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    saved_before = json.loads(progress.read_text())["episodes_saved"]
    assert 2 <= saved_before < 4

    result = run(small_cfg(root, 4, workers=1, checkpoint_every=1))
    assert result.episodes == 4 and result.new_episodes == 4 - saved_before

    # Same episodes as the uninterrupted two-worker run: nothing lost, nothing duplicated.
    resumed, ref = frames_table(root), frames_table(reference)
    assert list(resumed["index"]) == list(range(len(resumed)))
    assert list(resumed["episode_index"]) == list(ref["episode_index"])
    np.testing.assert_array_equal(np.stack(resumed["action"]), np.stack(ref["action"]))
    np.testing.assert_array_equal(np.stack(resumed["observation.state"]), np.stack(ref["observation.state"]))
    prov = pd.read_parquet(root / "meta/roboview/episodes.parquet")
    ref_prov = pd.read_parquet(reference / "meta/roboview/episodes.parquet")
    pd.testing.assert_frame_equal(prov, ref_prov)

    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    ds = LeRobotDataset(REPO_ID, root=root)
    assert ds.num_episodes == 4 and ds.num_frames == len(ref)
    last = ds[ds.num_frames - 1]  # frames of the resumed part decode too
    assert int(last["episode_index"]) == 3 and float(last["observation.images.wrist"].std()) > 0.02

    # Asking again for the same count does nothing; asking for more continues.
    again = run(small_cfg(root, 4, workers=1))
    assert again.new_episodes == 0 and again.episodes == 4


def _cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return cli.run("roboview.pipelines.collect", *args, cwd=cwd, timeout=120)


def _main(capsys, *args: str) -> subprocess.CompletedProcess:
    """`_cli(*args)` through roboview.pipelines.collect's `main` in this process: its exit status and stderr."""
    from roboview.pipelines.collect import main

    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_:
        main(list(args))
    return subprocess.CompletedProcess(args, exit_.value.code, "", capsys.readouterr().err)


@pytest.mark.parametrize(
    "args, message",
    [
        (["--dataset.num_episodes=0"], "--dataset.num_episodes=0 must be a positive count"),
        (["--num_workers=-1"], "--num_workers=-1 must be a positive count"),
        (
            ["--dataset.cameras=[front,top_down]"],
            "['top_down']; allowed for --dataset.task=pick_place: front, left_top, right_top, wrist",
        ),
        (["--dataset.fps=7"], "--dataset.fps=7 must be a positive divisor of 500"),
        (["--dataset.vcodec=mjpeg"], "'mjpeg' unknown; allowed: libsvtav1, h264, hevc"),
        (["--dataset.repo_id=noslash"], "'noslash' must look like ORG/NAME"),
        (["--dataset.randomize=[color,lighting]"], "factor(s) ['lighting']; allowed: color, camera_pose"),
    ],
)
def test_cli_rejects_bad_values_before_work(tmp_path, capsys, args, message):
    root = tmp_path / "ds"
    proc = _main(capsys, f"--dataset.root={root}", *args)
    assert proc.returncode == 2
    assert message in proc.stderr and "Traceback" not in proc.stderr
    assert not root.exists()


def test_cli_refuses_foreign_or_mismatched_roots(reference, tmp_path, capsys):
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine")
    # The command line itself (exit status 2, the message on stderr); the rest through the same `main`.
    proc = _cli(f"--dataset.root={foreign}", f"--dataset.repo_id={REPO_ID}", cwd=tmp_path)
    assert proc.returncode == 2 and "holds no RoboView collection" in proc.stderr
    assert sorted(p.name for p in foreign.iterdir()) == ["notes.txt"]

    before = (reference / "meta/info.json").read_text()
    proc = _main(
        capsys,
        f"--dataset.root={reference}",
        f"--dataset.repo_id={REPO_ID}",
        "--dataset.num_episodes=6",
        "--dataset.image_size=96",
    )
    assert proc.returncode == 2 and "image_size: existing 64 vs requested 96" in proc.stderr
    proc = _main(
        capsys,
        f"--dataset.root={reference}",
        f"--dataset.repo_id={REPO_ID}",
        "--dataset.image_size=64",
        "--max_steps=100",
        "--dataset.randomize=[color]",
    )
    assert proc.returncode == 2 and "randomize: existing () vs requested ('color',)" in proc.stderr
    assert (reference / "meta/info.json").read_text() == before

    a_file = tmp_path / "file"
    a_file.write_text("x")
    proc = _main(capsys, f"--dataset.root={a_file}", f"--dataset.repo_id={REPO_ID}")
    assert proc.returncode == 2 and "is a file" in proc.stderr


def test_randomized_collection_records_its_visuals_and_keeps_contexts_and_actions(reference, tmp_path):
    from roboview.sim.cameras import BASE_CAMERAS, WORKSPACE_CENTER
    from roboview.variation.factors.camera import ORBIT_RINGS

    root = tmp_path / "rand"
    cfg = small_cfg(root, 2, workers=1)
    cfg.dataset.randomize = ["camera_pose", "color"]
    cfg.dataset.__post_init__()  # canonical order, as the CLI does
    assert cfg.dataset.randomize == ["color", "camera_pose"]
    run(cfg)
    ref, rnd = (pd.read_parquet(r / "meta/roboview/episodes.parquet") for r in (reference, root))
    # The context-only reference shows the baseline in every episode, and says so.
    assert all(list(v) == [1.0, 0.0, 0.0] for v in ref["object_rgb"])
    assert all(np.allclose(p, BASE_CAMERAS["left_top"].pos) for p in ref["camera_left_top_pos"])
    assert all(len(r) == 0 for r in ref["randomized"])
    # Randomized: fresh visuals per episode, inside the documented continuous ranges...
    assert all(list(r) == ["color", "camera_pose"] for r in rnd["randomized"])
    rgbs = np.stack(rnd["object_rgb"].to_list())
    assert rgbs.shape == (2, 3) and not np.allclose(rgbs[0], rgbs[1]) and ((rgbs >= 0) & (rgbs <= 1)).all()
    for front, left, fovy in zip(
        rnd["camera_front_pos"], rnd["camera_left_top_pos"], rnd["camera_left_top_fovy"]
    ):
        assert np.allclose(front, left) and 45.0 <= fovy <= 50.0  # the perturbed cameras move together
        rel = np.asarray(left) - WORKSPACE_CENTER
        radius, height = np.hypot(rel[0], rel[1]), rel[2]
        assert ORBIT_RINGS[0][0] - 0.04 <= radius <= ORBIT_RINGS[-1][0] + 0.04
        assert ORBIT_RINGS[-1][1] - 0.03 <= height <= ORBIT_RINGS[0][1] + 0.03
    # ...while the task contexts, seeds and expert actions are those of the context-only collection.
    for col in ("attempt", "episode_seed", "initial_position", "shape", "instruction", "steps"):
        assert rnd[col].tolist() == ref[col].iloc[:2].tolist(), col
    ref_frames, rnd_frames = frames_table(reference), frames_table(root)
    n = len(rnd_frames)
    assert np.array_equal(np.stack(rnd_frames["action"]), np.stack(ref_frames["action"].iloc[:n]))
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    a, b = LeRobotDataset(REPO_ID, root=reference)[0], LeRobotDataset(REPO_ID, root=root)[0]
    assert float((a["observation.images.left_top"] - b["observation.images.left_top"]).abs().mean()) > 0.02


def test_env_shows_the_recorded_visuals(env):
    from roboview.tasks.env import baseline_instance
    from roboview.variation.randomization import sample_randomization

    visuals = sample_randomization(123, ("color", "camera_pose"))
    env.reset(
        seed=5,
        options={
            "instance": baseline_instance(),
            "object_rgb": visuals.object_rgb,
            "cameras": visuals.cameras,
        },
    )
    for name in ("front", "left_top"):
        pose = env.scene.camera_pose(name)
        assert np.allclose(pose.pos, visuals.cameras[name].pos, atol=1e-9)
        assert np.allclose(np.abs(np.dot(pose.quat, visuals.cameras[name].quat)), 1.0, atol=1e-9)
    geom = env.scene.ids.shape_geom[env.shape]
    assert np.allclose(env.model.geom_rgba[geom][:3], visuals.object_rgb)
    # The next reset without overrides is back to the instance's own visuals.
    env.reset(seed=5, options={"instance": baseline_instance()})
    assert np.allclose(env.scene.camera_pose("left_top").pos, (0.60, 0.64, 0.64))
    assert np.allclose(env.model.geom_rgba[geom][:3], (1.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="must be 3 sRGB values in"):
        env.reset(options={"instance": baseline_instance(), "object_rgb": (1.5, 0, 0)})


def test_every_video_holds_every_frame(reference):
    # lerobot's streaming encoder drops frames when its queue stays full (made for live capture); the
    # collection sizes the queue so that it cannot, and every parquet row has its video frame.
    import av

    episodes = pd.concat(
        [pd.read_parquet(f) for f in sorted((reference / "meta/episodes").rglob("*.parquet"))],
        ignore_index=True,
    )
    for cam in ("front", "left_top", "right_top", "wrist"):
        key = f"videos/observation.images.{cam}"
        for (chunk, file), group in episodes.groupby([f"{key}/chunk_index", f"{key}/file_index"]):
            path = reference / f"videos/observation.images.{cam}/chunk-{chunk:03d}/file-{file:03d}.mp4"
            with av.open(str(path)) as container:
                decoded = sum(1 for _ in container.decode(video=0))
            assert decoded == int(group["length"].sum()), (path, decoded, int(group["length"].sum()))
            spans = (group[f"{key}/to_timestamp"] - group[f"{key}/from_timestamp"]) * 10  # fps 10
            assert np.allclose(spans.to_numpy(), group["length"].to_numpy())
