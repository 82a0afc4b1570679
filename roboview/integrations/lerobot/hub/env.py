"""RoboView-Bias as a LeRobot EnvHub environment: frozen, factor-isolated splits of a visual-bias benchmark.

    from lerobot.envs.factory import make_env
    envs = make_env("ORG/roboview-env", n_envs=4, trust_remote_code=True)   # {split: {0: VectorEnv}}

This file is what `roboview.pipelines.publish --env_repo_id=ORG/NAME` uploads. It needs the `roboview` package in the
same environment (the simulator, the benchmark reader and the episode seeds live there) and a built
benchmark. Settings, from `cfg` when LeRobot passes a RoboView env config, else from environment variables:

    ROBOVIEW_BENCHMARK   a local benchmark folder (roboview.pipelines.build_benchmark), or a hub dataset repo id
                         (ORG/NAME, as roboview.pipelines.publish uploads it) fetched with huggingface_hub
    ROBOVIEW_TASK        splits to run, comma-separated, or `all` (default: color)
    ROBOVIEW_CAMERAS     cameras the policy reads (default: left_top,wrist)
    ROBOVIEW_IMAGE_SIZE  square image side the policy was trained on (default: 96)
    ROBOVIEW_N_REPEATS   repeats per instance (default: 1)
    ROBOVIEW_MAX_STEPS   steps before an episode is cut (default: 120)

Each split is one task group; episode i of a split (reset seed start_seed + i, lerobot-eval's rule with
--seed=1000) is the split's i-th (instance, repeat), run with RoboView's own episode seed.
"""

from __future__ import annotations

import os
from pathlib import Path

SETTINGS = {
    "benchmark_path": ("ROBOVIEW_BENCHMARK", str),
    "task": ("ROBOVIEW_TASK", str),
    "cameras": ("ROBOVIEW_CAMERAS", str),
    "image_size": ("ROBOVIEW_IMAGE_SIZE", int),
    "n_repeats": ("ROBOVIEW_N_REPEATS", int),
    "max_steps": ("ROBOVIEW_MAX_STEPS", int),
}


def _benchmark_folder(where: str) -> str:
    """A local folder as is; a hub dataset repo id (ORG/NAME) downloaded into the hub cache."""
    if Path(where).is_dir():
        return where
    if where.count("/") == 1 and not where.startswith((".", "/")):
        from huggingface_hub import snapshot_download

        return snapshot_download(repo_id=where, repo_type="dataset")
    raise FileNotFoundError(
        f"ROBOVIEW_BENCHMARK={where!r} is neither a benchmark folder nor a hub dataset repo id "
        "(ORG/NAME); build one with `roboview-build-benchmark`"
    )


def make_env(n_envs: int = 1, use_async_envs: bool = False, cfg=None):
    """{split: {0: VectorEnv}} for the configured splits (LeRobot's EnvHub entry point)."""
    try:
        from roboview.integrations.lerobot import RoboViewEnv
    except ImportError as exc:
        raise ImportError(
            "the RoboView env needs the `roboview` package installed beside lerobot "
            "(pip install the RoboView repository)"
        ) from exc
    if not isinstance(cfg, RoboViewEnv):
        given = {name: kind(os.environ[var]) for name, (var, kind) in SETTINGS.items() if os.environ.get(var)}
        if "benchmark_path" not in given:
            raise ValueError(
                "set ROBOVIEW_BENCHMARK to a benchmark folder or a hub dataset repo id (ORG/NAME)"
            )
        given["benchmark_path"] = _benchmark_folder(given["benchmark_path"])
        cfg = RoboViewEnv(**given)
    return cfg.create_envs(n_envs, use_async_envs)
