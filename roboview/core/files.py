"""Two things several stages need of the file system: a digest over a set of files, and RoboView's cache folder."""

from __future__ import annotations

import hashlib
import os
from collections.abc import Iterable
from pathlib import Path


def files_sha256(root: Path, files: Iterable[Path]) -> str:
    """SHA-256 over `files` in the order given: each one's path relative to `root`, a NUL, then its bytes."""
    digest = hashlib.sha256()
    for file in files:
        digest.update(Path(file).relative_to(root).as_posix().encode() + b"\0")
        with open(file, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                digest.update(block)
    return digest.hexdigest()


def cache_dir(name: str) -> Path:
    """RoboView's cache folder for `name`: $XDG_CACHE_HOME/roboview/<name> (~/.cache/roboview/<name>), as Hugging
    Face's caches."""
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "roboview" / name
