"""Writing expert demos into a LeRobotDataset v3 with lerobot's own writer, crash-safely.

lerobot keeps its parquet writers open until `finalize()`, so a killed process leaves files
without footers. We therefore write in *checkpoints*: every `checkpoint_every` episodes the
dataset is finalized and reopened (lerobot's own resume path, which starts new data/video/meta
files), and `meta/roboview/progress.json` records what is complete, together with a copy of the
three metadata files lerobot rewrites in place (info.json, stats.json, tasks.parquet). On the next
run anything written after the last checkpoint is removed and those files restored, so a resumed
dataset holds exactly the checkpointed episodes — nothing lost, nothing duplicated.
"""

from __future__ import annotations

import json
import logging
import shutil
from dataclasses import asdict, dataclass
from pathlib import Path

import pandas as pd

from roboview.core.folders import folder_problem
from roboview.demos.recorder import DemoEpisode
from roboview.tasks import load_task
from roboview.tasks.env import STATE_KEY, action_names, state_names
from roboview.tasks.world import camera_of_feature, feature_key
from roboview.variation.factors import DEFAULT_TASK

log = logging.getLogger(__name__)

PROGRESS_DIR = Path("meta/roboview")
PROGRESS_FILE = PROGRESS_DIR / "progress.json"
PROVENANCE_FILE = PROGRESS_DIR / "episodes.parquet"
SNAPSHOT_DIR = PROGRESS_DIR / "checkpoint"
# Files lerobot rewrites in place on every episode (restored on rollback).
REWRITTEN_FILES = (Path("meta/info.json"), Path("meta/stats.json"), Path("meta/tasks.parquet"))
# Folders whose files are only ever added, never rewritten, after a reopen.
APPEND_ONLY_DIRS = ("data", "videos", "meta/episodes")
TEMP_DIRS = ("images",)
PROGRESS_FORMAT = 1


class DatasetRootError(ValueError):
    """The dataset root holds something this collection cannot safely write into."""


@dataclass(frozen=True)
class CollectionSignature:
    """What must match for a root to be resumed: a different value means a different dataset."""

    repo_id: str
    fps: int
    image_size: int
    cameras: tuple[str, ...]
    seed: int
    max_steps: int
    randomize: tuple[str, ...] = ()  # collections made before randomization existed had none
    task: str = DEFAULT_TASK  # collections made before the task axis were pick_place
    control: str = "joint"  # collections made before end-effector control were joint
    contexts: tuple[tuple[str, tuple[str, ...]], ...] = ()  # the context values drawn from (empty: all)
    cover: bool = False  # each attempt the next combination of `contexts`' values, not a random draw


def demo_features(
    cameras: tuple[str, ...], image_size: int, control: str = "joint", task: str = DEFAULT_TASK
) -> dict[str, dict]:
    """LeRobot features: one video per camera, 8-d state and the control's action, named as the task's env names
    them (RoboView's scene: docs/benchmark.md, "The task and its interfaces", docs/control.md; LIBERO's: the
    `{"motors": [...]}` names of LeRobot-format LIBERO datasets, docs/libero.md)."""
    features = {
        feature_key(cam): {
            "dtype": "video",
            "shape": (image_size, image_size, 3),
            "names": ["height", "width", "channels"],
        }
        for cam in cameras
    }
    names = load_task(task).env_class().feature_names(control)
    if names is None:
        names = (list(state_names(control)), list(action_names(control)))
    for key, value in zip((STATE_KEY, "action"), names):
        listed = next(iter(value.values())) if isinstance(value, dict) else value
        features[key] = {"dtype": "float32", "shape": (len(listed),), "names": value}
    return features


@dataclass
class Progress:
    """Checkpointed state of a collection (meta/roboview/progress.json)."""

    signature: CollectionSignature
    episodes_saved: int = 0
    next_attempt: int = 0
    failures: int = 0
    format: int = PROGRESS_FORMAT

    @classmethod
    def load(cls, root: Path) -> Progress:
        raw = json.loads((root / PROGRESS_FILE).read_text())
        if raw.get("format") != PROGRESS_FORMAT:
            raise DatasetRootError(
                f"{root / PROGRESS_FILE} has format {raw.get('format')!r}; "
                f"this version reads format {PROGRESS_FORMAT}"
            )
        sig = raw.pop("signature")
        sig["cameras"] = tuple(sig["cameras"])
        sig["randomize"] = tuple(sig.get("randomize", ()))
        sig["contexts"] = tuple((name, tuple(values)) for name, values in sig.get("contexts", ()))
        return cls(signature=CollectionSignature(**sig), **raw)

    def save(self, root: Path) -> None:
        path = root / PROGRESS_FILE
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps(asdict(self), indent=2))
        tmp.replace(path)  # atomic: a crash leaves either the old or the new checkpoint


def check_root(root: Path, signature: CollectionSignature) -> Progress | None:
    """Validate `root` before any work: None = start fresh, else the checkpoint to resume from."""
    problem = folder_problem(
        root,
        "collection",
        PROGRESS_FILE,
        "choose a new folder (or one from an earlier run) or delete this one",
        label=f"dataset root {root}",
        writing=True,
    )
    if problem:
        raise DatasetRootError(problem)
    if not (root / PROGRESS_FILE).is_file():
        return None  # new or empty
    progress = Progress.load(root)
    if progress.signature != signature:
        diffs = {
            k: (v, getattr(signature, k))
            for k, v in asdict(progress.signature).items()
            if (tuple(v) if isinstance(v, list) else v) != getattr(signature, k)
        }
        detail = ", ".join(f"{k}: existing {old!r} vs requested {new!r}" for k, (old, new) in diffs.items())
        raise DatasetRootError(
            f"dataset root {root} holds a collection made with different settings ({detail}); "
            "rerun with the same settings to resume, or choose a new root"
        )
    return progress


def _append_only_files(root: Path) -> list[str]:
    return sorted(
        str(p.relative_to(root))
        for d in APPEND_ONLY_DIRS
        if (root / d).exists()
        for p in (root / d).rglob("*")
        if p.is_file()
    )


CARD = "README.md"


def _names(info: dict, key: str) -> list[str]:
    """A feature's entry names as info.json lists them (a list, or LeRobot-format `{"motors": [...]}`)."""
    names = info["features"][key]["names"]
    return list(next(iter(names.values())) if isinstance(names, dict) else names)


def write_card(root: Path, repo_id: str, task: str, provenance_rows: int, control: str = "joint") -> Path:
    """The dataset card (README.md), LeRobot's own template (`create_lerobot_dataset_card`, what its push writes)
    filled with what RoboView knows: how the demos were made and what they do not vary."""
    from lerobot.datasets.io_utils import load_info
    from lerobot.datasets.utils import create_lerobot_dataset_card

    info = json.loads((root / "meta" / "info.json").read_text())
    cameras = [c for c in map(camera_of_feature, info["features"]) if c]
    world = load_task(task).env_class().world
    description = (
        f"Scripted expert demonstrations of the RoboView `{task}` task ({world.title}), collected with "
        f"context-only randomization: its context factors ({', '.join(load_task(task).context_factors())}) and the "
        f"episode seed vary; every visual "
        f"factor (object color, cameras, lighting, table) stays at its baseline, so a policy trained here can be "
        f"measured for visual bias on the RoboView-Bias benchmark.\n\n"
        f"- Episodes: {info['total_episodes']} ({info['total_frames']} frames at {info['fps']} fps)\n"
        f"- Cameras: {', '.join(cameras)} ({info['features'][feature_key(cameras[0])]['shape'][0]} px square)\n"
        f"- Control: `{control}`; `observation.state`: {', '.join(_names(info, STATE_KEY))}; `action`: "
        f"{', '.join(_names(info, 'action'))}\n"
        f"- Per-episode provenance (instance, context, seed): `{PROVENANCE_FILE.as_posix()}` "
        f"({provenance_rows} rows)"
    )
    card = create_lerobot_dataset_card(
        tags=["roboview", "visual-bias", task],
        dataset_info=load_info(root),
        license="apache-2.0",
        repo_id=repo_id,
        dataset_description=description,
    )
    card.save(root / CARD)
    return root / CARD


def write_checkpoint(root: Path, progress: Progress, provenance: list[dict]) -> None:
    """Record a consistent state. Call only right after `dataset.finalize()`."""
    snap = root / SNAPSHOT_DIR
    snap.mkdir(parents=True, exist_ok=True)
    for rel in REWRITTEN_FILES:
        if (root / rel).exists():
            shutil.copy2(root / rel, snap / rel.name)
    (snap / "files.json").write_text(json.dumps(_append_only_files(root)))
    if provenance:
        frame = pd.DataFrame(provenance)
        tmp = root / PROVENANCE_FILE.with_suffix(".tmp")
        frame.to_parquet(tmp, index=False)
        tmp.replace(root / PROVENANCE_FILE)
    progress.save(root)


def load_provenance(root: Path) -> list[dict]:
    """The per-episode provenance rows collected so far (none yet: empty)."""
    path = root / PROVENANCE_FILE
    return pd.read_parquet(path).to_dict("records") if path.exists() else []


def read_provenance(root: str | Path) -> tuple[pd.DataFrame, list[str]]:
    """A finished collection's per-episode provenance and its camera names (from meta/info.json)."""
    root = Path(root)
    info_path = root / "meta" / "info.json"
    if (
        not info_path.is_file()
        or not (root / PROVENANCE_FILE).is_file()
        or not (root / PROGRESS_FILE).is_file()
    ):
        raise DatasetRootError(
            f"{root} is not a roboview.pipelines.collect dataset (meta/info.json, {PROVENANCE_FILE} or "
            f"{PROGRESS_FILE} missing)"
        )
    Progress.load(root)  # checks the format version
    cameras = [c for c in map(camera_of_feature, json.loads(info_path.read_text())["features"]) if c]
    return pd.read_parquet(root / PROVENANCE_FILE), cameras


def roll_back(root: Path, progress: Progress) -> int:
    """Remove everything written after the last checkpoint; returns how many files were removed."""
    for tmp in TEMP_DIRS:
        shutil.rmtree(root / tmp, ignore_errors=True)
    snap = root / SNAPSHOT_DIR
    kept = set(json.loads((snap / "files.json").read_text()))
    removed = 0
    for rel in _append_only_files(root):
        if rel not in kept:
            (root / rel).unlink()
            removed += 1
    for rel in REWRITTEN_FILES:
        if (snap / rel.name).exists():
            shutil.copy2(snap / rel.name, root / rel)
    if removed:
        log.warning(
            "rolled back %d file(s) written after the last checkpoint (%d episodes kept)",
            removed,
            progress.episodes_saved,
        )
    return removed


def add_episode(dataset, episode: DemoEpisode) -> None:  # dataset: lerobot LeRobotDataset
    """Append one successful expert episode through lerobot's add_frame / save_episode."""
    task = episode.instruction
    for t in range(episode.steps):
        frame = {feature_key(cam): frames[t] for cam, frames in episode.images.items()}
        frame[STATE_KEY] = episode.states[t]
        frame["action"] = episode.actions[t]
        frame["task"] = task
        dataset.add_frame(frame)
    dataset.save_episode()
