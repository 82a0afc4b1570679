"""Asset folders an external benchmark publishes apart from its package, named on the command line or in the
environment, so the worker processes a verb starts see them too.

LIBERO-plus's light and background variants load scene files from its asset archive (`assets.zip`), which no package
ships: `--liberoplus.assets=DIR` on `roboview-build-benchmark` and `roboview-evaluate`, or `ROBOVIEW_LIBEROPLUS_ASSETS=DIR`
(roboview.libero.plus_scenes reads it and says which files a preset lacks).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

LIBEROPLUS_ASSETS_ENV = "ROBOVIEW_LIBEROPLUS_ASSETS"
LIBEROPLUS_ASSETS_FLAG = "--liberoplus.assets"


def liberoplus_assets_dir() -> Path | None:
    """LIBERO-plus's unpacked asset folder (`ROBOVIEW_LIBEROPLUS_ASSETS`, set by `--liberoplus.assets`); None: unset."""
    value = os.environ.get(LIBEROPLUS_ASSETS_ENV, "")
    return Path(value) if value else None


def set_liberoplus_assets_dir(path: str) -> None:
    """Point this process and the workers it starts at LIBERO-plus's asset folder `path` (a ValueError if it is no
    folder)."""
    folder = Path(path).expanduser().resolve()
    if not folder.is_dir():
        raise ValueError(
            f"{LIBEROPLUS_ASSETS_FLAG}={path}: no such folder (LIBERO-plus's unpacked assets, holding scenes/)"
        )
    os.environ[LIBEROPLUS_ASSETS_ENV] = str(folder)


@dataclass
class LiberoPlusAssets:
    # LIBERO-plus's unpacked asset folder (its assets.zip: scenes/, textures/ …), which its light and background
    # presets load; empty: the environment variable ROBOVIEW_LIBEROPLUS_ASSETS, if set.
    assets: str = ""

    def __post_init__(self) -> None:
        if self.assets:
            set_liberoplus_assets_dir(self.assets)
