import os
import tempfile

# Headless rendering for every test process (and the workers they spawn).
os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
os.environ.setdefault("HF_HUB_OFFLINE", "1")
os.environ.setdefault("SVT_LOG", "1")
# Caches a test run writes (the VLM answer cache) go to a folder of its own, never the user's ~/.cache.
os.environ["XDG_CACHE_HOME"] = tempfile.mkdtemp(prefix="roboview-test-cache-")

import pytest  # noqa: E402


@pytest.fixture(scope="session")
def env():
    from roboview_data.sim.env import PickPlaceEnv

    env = PickPlaceEnv(image_size=96, depth=False)
    yield env
    env.close()


@pytest.fixture(scope="session")
def tiny_benchmark(tmp_path_factory):
    """The `tiny` preset built once for every test that only reads a benchmark (57 instances, 64² previews)."""
    from pipelines.build_benchmark import BuildConfig
    from pipelines.build_benchmark import run as build

    out = tmp_path_factory.mktemp("bench") / "tiny"
    build(BuildConfig(output_dir=str(out), preset="tiny", image_size=64))
    return out
