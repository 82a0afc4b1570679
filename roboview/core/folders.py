"""The one guard for a folder RoboView reads or writes: a path that must be a folder marked as holding a
RoboView benchmark, collection, evaluation or results by one file in it (`benchmark.json`, the collection's
progress file, `run.json`).

A folder a command writes into may also be new or empty (`writing=True`); one it reads must exist. The
messages name the path (or the flag and path, `label`) and end with the caller's advice:

    X is a file, not a folder; ADVICE
    X does not exist; ADVICE                                              (reading)
    X is not empty and holds no RoboView WHAT (MARKER missing); ADVICE    (writing)
    X holds no RoboView WHAT (MARKER missing); ADVICE                     (reading)
"""

from __future__ import annotations

from pathlib import Path


def folder_problem(
    path: Path, what: str, marker: str | Path, advice: str, *, label: str = "", writing: bool = False
) -> str | None:
    """Why `path` is not a folder holding a RoboView `what` (the file `marker` in it says it does), in one
    line ending with `advice`; None when it is one, and, when `writing`, also when it is new or empty."""
    path = Path(path)
    name = label or str(path)
    if path.exists() and not path.is_dir():
        return f"{name} is a file, not a folder; {advice}"
    if not path.exists():
        return None if writing else f"{name} does not exist; {advice}"
    if (path / marker).is_file():
        return None
    if writing:
        if not any(path.iterdir()):
            return None
        return f"{name} is not empty and holds no RoboView {what} ({marker} missing); {advice}"
    return f"{name} holds no RoboView {what} ({marker} missing); {advice}"
