"""Publish a built benchmark (and optionally a collected LeRobot dataset), or a verified result bundle, to the
Hugging Face hub.

    roboview-publish --path=outputs/benchmark --repo_id=ORG/NAME [--dry_run=true]
    roboview-publish --results=outputs/eval/vision --repo_id=ORG/vision-results [--dry_run=true]
           [--benchmark_repo_id=ORG/BENCH] [--model_repo_id=ORG/MODEL]

With `--results`: the results folder is verified first (`roboview.pipelines.verify --results`, against `--benchmark.path` or
the benchmark its provenance names) and refused, with the failed checks, unless every check passes. The bundle —
the results, their report, verify.json, a dataset card and bundle.json (the SHA-256 of every file) — is written
to `--staging_dir` (default: `<results>_bundle`) and uploaded as a Hub dataset. `--model_repo_id` also writes the
model repo's `.eval_results/<benchmark>.yaml` (one entry per split: the success rate, the bundle as source), opened
as a pull request. `--dry_run=true` writes the exact folder and lists what would be uploaded.

Creates the dataset repo if missing, uploads the folder, and tags the upload with the benchmark
version from `benchmark.json`. `--env_repo_id=ORG/NAME` also publishes RoboView as a LeRobot EnvHub env
(`roboview/integrations/lerobot/hub/env.py` and a README pointing it at the benchmark repo). `--dry_run=true` lists exactly what would be uploaded and touches
nothing. Without a token, in offline mode or without network it fails before changing anything.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass, field
from fnmatch import fnmatch
from pathlib import Path
from typing import Any

from roboview.benchmark.format import MANIFEST, load_benchmark
from roboview.core.cli_errors import flag_errors
from roboview.pipelines._cli import BenchmarkPath, cli_main

log = logging.getLogger(__name__)

CONTACT_SHEET = "contact_sheet/*"


class PublishError(RuntimeError):
    """The hub cannot be reached or refuses; nothing was changed."""


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
    # Also write this model repo's .eval_results/<benchmark>.yaml (needs --benchmark_repo_id), opened as a PR.
    model_repo_id: str | None = None
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
        if json.loads(manifest.read_text()).get("status") != "ok":
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


@dataclass(frozen=True)
class Plan:
    repo_id: str
    version: str
    files: list[tuple[str, int]]  # (path in repo, bytes)
    lerobot_files: list[tuple[str, int]]
    env_files: dict[str, str]  # EnvHub repo: path in repo -> text

    @property
    def total_bytes(self) -> int:
        env = sum(len(text.encode()) for text in self.env_files.values())
        return sum(size for _, size in self.files + self.lerobot_files) + env


def _files(root: Path, ignore: list[str]) -> list[tuple[str, int]]:
    out = []
    for p in sorted(root.rglob("*")):
        rel = p.relative_to(root).as_posix()
        if p.is_file() and not any(fnmatch(rel, pattern) for pattern in ignore):
            out.append((rel, p.stat().st_size))
    return out


def plan(cfg: PublishConfig) -> Plan:
    root = Path(cfg.path)
    version = json.loads((root / MANIFEST).read_text())["benchmark_version"]
    ignore = [] if cfg.include_contact_sheet else [CONTACT_SHEET]
    lerobot = _files(Path(cfg.lerobot_root), ["images/*"]) if cfg.lerobot_root else []
    env = env_hub_files(cfg.env_repo_id, cfg.repo_id, version) if cfg.env_repo_id else {}
    return Plan(cfg.repo_id, version, _files(root, ignore), lerobot, env)


def env_hub_files(env_repo_id: str, benchmark_repo_id: str, version: str) -> dict[str, str]:
    """The EnvHub repo: RoboView's env.py (make_env) and a README that points it at the benchmark repo."""
    import roboview.integrations.lerobot

    env_py = (Path(roboview.integrations.lerobot.__file__).parent / "hub" / "env.py").read_text()
    readme = (
        f"---\ntags: [lerobot, envhub, roboview, robot-learning, visual-bias]\n---\n"
        f"# RoboView-Bias ({version}) as a LeRobot EnvHub environment\n\n"
        f"Frozen, factor-isolated splits of the RoboView-Bias benchmark (`{benchmark_repo_id}`).\n"
        "Needs the `roboview` package installed beside lerobot.\n\n"
        "```python\nimport os\nfrom lerobot.envs.factory import make_env\n\n"
        f'os.environ["ROBOVIEW_BENCHMARK"] = "{benchmark_repo_id}"\n'
        'os.environ["ROBOVIEW_TASK"] = "color,camera_pose"\n'
        f'envs = make_env("{env_repo_id}", n_envs=4, trust_remote_code=True)\n```\n\n'
        "Settings: see the docstring of `env.py`.\n"
    )
    return {"env.py": env_py, "README.md": readme}


def _hub_api():
    """An authenticated HfApi, or PublishError saying what is missing (checked before any change)."""
    from huggingface_hub import HfApi, constants, get_token

    if constants.HF_HUB_OFFLINE:
        raise PublishError(
            "offline mode is on (HF_HUB_OFFLINE=1); unset it to publish, "
            "or use --dry_run=true to see what would be uploaded"
        )
    token = get_token()
    if not token:
        raise PublishError(
            "no Hugging Face token: run `huggingface-cli login` or set HF_TOKEN "
            "(use --dry_run=true to see what would be uploaded)"
        )
    api = HfApi(token=token)
    try:
        user = api.whoami()
    except Exception as exc:  # network down, endpoint unreachable, token refused
        raise PublishError(
            f"cannot reach the hub at {constants.ENDPOINT} or the token was refused: "
            f"{type(exc).__name__}: {exc}"
        ) from exc
    log.info("publishing as %s", user.get("name"))
    return api


def publish(cfg: PublishConfig, the_plan: Plan) -> str:
    api = _hub_api()
    api.create_repo(cfg.repo_id, repo_type="dataset", private=cfg.private, exist_ok=True)
    ignore = None if cfg.include_contact_sheet else [CONTACT_SHEET]
    commit = api.upload_folder(
        folder_path=cfg.path,
        repo_id=cfg.repo_id,
        repo_type="dataset",
        ignore_patterns=ignore,
        commit_message=f"RoboView benchmark {the_plan.version}",
    )
    api.create_tag(cfg.repo_id, tag=the_plan.version, repo_type="dataset", exist_ok=True)
    if cfg.env_repo_id:
        from huggingface_hub import CommitOperationAdd

        api.create_repo(cfg.env_repo_id, private=cfg.private, exist_ok=True)
        api.create_commit(
            cfg.env_repo_id,
            [CommitOperationAdd(path, text.encode()) for path, text in the_plan.env_files.items()],
            commit_message=f"RoboView EnvHub env for {cfg.repo_id} {the_plan.version}",
        )
    if cfg.lerobot_root:
        from lerobot.datasets.lerobot_dataset import LeRobotDataset

        LeRobotDataset(cfg.lerobot_repo_id, root=cfg.lerobot_root).push_to_hub(
            tags=["roboview", "franka-panda", "mujoco"], private=cfg.private
        )
    return str(commit)


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
    publish(cfg, the_plan)
    print(f"[publish] {cfg.repo_id} tagged {the_plan.version}")
    return the_plan


# --- a result bundle ----------------------------------------------------------------------------------


def stage_results(cfg: PublishConfig) -> tuple[Path, dict[str, Any], str | None]:
    """Verify the results, write the bundle folder; (folder, manifest, .eval_results text or None).
    PublishError, with every failed check, for results that do not verify."""
    import datetime
    import shutil

    import pandas as pd

    from roboview.eval.reporting import bundle
    from roboview.eval.reporting.report import HTML_FILE, REPORT_FILE, load_results, write_report
    from roboview.eval.running import provenance
    from roboview.eval.running.results import PARQUET, RUN_FILE, counted, is_privileged_run
    from roboview.eval.verification import benchmark_path, verify_results

    results = Path(cfg.results)
    verified = verify_results(results, cfg.benchmark.path or None)
    failed = [c for c in verified.checks if not c.passed]
    if failed:
        raise PublishError(
            f"{results} does not verify, so it is not published: "
            + "; ".join(f"{c.name}: {c.detail}" for c in failed)
            + " (roboview-verify --results=... prints every check)"
        )
    episodes, sources = load_results([results / PARQUET])
    policies = sorted(map(str, counted(episodes)["policy"].unique()))
    if len(policies) != 1:
        raise PublishError(
            f"{results} holds several policies ({', '.join(policies)}); publish one per bundle"
        )
    policy = policies[0]
    staging = Path(cfg.staging_dir) if cfg.staging_dir else results.with_name(results.name + "_bundle")
    if staging.resolve() == results.resolve() or results.resolve() in staging.resolve().parents:
        raise PublishError(f"--staging_dir={staging} must lie outside the results folder {results}")
    if staging.exists():
        shutil.rmtree(staging)
    staging.mkdir(parents=True)
    bundle.copy_results(results, staging)
    report = write_report(episodes, staging / bundle.REPORT_DIR, sources=sources)
    entries = provenance.read(results)
    bench_root = benchmark_path(results, cfg.benchmark.path or None)
    manifest = json.loads((bench_root / MANIFEST).read_text())
    checks = [{"name": c.name, "passed": c.passed, "detail": c.detail} for c in verified.checks]
    identity = {
        "policy": policy,
        "benchmark_repo_id": cfg.benchmark_repo_id,
        "benchmark_version": manifest["benchmark_version"],
        "benchmark_content_hash": bundle.content_hash(manifest),
        "episodes": int(counted(episodes).shape[0]),
        "conformance": sorted(set(pd.Series(episodes.get("conformance", [])).dropna().astype(str))),
    }
    (staging / bundle.VERIFY_FILE).write_text(
        json.dumps(
            {
                "checks": checks,
                "passed": True,
                "stacks": [e["conformance"] for e in entries if e.get("conformance")],
            }
            | identity,
            indent=2,
            default=str,
        )
        + "\n"
    )
    (staging / bundle.CARD_FILE).write_text(
        bundle.card(
            policy=policy,
            repo_id=cfg.repo_id,
            identity=identity,
            checks=checks,
            report_md=(report.output_dir / REPORT_FILE).read_text(),
            privileged=is_privileged_run(json.loads((results / RUN_FILE).read_text())),
        )
    )
    assert (report.output_dir / HTML_FILE).is_file()
    written = bundle.write_manifest(staging, identity)
    eval_results = None
    if cfg.model_repo_id:
        date = max((e.get("ended") or "" for e in entries), default="") or datetime.datetime.now(
            datetime.UTC
        ).isoformat(timespec="seconds")
        eval_results = bundle.eval_results_yaml(
            bundle.eval_result_entries(
                report.metrics,
                benchmark_repo_id=cfg.benchmark_repo_id,
                results_repo_id=cfg.repo_id,
                date=date,
            )
        )
        target = staging.with_name(staging.name + "_eval_results") / ".eval_results"
        target.mkdir(parents=True, exist_ok=True)
        (target / bundle.eval_results_name(cfg.benchmark_repo_id)).write_text(eval_results)
    return staging, written, eval_results


def publish_results(cfg: PublishConfig) -> Plan:
    from roboview.eval.reporting import bundle

    staging, manifest, eval_results = stage_results(cfg)
    files = _files(staging, [])
    the_plan = Plan(cfg.repo_id, manifest["benchmark_version"], files, [], {})
    eval_path = f".eval_results/{bundle.eval_results_name(cfg.benchmark_repo_id or 'x/roboview')}"
    if cfg.dry_run:
        for rel, size in files:
            print(f"{size:>12,}  {cfg.repo_id}/{rel}")
        if eval_results is not None:
            print(f"{len(eval_results.encode()):>12,}  {cfg.model_repo_id}/{eval_path} (pull request)")
        print(
            f"[dry run] result bundle of {manifest['policy']} in {staging}: {len(files)} files, "
            f"{the_plan.total_bytes:,} bytes; verified; nothing uploaded"
        )
        return the_plan
    api = _hub_api()
    api.create_repo(cfg.repo_id, repo_type="dataset", private=cfg.private, exist_ok=True)
    api.upload_folder(
        folder_path=str(staging),
        repo_id=cfg.repo_id,
        repo_type="dataset",
        commit_message=f"RoboView-Bias results of {manifest['policy']} on {manifest['benchmark_version']}",
    )
    if eval_results is not None:
        from huggingface_hub import CommitOperationAdd

        api.create_commit(
            cfg.model_repo_id,
            [CommitOperationAdd(eval_path, eval_results.encode())],
            commit_message=f"RoboView-Bias eval results ({manifest['benchmark_version']})",
            create_pr=True,
        )
    print(f"[publish] {cfg.repo_id}: result bundle of {manifest['policy']} ({len(files)} files)")
    return the_plan


def main(args: list[str] | None = None) -> Plan:
    return cli_main(PublishConfig, run, None, (PublishError,), args)


if __name__ == "__main__":
    main()
