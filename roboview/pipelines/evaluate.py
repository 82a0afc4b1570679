"""Roll out a policy over the frozen benchmark instances and append one row per episode.

    roboview-evaluate --benchmark.path=outputs/benchmark --policy.type=vision \
        --eval.n_repeats=5 --eval.num_workers=2 --output_dir=outputs/eval/vision

Each (instance, repeat) runs once with seed SHA-256(f"{context_id}:{repeat}") — common random
numbers: every value of a context runs repeat r with the same seed; episodes stop early on
success. `--eval.protocol=paper` runs the paper's 5 repeats (10 on the factorial split). Rows go to OUT/episodes.parquet (journalled in OUT/episodes.jsonl as they
finish). Rerunning the same command resumes: finished pairs are skipped, none is duplicated. An episode
that infrastructure ended (a lost policy server, an endpoint outage, a dead worker, a render failure) is
recorded with status infra_error, counted in no rate, run again after the pass (`--eval.max_infra_retries`)
and by a rerun, its new row replacing the old.
"""

from __future__ import annotations

import logging
import os
import time
from collections import defaultdict
from dataclasses import dataclass, field, replace
from pathlib import Path

from tqdm import tqdm

from roboview.benchmark.format import load_benchmark, select_items
from roboview.core.cli_errors import flag_errors
from roboview.eval.running import provenance, videos
from roboview.eval.running.backends import BACKENDS, ClusterLost, run_local, run_ray
from roboview.eval.running.results import EpisodeStore, ResultsError, is_counted, shard_of
from roboview.eval.running.rollout import WorkerSpec, WorkItem
from roboview.pipelines._cli import cli_main
from roboview.policies.base import PolicyConfig, missing_policy_type
from roboview.policies.errors import PolicyUnavailable
from roboview.policies.types import load_policy_types
from roboview.policies.vlm.sgl import SGLConfig
from roboview.sim.cameras import check_image_size
from roboview.tasks import DEFAULT_TASK

log = logging.getLogger(__name__)


@dataclass
class BenchmarkConfig:
    # Benchmark folder written by roboview.pipelines.build_benchmark.
    path: str = "outputs/benchmark"
    # Comma-separated splits to evaluate; empty: every split of the benchmark.
    splits: str = ""
    # Comma-separated values to keep (the `value` column, e.g. red for the baseline color);
    # empty: every value.
    values: str = ""
    # Run even when this machine's conformance check says it renders or simulates the benchmark `different`ly
    # from the machine that built it (roboview.pipelines.verify shows the figures); every row is then marked `different`.
    allow_drift: bool = False

    @property
    def split_list(self) -> list[str] | None:
        return [s.strip() for s in self.splits.split(",") if s.strip()] or None

    @property
    def value_list(self) -> list[str] | None:
        return [v.strip() for v in self.values.split(",") if v.strip()] or None


DEFAULT_IMAGE_SIZE = 224
VIDEO_FPS = 10  # the env's control rate: videos play in real time
# protocol → (repeats for splits not listed (0: n_repeats), per-split repeats)
PROTOCOLS: dict[str, tuple[int, dict[str, int]]] = {"": (0, {}), "paper": (5, {"color_x_camera_pose": 10})}


@dataclass
class EvalConfig:
    # Episodes per instance, every split without its own entry in split_repeats.
    n_repeats: int = 5
    # Per-split repeats overriding n_repeats, comma-separated split=N (e.g. color_x_camera_pose=10).
    # `roboview-plan` says how many a split needs to detect a given bias.
    split_repeats: str = ""
    # paper: the paper's protocol, 5 repeats per single-factor instance and 10 per factorial
    # instance (sets n_repeats and split_repeats; explicit split_repeats entries still win).
    protocol: str = ""
    # Evaluate only the first N instances of each chosen split (fixed order); 0 = all.
    limit: int = 0
    # Evaluate only the first N task contexts of each chosen split, every value of each (a sample
    # that keeps every value, e.g. --eval.contexts=2 for a quick bias profile); 0 = all.
    contexts: int = 0
    # Worker processes (local) or actors (ray).
    num_workers: int = 2
    # Envs per worker, stepped in lockstep: the policy is called once per step on their batch of
    # observations (one model copy per worker, batched forward passes for checkpoints; see docs/evaluation.md,
    # "Fast evaluation"). 1: one env per worker.
    envs_per_worker: int = 1
    # One policy server process holds the only model copy and answers every worker's envs in one batched
    # forward pass per chunk (the GPU layout: many CPU render workers, one GPU model; local backend,
    # chunked checkpoints). See eval/running/policy_server.py and docs/evaluation.md.
    policy_server: bool = False
    # Episode videos (MP4 per observed camera, linked from the report): N (the first N episodes run),
    # failures, all; empty: none. A video episode renders every camera at every step.
    videos: str = ""
    # Render every camera at every step instead of when a policy reads it (same rows; slower): for
    # measuring what lazy rendering saves.
    eager_render: bool = False
    # local (process pool, spawn) or ray.
    backend: str = "local"
    # Address of an existing Ray cluster (host:port of its head); empty starts a local one.
    ray_address: str = ""
    # i/N: run only shard i of N (0 ≤ i < N): the instances whose id hashes to i, every repeat of each, so N
    # machines or CI jobs each run one deterministic slice; `roboview-merge` joins their folders.
    shard: str = ""
    # Write a Rerun recording of every episode to this .rrd file; when it exists (an earlier run's), the new
    # episodes go to NAME-2.rrd, NAME-3.rrd, … and the earlier recording is kept.
    rerun: str = ""
    # Control steps before an episode counts as a failure.
    max_steps: int = 120
    # Episodes ended by infrastructure, not by the policy (a policy server lost mid-episode, an endpoint still
    # failing after its retries, a worker that died, a render failure) are recorded with status infra_error and
    # counted in no rate; after the pass they run again, at most this many times (0: not in this run). Rerunning
    # the same command runs the ones left again.
    max_infra_retries: int = 2
    # Camera image side (pixels); 0: the policy's own (a checkpoint's input size), else 224.
    # A size that disagrees with the checkpoint's fails before any rollout.
    image_size: int = 0
    # Adaptive evaluation (docs/adaptive.md): repeats run in rounds over every instance of a split; from the
    # second round on, a group-sequential likelihood-ratio test stops the split for "bias" (type-I error
    # ≤ alpha over every look), for "no_bias" (a bias of logit SD tau would have shown, at the target power)
    # or at max_repeats. Two-factor splits run their fixed repeats.
    adaptive: bool = False
    # Adaptive: the most rounds (repeats per instance) a split runs before it stops undecided.
    max_repeats: int = 10
    # Adaptive: type-I error of the "bias" verdict, spent over every look at the split.
    alpha: float = 0.05
    # Adaptive: the bias of interest, as the logit SD of the value effects (as in roboview.pipelines.plan).
    tau: float = 0.3
    # Adaptive: power kept against a bias of size tau before a split may stop for "no_bias".
    power: float = 0.8

    # --help lists these fields after the common ones, under these headings.
    help_groups = {
        "advanced --eval.* (speed, scale and recovery; docs/evaluation.md, docs/scaling.md)": (
            "envs_per_worker",
            "policy_server",
            "eager_render",
            "backend",
            "ray_address",
            "shard",
            "rerun",
            "max_infra_retries",
        ),
        "adaptive evaluation, --eval.adaptive=true (docs/adaptive.md)": (
            "adaptive",
            "max_repeats",
            "alpha",
            "tau",
            "power",
        ),
    }

    def __post_init__(self) -> None:
        if self.image_size:  # 0: the policy's own size
            check_image_size(self.image_size, "--eval.image_size", why="or 0 for the policy's own size")
        for name in ("n_repeats", "num_workers", "max_steps", "envs_per_worker"):
            if getattr(self, name) <= 0:
                raise ValueError(f"--eval.{name}={getattr(self, name)} must be a positive count")
        if self.limit < 0:
            raise ValueError(f"--eval.limit={self.limit} must be ≥ 0 (0 = every instance)")
        if self.max_infra_retries < 0:
            raise ValueError(
                f"--eval.max_infra_retries={self.max_infra_retries} must be ≥ 0 (0 = no re-run in this run)"
            )
        if self.contexts < 0:
            raise ValueError(f"--eval.contexts={self.contexts} must be ≥ 0 (0 = every context)")
        if self.backend not in BACKENDS:
            raise ValueError(f"unknown --eval.backend={self.backend!r}; allowed: {', '.join(BACKENDS)}")
        if self.rerun and not self.rerun.endswith(".rrd"):
            raise ValueError(f"--eval.rerun={self.rerun!r} must name a .rrd file")
        if self.protocol not in PROTOCOLS:
            raise ValueError(
                f"unknown --eval.protocol={self.protocol!r}; allowed: {', '.join(map(repr, PROTOCOLS))}"
            )
        self.split_repeat_table  # noqa: B018  (parses split_repeats now, so a typo fails before any work)
        self.shard_index  # noqa: B018  (parses shard now)
        if self.shard and self.adaptive:
            raise ValueError(
                f"--eval.shard={self.shard} with --eval.adaptive=true: an adaptive split decides on all of "
                "its instances at once, so it cannot be sharded; drop one of the two"
            )
        self.video_mode  # noqa: B018  (parses videos now)
        if self.adaptive:
            self.design  # noqa: B018  (validates alpha, tau, power, max_repeats)

    @property
    def shard_index(self) -> tuple[int, int] | None:
        """(i, N) of --eval.shard=i/N; None when not sharded."""
        if not self.shard:
            return None
        i, sep, n = self.shard.partition("/")
        if not (sep and i.strip().isdigit() and n.strip().isdigit() and 0 <= int(i) < int(n)):
            raise ValueError(
                f"--eval.shard={self.shard!r} must be i/N with 0 ≤ i < N, e.g. 0/4 (the first of four)"
            )
        return int(i), int(n)

    @property
    def design(self):
        from roboview.eval.statistics.adaptive import Design

        return Design(alpha=self.alpha, tau=self.tau, power=self.power, max_repeats=self.max_repeats)

    @property
    def video_mode(self) -> str | int:
        with flag_errors("--eval.videos"):
            return videos.parse(self.videos)

    @property
    def split_repeat_table(self) -> dict[str, int]:
        """split → repeats as given by --eval.split_repeats."""
        table = {}
        for item in filter(None, (x.strip() for x in self.split_repeats.split(","))):
            name, sep, count = item.partition("=")
            if not sep or not count.strip().isdigit() or int(count) <= 0:
                raise ValueError(f"--eval.split_repeats entry {item!r} must be split=N with N ≥ 1")
            table[name.strip()] = int(count)
        return table

    def repeats_for(self, split: str) -> int:
        """Repeats for `split`: split_repeats entry, else the protocol's, else n_repeats."""
        default, table = PROTOCOLS[self.protocol]
        return {**table, **self.split_repeat_table}.get(split, default or self.n_repeats)


@dataclass
class EvaluateConfig:
    # The benchmark to evaluate, and which of its splits and values.
    benchmark: BenchmarkConfig = field(default_factory=BenchmarkConfig)
    # Required: --policy.type=NAME (no default; `expert` is the privileged scripted expert, a ceiling).
    policy: PolicyConfig = None  # type: ignore[assignment]
    # How many episodes run, and how.
    eval: EvalConfig = field(default_factory=EvalConfig)
    # Folder for episodes.parquet (and its journal); rerun the same command to resume.
    output_dir: str = "outputs/eval"
    # The Semantic Grounding Layer around the policy: --sgl.enable=true (docs/vlm.md).
    sgl: SGLConfig = field(default_factory=SGLConfig)

    def __post_init__(self) -> None:
        if self.policy is None:
            raise ValueError(missing_policy_type())


@dataclass(frozen=True)
class EvaluateResult:
    output_dir: Path
    episodes: int
    new_episodes: int
    success_rate: float
    elapsed_s: float
    # Episodes in the results whose row says infrastructure ended them (not in success_rate; a rerun runs them).
    infra_errors: int = 0

    @property
    def episodes_per_hour(self) -> float:
        return 3600 * self.new_episodes / self.elapsed_s if self.elapsed_s else float("nan")


def resolve_image_size(policy: PolicyConfig, requested: int) -> int:
    """The policy's own image side if it has one (a checkpoint's), else `requested`, else 224."""
    own = policy.input_image_size()
    if own is not None and requested and requested != own:
        raise ValueError(
            f"--eval.image_size={requested} but the checkpoint {policy.checkpoint} was trained on {own}×{own} "
            f"images; drop the flag (the checkpoint's size is used) or pass {own}"
        )
    return own or requested or DEFAULT_IMAGE_SIZE


@dataclass
class Plan:
    """What a run evaluates: the instances per split (after --benchmark.values, --eval.contexts / limit and
    --eval.shard), repeats per split, the adaptive splits, tasks and the image size."""

    version: str
    chosen: dict[str, list]
    repeats: dict[str, int]
    adaptive: set[str]
    tasks: list[str]
    image_size: int

    @property
    def work(self) -> list[WorkItem]:
        return [
            WorkItem(item, r)
            for split, items in self.chosen.items()
            for item in items
            for r in range(self.repeats[split])
        ]


def plan(cfg: EvaluateConfig) -> Plan:
    """Load the benchmark and check every flag against it: anything wrong fails here, before any rollout."""
    with flag_errors("--benchmark.path"):
        bench = load_benchmark(cfg.benchmark.path, cfg.benchmark.split_list)
    policy = cfg.policy
    unknown = [s for s in cfg.eval.split_repeat_table if s not in bench.splits]
    if unknown:
        raise ValueError(
            f"--eval.split_repeats names split(s) {unknown} not being evaluated; "
            f"evaluated: {', '.join(bench.splits)}"
        )
    if cfg.benchmark.value_list:
        present = {i.record["value"] for items in bench.splits.values() for i in items}
        missing = sorted(set(cfg.benchmark.value_list) - present)
        if missing:
            raise ValueError(
                f"--benchmark.values names {missing}, absent from the chosen splits; present: "
                f"{', '.join(sorted(present)[:20])}{' …' if len(present) > 20 else ''}"
            )
        keep = set(cfg.benchmark.value_list)
        bench.splits.update(
            {s: [i for i in items if i.record["value"] in keep] for s, items in bench.splits.items()}
        )
    if cfg.eval.policy_server and not policy.batchable():
        raise ValueError(
            f"--eval.policy_server=true needs a policy with one batched model (a chunked LeRobot "
            f"checkpoint: act, pi0, pi05, smolvla); {policy.type!r} has none: drop the flag"
        )
    if cfg.eval.policy_server and cfg.eval.backend != "local":
        raise ValueError("--eval.policy_server=true runs with --eval.backend=local only")
    adaptive = {
        split
        for split, items in bench.splits.items()
        if cfg.eval.adaptive and items and "|" not in items[0].record["factor"]
    }
    chosen = {
        split: select_items(items, cfg.eval.contexts, cfg.eval.limit) for split, items in bench.splits.items()
    }
    if cfg.eval.shard_index is not None:
        i, n = cfg.eval.shard_index
        chosen = {
            split: [x for x in items if shard_of(x.record["instance_id"], n) == i]
            for split, items in chosen.items()
        }
    return Plan(
        version=bench.version,
        chosen=chosen,
        adaptive=adaptive,
        repeats={
            split: cfg.eval.max_repeats if split in adaptive else cfg.eval.repeats_for(split)
            for split in bench.splits
        },
        tasks=list(dict.fromkeys(i.instance.task for items in bench.splits.values() for i in items)),
        image_size=resolve_image_size(policy, cfg.eval.image_size),
    )


def check_conformance(bench: BenchmarkConfig, version: str) -> dict:
    """The start-of-run conformance check (roboview.benchmark.conformance.gate): `different` stops the run
    before any episode unless --benchmark.allow_drift=true. Returns what provenance records: the verdict, the
    measured drift, the stack this machine runs, and how it differs from the stack that built the benchmark."""
    from roboview.benchmark import conformance

    return conformance.gate(Path(bench.path), version, bench.allow_drift, "--benchmark.allow_drift").record()


def run_info(cfg: EvaluateConfig, p: Plan) -> dict:
    """What run.json records: a rerun into the same folder must ask for exactly this to resume."""
    policy = cfg.policy
    return {
        "benchmark_version": p.version,
        "values": cfg.benchmark.value_list,
        "policy": policy.type,
        "policy_path": policy.checkpoint,
        **({"policy_name": policy.name} if policy.name else {}),
        "policy_options": policy.options(),
        "control": policy.env_control(),
        "n_repeats": p.repeats,
        "max_steps": cfg.eval.max_steps,
        "image_size": p.image_size,
        **(
            {
                "adaptive": {
                    "alpha": cfg.eval.alpha,
                    "tau": cfg.eval.tau,
                    "power": cfg.eval.power,
                    "max_repeats": cfg.eval.max_repeats,
                }
            }
            if cfg.eval.adaptive
            else {}
        ),
        **({"shard": cfg.eval.shard} if cfg.eval.shard else {}),
    }


class Runner:
    """Runs work items on the chosen backend and journals each row as it finishes: videos, the Rerun recording,
    the progress bar with success per split, and where a Ray run's episodes ran (`cluster`, for provenance)."""

    def __init__(self, cfg: EvaluateConfig, p: Plan, store: EpisodeStore, total: int) -> None:
        self.cfg, self.plan, self.store = cfg, p, store
        self.conformance = ""  # the start-of-run conformance verdict, written into every row
        self.mode = cfg.eval.video_mode
        self.rerun = None
        if cfg.eval.rerun:
            from roboview.eval.running.rerun_log import RerunLogger

            self.rerun = RerunLogger(Path(cfg.eval.rerun))
        # CPU inference: split the cores between workers so num_workers × threads never oversubscribes.
        self.threads = max(1, (os.cpu_count() or 1) // cfg.eval.num_workers)
        self.cluster: dict[str, dict] = {}
        self.per_split: dict[str, list[int]] = defaultdict(lambda: [0, 0])
        self.policy_name: str | None = None  # the rows' policy name, for the rows of workers that died
        for row in filter(is_counted, store.rows.values()):
            self.per_split[row["split"]][0] += row["success"]
            self.per_split[row["split"]][1] += 1
            self.policy_name = row.get("policy") or self.policy_name
        done = sum(store.done(w.key) for w in p.work)
        self.bar = tqdm(
            total=total, initial=done, desc=f"eval {cfg.policy.type}", unit="ep", dynamic_ncols=True
        )
        self.new = self.started = 0

    def streams(self, todo: list[WorkItem]):
        """One pool per task (each worker holds one task's env and the policy), tasks one after another."""
        cfg = self.cfg
        for task in self.plan.tasks or [DEFAULT_TASK]:
            spec = WorkerSpec(
                cfg.policy,
                self.plan.image_size,
                cfg.eval.max_steps,
                record_media=self.rerun is not None,
                torch_threads=self.threads,
                task=task,
                envs_per_worker=cfg.eval.envs_per_worker,
                videos_of_failures_only=self.mode == "failures",
                eager=cfg.eval.eager_render,
                policy_server=cfg.eval.policy_server,
            )
            items = [w for w in todo if w.item.instance.task == task]
            if not items:
                continue
            if cfg.eval.backend == "ray":
                inner = run_ray(
                    spec,
                    items,
                    cfg.eval.num_workers,
                    cfg.eval.ray_address or None,
                    stats=self.cluster.setdefault(task, {}),
                )
            else:
                inner = run_local(spec, items, cfg.eval.num_workers)
            try:
                yield from inner
            finally:
                inner.close()

    def execute(self, todo: list[WorkItem]) -> None:
        """Run `todo`, journalling each row as it finishes (videos for the episodes `--eval.videos` films); then
        run those that infrastructure ended again, at most `--eval.max_infra_retries` times."""
        if self.mode:
            todo = [
                WorkItem(w.item, w.repeat, video=videos.filmed(self.mode, self.started + i))
                for i, w in enumerate(todo)
            ]
        self.started += len(todo)
        self._pass(todo)
        retries = self.cfg.eval.max_infra_retries
        for attempt in range(1, retries + 1):
            again = [w for w in todo if self.store.infra_error(w.key)]
            if not again:
                break
            reason = self.store.rows[again[0].key]["failure_reason"]
            log.warning(
                "%d episode(s) ended by infrastructure, not by the policy (e.g. %s); running them again "
                "(%d/%d)",
                len(again),
                reason,
                attempt,
                retries,
            )
            self._pass(again)

    def _pass(self, todo: list[WorkItem]) -> None:
        stream = self.streams(todo)
        try:
            for _, result in stream:
                self.record(result)
        finally:
            stream.close()

    def record(self, result) -> None:
        row = result.row
        if row.get("policy") is None:  # a worker that died running it could not say its name
            row["policy"] = self.policy_name or self.cfg.policy.name or self.cfg.policy.type
        if result.video:  # written before the row is journalled: a listed video exists
            paths = [videos.relative_path(row, cam) for cam in result.video]
            for path, frames in zip(paths, result.video.values()):
                videos.write_mp4(Path(self.cfg.output_dir) / path, frames, VIDEO_FPS)
            row["video"] = ",".join(paths)
        row["conformance"] = self.conformance
        self.store.add(row)
        self.new += 1
        if not is_counted(row):  # not done: it runs again, and counts in no rate
            return
        self.policy_name = row["policy"]
        if self.rerun is not None:
            self.rerun.log_episode(result)
        stats = self.per_split[row["split"]]
        stats[0] += row["success"]
        stats[1] += 1
        self.bar.update(1)
        self.bar.set_postfix({s: f"{k / n:.0%}" for s, (k, n) in self.per_split.items()})

    def close(self) -> None:
        self.bar.close()
        self.store.close()
        if self.rerun is not None:
            self.rerun.close()


def run(cfg: EvaluateConfig) -> EvaluateResult:
    cfg = replace(cfg, policy=cfg.sgl.wrap(cfg.policy))  # the SGL's endpoint is checked here
    p = plan(cfg)
    conformance = check_conformance(cfg.benchmark, p.version)
    with flag_errors("--output_dir"):
        store = EpisodeStore(Path(cfg.output_dir), run_info(cfg, p))
    work = p.work
    entry = provenance.start_entry(p.version, cfg.policy.checkpoint)
    entry["benchmark_path"] = str(Path(cfg.benchmark.path).resolve())
    entry["conformance"] = conformance
    entry["control"] = cfg.policy.env_control()
    verdict = conformance["verdict"]
    if cfg.policy.served_by() is not None:
        entry["policy_server"] = cfg.policy.served_by()
    provenance.record(Path(cfg.output_dir), entry)
    log.info(
        "%d episodes planned%s, %d already done",
        len(work),
        " at most (adaptive)" if p.adaptive else "",
        sum(store.done(w.key) for w in work),
    )
    runner = Runner(cfg, p, store, len(work))
    runner.conformance = verdict
    t0 = time.perf_counter()
    try:
        if p.adaptive:
            run_rounds(cfg, p.chosen, p.repeats, p.adaptive, store, runner.execute, runner.bar)
        else:
            runner.execute([w for w in work if not store.done(w.key)])
    except KeyboardInterrupt as exc:  # Ctrl-C: cli_main ends with this line instead of a traceback
        from roboview.pipelines._cli import interrupted

        n = len(store.rows)
        raise interrupted(
            exc, f"{n} episode{'s' * (n != 1)} saved in {cfg.output_dir}; rerun the same command to resume"
        ) from exc
    finally:
        runner.close()
        provenance.record(
            Path(cfg.output_dir),
            entry
            | {"ended": provenance.now(), "episodes_run": runner.new}
            | ({"ray": _merge_cluster(runner.cluster)} if runner.cluster else {}),
        )
    total = len(store.rows)
    kept = [r for r in store.rows.values() if is_counted(r)]
    successes = sum(r["success"] for r in kept)
    return EvaluateResult(
        Path(cfg.output_dir),
        total,
        runner.new,
        successes / len(kept) if kept else float("nan"),
        time.perf_counter() - t0,
        infra_errors=total - len(kept),
    )


def run_rounds(
    cfg: EvaluateConfig,
    chosen: dict[str, list],
    repeats: dict[str, int],
    adaptive: set[str],
    store: EpisodeStore,
    execute,
    bar,
) -> None:
    """Adaptive evaluation: round r runs repeat r of every instance of the splits still running (and of the
    fixed splits); before each round the splits' test decides who stops. A rerun recomputes the same
    decisions from the rows already written, so it resumes mid-split where it stopped."""
    from roboview.eval.statistics.adaptive import decide_split, write_record

    design = cfg.eval.design
    out = Path(cfg.output_dir)
    active = set(adaptive)
    records: dict[str, dict] = {}
    for r in range(design.max_repeats + 1):
        for split in sorted(active):
            # Rows infrastructure ended (still so after their re-runs) enter no decision.
            rows = [
                row
                for item in chosen[split]
                for rep in range(r)
                if (row := store.rows.get((item.record["instance_id"], rep))) is not None and is_counted(row)
            ]
            decision = decide_split(rows, r, design)
            if decision.stopped:
                records[split] = decision.record(len(rows))
                active.discard(split)
                bar.total -= len(chosen[split]) * (design.max_repeats - r)
                bar.refresh()
                log.info(
                    "split %s: stopped after %d round(s): %s (LRT %s)",
                    split,
                    r,
                    decision.stopped,
                    "—" if decision.statistic is None else f"{decision.statistic:.1f}",
                )
                write_record(out, design, records)
        if r == design.max_repeats:
            break
        execute(
            [
                WorkItem(item, r)
                for split, items in chosen.items()
                for item in items
                if (split in active or (split not in adaptive and r < repeats[split]))
                and not store.done((item.record["instance_id"], r))
            ]
        )
    execute(
        [
            WorkItem(item, rep)
            for split, items in chosen.items()
            if split not in adaptive
            for item in items
            for rep in range(design.max_repeats, repeats[split])
            if not store.done((item.record["instance_id"], rep))
        ]
    )


def _merge_cluster(per_task: dict[str, dict]) -> dict:
    """The Ray run's record: cluster address, episodes per node id, actors lost (summed over tasks)."""
    nodes: dict[str, int] = {}
    for stats in per_task.values():
        for node, n in stats.get("nodes", {}).items():
            nodes[node] = nodes.get(node, 0) + n
    first = next(iter(per_task.values()))
    return {
        "address": first.get("address"),
        "nodes": nodes,
        "lost_actors": sum(s.get("lost_actors", 0) for s in per_task.values()),
    }


def rate_text(result: EvaluateResult) -> str:
    """ "N new, SR x%, R episodes/h"; a rerun with nothing left to run says so instead of printing 0/h or nan."""
    sr = "SR —" if result.success_rate != result.success_rate else f"SR {result.success_rate:.1%}"
    if not result.new_episodes:
        return f"already complete, nothing new to run; {sr}"
    return f"{result.new_episodes} new, {sr}, {result.episodes_per_hour:.0f} episodes/h"


def summary(cfg: EvaluateConfig, result: EvaluateResult) -> None:
    """The line the command prints when it ends: episodes, where, the rate, infrastructure errors."""
    infra = (
        f"; {result.infra_errors} ended by infrastructure errors (status infra_error), counted in no rate: "
        "rerun the same command to re-run them"
        if result.infra_errors
        else ""
    )
    policy = cfg.policy.name or cfg.policy.type
    if cfg.policy.privileged:
        policy += " (privileged: reads the simulator state; a ceiling, not a policy's result)"
    print(
        f"[evaluate] {result.episodes} episodes of {policy} in {result.output_dir / 'episodes.parquet'} "
        f"({rate_text(result)}{infra})"
    )
    if cfg.eval.rerun:
        from roboview.eval.running.rerun_log import recordings

        files = recordings(cfg.eval.rerun)
        print(
            f"[evaluate] Rerun recording{'s' if len(files) > 1 else ''} of {cfg.eval.rerun}: "
            + (f"rerun {' '.join(map(str, files))}" if files else "none yet (no episode was recorded)")
        )


def main(args: list[str] | None = None) -> EvaluateResult:
    # Builtin and plugin policy types load first, so --policy.type can name any of them.
    from roboview.benchmark.conformance import ConformanceError

    return cli_main(
        EvaluateConfig,
        run,
        summary,
        (ValueError, ResultsError, ClusterLost, PolicyUnavailable, ConformanceError),
        args,
        before_parse=load_policy_types,
    )


if __name__ == "__main__":
    main()
