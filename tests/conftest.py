import os
import tempfile

# Headless rendering for every test process (and the workers they spawn).
os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
os.environ.setdefault("HF_HUB_OFFLINE", "1")
os.environ.setdefault("SVT_LOG", "1")
# Mesa's llvmpipe rasterizes in the rendering thread instead of handing tiles to threads of its own: a test run keeps
# two pytest processes, their worker pools and servers rendering at once, and on a 2-core machine the hand-offs cost
# more than they save (render-heavy test files: 187 s → 150 s). The frames are bit-identical for any thread count.
os.environ.setdefault("LP_NUM_THREADS", "0")
# Caches a test run writes (the conformance verdicts, the VLM answer cache) go to a folder of its own, never the
# user's ~/.cache: one per run, made by the process that starts it and inherited by its pytest-xdist workers, so a
# benchmark's conformance verdict is measured once per run, not once per worker.
os.environ["ROBOVIEW_TEST_CACHE"] = os.environ.get("ROBOVIEW_TEST_CACHE") or tempfile.mkdtemp(
    prefix="roboview-test-cache-"
)
os.environ["XDG_CACHE_HOME"] = os.environ["ROBOVIEW_TEST_CACHE"]

from pathlib import Path  # noqa: E402

import pytest  # noqa: E402

# Test tiers: every test module declares its tier, `pytestmark = pytest.mark.fast` (seconds: statistics, formats,
# registries, imports, no rendering, training or servers) or `pytest.mark.slow` (renders, simulates, trains, starts
# servers, clusters or a browser); a test may carry the other tier's marker to leave its module's tier. `make
# test-fast` runs `--tier=fast` (the closest marker decides). A test in no tier, and a fast test that takes a slow
# fixture (one that renders, builds or trains), fails, naming what to do.
TIERS = ("fast", "slow")
TIER_PROBLEM = pytest.StashKey[str]()
SLOW_FIXTURES = {"env", "tiny_benchmark", "tiny_demos", "tiny_checkpoint", "bench", "tiny_results"}


def tier_of(item) -> str | None:
    """The tier of a collected test: its closest `fast` or `slow` marker (the test's own, else its class's, else its
    module's `pytestmark`); None when it has neither."""
    return next((mark.name for mark in item.iter_markers() if mark.name in TIERS), None)


def tier_problem(item) -> str | None:
    """What puts a collected test outside the tiers: no tier, or a fast test taking a slow fixture; None when fine."""
    tier = tier_of(item)
    if tier is None:
        return f"{item.nodeid}: no tier; declare `pytestmark = pytest.mark.fast` (or slow) in its module"
    slow = SLOW_FIXTURES & set(item.fixturenames)
    if tier == "fast" and slow:
        return f"{item.nodeid}: marked fast but takes {', '.join(sorted(slow))}; mark it `@pytest.mark.slow`"
    return None


def tier_problems(items) -> list[str]:
    return [problem for item in items if (problem := tier_problem(item))]


def pytest_addoption(parser):
    parser.addoption(
        "--tier", choices=TIERS, help="run one tier only: fast (seconds each) or slow (tests/conftest.py)"
    )


def pytest_collection_modifyitems(config, items):
    # A test outside the tiers fails at its setup, named, in every process of the run (xdist workers included).
    for item in items:
        if problem := tier_problem(item):
            item.stash[TIER_PROBLEM] = problem
    wanted = config.getoption("--tier")
    if wanted:
        other = [item for item in items if tier_of(item) != wanted]
        if other:
            config.hook.pytest_deselected(items=other)
            items[:] = [item for item in items if tier_of(item) == wanted]
    items[:] = schedule(items)


def schedule(items: list) -> list:
    """The order pytest-xdist hands out test files in (`make test` passes `--no-loadscope-reorder`, so it keeps this
    one): files with the most tests first, as pytest-xdist's own order, except that the files marked `schedule_first`
    go before them all, those with the fewest tests first. The mark is for a file of few long tests (the Ray cluster's
    one test of 1.5 min, the expert's three sweeps): by its count it would come among the last, and one process would
    run it alone while the other has finished. Handing out the longest files first instead was slower: the
    multi-process ones, started together, oversubscribe two cores (measured: docs/CHANGELOG.md)."""
    files: dict[str, list] = {}
    for item in items:
        files.setdefault(item.nodeid.split("::")[0], []).append(item)

    def first(tests: list) -> bool:
        return any(mark.name == "schedule_first" for mark in tests[0].iter_markers())

    order = sorted(files.values(), key=lambda tests: (0, len(tests)) if first(tests) else (1, -len(tests)))
    return [item for tests in order for item in tests]


def pytest_runtest_setup(item):
    problem = item.stash.get(TIER_PROBLEM, None)
    if problem:
        pytest.fail(f"outside the tiers: {problem}", pytrace=False)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_teardown(item):
    """After a test and its fixtures' teardown: a variable that modules read at import time (tests/helpers/cli.py,
    IMPORT_TIME, HF_*) left changed in this process would start every later command-line run of the process from a
    fresh interpreter (seconds each) instead of a fork. The test that leaked it fails, naming it; the value is put
    back."""
    result = yield
    from tests.helpers import cli

    leaked = cli.import_time_changes(os.environ)
    if leaked:
        cli.restore_import_time(leaked)
        pytest.fail(
            f"{item.nodeid} left import-time environment variables changed (run's → now): {leaked}; set them in "
            "the command's env= or with monkeypatch.setenv, or set them where the program runs, not on import",
            pytrace=False,
        )
    return result


def _preload_for_the_run() -> None:
    """A test process starts many pools — expert, renderer, collector and checkpoint workers — and command-line runs
    (tests/helpers/cli.py), all forks of its fork server, so that server imports what all of them use
    (roboview.core.workers.preload): LeRobot's policies (seconds per process here) once per test process, instead of
    once in each checkpoint worker, policy server and lerobot-eval run."""
    from roboview.core import workers

    workers.preload(
        "roboview.eval.running.rollout",
        "roboview.benchmark.render",
        "roboview.demos.collection",
        "lerobot.policies",
        "lerobot.policies.act.modeling_act",
        "lerobot.scripts.lerobot_eval",
        "lerobot.scripts.lerobot_train",
        "roboview.pipelines.evaluate",
        "roboview.pipelines.serve_policy",
        # Imported where they are first used: by the VLM agents' and the fairness screen's workers (the openai
        # client), by each conformance check (the GL driver's strings); once here instead.
        "openai",
        "OpenGL.GL",
    )


_preload_for_the_run()
import tests.helpers.cli  # noqa: E402, F401  (its snapshot of the run's environment, taken before any test)


@pytest.fixture(scope="session")
def env():
    from roboview.tasks.pick_place import PickPlaceEnv

    env = PickPlaceEnv(image_size=96, depth=False)
    yield env
    env.close()


def shared_folder(tmp_path_factory, name: str, build) -> Path:
    """A folder `build(folder)` fills once for the whole run: under pytest-xdist the first worker that needs it
    builds it (the others wait on a lock, then read it), so the processes do not each build their own."""
    import shutil

    from filelock import FileLock

    base = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        base = base.parent  # the run's folder, shared by every worker
    folder = base / f"shared-{name}"
    with FileLock(str(folder) + ".lock"):
        if not (folder / ".built").is_file():
            shutil.rmtree(folder, ignore_errors=True)
            folder.mkdir(parents=True)
            build(folder)
            (folder / ".built").touch()
    return folder


@pytest.fixture(scope="session")
def tiny_benchmark(tmp_path_factory):
    """The `tiny` preset built once for every test that only reads a benchmark (57 instances, rendered at 64²)."""
    from roboview.pipelines.build_benchmark import BuildConfig
    from roboview.pipelines.build_benchmark import run as build

    def make(folder: Path) -> None:
        build(BuildConfig(output_dir=str(folder / "tiny"), preset="tiny", image_size=64))

    return shared_folder(tmp_path_factory, "bench", make) / "tiny"


@pytest.fixture(scope="session")
def tiny_demos(tmp_path_factory) -> Path:
    """2 expert demos (left_top + wrist at 64²) collected by roboview.pipelines.collect as repo_id `t/demos`."""
    from roboview.pipelines.collect import CollectConfig, DatasetConfig
    from roboview.pipelines.collect import run as collect

    def make(folder: Path) -> None:
        collect(
            CollectConfig(
                DatasetConfig(
                    repo_id="t/demos",
                    root=str(folder / "ds"),
                    num_episodes=2,
                    image_size=64,
                    cameras=["left_top", "wrist"],
                ),
                num_workers=1,
            )
        )

    return shared_folder(tmp_path_factory, "demos", make) / "ds"


@pytest.fixture(scope="session")
def tiny_checkpoint(tmp_path_factory, tiny_benchmark, tiny_demos) -> Path:
    """A 2-step ACT checkpoint (left_top + wrist at 64²) trained by roboview.pipelines.train on `tiny_demos`."""
    from tests.helpers import cli

    def make(root: Path) -> None:
        # The reference recipe (roboview.pipelines.train → lerobot-train), 2 steps; a third step resumes the run.
        args = [
            "--dataset.repo_id=t/demos",
            f"--dataset.root={tiny_demos}",
            f"--output_dir={root / 'train'}",
            "--batch_size=2",
            "--save_freq=2",
            "--device=cpu",
        ]
        # With a periodic evaluation on the RoboView split through lerobot-train's own eval loop (the plugin).
        periodic = [
            f"--benchmark.path={tiny_benchmark}",
            "--eval_splits=color",
            "--eval_episodes=2",
            "--eval_freq=2",
        ]
        proc = cli.run("roboview.pipelines.train", *args, "--steps=2", *periodic, timeout=600)
        assert proc.returncode == 0, proc.stderr[-2000:]
        assert (
            "'task_group': 'color'" in proc.stdout + proc.stderr
            and "'n_episodes': 2" in proc.stdout + proc.stderr
        )
        dry = cli.run("roboview.pipelines.train", *args, "--steps=3", "--dry_run=true", timeout=120)
        assert (
            "--resume=true" in dry.stdout
            and "checkpoints/last/pretrained_model/train_config.json" in dry.stdout
        )

    return (
        shared_folder(tmp_path_factory, "ckpt", make) / "train" / "checkpoints" / "last" / "pretrained_model"
    )
