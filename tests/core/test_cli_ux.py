"""What a user sees at the command line: Ctrl-C, a misspelled flag, --help's preset list, other libraries' logs."""

import logging
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from roboview.pipelines._cli import cli_main, interrupted
from tests.helpers import cli

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]
ENV = os.environ | {"PYTHONPATH": str(ROOT)}


def _cli(module: str, *args: str, timeout: int = 120) -> subprocess.CompletedProcess:
    return cli.run(module, *args, timeout=timeout)


def test_ctrl_c_during_evaluate_says_what_was_saved_and_a_rerun_resumes(tiny_benchmark, tmp_path):
    from roboview.pipelines.evaluate import BenchmarkConfig, EvalConfig, EvaluateConfig, run
    from roboview.policies.types import policy_config

    out = tmp_path / "ev"
    flags = [
        f"--benchmark.path={tiny_benchmark}",
        "--policy.type=expert",
        "--benchmark.splits=color",
        "--eval.limit=6",
        "--eval.n_repeats=2",
        "--eval.image_size=64",
        f"--output_dir={out}",
    ]
    # Its own process group, signalled as a terminal's Ctrl-C is: the command and its workers all get SIGINT.
    proc = cli.start("roboview.pipelines.evaluate", *flags, new_session=True)
    journal = out / "episodes.jsonl"
    deadline = time.time() + 300
    while time.time() < deadline and not (journal.exists() and journal.read_text().count("\n") >= 1):
        time.sleep(0.1)
    os.killpg(proc.pid, signal.SIGINT)
    _, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130, stderr[-2000:]
    assert "Traceback" not in stderr and "KeyboardInterrupt" not in stderr, stderr[-2000:]
    saved = len(journal.read_text().splitlines())
    assert 1 <= saved < 12
    last = stderr.strip().splitlines()[-1]
    assert last == (
        f"interrupted: {saved} episode{'s' * (saved != 1)} saved in {out}; rerun the same command to resume"
    ), stderr[-2000:]

    result = run(
        EvaluateConfig(
            BenchmarkConfig(path=str(tiny_benchmark), splits="color"),
            policy_config("expert"),
            EvalConfig(n_repeats=2, limit=6, image_size=64),
            str(out),
        )
    )
    assert result.new_episodes == 12 - saved, journal.read_text()[-3000:]
    rows = pd.read_parquet(out / "episodes.parquet")
    assert len(rows) == 12 and not rows.duplicated(["instance_id", "repeat"]).any()


def test_ctrl_c_during_collect_says_how_many_demos_a_rerun_keeps(tmp_path, monkeypatch, capsys):
    import roboview.demos.collection
    import roboview.pipelines.collect as collect
    from roboview.demos.dataset import Progress

    real = roboview.demos.collection.attempts

    def three_then_ctrl_c(job, first_attempt):
        episodes = real(job, first_attempt)
        try:
            for _ in range(3):
                yield next(episodes)
            raise KeyboardInterrupt
        finally:
            episodes.close()

    monkeypatch.setattr(roboview.demos.collection, "attempts", three_then_ctrl_c)
    root = tmp_path / "demos"
    with pytest.raises(SystemExit) as exit_:
        collect.main(
            [
                f"--dataset.root={root}",
                "--dataset.repo_id=t/demos",
                "--dataset.num_episodes=10",
                "--dataset.image_size=64",
                "--dataset.cameras=wrist",
                "--num_workers=1",
                "--checkpoint_every=2",
            ]
        )
    assert exit_.value.code == 130
    kept = Progress.load(root).episodes_saved  # what a rerun resumes from
    assert 0 < kept <= 3
    message = capsys.readouterr().err.strip().splitlines()[-1]
    assert message.startswith(f"interrupted: {kept} demo{'s' * (kept != 1)} saved in {root}")
    assert message.endswith("; rerun the same command to resume")


def test_ctrl_c_during_build_says_nothing_was_written(tmp_path, monkeypatch, capsys):
    import roboview.benchmark.build
    import roboview.pipelines.build_benchmark as build

    def ctrl_c(spec, instances):
        raise KeyboardInterrupt

    monkeypatch.setattr(roboview.benchmark.build, "render_all", ctrl_c)
    out = tmp_path / "bench"
    with pytest.raises(SystemExit) as exit_:
        build.main([f"--output_dir={out}", "--preset=tiny"])
    assert exit_.value.code == 130 and not out.exists()
    message = capsys.readouterr().err.strip().splitlines()[-1]
    assert message.startswith(f"interrupted: nothing written to {out}")


def test_ctrl_c_elsewhere_says_to_rerun(capsys):
    from roboview.pipelines.plan import PlanConfig

    def run(cfg):
        raise KeyboardInterrupt

    with pytest.raises(SystemExit) as exit_:
        cli_main(PlanConfig, run, args=[])
    assert exit_.value.code == 130
    assert capsys.readouterr().err.strip().splitlines()[-1] == "interrupted; rerun the same command"

    def run_saying(cfg):  # the innermost message wins over on_interrupt
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            raise interrupted(exc, "3 things kept") from exc

    with pytest.raises(SystemExit):
        cli_main(PlanConfig, run_saying, args=[], on_interrupt=lambda cfg: "unused")
    assert capsys.readouterr().err.strip() == "interrupted: 3 things kept"


@pytest.mark.parametrize(
    "module, wrong, right",
    [
        ("roboview.pipelines.evaluate", "--eval.n_repeat=3", "--eval.n_repeats"),
        ("roboview.pipelines.collect", "--dataset.num_episode=3", "--dataset.num_episodes"),
    ],
)
def test_a_misspelled_flag_gets_two_lines_and_the_closest_real_flag(module, wrong, right):
    proc = _cli(module, "--policy.type=expert" if module.endswith("evaluate") else "--seed=1", wrong)
    assert proc.returncode == 2 and not proc.stdout
    lines = proc.stderr.strip().splitlines()
    assert lines == [
        f"error: unknown flag {wrong.split('=')[0]}",
        f"did you mean {right}? (--help lists every flag)",
    ]


def test_evaluate_help_puts_the_common_flags_first():
    from roboview.pipelines._cli import format_help
    from roboview.pipelines.evaluate import EvaluateConfig
    from roboview.policies.types import load_policy_types

    load_policy_types()
    text = format_help(EvaluateConfig)
    assert text.startswith("usage: ") and text.count("--config_path") == 1 and "Config file" not in text
    common = [
        text.index(f"\n  {flag} ") for flag in ("--policy.type", "--benchmark.path", "--eval.n_repeats")
    ]
    advanced = [text.index(f"\n  {flag} ") for flag in ("--eval.envs_per_worker", "--eval.alpha")]
    per_type = text.index("\n--policy.type=lerobot:")
    assert max(common) < min(advanced) and max(advanced) < per_type
    # With a type named, only that type's own flags are listed.
    one = format_help(EvaluateConfig, ["--policy.type=lerobot"])
    assert (
        "\n--policy.type=lerobot:" in one and "--policy.type=openpi:" not in one and "--policy.url" not in one
    )


def test_build_help_lists_every_preset_with_its_instance_count():
    from roboview.tasks import PRESETS
    from roboview.variation.instances import generate_suite

    proc = _cli("roboview.pipelines.build_benchmark", "--help")
    assert proc.returncode == 0
    text = " ".join(proc.stdout.split())
    for name, suite in PRESETS.items():
        if suite.generator.endswith(":scene_suite"):  # LIBERO-plus's light and background: its asset folder
            assert f" {name} (needs --liberoplus.assets=DIR" in text or re.search(
                rf" {name} \(\d[\d,]*\)", text
            ), name
            continue
        assert f" {name} ({len(generate_suite(suite)):,})" in text, name
    assert "tiny (57)" in text


def test_other_libraries_info_lines_are_silenced_ours_kept(tiny_benchmark):
    from roboview.pipelines._cli import setup_environment

    setup_environment()
    assert not logging.getLogger("OpenGL.acceleratesupport").isEnabledFor(logging.INFO)
    assert logging.getLogger("OpenGL.acceleratesupport").isEnabledFor(logging.WARNING)
    assert logging.getLogger("roboview.pipelines.evaluate").isEnabledFor(logging.INFO)
    # A quick command that imports PyOpenGL after logging is set up.
    proc = _cli("roboview.pipelines.plan", f"--benchmark.path={tiny_benchmark}")
    assert proc.returncode == 0, proc.stderr[-1500:]
    assert "OpenGL.acceleratesupport" not in proc.stderr and "OpenGL_accelerate" not in proc.stderr


def test_every_image_size_flag_checks_the_one_bound():
    from roboview.pipelines.build_benchmark import GATE_IMAGE_MIN, BuildConfig
    from roboview.pipelines.collect import TRAIN_IMAGE_MIN, DatasetConfig
    from roboview.pipelines.evaluate import EvalConfig
    from roboview.sim.cameras import IMAGE_SIZE_MAX, IMAGE_SIZE_MIN, check_image_size

    assert (IMAGE_SIZE_MIN, TRAIN_IMAGE_MIN, GATE_IMAGE_MIN, IMAGE_SIZE_MAX) == (16, 32, 64, 640)
    check_image_size(IMAGE_SIZE_MIN)
    with pytest.raises(ValueError, match=r"^image_size=15 out of range; allowed 16\.\.640$"):
        check_image_size(IMAGE_SIZE_MIN - 1)
    with pytest.raises(ValueError, match=r"^--eval.image_size=641 out of range; allowed 16\.\.640 \(or 0"):
        EvalConfig(image_size=IMAGE_SIZE_MAX + 1)
    assert EvalConfig(image_size=0).image_size == 0  # the policy's own size
    with pytest.raises(ValueError, match=r"^--dataset.image_size=16 out of range; allowed 32\.\.640 \(tr"):
        DatasetConfig(repo_id="a/b", image_size=16)
    with pytest.raises(ValueError, match=r"^--image_size=32 out of range; allowed 64\.\.640 \(the fairness"):
        BuildConfig(preset="tiny", image_size=32)
    assert BuildConfig(preset="tiny", image_size=64).image_size == 64


def test_vlm_endpoint_flags_nest_and_the_flat_spelling_still_works_with_a_warning(capsys):
    from roboview.core.cli_flags import flag_aliases, renamed_flags
    from roboview.pipelines._cli import parse
    from roboview.pipelines.build_benchmark import BuildConfig
    from roboview.pipelines.evaluate import EvaluateConfig
    from roboview.policies.types import load_policy_types

    load_policy_types()
    base = ["--benchmark.path=b", "--policy.type=vlm_simple", "--sgl.enable=true"]
    new = parse(
        EvaluateConfig,
        [
            *base,
            "--policy.endpoint.base_url=http://h:1/v1",
            "--policy.endpoint.model=m",
            "--policy.endpoint.max_in_flight=2",
            "--sgl.endpoint.model=s",
        ],
    )
    assert capsys.readouterr().err == ""
    old = parse(
        EvaluateConfig,
        [
            *base,
            "--policy.base_url=http://h:1/v1",
            "--policy.model=m",
            "--policy.max_in_flight=2",
            "--policy.model=m",
            "--sgl.model=s",
        ],
    )
    assert old.policy.endpoint == new.policy.endpoint and old.sgl.endpoint == new.sgl.endpoint
    assert (new.policy.endpoint.base_url, new.policy.endpoint.model, new.policy.endpoint.max_in_flight) == (
        "http://h:1/v1",
        "m",
        2,
    )
    assert new.sgl.endpoint.model == "s" and new.policy.options()["model"] == "m"  # run.json keeps its keys
    assert capsys.readouterr().err.splitlines() == [  # one line per old flag, naming the new one
        "warning: --policy.base_url is deprecated; use --policy.endpoint.base_url",
        "warning: --policy.model is deprecated; use --policy.endpoint.model",
        "warning: --policy.max_in_flight is deprecated; use --policy.endpoint.max_in_flight",
        "warning: --sgl.model is deprecated; use --sgl.endpoint.model",
    ]
    # Another policy type's own flag of the same name is left alone (openpi has --policy.timeout_s).
    openpi = ["--policy.type=openpi", "--policy.timeout_s=5"]
    assert "--policy.timeout_s" not in flag_aliases(EvaluateConfig, openpi)
    assert renamed_flags(EvaluateConfig, openpi) == openpi and capsys.readouterr().err == ""
    # The build's screen is an endpoint itself: its flags keep their names.
    build = parse(
        BuildConfig, ["--preset=tiny", "--vlm_screen.base_url=http://h:1/v1", "--vlm_screen.model=g"]
    )
    screen = build.vlm_screen
    assert build.screen_enabled and (screen.base_url, screen.model) == ("http://h:1/v1", "g")
    with pytest.raises(SystemExit):
        parse(EvaluateConfig, [*base, "--policy.model=", "--sgl.endpoint.model=s"])
    assert "--policy.endpoint.model is empty" in capsys.readouterr().err


SLOW_START = """
import sys, time
from roboview.core.workers import WorkerPool


class SlowToStart:
    def __init__(self):
        time.sleep(60)  # a worker still starting (an env, a policy loading) when Ctrl-C comes

    def run(self, item):
        return item


if __name__ == "__main__":
    try:
        with WorkerPool(2, SlowToStart) as pool:
            futures = [pool.submit(i) for i in range(2)]
            print("submitted", flush=True)
            [f.result() for f in futures]
    except KeyboardInterrupt:
        print("interrupted: nothing saved", file=sys.stderr, flush=True)
        sys.exit(130)
"""


def test_ctrl_c_while_workers_are_still_starting_prints_no_traceback(tmp_path):
    """The command and its workers get SIGINT (a terminal's Ctrl-C) while both workers are in their start-up: the
    workers ignore it, the parent ends them at once and says so, no traceback from any process."""
    script = tmp_path / "slow_start.py"
    script.write_text(SLOW_START)
    proc = subprocess.Popen(
        [sys.executable, str(script)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        preexec_fn=cli.terminal_signals,
        cwd=ROOT,
        env=ENV,
    )
    assert proc.stdout.readline().strip() == "submitted"
    time.sleep(2)  # both workers spawned and inside their initializer
    start = time.time()
    os.killpg(proc.pid, signal.SIGINT)
    _, stderr = proc.communicate(timeout=50)
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr and "KeyboardInterrupt" not in stderr, stderr
    assert stderr.strip().splitlines()[-1] == "interrupted: nothing saved"
    assert time.time() - start < 30  # the workers were ended, not waited for
