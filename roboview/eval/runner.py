"""The evaluation runner: a plan checked against the benchmark before any episode (`plan`), the start-of-run
conformance check, the worker pool or Ray cluster streaming rows into the results folder (`Runner`), resume,
infrastructure retries and adaptive rounds (`run_rounds`). `roboview-evaluate` parses flags and calls `run`."""

from __future__ import annotations

import logging
import os
import time
from collections import defaultdict
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

from tqdm import tqdm

from roboview.benchmark.format import load_benchmark, select_items
from roboview.core.cli_errors import flag_errors
from roboview.core.workers import threads_per_worker
from roboview.eval.config import DEFAULT_IMAGE_SIZE, VIDEO_FPS, BenchmarkConfig, EvaluateConfig
from roboview.eval.running import provenance, videos
from roboview.eval.running.backends import run_local, run_ray
from roboview.eval.running.results import EpisodeStore, is_counted, shard_of
from roboview.eval.running.rollout import WorkerSpec, WorkItem
from roboview.policies.base import PolicyConfig
from roboview.policies.fit import fit_policy
from roboview.tasks import DEFAULT_TASK, load_task
from roboview.tasks.repetition import Repetition, check_repeats

log = logging.getLogger(__name__)


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
    --eval.shard), repeats per split, the adaptive splits, tasks, the image size, and per task whose repeats advance
    a context factor (LIBERO's init state) the rule (run.json records it)."""

    version: str
    chosen: dict[str, list]
    repeats: dict[str, int]
    adaptive: set[str]
    tasks: list[str]
    image_size: int
    repetition: dict[str, Repetition] = field(default_factory=dict)

    @property
    def work(self) -> list[WorkItem]:
        return [
            WorkItem(item, r)
            for split, items in self.chosen.items()
            for item in items
            for r in range(self.repeats[split])
        ]


def follow_protocol(cfg: EvaluateConfig, bench) -> None:
    """--eval.protocol: a protocol the benchmark declares, covering every chosen split, sets the run's repeats."""
    from roboview.benchmark.protocols import choose

    protocol = choose(bench.protocols, cfg.eval.protocol)
    outside = [s for s in bench.splits if s not in protocol.splits]
    if outside:
        raise ValueError(
            f"--eval.protocol={protocol.name} does not cover split(s) {', '.join(outside)}; it covers "
            f"{', '.join(protocol.splits)}"
        )
    if cfg.benchmark.value_list:
        raise ValueError(
            f"--eval.protocol={protocol.name} covers every value of a split; drop --benchmark.values "
            "(or the protocol: such a run is not ranked on a board)"
        )
    cfg.eval.follow(protocol)


def plan(cfg: EvaluateConfig) -> Plan:
    """Load the benchmark and check every flag against it: anything wrong fails here, before any rollout."""
    with flag_errors("--benchmark.path"):
        bench = load_benchmark(cfg.benchmark.path, cfg.benchmark.split_list)
    policy = cfg.policy
    if cfg.eval.protocol:
        follow_protocol(cfg, bench)
    unknown = [s for s in cfg.eval.split_repeat_table if s not in bench.splits and not cfg.eval.protocol]
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
    tasks = list(dict.fromkeys(i.instance.task for items in bench.splits.values() for i in items))
    fit_policy(policy, tasks, (i.instance for items in chosen.values() for i in items))
    repeats = {s: cfg.eval.max_repeats if s in adaptive else cfg.eval.repeats_for(s) for s in bench.splits}
    with flag_errors("--eval.max_repeats" if adaptive else "--eval.n_repeats"):
        rules = check_repeats([(i.instance, i.repetition, repeats[s]) for s in chosen for i in chosen[s]])
    image_size = resolve_image_size(policy, cfg.eval.image_size)
    return Plan(bench.version, chosen, repeats, adaptive, tasks, image_size, rules)


def probe_policy(cfg: EvaluateConfig, p: Plan) -> None:
    """Pre-flight for a policy whose protocol declares nothing of what it answers (an openpi server, a vla-eval
    server with a `raw` action spec): one step of the first instance through the evaluation's own path. Anything but
    a clean step (an action of the wrong width, a model that raises, a server that drops) is a wrong setup: it
    stops the run here, named, before any episode is counted."""
    from roboview.eval.running.rollout import EvalWorker, WorkerSpec, WorkItem

    policy = cfg.policy
    items = next((items for items in p.chosen.values() if items), None)
    if policy.declares_outputs() or items is None:
        return
    worker = EvalWorker(WorkerSpec(policy, p.image_size, max_steps=1, task=items[0].instance.task))
    try:
        row = worker.run(WorkItem(items[0], 0)).row
    finally:
        worker.close()
    reason = row.get("failure_reason") or ""
    if row["status"] == "ok" and (row["success"] or reason.endswith("within 1 steps")):
        return
    raise ValueError(
        f"pre-flight: one step of {items[0].record['instance_id']} with --policy.type={policy.type} failed, so no "
        f"episode was run: {reason}"
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
        # The benchmark's protocol the run claims (--eval.protocol); "": none, the flags' repeats.
        "protocol": cfg.eval.protocol,
        "values": cfg.benchmark.value_list,
        "policy": policy.type,
        # Whether the policy type reads the simulator state (PolicyConfig.privileged): boards rank it apart.
        "privileged": policy.privileged,
        "policy_path": policy.checkpoint,
        **({"policy_name": policy.name} if policy.name else {}),
        "policy_options": policy.options(),
        "control": policy.env_control(),
        "n_repeats": p.repeats,
        **({"repetition": {t: asdict(r) for t, r in p.repetition.items()}} if p.repetition else {}),
        "max_steps": max_steps(cfg, p.tasks),
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


def max_steps(cfg: EvaluateConfig, tasks: list[str]) -> int | None:
    """The step budget run.json records: --eval.max_steps, else the tasks' own (None where it is per context)."""
    if cfg.eval.max_steps:
        return cfg.eval.max_steps
    budgets = {load_task(task).default_steps() for task in tasks or [DEFAULT_TASK]}
    return None if None in budgets else max(budgets)


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
        # CPU inference: the free cores split between workers, so num_workers × threads never oversubscribes.
        self.threads = threads_per_worker(cfg.eval.num_workers, cfg.eval.torch_threads)
        log.info("inference threads per worker: %d (--eval.torch_threads)", self.threads)
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
                cfg.eval.max_steps or load_task(task).default_steps(),
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
    probe_policy(cfg, p)
    with flag_errors("--output_dir"):
        store = EpisodeStore(Path(cfg.output_dir), run_info(cfg, p))
    work = p.work
    entry = provenance.start_entry(p.version, cfg.policy.checkpoint)
    entry |= {"benchmark_path": str(Path(cfg.benchmark.path).resolve()), "conformance": conformance}
    # What the episodes ran with, as run.json records it too: roboview-verify holds the two to each other.
    entry |= {k: store.run_info[k] for k in ("control", "image_size", "max_steps")}
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
    entry["torch_threads"] = {"per_worker": runner.threads, "load_average_1m": round(os.getloadavg()[0], 2)}
    t0 = time.perf_counter()
    try:
        if p.adaptive:
            run_rounds(cfg, p.chosen, p.repeats, p.adaptive, store, runner.execute, runner.bar)
        else:
            runner.execute([w for w in work if not store.done(w.key)])
    except KeyboardInterrupt as exc:  # Ctrl-C: cli_main ends with this line instead of a traceback
        from roboview.core.cli import interrupted

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
            rows = _counted_rows(chosen[split], r, store)
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


def _counted_rows(items: list, rounds: int, store: EpisodeStore) -> list[dict]:
    """The rows of `items`' first `rounds` repeats that count: rows infrastructure ended (still so after their
    re-runs) enter no decision."""
    return [
        row
        for item in items
        for rep in range(rounds)
        if (row := store.rows.get((item.record["instance_id"], rep))) is not None and is_counted(row)
    ]


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
