"""A run's plan, checked against the loaded benchmark before any episode: the instances, repeats, adaptive splits,
tasks and image size (`plan`), the protocol it follows, the one-step pre-flight of a policy that declares nothing
(`probe_policy`), the start-of-run conformance check (`check_conformance`) and what run.json records (`run_info`)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path

from roboview.benchmark.format import Benchmark, load_benchmark, select_items
from roboview.core.cli_errors import flag_errors
from roboview.core.workers import threads_per_worker
from roboview.eval.campaign.config import DEFAULT_IMAGE_SIZE, EvaluateConfig
from roboview.eval.running.results import recorded_threads, shard_of
from roboview.eval.running.rollout import WorkItem
from roboview.eval.running.row import STATUS, STATUS_OK
from roboview.policies.base import PolicyConfig
from roboview.policies.fit import fit_policy
from roboview.tasks import DEFAULT_TASK, load_task
from roboview.tasks.repetition import Repetition, check_repeats


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
    # The benchmark as loaded and checked once: the start-of-run conformance check reads it, not the folder again.
    benchmark: Benchmark | None = None

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
    return Plan(bench.version, chosen, repeats, adaptive, tasks, image_size, rules, bench)


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
    if row[STATUS] == STATUS_OK and (row["success"] or reason.endswith("within 1 steps")):
        return
    raise ValueError(
        f"pre-flight: one step of {items[0].record['instance_id']} with --policy.type={policy.type} failed, so no "
        f"episode was run: {reason}"
    )


def check_conformance(cfg: EvaluateConfig, p: Plan) -> dict:
    """The start-of-run conformance check on the planned benchmark (roboview.benchmark.conformance.gate):
    `different` stops the run before any episode unless --benchmark.allow_drift=true. Returns what provenance
    records: the verdict, the measured drift, the stack this machine runs, and how it differs from the stack that
    built the benchmark."""
    from roboview.benchmark import conformance

    return conformance.gate(p.benchmark, cfg.benchmark.allow_drift, "--benchmark.allow_drift").record()


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
        "torch_threads": inference_threads(cfg),
    }


def inference_threads(cfg: EvaluateConfig) -> int:
    """The intra-op threads of each worker's torch policy, which run.json records so a replay computes with the
    same (they change a CPU policy's actions in the last bits): --eval.torch_threads when given; else the count the
    folder's episodes already ran with (a resume keeps it, whatever the load now); else the cores the load
    average leaves free, split between the workers."""
    return (
        cfg.eval.torch_threads
        or recorded_threads(Path(cfg.output_dir))
        or threads_per_worker(cfg.eval.num_workers, 0)
    )


def max_steps(cfg: EvaluateConfig, tasks: list[str]) -> int | None:
    """The step budget run.json records: --eval.max_steps, else the tasks' own (None where it is per context)."""
    if cfg.eval.max_steps:
        return cfg.eval.max_steps
    budgets = {load_task(task).default_steps() for task in tasks or [DEFAULT_TASK]}
    return None if None in budgets else max(budgets)
