"""Publish a built benchmark (and optionally a collected LeRobot dataset), or a verified result bundle, to the
Hugging Face hub.

    roboview-publish --path=outputs/benchmark --repo_id=ORG/NAME [--dry_run=true]
    roboview-publish --results=outputs/eval/vision --repo_id=ORG/vision-results [--dry_run=true]
           [--benchmark_repo_id=ORG/BENCH] [--model_repo_id=ORG/MODEL [--results_per_value=true]]

With `--results`: the results folder is verified first (`roboview.pipelines.verify --results`, against `--benchmark.path` or
the benchmark its provenance names) and refused, with the failed checks, unless every check passes. The bundle —
the results, their report, verify.json, a dataset card and bundle.json (the SHA-256 of every file) — is written
to `--staging_dir` (default: `<results>_bundle`) and uploaded as a Hub dataset. `--model_repo_id` also writes the
model repo's `.eval_results/<benchmark>.yaml` in the Hub's layout (roboview.eval.reporting.eval_results: one entry
per factor and one per control arm, each a success rate ×100 with its episodes and interval in the notes, the
bundle as source; `--results_per_value=true` adds one per value), opened as a pull request. `--dry_run=true` writes
the exact folder and the exact `.eval_results` file beside it, and lists what would be uploaded.

Creates the dataset repo if missing, uploads the folder, and tags the upload with the benchmark
version from `benchmark.json`. `--env_repo_id=ORG/NAME` also publishes RoboView as a LeRobot EnvHub env
(`roboview/integrations/lerobot/hub/env.py` and a README pointing it at the benchmark repo). `--dry_run=true` lists exactly what would be uploaded and touches
nothing. Without a token, in offline mode or without network it fails before changing anything.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from roboview.benchmark.format import BUILT, MANIFEST, load_benchmark
from roboview.core.cli_errors import flag_errors
from roboview.integrations.publishing.benchmark import Release, release_plan, upload_release
from roboview.integrations.publishing.hub import Plan, PublishError, folder_files
from roboview.pipelines._cli import BenchmarkPath, cli_main


@dataclass
class PublishConfig:
    # Benchmark folder written by roboview.pipelines.build_benchmark.
    path: str = "outputs/benchmark"
    # Hub dataset repo to push the benchmark to (ORG/NAME).
    repo_id: str = ""
    # List what would be uploaded, and where, without contacting the hub.
    dry_run: bool = False
    # Also upload the contact sheet (HTML + previews; the previews are already in the parquet).
    include_contact_sheet: bool = False
    # Create the repo as private.
    private: bool = False
    # Optionally also push a LeRobot dataset collected by roboview.pipelines.collect (its root folder) ...
    lerobot_root: str | None = None
    # ... to this hub repo (ORG/NAME), through lerobot's own push_to_hub.
    lerobot_repo_id: str | None = None
    # Optionally also publish RoboView as a LeRobot EnvHub env (env.py with make_env, and a README that
    # points it at the benchmark repo) to this hub repo (ORG/NAME).
    env_repo_id: str | None = None
    # A results folder (roboview.pipelines.evaluate --output_dir) to publish as a verified result bundle instead of a
    # benchmark; --path is then not used.
    results: str = ""
    # The benchmark the results are verified against (default: the one their provenance names).
    benchmark: BenchmarkPath = field(default_factory=BenchmarkPath)
    # Where the benchmark is published on the Hub (ORG/NAME): named in the card and in .eval_results.
    benchmark_repo_id: str | None = None
    # Also write this model repo's .eval_results/<benchmark>.yaml (needs --benchmark_repo_id), opened as a PR: one
    # entry per factor and one per control arm.
    model_repo_id: str | None = None
    # With --model_repo_id: also one .eval_results entry per value of each single-factor split (color=blue).
    results_per_value: bool = False
    # Folder the bundle is written to before the upload (default: <results>_bundle); replaced if it exists.
    staging_dir: str | None = None

    def __post_init__(self) -> None:
        for flag, value in (
            ("repo_id", self.repo_id),
            ("lerobot_repo_id", self.lerobot_repo_id),
            ("env_repo_id", self.env_repo_id),
            ("benchmark_repo_id", self.benchmark_repo_id),
            ("model_repo_id", self.model_repo_id),
        ):
            if value is not None and (value.count("/") != 1 or not all(value.split("/"))):
                raise ValueError(f"--{flag}={value!r} must look like ORG/NAME")
        if self.results_per_value and not (self.results and self.model_repo_id):
            raise ValueError(
                "--results_per_value=true needs --results=DIR and --model_repo_id=ORG/MODEL: it adds entries to "
                "the model repo's .eval_results file"
            )
        if self.results:
            from roboview.eval.running.inputs import results_folder_problem

            if problem := results_folder_problem(Path(self.results)):
                raise ValueError(f"--results: {problem}")
            if self.model_repo_id and not self.benchmark_repo_id:
                raise ValueError(
                    "--model_repo_id needs --benchmark_repo_id=ORG/NAME: .eval_results entries name the "
                    "benchmark's Hub dataset"
                )
            return
        manifest = Path(self.path) / MANIFEST
        if not manifest.is_file():
            raise ValueError(
                f"--path={self.path} holds no built benchmark ({MANIFEST} missing); "
                "run roboview.pipelines.build_benchmark first"
            )
        if json.loads(manifest.read_text()).get("status") != BUILT:
            raise ValueError(f"--path={self.path} is a failed build (fairness gate); fix and rebuild first")
        with flag_errors(
            "--path"
        ):  # every cell against the build's checksums: an edited benchmark is not published
            load_benchmark(self.path)
        if (self.lerobot_root is None) != (self.lerobot_repo_id is None):
            raise ValueError("--lerobot_root and --lerobot_repo_id go together")
        if self.lerobot_root is not None and not (Path(self.lerobot_root) / "meta/info.json").is_file():
            raise ValueError(
                f"--lerobot_root={self.lerobot_root} is not a LeRobot dataset (meta/info.json missing)"
            )

    @property
    def release(self) -> Release:
        """The benchmark release these flags describe."""
        return Release(
            Path(self.path),
            self.repo_id,
            self.private,
            self.include_contact_sheet,
            self.lerobot_root,
            self.lerobot_repo_id,
            self.env_repo_id,
        )


def plan(cfg: PublishConfig) -> Plan:
    """Every file the benchmark's release uploads, with its size, and its version tag."""
    return release_plan(cfg.release)


def run(cfg: PublishConfig) -> Plan:
    if not cfg.repo_id:
        raise PublishError("--repo_id=ORG/NAME is required")
    if cfg.results:
        return publish_results(cfg)
    the_plan = plan(cfg)
    if cfg.dry_run:
        for rel, size in the_plan.files:
            print(f"{size:>12,}  {cfg.repo_id}/{rel}")
        for rel, size in the_plan.lerobot_files:
            print(f"{size:>12,}  {cfg.lerobot_repo_id}/{rel}")
        for rel, text in the_plan.env_files.items():
            print(f"{len(text.encode()):>12,}  {cfg.env_repo_id}/{rel}")
        count = len(the_plan.files) + len(the_plan.lerobot_files) + len(the_plan.env_files)
        print(
            f"[dry run] {count} files, "
            f"{the_plan.total_bytes:,} bytes; tag {the_plan.version}; nothing uploaded"
        )
        return the_plan
    upload_release(cfg.release, the_plan)
    print(f"[publish] {cfg.repo_id} tagged {the_plan.version}")
    return the_plan


def publish_results(cfg: PublishConfig) -> Plan:
    """Stage the verified bundle of --results, then list it (--dry_run) or upload it."""
    from roboview.integrations.publishing.results import BundleRepos, stage_bundle, upload_bundle

    repos = BundleRepos(cfg.repo_id, cfg.benchmark_repo_id, cfg.model_repo_id)
    staging = Path(cfg.staging_dir) if cfg.staging_dir else None
    staged = stage_bundle(
        Path(cfg.results), repos, cfg.benchmark.path or None, staging, cfg.results_per_value
    )
    files = folder_files(staged.folder, [])
    the_plan = Plan(cfg.repo_id, staged.manifest["benchmark_version"], files, [], {})
    policy = staged.manifest["policy"]
    if cfg.dry_run:
        for rel, size in files:
            print(f"{size:>12,}  {cfg.repo_id}/{rel}")
        if staged.eval_results is not None:
            size, count = len(staged.eval_results.encode()), len(yaml.safe_load(staged.eval_results))
            print(
                f"{size:>12,}  {cfg.model_repo_id}/{repos.eval_results_path} (pull request): {count} entries, "
                f"written to {staged.eval_results_file}"
            )
        print(
            f"[dry run] result bundle of {policy} in {staged.folder}: {len(files)} files, "
            f"{the_plan.total_bytes:,} bytes; verified; nothing uploaded"
        )
        return the_plan
    upload_bundle(staged, repos, cfg.private)
    print(f"[publish] {cfg.repo_id}: result bundle of {policy} ({len(files)} files)")
    return the_plan


def main(args: list[str] | None = None) -> Plan:
    return cli_main(PublishConfig, run, None, (PublishError,), args)


if __name__ == "__main__":
    main()
