"""The evaluation runner: the plan (roboview.eval.campaign.plan) run on the worker pool or Ray cluster, streaming rows
into the results folder (`Runner`), with resume, infrastructure retries and adaptive rounds
(roboview.eval.campaign.rounds). `roboview-evaluate` parses flags and calls `run`."""

from __future__ import annotations

import logging
import os
import time
from collections import defaultdict
from dataclasses import dataclass, replace
from pathlib import Path

from tqdm import tqdm

from roboview.core.cli_errors import flag_errors
from roboview.eval.campaign.config import VIDEO_FPS, EvaluateConfig
from roboview.eval.campaign.plan import Plan, check_conformance, plan, probe_policy, run_info
from roboview.eval.campaign.rounds import run_rounds
from roboview.eval.running import provenance, videos
from roboview.eval.running.backends import run_local, run_ray
from roboview.eval.running.results import EpisodeStore, is_counted
from roboview.eval.running.rollout import WorkerSpec, WorkItem
from roboview.tasks import DEFAULT_TASK, load_task

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
        # CPU inference: the threads run.json records (plan.inference_threads), so a replay computes as these did.
        self.threads = store.run_info["torch_threads"]
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
    conformance = check_conformance(cfg, p)
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

        n = store.saved()
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
