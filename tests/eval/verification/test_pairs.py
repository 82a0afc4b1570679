"""A pair replayed (roboview.eval.verification.pairs, `roboview-pair`): an episode and its twin under another value,
re-run with the recorded policy, each equal to its recorded row; the step where their actions part found where a
policy built to part there parts; one Rerun recording of both; a replay that does not reproduce its row said so;
bad input refused in one line."""

import json

import numpy as np
import pandas as pd
import pytest

from roboview.eval.verification.pairs import REPLAYED, discordant, parting_step, record, replay_pair

pytestmark = pytest.mark.slow

PART_AT = 6
TYPE = "parting_for_tests"


def test_the_parting_step_is_the_first_step_whose_actions_differ_beyond_the_tolerance():
    a = np.zeros((10, 8))
    assert parting_step(a, a.copy()) == (None, 0.0)
    b = a.copy()
    b[7, 3] = 0.5
    b[9, 0] = 2.0
    assert parting_step(a, b) == (7, 0.5)
    b[7, 3] = 1e-9  # within the tolerance: not a difference
    assert parting_step(a, b) == (9, 2.0)
    assert parting_step(a, b, tolerance=3.0) == (None, 0.0)
    assert parting_step(a, a[:6]) == (6, 0.0)  # the same actions, but one episode ended there


@pytest.fixture(scope="module")
def results(tiny_benchmark, tmp_path_factory):
    """The parting policy's red and blue episodes of the first context of the tiny benchmark's color split. The
    test policy type is registered for this module only (other modules' tests list the registered types)."""
    from roboview.eval.campaign.config import BenchmarkConfig, EvalConfig, EvaluateConfig
    from roboview.pipelines.evaluate import run
    from roboview.policies.base import PolicyConfig
    from tests.helpers.parting_policy import PartingConfig

    out = tmp_path_factory.mktemp("pairs") / "ev"
    PolicyConfig._choice_registry[TYPE] = PartingConfig  # importing the module registered it once per process
    try:
        run(
            EvaluateConfig(
                BenchmarkConfig(str(tiny_benchmark), splits="color", values="red,blue"),
                PartingConfig(part_at=PART_AT),
                EvalConfig(n_repeats=1, num_workers=1, contexts=1, image_size=64),
                str(out),
            )
        )
        yield out
    finally:
        PolicyConfig._choice_registry.pop(TYPE, None)


def test_a_replayed_pair_is_its_recorded_rows_and_parts_where_the_policy_does(results, tiny_benchmark):
    from rerun.experimental import RrdReader

    rows = pd.read_parquet(results / "episodes.parquet")
    assert sorted(rows["value"]) == ["blue", "red"] and set(rows["policy"]) == {TYPE}
    blue = rows[rows["value"] == "blue"].iloc[0]
    pair = replay_pair(results, blue["instance_id"], 0, benchmark=tiny_benchmark)
    assert pair.other.record["value"] == "red"  # the control arm: the context's all-baseline instance
    for side in (pair.value, pair.other):
        assert {k: side.replayed[k] for k in REPLAYED} == {k: side.row[k] for k in REPLAYED}
    assert pair.faithful and pair.why == []
    assert pair.parting == PART_AT and pair.parting_gap > pair.tolerance  # red and blue: different mean reds
    assert np.array_equal(pair.value.actions[:PART_AT], pair.other.actions[:PART_AT])
    # Naming the twin's value gives the same pair.
    named = replay_pair(results, blue["instance_id"], 0, against="red", benchmark=tiny_benchmark)
    assert named.other.record["instance_id"] == pair.other.record["instance_id"] and named.parting == PART_AT
    # One recording: both episodes' cameras and actions on the step timeline, the outcomes and the parting step.
    rrd = record(pair, results / "pairs" / "pair.rrd")
    entities, steps = set(), {}
    for chunk in RrdReader(rrd).stream():
        entities.add(chunk.entity_path)
        if not chunk.is_static and "step" in chunk.to_record_batch().column_names:
            steps.setdefault(chunk.entity_path, []).extend(chunk.to_record_batch().column("step").to_pylist())
    for side in ("value", "other"):
        assert f"/pair/{side}/camera/front" in entities and f"/pair/{side}/action" in entities
        assert f"/pair/paths/{side}/ee_path" in entities and f"/pair/{side}/instance" in entities
    assert sorted(steps["/pair/value/action"]) == list(range(len(pair.value.actions)))
    assert PART_AT in steps["/pair/events"]


def test_a_replay_that_does_not_reproduce_its_row_says_so(results, tiny_benchmark, tmp_path):
    import shutil

    import pyarrow as pa
    import pyarrow.parquet as pq

    forged = tmp_path / "forged"
    shutil.copytree(results, forged)
    table = pq.read_table(forged / "episodes.parquet")
    rows = [r | {"steps": 7} if r["value"] == "blue" else r for r in table.to_pylist()]
    pq.write_table(pa.Table.from_pylist(rows, schema=table.schema), forged / "episodes.parquet")
    blue = next(r for r in rows if r["value"] == "blue")
    pair = replay_pair(forged, blue["instance_id"], 0, benchmark=tiny_benchmark)
    assert not pair.faithful
    assert pair.why == [
        f"color=blue: the replay ended differently from its row (steps 7 → {pair.value.replayed['steps']})"
    ]


def test_discordant_pairs_and_bad_input_in_one_line(results, tiny_benchmark):
    from roboview.benchmark.format import load_benchmark
    from roboview.pipelines.pair import PairConfig
    from roboview.pipelines.pair import run as pair_run

    rows = pd.read_parquet(results / "episodes.parquet").to_dict("records")
    bench = load_benchmark(tiny_benchmark)
    same = [dict(r) for r in rows]
    assert discordant(same, bench, "color", "blue") == []  # both ended alike
    flipped = [r | {"success": not r["success"]} if r["value"] == "blue" else r for r in same]
    blue = next(r for r in rows if r["value"] == "blue")
    assert discordant(flipped, bench, "color", "blue") == [(blue["instance_id"], 0)]
    with pytest.raises(
        ValueError, match=r"split color holds no value 'gold' in these results; its values: blue, red"
    ):
        discordant(same, bench, "color", "gold")
    with pytest.raises(ValueError, match=r"the results hold no split 'colour'; their splits: color"):
        discordant(same, bench, "colour", "gold")
    with pytest.raises(
        ValueError, match=r"split color holds no value 'teal' in context \w+; its values there: "
    ):
        replay_pair(results, blue["instance_id"], 0, against="teal", benchmark=tiny_benchmark)
    with pytest.raises(ValueError, match=r"instance 'nope' is not in benchmark tiny-"):
        replay_pair(results, "nope", 0, benchmark=tiny_benchmark)
    with pytest.raises(
        ValueError, match=r"every episode of color=blue ended as its twin's \(the control arm\)"
    ):
        pair_run(PairConfig(results=str(results), split="color", value="blue"))
    for bad, message in (
        ({}, "--results is required"),
        ({"results": "x", "instance": "i", "split": "color", "value": "red"}, "not both"),
        ({"results": "x", "split": "color"}, "--split and --value go together"),
        ({"results": "x"}, r"name one episode \(--instance, --repeat\), or a split's value"),
        ({"results": "x", "instance": "i", "tolerance": -1.0}, "--tolerance=-1.0 must be ≥ 0"),
    ):
        with pytest.raises(ValueError, match=message) as info:
            PairConfig(**bad)
        assert "\n" not in str(info.value)
    assert json.loads((results / "run.json").read_text())["policy"] == TYPE


def test_the_report_draws_a_strip_for_a_planted_bias_and_none_for_a_null_split(
    tiny_benchmark, results, tmp_path
):
    from roboview.eval.campaign.config import BenchmarkConfig, EvalConfig, EvaluateConfig
    from roboview.pipelines.evaluate import run as evaluate
    from roboview.pipelines.report import ReportConfig
    from roboview.pipelines.report import run as report
    from roboview.policies.types import policy_config

    # The vision agent loses gold objects against the yellow box (a planted bias): 9 pairs, every one discordant.
    vision = tmp_path / "vision"
    evaluate(
        EvaluateConfig(
            BenchmarkConfig(str(tiny_benchmark), splits="color", values="red,gold"),
            policy_config("vision"),
            EvalConfig(n_repeats=3, num_workers=1),
            str(vision),
        )
    )
    out = report(
        ReportConfig(results=str(vision), output_dir=str(tmp_path / "report"), plots=False)
    ).output_dir
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["splits"]["color"]["per_value"]["gold"]["p_control"] < 0.05
    [strip] = metrics["strips"]["drawn"]
    assert (strip["split"], strip["value"], strip["against"], strip["faithful"]) == (
        "color",
        "gold",
        "red",
        True,
    )
    assert strip["command"] == (
        f"roboview-pair --results={vision} --instance={strip['instance_id']} --repeat={strip['repeat']}"
    )
    from PIL import Image

    image = np.asarray(Image.open(out / strip["file"]))
    assert image.shape[0] > 300 and image.shape[1] > 400 and image.std() > 20  # two rows of frames, not blank
    text = (out / "report.md").read_text()
    assert "## Where they part" in text and f"]({strip['file']})" in text and strip["command"] in text
    html = (out / "report.html").read_text()
    assert "Where they part" in html and f'src="{strip["file"]}"' not in html  # carried inline
    # A null split draws none: the parting policy's red and blue end alike.
    null = report(
        ReportConfig(results=str(results), output_dir=str(tmp_path / "null"), plots=False)
    ).output_dir
    assert "strips" not in json.loads((null / "metrics.json").read_text())
    assert "Where they part" not in (null / "report.md").read_text()
    from tests.helpers.browser import chromium_binary, load_page

    if chromium_binary() is None:
        pytest.skip("no chromium on PATH (make sysdeps installs Debian's chromium package)")
    page = load_page(out / "report.html")
    assert page.errors == []
    [shown] = [i for i in page.images if i["alt"] == "color = gold against red"]
    assert shown["natural_width"] == image.shape[1] and shown["width"] > 200
