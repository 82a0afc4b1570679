"""Where a LeRobot checkpoint's files are: a local folder, or a Hugging Face hub repo through the hub cache.

`--policy.path` takes a `pretrained_model` folder written by lerobot-train (or the checkpoint folder that
holds one), or a hub model id (`ORG/NAME`, e.g. a fine-tuned π0.5 a collaborator pushed). A hub id is
resolved by huggingface_hub's `snapshot_download`: from the hub cache when the files are there (always so
with `HF_HUB_OFFLINE=1`), else downloaded into it. A training run folder (lerobot-train's --output_dir) is refused with the exact path of
its last checkpoint to pass: which weights are evaluated is never guessed.
"""

from __future__ import annotations

import re
from pathlib import Path

REPO_ID = re.compile(r"^[A-Za-z0-9][\w.-]*/[\w.-]+$")


class CheckpointError(ValueError):
    """The checkpoint is missing, unreadable, or does not fit the env's features."""


def checkpoint_dir(path: str | None) -> Path:
    """The folder holding the checkpoint's config.json (a local folder, its pretrained_model/, or a hub repo)."""
    if not path:
        raise CheckpointError(
            "a LeRobot policy needs a checkpoint path (a `pretrained_model` folder "
            "written by lerobot-train, e.g. outputs/train/checkpoints/last/pretrained_model, "
            "or a hub model id ORG/NAME)"
        )
    root = Path(path)
    if not root.exists() and REPO_ID.match(path):
        root = _from_hub(path)
    if (root / "pretrained_model" / "config.json").is_file():
        root = root / "pretrained_model"
    if not (root / "config.json").is_file():
        found = training_checkpoints(root)
        if (
            found
        ):  # a training run folder (or its checkpoints/): say which folder to pass, never guess silently
            others = [p.parent.name for p in found[1:6]]
            raise CheckpointError(
                f"{path} is a lerobot-train run folder, not a checkpoint: pass --policy.path={found[0]} (its "
                f"{'last' if found[0].parent.name == 'last' else 'latest'} checkpoint)"
                + (
                    f"; other checkpoints: {', '.join(others)}{' …' if len(found) > 6 else ''} (same path with that "
                    "name in place of " + found[0].parent.name + ")"
                    if others
                    else ""
                )
            )
        raise CheckpointError(
            f"{path} holds no LeRobot checkpoint (config.json missing); expected a `pretrained_model` "
            "folder written by lerobot-train (RUN/checkpoints/last/pretrained_model) or a hub id ORG/NAME"
        )
    return root


def training_checkpoints(root: Path) -> list[Path]:
    """The `pretrained_model` folders of a lerobot-train run folder (its --output_dir) or of its `checkpoints/`
    folder: `last` first, then by step, newest first. Empty for any other folder."""
    folder = root / "checkpoints" if (root / "checkpoints").is_dir() else root
    if not folder.is_dir():
        return []
    found = [
        step / "pretrained_model"
        for step in folder.iterdir()
        if (step / "pretrained_model" / "config.json").is_file()
    ]

    def order(model: Path) -> tuple[int, int, str]:
        name = model.parent.name
        return (0, 0, name) if name == "last" else (1, -int(name), name) if name.isdigit() else (2, 0, name)

    return sorted(found, key=order)


def _from_hub(repo_id: str) -> Path:
    from huggingface_hub import constants, snapshot_download

    try:
        return Path(snapshot_download(repo_id=repo_id))
    except Exception as exc:  # not cached offline, no network, unknown or gated repo
        where = "it is not in the hub cache" if constants.HF_HUB_OFFLINE else "it could not be fetched"
        raise CheckpointError(
            f"--policy.path={repo_id!r} is no local folder, so it was read as a hub model id, and "
            f"{where} ({constants.HF_HUB_CACHE}): {type(exc).__name__}: {exc}"
        ) from exc
