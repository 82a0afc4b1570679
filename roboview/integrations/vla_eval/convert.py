"""vla-eval's results of a RoboView benchmark → a RoboView results folder (`episodes.parquet`).

    python -m roboview.integrations.vla_eval.convert --results=outputs/vla_eval/RoboView_aggregate.json \
        --benchmark.path=outputs/benchmark --output_dir=outputs/eval/vla_eval [--policy_name=NAME]

`--results` takes what `vla-eval run` writes: its aggregate JSON (`<name>_aggregate.json`), its SQLite
recording (`recording-<eval_id>.sqlite`, read through vla-eval's own exporter, e.g. for a sharded run before
`vla-eval export`) or the output folder holding them. Every episode of a `RoboViewBenchmark` entry becomes the
row `roboview.pipelines.evaluate` writes for its (instance, repeat): the instance's record, the episode seed, success,
steps, failure reason, isolation certificate and conformance verdict as the benchmark measured them.

One rule for a crash, as `roboview-evaluate --policy.type=vla_eval` scores it: an episode whose model raised on
its observation (vla-eval's `model_act`) is the policy's failure, counted (a model that crashes on gray cubes
only is biased against gray cubes); its isolation certificate, which vla-eval does not return for an errored
episode, is re-derived by resetting the instance with the episode's seed. Every other error vla-eval recorded
(server unreachable, connection closed, timeout, the environment failing to start or step) is a row with status
`infra_error`, counted in no rate, as in `roboview.pipelines.evaluate`. `provenance.json` records
vla-eval's run (eval id, harness version, model server, config) and the conformance record of each process
that ran episodes; `roboview.pipelines.report` and `roboview.pipelines.verify --results=OUT` read the folder as any other.
"""

from __future__ import annotations

import inspect
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from roboview.benchmark.format import load_benchmark
from roboview.eval.running import provenance
from roboview.eval.running.results import PARQUET, EpisodeStore
from roboview.eval.running.row import INFRA_ERROR, EpisodeRow
from roboview.integrations.vla_eval.benchmark import RoboViewBenchmark

BENCHMARK_CLASS = f"{RoboViewBenchmark.__module__}:{RoboViewBenchmark.__name__}"
# vla-eval's failure phases that are the policy's own: the model raised on this input.
POLICY_PHASES = frozenset({"model_act"})
PARAM_DEFAULTS = {
    name: p.default
    for name, p in inspect.signature(RoboViewBenchmark.__init__).parameters.items()
    if p.default is not inspect.Parameter.empty
}


def read_aggregates(path: Path) -> list[dict]:
    """vla-eval's aggregates from an aggregate JSON, a recording SQLite (vla-eval's exporter) or a folder: the reader
    `roboview.pipelines.audit --format=vla_eval` uses."""
    from roboview.eval.running.harnesses.vla_eval_results import read_results

    return [body for _, body in read_results(path)]


def roboview_entries(aggregates: list[dict]) -> list[dict]:
    """The aggregates of RoboViewBenchmark entries (a config may list other benchmarks too)."""
    ours = [a for a in aggregates if (a.get("config") or {}).get("benchmark") == BENCHMARK_CLASS]
    if not ours:
        names = sorted({(a.get("config") or {}).get("benchmark", "?") for a in aggregates})
        raise ValueError(
            f"the vla-eval results hold no {BENCHMARK_CLASS} entry (they hold: {', '.join(names)})"
        )
    return ours


def episode_row(episode: dict, record: dict, policy: str, verdict: str, isolation: str | None = None) -> dict:
    """The RoboView row of one vla-eval episode (its task fields sit at the top, the result under metrics);
    `verdict`: the conformance verdict of the process that ran it, for an episode that returned no result;
    `isolation`: the re-derived certificate of an episode whose model raised (`POLICY_PHASES`)."""
    metrics = episode.get("metrics") or {}
    common = dict(
        record=record,
        repeat=int(episode["repeat"]),
        # The seed the episode was reset with (roboview-verify checks it is its (context, repeat)'s).
        episode_seed=int(episode["episode_seed"]),
        unit=str(episode.get("episode_unit") or ""),
        duration_s=episode.get("elapsed_sec"),
        policy=policy,
    )
    if episode.get("failure_reason") or "steps" not in metrics:  # vla-eval recorded the episode as errored
        detail = (episode.get("failure_detail") or "").strip().splitlines()
        reason = episode.get("failure_reason") or "no result"
        # The model raised: the policy's failure (vla-eval does not say after how many steps).
        if reason in POLICY_PHASES:
            return EpisodeRow(
                **common,
                success=False,
                steps=int(episode.get("steps") or 0),
                failure_reason="policy error: " + (detail[-1].split("Error: ", 1)[-1] if detail else reason),
                isolation=isolation,
                conformance=verdict,
            ).as_dict()
        return EpisodeRow(
            **common,
            success=False,
            steps=int(episode.get("steps") or 0),
            failure_reason=f"infrastructure error: vla-eval {reason}" + (f": {detail[-1]}" if detail else ""),
            status=INFRA_ERROR,
            conformance=verdict,
        ).as_dict()
    return EpisodeRow(
        **common,
        success=bool(metrics["success"]),
        steps=int(metrics["steps"]),
        failure_reason=metrics["failure_reason"],
        isolation=metrics["isolation"],
        conformance=metrics["conformance"],
    ).as_dict()


def convert(results: Path, benchmark_path: str, output_dir: Path, policy_name: str = "") -> Path:
    """Write the RoboView results folder `output_dir` from vla-eval's `results` of the benchmark at
    `benchmark_path` (empty: the folder its config names); the path of the episodes file written."""
    entries = roboview_entries(read_aggregates(Path(results)))
    params = [PARAM_DEFAULTS | (a["config"].get("params") or {}) for a in entries]
    root = _benchmark_root(benchmark_path, params)
    bench = load_benchmark(root)
    records = {i.record["instance_id"]: i.record for items in bench.splits.values() for i in items}
    episodes = [(a, e) for a in entries for t in a["tasks"] for e in t["episodes"]]
    _check_episodes(episodes, records, bench.version, root)
    _check_same_params(params)
    policy = policy_name or entries[0].get("server_info", {}).get("model_server") or "vla-eval"
    splits = list(dict.fromkeys(e["split"] for _, e in episodes))
    store = EpisodeStore(
        Path(output_dir), _run_info(entries, params[0], results, bench.version, policy, splits)
    )
    verdicts = {
        e.get("sid"): e["metrics"]["conformance"] for _, e in episodes if "conformance" in e["metrics"]
    }
    crashed = [e for _, e in episodes if e.get("failure_reason") in POLICY_PHASES]
    certificates, local = rederive_isolation(crashed, params[0], root)
    crashed_ids = {id(e) for e in crashed}
    for _, episode in episodes:
        verdict = verdicts.get(episode.get("sid")) or (local["verdict"] if id(episode) in crashed_ids else "")
        key = (episode["instance_id"], int(episode["repeat"]))
        store.add(
            episode_row(episode, records[episode["instance_id"]], policy, verdict, certificates.get(key))
        )
    store.close()
    entries_out = provenance_entries(entries, episodes, bench.version, root)
    # This process's own conformance check, or the benchmark named where no episode returned one.
    if local or not entries_out:
        entries_out.append(convert_entry(entries[0], bench.version, root, local, len(crashed)))
    provenance.write(Path(output_dir), entries_out)
    return Path(output_dir) / PARQUET


def rederive_isolation(crashed: list[dict], params: dict, root: str) -> tuple[dict, dict]:
    """The isolation certificate of each episode whose model raised, keyed by (instance id, repeat): the instance
    reset with the episode's seed by the same `RoboViewBenchmark` vla-eval ran, after its conformance check of
    this machine (the record, returned second; empty when nothing crashed)."""
    if not crashed:
        return {}, {}
    names = list(dict.fromkeys(e["split"] for e in crashed))
    kept = ("n_repeats", "contexts", "limit", "cameras", "image_size", "max_steps", "control", "allow_drift")
    bench = RoboViewBenchmark(root, names, send_images=False, **{k: params[k] for k in kept})
    try:
        tasks = {(t["instance_id"], t["repeat"]): t for t in bench.get_tasks()}  # runs the conformance check
        out = {}
        for episode in crashed:
            key = (episode["instance_id"], int(episode["repeat"]))
            bench.reset(tasks[key])
            out[key] = bench.isolation
        return out, bench.conformance
    finally:
        bench.cleanup()


def convert_entry(aggregate: dict, version: str, root: str, conformance: dict, rederived: int) -> dict:
    """Provenance of the conversion itself: the benchmark it was given, and (when it re-derived certificates)
    its own conformance record."""
    return provenance.start_entry(version, None) | {
        "ended": provenance.now(),
        "benchmark_path": str(Path(root).resolve()),
        "conformance": conformance or None,
        "isolation_rederived": rederived,
        "vla_eval": {"eval_id": aggregate.get("eval_id"), "config": aggregate.get("config")},
        "episodes_run": 0,
    }


def _benchmark_root(benchmark_path: str, params: list[dict]) -> str:
    """The benchmark folder to read: `--benchmark.path`, else the first entry's params.benchmark_path."""
    root = benchmark_path or params[0].get("benchmark_path", "")
    if not root or not Path(root).is_dir():
        raise ValueError(
            f"--benchmark.path={root!r}: no such folder; pass the benchmark folder vla-eval ran "
            "(params.benchmark_path)"
        )
    return root


def _check_episodes(episodes: list, records: dict[str, dict], version: str, root: str) -> None:
    """Every episode ran this benchmark version, an instance of it, and its (instance, repeat) once."""
    versions = sorted({str(e.get("benchmark_version")) for _, e in episodes} - {version})
    if versions:
        raise ValueError(
            f"the vla-eval episodes ran benchmark version(s) {', '.join(versions)}; {root} is version "
            f"{version}: pass the benchmark folder they ran"
        )
    unknown = sorted({e["instance_id"] for _, e in episodes if e["instance_id"] not in records})
    if unknown:
        raise ValueError(
            f"{len(unknown)} instance(s) of the vla-eval results are not in {root}: {unknown[:3]}"
        )
    counts = Counter((e["instance_id"], int(e["repeat"])) for _, e in episodes)
    twice = sorted(k for k, n in counts.items() if n > 1)
    if twice:
        raise ValueError(
            f"(instance, repeat) {twice[0]} ran {counts[twice[0]]} times: run the benchmark with "
            "episodes_per_task: 1 (repeats come from params.n_repeats)"
        )


def _check_same_params(params: list[dict]) -> None:
    """The entries share the params a results folder holds once."""
    for name in ("n_repeats", "max_steps", "image_size", "control"):
        if len({p[name] for p in params}) > 1:
            raise ValueError(
                f"the RoboView entries were run with different params.{name}: convert them apart"
            )


def _run_info(
    entries: list[dict], first: dict, results: Path, version: str, policy: str, splits: list[str]
) -> dict:
    """The results folder's run description, as `roboview.pipelines.evaluate` writes it."""
    return {
        "benchmark_version": version,
        "values": None,
        "policy": policy,
        "policy_path": None,
        "policy_options": {
            "source": "vla-eval",
            "results": str(Path(results).resolve()),
            "server_url": (entries[0]["config"].get("server") or {}).get("url"),
            "control": first["control"],
            "cameras": first["cameras"],
        },
        "n_repeats": {split: first["n_repeats"] for split in splits},
        "max_steps": first["max_steps"],
        "image_size": first["image_size"],
    }


def provenance_entries(entries: list[dict], episodes: list, version: str, root: str) -> list[dict]:
    """One entry per process that ran episodes (its conformance record), naming vla-eval's run."""
    base = provenance.start_entry(version, None) | {
        "ended": provenance.now(),
        "benchmark_path": str(Path(root).resolve()),
    }
    out = []
    for aggregate, episode in episodes:
        record = (episode.get("metrics") or {}).get("conformance_record")
        if record is None:
            continue
        out.append(
            base
            | {
                "conformance": record,
                "vla_eval": {
                    "eval_id": aggregate.get("eval_id"),
                    "harness_version": aggregate.get("harness_version"),
                    "created_at": aggregate.get("created_at"),
                    "server_info": aggregate.get("server_info"),
                    "config": aggregate.get("config"),
                    "process": episode.get("sid"),  # vla-eval's id of the process that ran it
                },
                "episodes_run": sum(1 for _, e in episodes if e.get("sid") == episode.get("sid")),
            }
        )
    return out


@dataclass
class BenchmarkFolder:
    # The benchmark folder vla-eval ran (params.benchmark_path); empty: the one its config names.
    path: str = ""


@dataclass
class ConvertConfig:
    # vla-eval's results: <name>_aggregate.json, recording-<eval_id>.sqlite, or vla-eval run's output_dir.
    results: str = ""
    # The benchmark vla-eval ran.
    benchmark: BenchmarkFolder = field(default_factory=BenchmarkFolder)
    # RoboView results folder to write.
    output_dir: str = ""
    # The results' policy column; empty: the model server's class name as vla-eval recorded it.
    policy_name: str = ""

    def __post_init__(self) -> None:
        if not self.results or not Path(self.results).exists():
            raise ValueError(
                f"--results={self.results!r}: no such file or folder (vla-eval run writes "
                "OUTPUT_DIR/<name>_aggregate.json and OUTPUT_DIR/recording-<eval_id>.sqlite)"
            )
        if not self.output_dir:
            raise ValueError("--output_dir is required: the RoboView results folder to write")


def run(cfg: ConvertConfig) -> Path:
    return convert(Path(cfg.results), cfg.benchmark.path, Path(cfg.output_dir), cfg.policy_name)


def main(argv: list[str] | None = None) -> Path:
    from roboview.core.cli import cli_main

    return cli_main(ConvertConfig, run, lambda cfg, path: print(f"[convert] {path}"), args=argv)


if __name__ == "__main__":
    main()
