"""What every upload to the Hugging Face Hub shares: the plan it lists (files and bytes) and the authenticated
API, checked before anything changes."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from fnmatch import fnmatch
from pathlib import Path

log = logging.getLogger(__name__)


class PublishError(RuntimeError):
    """The hub cannot be reached or refuses; nothing was changed."""


@dataclass(frozen=True)
class Plan:
    """What an upload sends: the dataset repo's files, a LeRobot dataset's files and the EnvHub repo's files."""

    repo_id: str
    version: str
    files: list[tuple[str, int]]  # (path in repo, bytes)
    lerobot_files: list[tuple[str, int]]
    env_files: dict[str, str]  # EnvHub repo: path in repo -> text

    @property
    def total_bytes(self) -> int:
        """The bytes the upload sends."""
        env = sum(len(text.encode()) for text in self.env_files.values())
        return sum(size for _, size in self.files + self.lerobot_files) + env


def folder_files(root: Path, ignore: list[str]) -> list[tuple[str, int]]:
    """(path relative to `root`, bytes) of every file under it, in sorted order, less those matching `ignore`."""
    out = []
    for p in sorted(root.rglob("*")):
        rel = p.relative_to(root).as_posix()
        if p.is_file() and not any(fnmatch(rel, pattern) for pattern in ignore):
            out.append((rel, p.stat().st_size))
    return out


def hub_api():
    """An authenticated HfApi, or PublishError saying what is missing (checked before any change)."""
    from huggingface_hub import HfApi, constants, get_token

    if constants.HF_HUB_OFFLINE:
        raise PublishError(
            "offline mode is on (HF_HUB_OFFLINE=1); unset it to publish, "
            "or use --dry_run=true to see what would be uploaded"
        )
    token = get_token()
    if not token:
        raise PublishError(
            "no Hugging Face token: run `huggingface-cli login` or set HF_TOKEN "
            "(use --dry_run=true to see what would be uploaded)"
        )
    api = HfApi(token=token)
    try:
        user = api.whoami()
    except Exception as exc:  # network down, endpoint unreachable, token refused
        raise PublishError(
            f"cannot reach the hub at {constants.ENDPOINT} or the token was refused: "
            f"{type(exc).__name__}: {exc}"
        ) from exc
    log.info("publishing as %s", user.get("name"))
    return api
