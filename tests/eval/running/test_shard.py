"""Sharded runs: --eval.shard=i/N slices the work deterministically; roboview.pipelines.merge joins the folders."""

from __future__ import annotations

import json
import shutil
from collections import Counter
from pathlib import Path

import pandas as pd
import pytest

from roboview.eval.running.results import ResultsError, shard_of
from roboview.eval.statistics.metrics import MetricsConfig
from roboview.pipelines.evaluate import EvalConfig
from roboview.pipelines.merge import MergeConfig
from roboview.pipelines.merge import main as merge_main
from roboview.pipelines.merge import run as merge
from roboview.pipelines.report import ReportConfig
from roboview.pipelines.report import run as report
from tests.helpers.evaluation import evaluate, rows

pytestmark = pytest.mark.slow

SPLITS, LIMIT, REPEATS = "color,dist_scale", 3, 2  # 12 episodes


def _evaluate_shard(bench: Path, out: Path, shard: str, policy: str = "expert"):
    from roboview.pipelines.evaluate import BenchmarkConfig, EvaluateConfig, run
    from roboview.policies.types import policy_config

    return run(
        EvaluateConfig(
            BenchmarkConfig(str(bench), SPLITS),
            policy_config(policy),
            EvalConfig(n_repeats=REPEATS, limit=LIMIT, image_size=64, shard=shard),
            str(out),
        )
    )


@pytest.fixture(scope="module")
def shards(tiny_benchmark, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("shards")
    evaluate(tiny_benchmark, tmp / "whole", splits=SPLITS, limit=LIMIT, repeats=REPEATS)
    for i in range(3):
        _evaluate_shard(tiny_benchmark, tmp / f"s{i}", f"{i}/3")
    return tmp


def test_shards_partition_the_work_and_merge_to_the_whole_run(shards, tmp_path):
    parts = [rows(shards / f"s{i}") for i in range(3)]
    keys = [set(zip(p["instance_id"], p["repeat"])) for p in parts]
    assert all(keys) and not (keys[0] & keys[1] or keys[0] & keys[2] or keys[1] & keys[2])
    for i, part in enumerate(parts):  # every repeat of an instance in the instance's own shard
        assert {shard_of(x, 3) for x in part["instance_id"]} == {i}
    result = merge(
        MergeConfig(
            results=",".join(str(shards / f"s{i}") for i in range(3)), output_dir=str(tmp_path / "merged")
        )
    )
    assert result.episodes == 12
    pd.testing.assert_frame_equal(rows(tmp_path / "merged"), rows(shards / "whole"))
    entries = json.loads((tmp_path / "merged" / "provenance.json").read_text())
    assert sorted(e["shard"] for e in entries) == ["0/3", "1/3", "2/3"]
    # The merged folder reports like any results folder.
    out = report(
        ReportConfig(
            results=str(tmp_path / "merged" / "episodes.parquet"),
            output_dir=str(tmp_path / "rep"),
            metrics=MetricsConfig(n_perm=20, n_glm=20),
            plots=False,
        )
    )
    assert out.metrics["splits"]["color"]["n_episodes"] == len(
        rows(shards / "whole").query("split == 'color'")
    )


def test_shard_of_is_stable_and_balanced():
    ids = [f"{i:016x}" for i in range(3000)]
    assert [shard_of(x, 4) for x in ids[:5]] == [shard_of(x, 4) for x in ids[:5]]
    counts = Counter(shard_of(x, 4) for x in ids)
    assert set(counts) == {0, 1, 2, 3} and min(counts.values()) > 650  # 750 expected each
    assert (
        shard_of("a3f9c2d1e0b4a5c6", 7)
        == int.from_bytes(__import__("hashlib").sha256(b"a3f9c2d1e0b4a5c6").digest()[:8], "big") % 7
    )


def test_merge_refuses_overlaps_missing_shards_and_other_runs(shards, tiny_benchmark, tmp_path, capsys):
    s = [shards / f"s{i}" for i in range(3)]
    with pytest.raises(ResultsError, match=r"shard\(s\) 2/3 missing"):
        merge(MergeConfig(results=f"{s[0]},{s[1]}", output_dir=str(tmp_path / "m1")))
    assert merge(
        MergeConfig(results=f"{s[0]},{s[1]}", output_dir=str(tmp_path / "m2"), partial=True)
    ).episodes == len(rows(s[0])) + len(rows(s[1]))
    with pytest.raises(ResultsError, match="given twice"):
        merge(MergeConfig(results=f"{s[0]},{s[0]},{s[1]},{s[2]}", output_dir=str(tmp_path / "m3")))
    # An episode in two folders: shard 1's journal also holds one of shard 0's episodes.
    leaky = tmp_path / "leaky"
    shutil.copytree(s[1], leaky)
    with (leaky / "episodes.jsonl").open("a") as f:
        f.write((s[0] / "episodes.jsonl").read_text().splitlines()[0] + "\n")
    with pytest.raises(ResultsError, match="overlap"):
        merge(MergeConfig(results=f"{s[0]},{leaky},{s[2]}", output_dir=str(tmp_path / "m4")))
    assert not (tmp_path / "m4").exists()  # refused before anything was written
    # Another policy's shard.
    _evaluate_shard(tiny_benchmark, tmp_path / "random1", "1/3", policy="random")
    with pytest.raises(ResultsError, match="policy: 'expert'.*'random'"):
        merge(MergeConfig(results=f"{s[0]},{tmp_path / 'random1'},{s[2]}", output_dir=str(tmp_path / "m5")))
    # Another benchmark version.
    other = tmp_path / "other_version"
    shutil.copytree(s[2], other)
    info = json.loads((other / "run.json").read_text())
    (other / "run.json").write_text(json.dumps(info | {"benchmark_version": "tiny-other"}))
    with pytest.raises(ResultsError, match="benchmark_version"):
        merge(MergeConfig(results=f"{s[0]},{s[1]},{other}", output_dir=str(tmp_path / "m6")))
    # An unsharded folder, and the CLI's message.
    with pytest.raises(SystemExit):
        merge_main([f"--results={s[0]},{shards / 'whole'}", f"--output_dir={tmp_path / 'm7'}"])
    assert "was not sharded" in capsys.readouterr().err


@pytest.mark.parametrize("shard, message", [("2/2", "0 ≤ i < N"), ("1", "i/N"), ("a/3", "i/N")])
def test_bad_shard_is_refused(shard, message):
    with pytest.raises(ValueError, match=message):
        EvalConfig(shard=shard)


def test_shard_and_adaptive_are_refused_together():
    with pytest.raises(ValueError, match="cannot be sharded"):
        EvalConfig(shard="0/2", adaptive=True)
