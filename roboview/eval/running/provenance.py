"""Provenance: what produced a results folder, so a number in a report can be traced and reproduced.

`provenance.json` in every results folder lists one entry per invocation (a resumed run adds one):
package versions (roboview with its git commit, lerobot, mujoco, torch, …), the benchmark version,
the checkpoint's content hash and config, the seed rule, the full command line, the machine (CPU
model and cores, GPU when torch sees one) and the start and end time (UTC). The report prints it.
"""

from __future__ import annotations

import importlib.metadata
import json
import os
import platform
import subprocess
import sys
from datetime import UTC, datetime
from pathlib import Path

from roboview.core.files import files_sha256
from roboview.policies.checkpoints import checkpoint_dir

FILE = "provenance.json"
PACKAGES = ("roboview", "lerobot", "mujoco", "torch", "gymnasium", "datasets", "numpy", "openai")
SEED_RULE = (
    "episode_seed = first 8 bytes of SHA-256(f'{context_id}:{repeat}') mod 2**31 (common random numbers: "
    "every value of a context runs repeat r with the same seed)"
)


def now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


def package_versions() -> dict[str, str | None]:
    versions: dict[str, str | None] = {}
    for name in PACKAGES:
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            versions[name] = None
    return versions


def git_commit(root: Path = Path(__file__).resolve().parents[1]) -> str | None:
    """The roboview checkout's commit (with `+dirty` when it has uncommitted changes); None outside git."""
    try:
        commit = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            timeout=10,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return commit + ("+dirty" if dirty else "")


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def machine() -> dict:
    info = {
        "hostname": platform.node(),
        "platform": platform.platform(),
        "python": platform.python_version(),
        "cpu": cpu_model(),
        "cpu_count": os.cpu_count(),
        "gpu": None,
    }
    torch = sys.modules.get("torch")  # only when a torch policy is in play: importing torch costs seconds
    if torch is not None and torch.cuda.is_available():
        info["gpu"] = [torch.cuda.get_device_name(i) for i in range(torch.cuda.device_count())]
    return info


def checkpoint_hash(path: str | Path) -> str:
    """SHA-256 over the checkpoint folder's files (relative names and contents, in sorted order)."""
    root = Path(path)
    if root.is_dir():
        return files_sha256(root, sorted(p for p in root.rglob("*") if p.is_file()))
    return files_sha256(root.parent, [root])


def checkpoint_info(path: str | None) -> dict | None:
    if not path:
        return None
    root = checkpoint_dir(path)
    config = root / "config.json"
    return {
        "path": str(root.resolve()),
        "sha256": checkpoint_hash(root),
        "config": json.loads(config.read_text()) if config.is_file() else None,
    }


def _short(word: str) -> str:
    """A path under the working directory as typed relative to it (`cwd` is recorded beside the command): a console
    script's interpreter is absolute in `sys.orig_argv`."""
    if not word.startswith("/"):
        return word
    try:
        return os.path.relpath(word) if Path(word).resolve().is_relative_to(Path.cwd().resolve()) else word
    except (OSError, ValueError):
        return word


def start_entry(benchmark_version: str, checkpoint: str | None, argv: list[str] | None = None) -> dict:
    return {
        "started": now(),
        "ended": None,
        "command": " ".join(map(_short, getattr(sys, "orig_argv", sys.argv) if argv is None else argv)),
        "cwd": os.getcwd(),
        "roboview_commit": git_commit(),
        "packages": package_versions(),
        "benchmark_version": benchmark_version,
        "checkpoint": checkpoint_info(checkpoint),
        "seed_rule": SEED_RULE,
        "machine": machine(),
    }


def record(folder: Path, entry: dict) -> None:
    """Append (or, for the same start time, update) `entry` in folder/provenance.json, atomically."""
    write(folder, [e for e in read(folder) if e.get("started") != entry["started"]] + [entry])


def write(folder: Path, entries: list[dict]) -> None:
    """folder/provenance.json holds exactly `entries` (written atomically)."""
    path = Path(folder) / FILE
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(entries, indent=2))
    tmp.replace(path)


def read(folder: Path) -> list[dict]:
    path = Path(folder) / FILE
    return json.loads(path.read_text()) if path.is_file() else []
