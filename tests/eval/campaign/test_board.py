"""The leaderboard, result bundles on the Hub and the Hub's eval-results files.

The significance groups are checked by simulation against a known truth; the rest runs on real result bundles of
the `tiny` benchmark (expert, random, vision on one split), published as a dry run, tampered with, and loaded in
headless Chromium.
"""

from __future__ import annotations

import datetime
import json
import shutil
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
import yaml

from roboview.eval.statistics.ranking import rank_table
from roboview.eval.statistics.significance import paired_success_test

pytestmark = pytest.mark.slow

SPLIT = "camera_pose"


# --- the groups, by simulation --------------------------------------------------------------------------


def simulated_groups(truth: dict[str, float], n: int, rng: np.random.Generator, alpha: float = 0.05):
    """One simulated board: paired episodes of each policy (independent given the truth), McNemar per pair."""
    outcomes = {name: rng.random(n) < p for name, p in truth.items()}
    names = sorted(truth)
    pvalues = {
        frozenset((a, b)): paired_success_test(outcomes[a], outcomes[b])
        for i, a in enumerate(names)
        for b in names[i + 1 :]
    }
    rows = rank_table({k: float(v.mean()) for k, v in outcomes.items()}, pvalues, True, alpha)
    return {r["policy"]: set(r["group"]) for r in rows}


def test_letters_never_separate_tied_policies_beyond_the_error_rate():
    """Truth: a and b tie (0.7), c is worse (0.4), d ties c. Over 400 boards, a pair the truth does not separate
    gets disjoint letters in at most α of them (Holm controls the family-wise rate), while the real gaps are
    found in nearly every board."""
    truth = {"a": 0.7, "b": 0.7, "c": 0.4, "d": 0.4}
    rng = np.random.default_rng(7)
    sims, false_split, found = 400, 0, 0
    for _ in range(sims):
        groups = simulated_groups(truth, 150, rng)
        false_split += not (groups["a"] & groups["b"]) or not (groups["c"] & groups["d"])
        found += all(not (groups[x] & groups[y]) for x in "ab" for y in "cd")
    bound = 0.05 + 3 * np.sqrt(0.05 * 0.95 / sims)
    assert false_split / sims <= bound, f"tied policies separated in {false_split}/{sims} boards"
    assert found / sims > 0.9, f"the 0.7 vs 0.4 gaps were found in only {found}/{sims} boards"


def test_letters_of_a_known_order():
    """Three policies far apart in truth get three letters in order; two identical ones share theirs."""
    rng = np.random.default_rng(3)
    groups = simulated_groups({"hi": 0.95, "mid": 0.5, "lo": 0.05}, 200, rng)
    assert groups == {"hi": {"a"}, "mid": {"b"}, "lo": {"c"}}
    ranked = rank_table({"x": 0.5, "y": 0.5}, {frozenset("xy"): 1.0}, True)
    assert [r["group"] for r in ranked] == ["a", "a"]


# --- real bundles --------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def bundles(tmp_path_factory, tiny_benchmark) -> dict[str, Path]:
    """expert, random and vision evaluated on one split of the tiny benchmark under its `quick` protocol (3
    repeats), each with a 60-step budget (the expert and vision finish within 54; random times out, and its
    replays cost half the default 120): each a partial results folder, that split whole."""
    from roboview.pipelines.evaluate import BenchmarkConfig, EvalConfig, EvaluateConfig
    from roboview.pipelines.evaluate import run as evaluate
    from roboview.policies.types import policy_config

    root = tmp_path_factory.mktemp("board")
    out = {}
    for name in ("expert", "random", "vision"):
        evaluate(
            EvaluateConfig(
                BenchmarkConfig(str(tiny_benchmark), SPLIT),
                policy_config(name),
                EvalConfig(protocol="quick", num_workers=1, image_size=64, max_steps=60),
                str(root / name),
            )
        )
        out[name] = root / name
    return out


def _board(bundles, tmp_path, *extra, replay=None, **kw):
    """A board of expert, random, vision and `extra`; `replay` None: --replay=0 (the checks of the bundles' files
    alone, fast), else the board's replay config."""
    from roboview.pipelines.leaderboard import BoardReplayConfig, LeaderboardConfig, run

    sources = ",".join([str(bundles[n]) for n in ("expert", "random", "vision")] + [str(e) for e in extra])
    replay = replay if replay is not None else BoardReplayConfig(n=0)
    return run(
        LeaderboardConfig(
            results=sources, output_dir=str(tmp_path / "board"), plots=False, replay=replay, **kw
        )
    )


def test_board_ranks_verified_bundles_with_groups_and_links(bundles, tmp_path):
    board = _board(bundles, tmp_path)
    assert board.protocol == "quick" and not board.rejected
    assert board.overall == {}  # partial bundles: ranked on the split they cover, never overall
    sr = {r["policy"]: r for r in board.splits[SPLIT]["sr"]}
    assert set(sr) == {"expert", "random", "vision"}
    # The expert (privileged) is a reference line, not rank 1; vision solves every episode here, random none.
    assert sr["expert"]["value"] == sr["vision"]["value"] == 1.0 and sr["random"]["value"] == 0.0
    assert sr["expert"]["rank"] is None and sr["expert"]["group"] == "ref" and sr["expert"]["reference"]
    assert (sr["vision"]["rank"], sr["vision"]["group"]) == (1, "a") and (
        sr["random"]["rank"],
        sr["random"]["group"],
    ) == (2, "b")
    assert sr["random"]["rank_range"] == [2, 2] and sr["vision"]["rank_range"] == [1, 1]
    # 0/27: Clopper–Pearson's upper end solves (1 − p)^27 = 0.025.
    assert sr["random"]["episodes"] == 27 and sr["random"]["ci95"][1] == pytest.approx(1 - 0.025 ** (1 / 27))
    assert all(r["protocol"] == "quick" and r["partial"] and not r["replayed"] for r in sr.values())
    assert list(board.splits) == [SPLIT]
    entries = {e.label: e for e in board.entries}
    assert entries["expert"].privileged and not entries["vision"].privileged
    saved = json.loads((tmp_path / "board" / "leaderboard.json").read_text())
    assert saved["benchmark_version"] == board.benchmark_version and saved["adjustment"] == "holm"
    assert saved["protocol"] == "quick" and saved["splits"][SPLIT]["sr"][0]["replay_note"]
    page = (tmp_path / "board" / "leaderboard.html").read_text()
    assert "(privileged: reference, not ranked)" in page and "cv_excess ×100 [95 % CI]" in page
    # Built with --replay=0: the title says so and no row is called verified.
    assert "<h1>RoboView-Bias leaderboard (not replayed: outcomes as the bundles report them)</h1>" in page
    assert "3 bundle(s) checked but not replayed" in page and "verified" not in page.split("<h2>")[0]
    assert saved["replay"]["n"] == 0 and all(e["table"] == "ranked" for e in saved["entries"])
    # The control arm beside each SR: none here (tiny's camera_pose split holds no `original` pose and no other
    # split ran), so the rows say so and the page shows no empty column.
    assert all(r["sr_control"] is None and r["sr_control_ci95"] is None for r in sr.values())
    assert "Control SR" not in page
    for e in board.entries:  # each row links to a report of that bundle's episodes
        report = tmp_path / "board" / e.report
        metrics = json.loads((report.parent / "metrics.json").read_text())
        assert report.is_file() and metrics["policy"] == e.policy
        assert metrics["splits"][SPLIT]["sr"] == sr[e.label]["value"]


def _retag(results: Path, to: Path, version: str) -> Path:
    """A copy of a results folder whose rows say they ran on benchmark `version`."""
    shutil.copytree(results, to)
    table = pq.read_table(to / "episodes.parquet")
    meta = dict(table.schema.metadata) | {b"roboview_benchmark_version": version.encode()}
    pq.write_table(table.replace_schema_metadata(meta), to / "episodes.parquet")
    run = json.loads((to / "run.json").read_text()) | {"benchmark_version": version}
    (to / "run.json").write_text(json.dumps(run))
    return to


def _flip_success(parquet: Path, n: int = 3) -> None:
    table = pq.read_table(parquet)
    success = table.column("success").to_pylist()
    flipped = [not s if i < n else s for i, s in enumerate(success)]
    table = table.set_column(table.schema.get_field_index("success"), "success", pa.array(flipped))
    pq.write_table(table, parquet)


def test_other_versions_tampered_and_missing_bundles_are_listed_apart(bundles, tmp_path):
    from roboview.pipelines.publish import PublishConfig
    from roboview.pipelines.publish import run as publish

    other = _retag(bundles["random"], tmp_path / "other", "tiny-000000000000")
    publish(
        PublishConfig(
            results=str(bundles["vision"]),
            repo_id="lab/vision-results",
            dry_run=True,
            staging_dir=str(tmp_path / "vision_bundle"),
        )
    )
    _flip_success(tmp_path / "vision_bundle" / "episodes.parquet")
    board = _board(bundles, tmp_path, other, tmp_path / "vision_bundle", tmp_path / "nowhere")
    reasons = {Path(r.source).name: r.reason for r in board.rejected}
    assert "results of benchmark tiny-000000000000; this board ranks" in reasons["other"]
    assert "files: 1 file(s) differ from bundle.json: episodes.parquet: edited" in reasons["vision_bundle"]
    assert "does not exist" in reasons["nowhere"]
    assert {e.label for e in board.entries} == {"expert", "random", "vision"}  # never ranked


def test_replay_refuses_edited_rows(bundles, tmp_path):
    """Rows edited in place (no bundle.json to compare with) are caught by re-running them."""
    from roboview.eval.verification import verify_results

    edited = tmp_path / "edited"
    shutil.copytree(bundles["random"], edited)
    _flip_success(edited / "episodes.parquet", n=27)  # every row: any sample finds them
    result = verify_results(edited, replay=6)
    replay = {c.name: c for c in result.checks}["replay"]
    assert not replay.passed and "6 of 6 re-run episodes end differently" in replay.detail
    assert "success True → False" in replay.detail
    honest = verify_results(bundles["random"], replay=3)
    assert {c.name: c for c in honest.checks}["replay"].passed


def test_an_episode_two_bundles_claim_is_re_run_once(bundles, tiny_benchmark):
    """A board's replayer re-runs an episode once for every bundle that claims it with the same policy: a forgery of
    an honest bundle is held to the honest bundle's re-runs, and caught by them."""
    from roboview.benchmark.format import load_benchmark
    from roboview.eval.verification.replay import Replayer, check_replay
    from roboview.eval.verification.results import read_table

    table, run = read_table(bundles["expert"])
    rows, bench, replayer = table.to_pylist()[:3], load_benchmark(tiny_benchmark), Replayer()
    try:
        honest, _ = check_replay(rows, bench, run, 3, 0.05, replayer)
        forged, _ = check_replay(
            [r | {"success": not r["success"]} for r in rows], bench, run, 3, 0.05, replayer
        )
    finally:
        replayer.close()
    assert honest.passed and not forged.passed, (honest.detail, forged.detail)
    assert (
        "3 of 3 re-run episodes end differently" in forged.detail and "success False → True" in forged.detail
    )
    assert replayer.episodes_run == 3


def test_published_bundle_dry_run_and_eval_results(bundles, tmp_path, capsys):
    from huggingface_hub import EvalResultEntry, parse_eval_result_entries

    from roboview.eval.reporting.bundle import BUNDLE_FILE, sha256_file
    from roboview.integrations.publishing.hub import PublishError
    from roboview.pipelines.publish import PublishConfig
    from roboview.pipelines.publish import run as publish

    staging = tmp_path / "bundle"
    cfg = PublishConfig(
        results=str(bundles["expert"]),
        repo_id="lab/expert-results",
        benchmark_repo_id="lab/roboview-bias",
        model_repo_id="lab/expert",
        dry_run=True,
        staging_dir=str(staging),
    )
    plan = publish(cfg)
    listed = capsys.readouterr().out
    files = {rel for rel, _ in plan.files}
    assert {
        "episodes.parquet",
        "run.json",
        "provenance.json",
        "verify.json",
        "README.md",
        BUNDLE_FILE,
        "report/metrics.json",
        "report/report.md",
        "report/report.html",
    } <= files
    assert "episodes.jsonl" not in files and "nothing uploaded" in listed
    # Every file listed is in the folder with the listed size, and bundle.json holds its hash.
    manifest = json.loads((staging / BUNDLE_FILE).read_text())
    for rel, size in plan.files:
        assert (staging / rel).stat().st_size == size
        if rel != BUNDLE_FILE:
            assert manifest["files"][rel] == sha256_file(staging / rel)
    assert manifest["benchmark_version"] == plan.version and manifest["policy"] == "expert"
    card = (staging / "README.md").read_text()
    assert "## Table 1" in card and plan.version in card and manifest["benchmark_content_hash"] in card
    assert "(privileged)" in card and "| conformance | pass |" in card
    verify = json.loads((staging / "verify.json").read_text())
    checks = {c["name"]: c for c in verify["checks"]}
    assert verify["passed"] and all(c["passed"] for name, c in checks.items() if name != "replay")
    # Staging re-ran no episode, and says so: never labelled replayed.
    assert checks["replay"]["passed"] is None and verify["replay"] is None and "| replay | not run |" in card
    assert verify["protocol"] == "quick" and verify["partial"] and verify["covered"] == [SPLIT]

    # The model repo's .eval_results file: the documented schema, one entry per split, read back by the Hub's
    # own parser.
    text = (tmp_path / "bundle_eval_results" / ".eval_results" / "roboview-bias.yaml").read_text()
    assert "lab/expert/.eval_results/roboview-bias.yaml" in listed
    data = yaml.safe_load(text)
    assert isinstance(data, list) and len(data) == 1
    entry = data[0]
    assert set(entry) <= {"dataset", "value", "verifyToken", "date", "source", "notes"}
    # The benchmark version is the dataset revision (the tag its release carries): a republished benchmark differs.
    assert entry["dataset"] == {"id": "lab/roboview-bias", "task_id": SPLIT, "revision": plan.version}
    assert isinstance(entry["value"], float) and entry["value"] == 100.0
    datetime.datetime.fromisoformat(entry["date"])
    assert entry["source"]["url"] == "https://huggingface.co/datasets/lab/expert-results"
    parsed = parse_eval_result_entries(data)
    assert parsed == [
        EvalResultEntry(
            dataset_id="lab/roboview-bias",
            task_id=SPLIT,
            value=100.0,
            dataset_revision=plan.version,
            date=entry["date"],
            source_url=entry["source"]["url"],
            source_name=entry["source"]["name"],
            notes=entry["notes"],
        )
    ]

    # Offline, the real upload stops with what to do, after writing nothing to the Hub.
    cfg.dry_run = False
    with pytest.raises(PublishError, match="offline mode is on"):
        publish(cfg)


def test_publish_refuses_results_that_do_not_verify(bundles, tmp_path):
    from roboview.integrations.publishing.hub import PublishError
    from roboview.pipelines.publish import PublishConfig
    from roboview.pipelines.publish import run as publish

    partial = tmp_path / "partial"
    shutil.copytree(bundles["random"], partial)
    table = pq.read_table(partial / "episodes.parquet")
    pq.write_table(table.slice(0, 10), partial / "episodes.parquet")
    with pytest.raises(
        PublishError,
        match=r"does not verify.*complete: protocol quick: camera_pose: 17 of 27 episodes missing",
    ):
        publish(PublishConfig(results=str(partial), repo_id="lab/x", dry_run=True))
    assert not (tmp_path / "partial_bundle").exists()


def test_board_page_in_chromium(bundles, tmp_path):
    from tests.helpers.browser import chromium_binary, load_page

    if chromium_binary() is None:
        pytest.skip("no chromium (make sysdeps installs it)")
    _board(bundles, tmp_path)
    order = "Array.from(document.querySelector('table.ranked').tBodies[0].rows).map(r => r.cells[1].textContent).join(',')"
    sort_by_sr = "document.querySelector('table.ranked').tHead.rows[0].cells[2].click(); " + order
    page = load_page(tmp_path / "board" / "leaderboard.html", scripts=(order, sort_by_sr, sort_by_sr))
    assert page.errors == []
    before, ascending, descending = page.evaluated
    # Ranked first, the privileged expert after them as a reference line; every bundle partial (one split).
    assert before == "vision (partial),random (partial),expert (privileged: reference, not ranked) (partial)"
    assert ascending.split(",")[0] == "random (partial)" and descending.split(",")[-1] == "random (partial)"
    # The screenshot shows the ranked table: dark text rows on white, the header band grey.
    shot = page.screenshot
    assert shot.shape[0] > 600
    dark_rows = np.flatnonzero((shot.min(axis=2) < 90).sum(axis=1) > 20)
    assert len(dark_rows) > 100


# --- a board no one can game ------------------------------------------------------------------------------


def _copy_with(bundle: Path, to: Path, edit_rows=None, edit_run=None) -> Path:
    """A copy of a results folder with its rows and/or run.json edited (the parquet's metadata kept)."""
    shutil.copytree(bundle, to)
    if edit_rows is not None:
        table = pq.read_table(to / "episodes.parquet")
        rows = edit_rows(table.to_pylist())
        pq.write_table(pa.Table.from_pylist(rows, schema=table.schema), to / "episodes.parquet")
    if edit_run is not None:
        run = json.loads((to / "run.json").read_text())
        (to / "run.json").write_text(json.dumps(edit_run(run)))
    return to


def _failed(folder: Path, **kw) -> dict[str, str]:
    from roboview.eval.verification import verify_results

    return {c.name: c.detail for c in verify_results(folder, **kw).checks if not c.passed}


def test_completeness_is_judged_against_the_benchmarks_protocol_not_the_run_json(bundles, tmp_path):
    from roboview.variation.instances import episode_seed

    vision = bundles["vision"]
    # Repeats dropped, run.json edited to say one repeat was asked for: still three under `quick`.
    one = _copy_with(
        vision,
        tmp_path / "one",
        lambda rows: [r for r in rows if r["repeat"] == 0],
        lambda run: run | {"n_repeats": {SPLIT: 1}},
    )
    assert "camera_pose: 18 of 27 episodes missing" in _failed(one)["complete"]
    # A value left out, run.json edited to say only the others were chosen.
    dropped = sorted({r["value"] for r in pq.read_table(vision / "episodes.parquet").to_pylist()})[0]
    values = _copy_with(
        vision,
        tmp_path / "values",
        lambda rows: [r for r in rows if r["value"] != dropped],
        lambda run: run | {"values": [dropped + "_not"]},
    )
    assert "episodes missing" in _failed(values)["complete"]

    # Padded: repeats beyond the protocol, their seeds recomputed so every other check holds.
    def pad(rows):
        extra = [
            r | {"repeat": 3, "episode_seed": episode_seed(r["context_id"], 3)}
            for r in rows
            if r["repeat"] == 0
        ]
        return rows + extra

    padded = _copy_with(vision, tmp_path / "padded", pad, lambda run: run | {"n_repeats": {SPLIT: 4}})
    assert "9 rows beyond the protocol (e.g." in _failed(padded)["complete"]
    # Claiming a protocol whose repeats it does not have, or one the benchmark does not declare.
    paper = _copy_with(vision, tmp_path / "paper", edit_run=lambda run: run | {"protocol": "paper"})
    assert "protocol paper: camera_pose: 18 of 45 episodes missing" in _failed(paper)["complete"]
    made_up = _copy_with(vision, tmp_path / "made_up", edit_run=lambda run: run | {"protocol": "lenient"})
    assert (
        "claims protocol 'lenient'; the benchmark declares adaptive, paper, quick"
        in _failed(made_up)["complete"]
    )
    # The honest folder: whole for the split it covers, partial for the protocol.
    from roboview.eval.verification import verify_results

    honest = verify_results(vision)
    assert honest.passed and honest.coverage == {"protocol": "quick", "covered": [SPLIT], "partial": True}


def test_replay_draws_its_sample_here_and_keeps_its_stated_guarantee():
    """By simulation: a forgery of 5 % of 400 rows is caught by the 59-episode sample in ≥ 95 % of verifications,
    a single changed row in about n/N of them; two verifications draw different samples."""
    import random

    from roboview.eval.verification.replay import draw_sample, guarantee, replay_size

    assert replay_size(0.05, 0.95) == 59 and replay_size(0.01, 0.99) == 459
    with pytest.raises(ValueError, match="strictly between 0 and 1"):
        replay_size(0.0, 0.95)
    rows = [{"instance_id": f"i{i}", "repeat": 0, "status": "ok"} for i in range(400)]
    forged, single = set(range(0, 400, 20)), {7}
    rng, sims = random.Random(11), 4000
    caught = one = 0
    for _ in range(sims):
        drawn = {int(r["instance_id"][1:]) for r in draw_sample(rows, 59, rng)}
        caught += bool(drawn & forged)
        one += bool(drawn & single)
    assert caught / sims >= 0.95 - 3 * np.sqrt(0.05 * 0.95 / sims)
    assert abs(one / sims - 59 / 400) < 3 * np.sqrt(0.15 * 0.85 / sims)
    first, second = draw_sample(rows, 59), draw_sample(rows, 59)
    assert {r["instance_id"] for r in first} != {r["instance_id"] for r in second}
    words = guarantee(59, 400, 0.05)
    assert (
        "≥ 5% of the rows is caught with probability ≥ 95.2%" in words and "a smaller one can pass" in words
    )


def test_conformance_is_re_derived_and_the_schema_checked_first(bundles, tmp_path):
    from roboview.eval.verification import verify_results

    # provenance says the run's stack was `different`; the rows were relabelled `identical`.
    relabelled = _copy_with(bundles["vision"], tmp_path / "relabelled")
    entries = json.loads((relabelled / "provenance.json").read_text())
    for e in entries:
        if e.get("conformance"):
            e["conformance"]["verdict"] = "different"
    (relabelled / "provenance.json").write_text(json.dumps(entries))
    detail = _failed(relabelled)["conformance"]
    assert "ran on a stack whose conformance is 'different'" in detail
    assert "rows labelled ['identical'], a verdict no run of this folder recorded" in detail
    # provenance's recorded stack differences edited away from what its stack gives.
    edited = _copy_with(bundles["vision"], tmp_path / "edited")
    entries = json.loads((edited / "provenance.json").read_text())
    for e in entries:
        if e.get("conformance"):
            e["conformance"]["stack"]["mujoco"] = "4.0.0"
    (edited / "provenance.json").write_text(json.dumps(entries))
    assert "mujoco: 3.8.1 vs 4.0.0" in _failed(edited)["conformance"]
    # No `success` column: the schema check fails and nothing else is read.
    blind = _copy_with(bundles["vision"], tmp_path / "blind")
    table = pq.read_table(blind / "episodes.parquet")
    pq.write_table(table.drop(["success"]), blind / "episodes.parquet")
    result = verify_results(blind)
    assert [c.name for c in result.checks] == ["schema"] and "no `success` column" in result.checks[0].detail
    # A success with a timeout's reason cannot happen.
    odd = _copy_with(
        bundles["random"],
        tmp_path / "odd",
        lambda rows: [rows[0] | {"success": True}, *rows[1:]],
    )
    assert "a success with failure reason" in _failed(odd)["plausible"]


def test_bad_bundles_are_listed_apart_and_the_board_goes_on(bundles, tmp_path, capsys):
    from roboview.pipelines.verify import main as verify_main

    no_repeat = _copy_with(bundles["random"], tmp_path / "no_repeat")
    table = pq.read_table(no_repeat / "episodes.parquet")
    pq.write_table(table.drop(["repeat"]), no_repeat / "episodes.parquet")
    zeroed = _copy_with(bundles["random"], tmp_path / "zeroed")
    data = bytearray((zeroed / "episodes.parquet").read_bytes())
    data[len(data) // 3 : len(data) - 8] = bytes(len(data) - 8 - len(data) // 3)  # pages and footer zeroed
    (zeroed / "episodes.parquet").write_bytes(bytes(data))
    listed = _copy_with(bundles["random"], tmp_path / "listed")
    (listed / "bundle.json").write_text("[]")
    board = _board(bundles, tmp_path, no_repeat, zeroed, listed)
    reasons = {Path(r.source).name: r.reason for r in board.rejected}
    assert "schema: no `repeat` column" in reasons["no_repeat"]
    assert "zeroed/episodes.parquet is not a readable parquet file" in reasons["zeroed"]
    assert "bundle.json: holds no `files` object (it is a JSON list)" in reasons["listed"]
    assert all("\n" not in r for r in reasons.values())
    assert {e.label for e in board.entries} == {"expert", "random", "vision"}
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_:
        verify_main([f"--results={zeroed}"])
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and "is not a readable parquet file" in err and "Traceback" not in err


def test_the_board_replays_bundles_whose_policy_runs_here(bundles, tmp_path):
    from roboview.pipelines.leaderboard import BoardReplayConfig

    board = _board(bundles, tmp_path, replay=BoardReplayConfig(n=2))
    assert not board.rejected and all(e.replayed for e in board.entries)
    for e in board.entries:
        assert (
            e.replay_note.startswith("2 episodes re-run with") and "a smaller one can pass" in e.replay_note
        )
    rows = json.loads((tmp_path / "board" / "leaderboard.json").read_text())["splits"][SPLIT]["sr"]
    assert all(r["replayed"] for r in rows)


def test_compare_decides_expert_against_random_in_one_round_and_leaves_equals_not_separated(
    bundles, tmp_path, capsys
):
    """roboview-compare on real bundles (3 rounds of tiny's camera_pose): the expert wins all 9 pairs of round 1
    (exact McNemar p 0.0039, under the 0.005 the first of 10 looks spends); expert and vision never disagree."""
    from roboview.pipelines.compare import main

    result = main([f"--results={bundles['random']},{bundles['expert']}", f"--output_dir={tmp_path}"])
    sr = result["splits"][SPLIT]["sr"]
    assert result["policies"] == ["random", "expert"] and result["splits"][SPLIT]["rounds"] == 3
    assert (sr["verdict"], sr["look"], sr["delta"]) == ("B better", 1, 1.0)
    assert sr["p"] == pytest.approx(2 / 2**9) and sr["alpha_spent"] == pytest.approx(0.005)
    assert json.loads((tmp_path / "compare.json").read_text())["overall"]["sr"]["verdict"] == "B better"
    out = capsys.readouterr().out
    assert "sr B better at round 1" in out
    same = main(
        [f"--results={bundles['vision']},{bundles['expert']}", "--max_repeats=3", "--stop_exit_code=true"]
    )
    assert same["overall"]["sr"]["verdict"] == "not separated" and same["overall"]["sr"]["needs"] is None
    with pytest.raises(SystemExit) as undecided:  # 3 of 10 planned rounds, nothing seen: keep running rounds
        main([f"--results={bundles['vision']},{bundles['expert']}", "--stop_exit_code=true"])
    assert undecided.value.code == 3
    with pytest.raises(SystemExit) as bad:
        main([f"--results={bundles['vision']}"])
    assert bad.value.code == 2 and "give exactly two results folders" in capsys.readouterr().err


# --- a board that checks before it ranks ----------------------------------------------------------------------


def _forge(bundle: Path, to: Path, flips: int = 15, edit_run=None, table_policy: str | None = None) -> Path:
    """A copy whose first `flips` failures are successes, episodes.parquet and episodes.jsonl rewritten to match
    (each a plausible success: no failure reason, 50 steps), run.json edited by `edit_run`, the table's own policy
    record set to `table_policy`."""
    shutil.copytree(bundle, to)
    table = pq.read_table(to / "episodes.parquet")
    rows, done = table.to_pylist(), 0
    for row in rows:
        if not row["success"] and done < flips:
            row.update(success=True, failure_reason="", steps=50)
            done += 1
    meta = dict(table.schema.metadata)
    if table_policy is not None:
        meta[b"roboview_policy"] = table_policy.encode()
    forged = pa.Table.from_pylist(rows, schema=table.schema.with_metadata(meta))
    pq.write_table(forged, to / "episodes.parquet")
    (to / "episodes.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    if edit_run is not None:
        (to / "run.json").write_text(json.dumps(edit_run(json.loads((to / "run.json").read_text()))))
    return to


def _served_elsewhere(run: dict) -> dict:
    """run.json naming a policy served at an address that answers nothing."""
    return run | {"policy": "openpi", "policy_options": {"url": "ws://127.0.0.1:9", "obs_format": "droid"}}


def test_a_forged_bundle_never_ranks_above_its_honest_original_on_a_default_board(bundles, tmp_path, capsys):
    """random's failures turned into successes (15 of 27): with its own reachable policy the default board's replay
    rejects it; naming an unreachable served policy in run.json fails the record check; made consistent with that
    policy, it is a claim, listed apart, never among the ranked rows or their letters."""
    from roboview.pipelines.leaderboard import LeaderboardConfig, run

    local = _forge(bundles["random"], tmp_path / "forged_local")
    naive = _forge(bundles["random"], tmp_path / "forged_naive", edit_run=_served_elsewhere)
    served = _forge(
        bundles["random"],
        tmp_path / "forged_served",
        edit_run=lambda run: _served_elsewhere(run) | {"policy_name": "random"},
        table_policy="openpi",
    )
    sources = [bundles["vision"], bundles["random"], local, naive, served]
    board = run(
        LeaderboardConfig(
            results=",".join(map(str, sources)), output_dir=str(tmp_path / "board"), plots=False
        )
    )
    printed = capsys.readouterr().out
    assert "[leaderboard] replay: 59 episodes of each bundle" in printed and "probability ≥ 95.2%" in printed
    assert board.replay["n"] == 59 and board.replay["detect"] == 0.05 and board.replay["confidence"] > 0.95
    reasons = {Path(r.source).name: r.reason for r in board.rejected}
    assert set(reasons) == {"forged_local", "forged_naive"}
    assert "replay: 15 of 27 re-run episodes end differently" in reasons["forged_local"]
    assert "success True → False" in reasons["forged_local"]
    assert (
        "record: 27 rows name policy 'random', run.json's policy 'openpi' names its rows 'openpi:droid'"
        in reasons["forged_naive"]
    )
    # Ranked: the honest bundles only, both replayed whole; the forged copy is a claim with its 15 of 27.
    sr = {r["policy"]: r for r in board.splits[SPLIT]["sr"]}
    assert set(sr) == {"vision", "random@random"} and sr["random@random"]["value"] == 0.0
    assert all(r["replayed"] and r["table"] == "ranked" for r in sr.values())
    assert all(e.replay_note.startswith("27 episodes re-run with") for e in board.entries)
    (claim,) = board.claims
    assert claim.source == str(served) and claim.table == "claims" and not claim.replayed
    assert claim.sr == pytest.approx(15 / 27) and claim.episodes == 27
    assert claim.replay_note.startswith("unreachable: cannot rebuild policy 'openpi'")
    assert "Connection refused" in claim.replay_note
    saved = json.loads((tmp_path / "board" / "leaderboard.json").read_text())
    assert [c["table"] for c in saved["claims"]] == ["claims"] and saved["replay"]["n"] == 59
    assert {e["label"]: e["table"] for e in saved["entries"]} == {
        "vision": "ranked",
        "random@random": "ranked",
    }
    page = (tmp_path / "board" / "leaderboard.html").read_text()
    ranked_part, claims_part = page.split("<h2>Claims (not replayed here: not ranked, not compared)</h2>")
    assert "random@forged_served" not in ranked_part and "random@forged_served" in claims_part
    assert "55.56 [35.33, 74.52]" in claims_part and "<h1>RoboView-Bias leaderboard</h1>" in page
    assert "2 ranked bundle(s) (replay passed), 1 claim(s) listed apart, 2 rejected" in page


def test_an_unreplayable_honest_bundle_is_a_claim_not_in_the_groups(bundles, tmp_path, monkeypatch):
    """vision's own bundle, its provenance saying it ran on another renderer: a claim ("another stack"), not
    replayed; a forged random bundle whose policy type says a re-run cannot reproduce it: a claim ("stochastic"),
    where the same forgery of a reproducible policy is rejected."""
    from roboview.pipelines.leaderboard import BoardReplayConfig
    from roboview.policies.adapters import RandomConfig

    other = _copy_with(bundles["vision"], tmp_path / "gpu_vision")
    entries = json.loads((other / "provenance.json").read_text())
    for e in entries:
        if e.get("conformance"):
            renderer = e["conformance"]["stack"]["renderer"]
            e["conformance"]["stack_differences"] = [
                f"renderer: {renderer['renderer']} vs NVIDIA H100/PCIe/SSE2"
            ]
            renderer["renderer"] = "NVIDIA H100/PCIe/SSE2"
    (other / "provenance.json").write_text(json.dumps(entries))
    stochastic = _forge(bundles["random"], tmp_path / "sampled", flips=27)
    monkeypatch.setattr(RandomConfig, "reproducible", False)
    board = _board(bundles, tmp_path, other, stochastic, replay=BoardReplayConfig(n=3))
    assert not board.rejected
    claims = {Path(c.source).name: c for c in board.claims}
    assert set(claims) == {"gpu_vision", "sampled"}
    assert claims["gpu_vision"].replay_note.startswith("another stack: it ran on MuJoCo")
    assert "renderer: NVIDIA H100/PCIe/SSE2 vs " in claims["gpu_vision"].replay_note
    assert claims["sampled"].replay_note.startswith("stochastic: 3 of 3 re-run episodes end differently")
    assert claims["gpu_vision"].sr == 1.0 and claims["sampled"].sr == 1.0
    # The groups hold the replayed bundles only; the claims get no letter and no row there.
    ranked = {r["policy"] for r in board.splits[SPLIT]["sr"]} | {
        r["policy"] for r in board.splits[SPLIT]["cv_excess"]
    }
    assert ranked == {"expert", "random@random", "vision@vision"}
    assert {e.label for e in board.entries} == ranked and all(e.replayed for e in board.entries)
    assert {c.label for c in board.claims} == {"vision@gpu_vision", "random@sampled"}
    for c in board.claims:  # each measured alone: a report of its own episodes only
        metrics = json.loads((tmp_path / "board" / Path(c.report).parent / "metrics.json").read_text())
        assert metrics["policy"] == c.label and metrics["splits"][SPLIT]["n_episodes"] == 27


def test_a_run_json_that_disagrees_with_its_rows_fails_verify(bundles, tmp_path, capsys):
    from roboview.eval.verification import verify_results
    from roboview.pipelines.verify import main as verify_main

    honest = {c.name: c for c in verify_results(bundles["random"]).checks}["record"]
    assert (
        honest.passed
        and "policy random (random), control joint, image size 64, max steps 60" in honest.detail
    )
    served = _copy_with(bundles["vision"], tmp_path / "served", edit_run=_served_elsewhere)
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_:
        verify_main([f"--results={served}"])
    lines = [line for line in capsys.readouterr().out.splitlines() if line.startswith("FAIL")]
    assert exit_.value.code == 1 and len(lines) == 1
    assert lines[0].split()[1] == "record" and "27 rows name policy 'vision'" in lines[0]
    assert "episodes.parquet records policy 'vision', run.json 'openpi'" in lines[0]
    # The step budget and the control, against the rows' timeouts and what provenance recorded.
    longer = _copy_with(bundles["random"], tmp_path / "longer", edit_run=lambda run: run | {"max_steps": 200})
    detail = _failed(longer)["record"]
    assert "run.json's max steps is 200, a run in provenance.json ran with 60" in detail
    assert "the rows time out within 60 steps" in detail
    ee = _copy_with(bundles["random"], tmp_path / "ee", edit_run=lambda run: run | {"control": "ee_delta"})
    assert _failed(ee) == {
        "record": "run.json's control is ee_delta, a run in provenance.json ran with joint"
    }
    # --policy.name is what the rows carry: run.json naming another one fails.
    renamed = _copy_with(
        bundles["random"], tmp_path / "renamed", edit_run=lambda run: run | {"policy_name": "x"}
    )
    assert (
        "27 rows name policy 'random', run.json's policy 'random' names its rows 'x'"
        in _failed(renamed)["record"]
    )


def test_the_board_replays_5_percent_at_95_by_default_and_replay_0_turns_it_off():
    from roboview.eval.campaign.board import Replay
    from roboview.pipelines._cli import parse, replay_flag
    from roboview.pipelines.leaderboard import LeaderboardConfig

    def size(*flags: str) -> int:
        return parse(LeaderboardConfig, replay_flag(["--results=a,b", *flags])).replay.size()

    assert size() == 59 and size("--replay=0") == 0 and size("--replay.n=0") == 0
    assert size("--replay=7") == 7 and size("--replay.detect=0.2") == 14
    assert size("--replay.detect=0.01", "--replay.confidence=0.99") == 459
    assert Replay(59).record() | {"guarantee": ""} == {
        "n": 59,
        "detect": 0.05,
        "confidence": 0.9515,
        "guarantee": "",
    }
    assert "nothing replayed (--replay=0)" in Replay(0).words()


def test_make_board_replays_and_its_page_says_what_it_replayed():
    """The Makefile's board target runs the leaderboard with its default replay, the stand-in VLM endpoint still up
    (its bundle can be re-run), and the page in git says what the board re-ran."""
    root = Path(__file__).resolve().parents[3]
    makefile = (root / "Makefile").read_text()
    recipe = makefile.split("\nboard: ")[1].split("\n\n")[0]
    commands = recipe.replace("\\\n", " ").splitlines()
    (board,) = [c for c in commands if "roboview-leaderboard" in c]
    assert "--replay=0" not in board and "--replay.n=0" not in board and "--replay.detect=0 " not in board
    assert "roboview-serve-vlm" in board and board.index("roboview-serve-vlm") < board.index(
        "roboview-leaderboard"
    )
    saved = json.loads((root / "docs/results/board/leaderboard.json").read_text())
    assert saved["replay"]["n"] == 59 and saved["replay"]["detect"] == 0.05
    assert all(e["replayed"] and e["table"] == "ranked" for e in saved["entries"])
    page = (root / "docs/results/board/leaderboard.html").read_text()
    assert (
        "<b>Replayed here</b>: 59 episodes of each bundle" in page
        and "not replayed" not in page.split("<h2>")[0]
    )
