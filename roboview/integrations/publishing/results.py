"""A verified result bundle on the Hub. Staging verifies the results (refused, with every failed check, unless
each passes) and writes the bundle folder: the results, their report, verify.json, a dataset card and
bundle.json (the SHA-256 of every file); with a model repo, also the `.eval_results` file opened there as a pull
request. The upload sends the staged folder as it is."""

from __future__ import annotations

import datetime
import json
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from roboview.benchmark.format import MANIFEST
from roboview.eval.reporting import bundle, eval_results
from roboview.eval.reporting.report import HTML_FILE, REPORT_FILE, load_results, write_report
from roboview.eval.running import provenance
from roboview.eval.running.results import PARQUET, RUN_FILE, counted, is_privileged_run
from roboview.eval.verification import Report, benchmark_path, verify_results
from roboview.integrations.publishing.hub import PublishError, hub_api


@dataclass(frozen=True)
class BundleRepos:
    """Where a bundle goes on the Hub: its dataset repo, the benchmark's dataset repo named in the card and the
    `.eval_results` entries, and the model repo whose `.eval_results` file it fills (None: none)."""

    repo_id: str
    benchmark_repo_id: str | None = None
    model_repo_id: str | None = None

    @property
    def eval_results_path(self) -> str:
        """The `.eval_results` file's path in the model repo."""
        return f".eval_results/{eval_results.eval_results_name(self.benchmark_repo_id or 'x/roboview')}"


@dataclass(frozen=True)
class StagedBundle:
    """A bundle folder ready to upload: its bundle.json, and the `.eval_results` text and the file it was written to
    beside the folder (None without a model repo)."""

    folder: Path
    manifest: dict[str, Any]
    eval_results: str | None
    eval_results_file: Path | None = None


def stage_bundle(
    results: Path,
    repos: BundleRepos,
    benchmark: str | None = None,
    staging: Path | None = None,
    per_value: bool = False,
) -> StagedBundle:
    """Verify `results` against `benchmark` (default: the one their provenance names) and write the bundle to
    `staging` (default: `<results>_bundle`, replaced if it exists); with a model repo, its `.eval_results` file
    beside it (`per_value`: an entry per value too). PublishError, with every failed check, for results that do not
    verify, and for results of several policies."""
    verified = verify_results(results, benchmark)
    failed = [c for c in verified.checks if not c.passed]
    if failed:
        raise PublishError(
            f"{results} does not verify, so it is not published: "
            + "; ".join(f"{c.name}: {c.detail}" for c in failed)
            + " (roboview-verify --results=... prints every check)"
        )
    episodes, sources = load_results([results / PARQUET])
    policy = _one_policy(results, episodes)
    staging = _fresh_staging(results, staging or results.with_name(results.name + "_bundle"))
    bundle.copy_results(results, staging)
    report = write_report(episodes, staging / bundle.REPORT_DIR, sources=sources)
    assert (report.output_dir / HTML_FILE).is_file()
    entries = provenance.read(results)
    identity = _identity(policy, episodes, repos, benchmark_path(results, benchmark))
    checks = _write_verify(staging, verified, entries, identity)
    (staging / bundle.CARD_FILE).write_text(
        bundle.card(
            policy=policy,
            repo_id=repos.repo_id,
            identity=identity,
            checks=checks,
            report_md=(report.output_dir / REPORT_FILE).read_text(),
            privileged=is_privileged_run(json.loads((results / RUN_FILE).read_text())),
        )
    )
    written = bundle.write_manifest(staging, identity)
    if not repos.model_repo_id:
        return StagedBundle(staging, written, None)
    version = identity["benchmark_version"]
    path = _write_eval_results(staging, repos, report.metrics, entries, version, per_value)
    return StagedBundle(staging, written, path.read_text(), path)


def _one_policy(results: Path, episodes: pd.DataFrame) -> str:
    policies = sorted(map(str, counted(episodes)["policy"].unique()))
    if len(policies) != 1:
        raise PublishError(
            f"{results} holds several policies ({', '.join(policies)}); publish one per bundle"
        )
    return policies[0]


def _fresh_staging(results: Path, staging: Path) -> Path:
    """`staging` emptied and made, after checking it lies outside the results folder."""
    if staging.resolve() == results.resolve() or results.resolve() in staging.resolve().parents:
        raise PublishError(f"--staging_dir={staging} must lie outside the results folder {results}")
    if staging.exists():
        shutil.rmtree(staging)
    staging.mkdir(parents=True)
    return staging


def _identity(policy: str, episodes: pd.DataFrame, repos: BundleRepos, bench_root: Path) -> dict[str, Any]:
    """What the bundle is: its policy, the benchmark (repo, version, content hash), its episodes, its stacks."""
    manifest = json.loads((bench_root / MANIFEST).read_text())
    return {
        "policy": policy,
        "benchmark_repo_id": repos.benchmark_repo_id,
        "benchmark_version": manifest["benchmark_version"],
        "benchmark_content_hash": bundle.content_hash(manifest),
        "episodes": int(counted(episodes).shape[0]),
        "conformance": sorted(set(pd.Series(episodes.get("conformance", [])).dropna().astype(str))),
    }


def _write_verify(staging: Path, verified: Report, entries: list[dict], identity: dict) -> list[dict]:
    """verify.json: every check (all passed), the runs' simulation stacks and the identity; the checks."""
    record = verified.record(
        unreplayed="not replayed when the bundle was staged"
    )  # staging re-runs no episode
    record["stacks"] = [e["conformance"] for e in entries if e.get("conformance")]
    checks = record["checks"]
    (staging / bundle.VERIFY_FILE).write_text(json.dumps(record | identity, indent=2, default=str) + "\n")
    return checks


def _write_eval_results(
    staging: Path, repos: BundleRepos, metrics: dict, entries: list[dict], version: str, per_value: bool
) -> Path:
    """The model repo's `.eval_results` file (roboview.eval.reporting.eval_results: an entry per split and per
    control arm, with `per_value` per value too, each at the benchmark's version: the tag its release carries),
    written to `<staging>_eval_results/.eval_results/`, beside the bundle; its path."""
    date = max((e.get("ended") or "" for e in entries), default="") or datetime.datetime.now(
        datetime.UTC
    ).isoformat(timespec="seconds")
    text = eval_results.eval_results_yaml(
        eval_results.eval_result_entries(
            metrics,
            benchmark_repo_id=repos.benchmark_repo_id,
            results_repo_id=repos.repo_id,
            date=date,
            revision=version,
            per_value=per_value,
        )
    )
    target = staging.with_name(staging.name + "_eval_results") / ".eval_results"
    target.mkdir(parents=True, exist_ok=True)
    path = target / eval_results.eval_results_name(repos.benchmark_repo_id)
    path.write_text(text)
    return path


def upload_bundle(staged: StagedBundle, repos: BundleRepos, private: bool = False) -> None:
    """Upload the staged folder as a Hub dataset, and open the `.eval_results` pull request on the model repo
    (PublishError before any change when the hub cannot be used)."""
    api = hub_api()
    manifest = staged.manifest
    api.create_repo(repos.repo_id, repo_type="dataset", private=private, exist_ok=True)
    api.upload_folder(
        folder_path=str(staged.folder),
        repo_id=repos.repo_id,
        repo_type="dataset",
        commit_message=f"RoboView-Bias results of {manifest['policy']} on {manifest['benchmark_version']}",
    )
    if staged.eval_results is not None:
        from huggingface_hub import CommitOperationAdd

        api.create_commit(
            repos.model_repo_id,
            [CommitOperationAdd(repos.eval_results_path, staged.eval_results.encode())],
            commit_message=f"RoboView-Bias eval results ({manifest['benchmark_version']})",
            create_pr=True,
        )
