"""RoboView as a LeRobot EnvHub env: lerobot's own hub loader runs roboview/integrations/lerobot/hub/env.py from a hub
cache (offline, a local folder laid out as the hub cache is) and gets one vector env per split."""

from pathlib import Path

import numpy as np
import pytest

from tests.helpers import cli

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]
ENV_PY = ROOT / "roboview" / "integrations" / "lerobot" / "hub" / "env.py"
REPO = "roboview/roboview-env"
COMMIT = "0123456789abcdef0123456789abcdef01234567"


@pytest.fixture()
def hub_cache(tmp_path) -> Path:
    """A hub cache holding REPO's env.py at COMMIT, as huggingface_hub's downloader would have left it."""
    cache = tmp_path / "hub"
    repo = cache / f"models--{REPO.replace('/', '--')}"
    (repo / "snapshots" / COMMIT).mkdir(parents=True)
    (repo / "snapshots" / COMMIT / "env.py").write_text(ENV_PY.read_text())
    (repo / "refs").mkdir()
    (repo / "refs" / "main").write_text(COMMIT)
    return cache


def test_lerobots_hub_loader_makes_one_vector_env_per_split(hub_cache, tiny_benchmark, monkeypatch):
    from lerobot.envs.factory import make_env

    from roboview.benchmark.format import load_benchmark

    monkeypatch.setenv("ROBOVIEW_BENCHMARK", str(tiny_benchmark))
    monkeypatch.setenv("ROBOVIEW_TASK", "color,dist_scale")
    monkeypatch.setenv("ROBOVIEW_CAMERAS", "front,wrist")
    monkeypatch.setenv("ROBOVIEW_IMAGE_SIZE", "48")
    monkeypatch.setenv("ROBOVIEW_MAX_STEPS", "30")
    with pytest.raises(RuntimeError, match="Refusing to execute remote code"):
        make_env(REPO, n_envs=2, hub_cache_dir=str(hub_cache))
    envs = make_env(REPO, n_envs=2, trust_remote_code=True, hub_cache_dir=str(hub_cache))
    assert list(envs) == ["color", "dist_scale"] and all(list(groups) == [0] for groups in envs.values())
    items = load_benchmark(tiny_benchmark, ["dist_scale"]).splits["dist_scale"]
    vec = envs["dist_scale"][0]
    obs, _ = vec.reset(seed=[1000, 1001])  # the split's episodes 0 and 1
    assert obs["pixels"]["front"].shape == (2, 48, 48, 3) and obs["pixels"]["wrist"].shape == (2, 48, 48, 3)
    assert obs["agent_pos"].shape == (2, 8)
    assert list(vec.call("task")) == ["dist_scale"] * 2 and vec.call("_max_episode_steps")[0] == 30
    assert list(vec.call("task_description")) == [
        items[0].instance.get("instruction"),
        items[1].instance.get("instruction"),
    ]
    assert not np.array_equal(obs["pixels"]["front"][0], obs["pixels"]["front"][1])  # dist 0 vs dist 1
    for groups in envs.values():
        groups[0].close()


def test_the_hub_env_says_what_it_needs(hub_cache, monkeypatch):
    from lerobot.envs.factory import make_env

    monkeypatch.delenv("ROBOVIEW_BENCHMARK", raising=False)
    with pytest.raises(ValueError, match="set ROBOVIEW_BENCHMARK"):
        make_env(REPO, n_envs=1, trust_remote_code=True, hub_cache_dir=str(hub_cache))
    monkeypatch.setenv("ROBOVIEW_BENCHMARK", "./no/such/folder")
    with pytest.raises(FileNotFoundError, match="neither a benchmark folder nor a hub dataset repo id"):
        make_env(REPO, n_envs=1, trust_remote_code=True, hub_cache_dir=str(hub_cache))


def test_publish_dry_run_lists_the_envhub_repo(tiny_benchmark):
    proc = cli.run(
        "roboview.pipelines.publish",
        f"--path={tiny_benchmark}",
        "--repo_id=org/roboview-bias",
        "--env_repo_id=org/roboview-env",
        "--dry_run=true",
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    assert f"{len(ENV_PY.read_text().encode()):,}  org/roboview-env/env.py" in proc.stdout
    assert "org/roboview-env/README.md" in proc.stdout
    from roboview.integrations.publishing.benchmark import env_hub_files

    readme = env_hub_files("org/roboview-env", "org/roboview-bias", "v1")["README.md"]
    assert 'ROBOVIEW_BENCHMARK"] = "org/roboview-bias"' in readme and 'make_env("org/roboview-env"' in readme
