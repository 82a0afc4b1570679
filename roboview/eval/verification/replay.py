"""Replay: re-run a sample of a results folder's episodes here with the policy its run.json records, and require
each to end as its row says.

The sample is drawn at verification time from the verifier's own randomness (`secrets.SystemRandom`), so nothing in
the folder predicts it. Its size follows from the guarantee asked for: to catch, with probability at least
`confidence`, any forgery that changed at least a share `detect` of the rows, n is the smallest with
1 − (1 − detect)^n ≥ confidence (≈ 59 episodes for 5 % at 95 %); drawing without replacement only does better. A
forgery of fewer rows can pass: one changed row of N is caught with probability n / N. Every verification says so.
"""

from __future__ import annotations

import datetime
import json
import math
import secrets
import time

from roboview.eval.running.results import is_counted
from roboview.eval.verification.report import Check, listed

REPLAYED = ("success", "steps", "failure_reason")  # what a replayed episode must reproduce


def replay_size(detect: float, confidence: float) -> int:
    """The smallest n with 1 − (1 − detect)^n ≥ confidence."""
    if not 0 < detect < 1 or not 0 < confidence < 1:
        raise ValueError(
            f"--replay.detect={detect} and --replay.confidence={confidence} must each lie strictly between 0 and 1"
        )
    return math.ceil(math.log(1 - confidence) / math.log(1 - detect))


def guarantee(n: int, total: int, detect: float) -> str:
    """The replay's guarantee in words, for n episodes drawn of `total`."""
    if n >= total:
        return f"all {total} episodes re-run: any changed outcome is caught"
    caught = 1 - (1 - detect) ** n
    return (
        f"{n} of {total} episodes drawn at random here: a forgery of ≥ {detect:.0%} of the rows is caught with "
        f"probability ≥ {caught:.1%}; a smaller one can pass (one changed row: {n / total:.1%})"
    )


def draw_sample(rows: list[dict], n: int, rng=None) -> list[dict]:
    """`n` of the counted rows (infrastructure errors are no results) drawn with `rng` (default: the system's
    randomness, which nothing in the folder predicts)."""
    counted = [r for r in rows if is_counted(r)]
    rng = rng or secrets.SystemRandom()
    return counted if n >= len(counted) else rng.sample(counted, n)


def check_replay(
    rows: list[dict], bench, run: dict, n: int, detect: float, replayer: Replayer | None = None
) -> tuple[Check, dict]:
    """Re-run a random sample of the episodes with the recorded policy; every one must end as its row says.
    Returns the check and what verify.json records (`reproducible`: whether the policy type says a re-run can
    reproduce its episodes; `error`: why the policy could not be rebuilt here). `replayer`: workers kept across
    calls (a board replaying many bundles); default: ones opened and closed here."""
    sample = draw_sample(rows, n)
    total = sum(map(is_counted, rows))
    record = {
        "n": len(sample),
        "detect": detect,
        "confidence": 1 - (1 - detect) ** len(sample) if len(sample) < total else 1.0,
        "drawn_at": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "passed": False,
        "disagreements": [],
    }
    own = replayer is None
    replayer = replayer or Replayer()
    try:
        try:
            policy = replayer.policy(run)
        except Exception as exc:  # any failure to rebuild the policy is the check's answer
            detail = f"cannot rebuild policy {run.get('policy')!r} from run.json: {type(exc).__name__}: {exc}"
            return Check("replay", False, " ".join(detail.split())), record | {"error": detail}
        start = time.perf_counter()
        differ = replayer.rerun(sample, bench, run, policy)
    finally:
        if own:
            replayer.close()
    reproducible = bool(getattr(policy, "reproducible", True))
    record |= {
        "passed": not differ,
        "disagreements": differ,
        "reproducible": reproducible,
        "seconds": round(time.perf_counter() - start, 2),
    }
    words = guarantee(len(sample), total, detect)
    detail = (
        f"{len(sample)} episodes re-run with {run['policy']} in {record['seconds']:.1f} s, each ended as recorded "
        f"({words})"
        if not differ
        else f"{len(differ)} of {len(sample)} re-run episodes end differently from their rows: {listed(differ)}"
        + ("" if reproducible else f" ({run['policy']} is not reproducible from the episode seed)")
    )
    return Check("replay", not differ, detail), record


class Replayer:
    """Policies rebuilt from run.json and the workers that re-run their episodes, each kept for every later sample
    that needs the same one: a heavy policy (a checkpoint, a connection) is loaded once per board, not once per
    bundle or episode. An episode of a policy that reproduces its episodes is re-run once: bundles that claim it
    with the same recorded policy (a copy, a forgery of an honest bundle) are each held to that one re-run."""

    def __init__(self) -> None:
        self._policies: dict[str, object] = {}
        self._workers: dict[tuple, object] = {}
        self._episodes: dict[tuple, dict] = {}
        self.episodes_run = 0  # episodes re-run so far (a re-run shared by several bundles counts once)

    @staticmethod
    def _key(run: dict) -> str:
        keys = ("policy", "policy_options", "policy_path", "policy_name", "control")
        return json.dumps({k: run.get(k) for k in keys}, sort_keys=True, default=str)

    @classmethod
    def _worker_key(cls, run: dict, task: str, record_media: bool) -> tuple:
        threads = int(run.get("torch_threads") or 0)  # the run's own: a CPU policy's actions depend on them
        return (
            cls._key(run),
            run.get("image_size", 224),
            run.get("max_steps", 120),
            threads,
            task,
            record_media,
        )

    def policy(self, run: dict):
        """The policy config run.json records (built once per distinct record)."""
        from roboview.policies.types import recorded_config

        key = self._key(run)
        if key not in self._policies:
            self._policies[key] = recorded_config(run)
        return self._policies[key]

    def worker(self, run: dict, policy, task: str, record_media: bool = False):
        """The worker that re-runs `task`'s episodes with the policy `run` records (built once, kept for every later
        call that needs the same one; `record_media`: keeping frames, paths and actions, as a pair replay does)."""
        from roboview.eval.running.rollout import EvalWorker, WorkerSpec

        key = self._worker_key(run, task, record_media)
        if key not in self._workers:
            _, image_size, max_steps, threads, _, _ = key
            spec = WorkerSpec(
                policy, image_size, max_steps, record_media=record_media, torch_threads=threads, task=task
            )
            self._workers[key] = EvalWorker(spec)
        return self._workers[key]

    def rerun(self, sample: list[dict], bench, run: dict, policy) -> list[str]:
        """Each sampled row's episode again; the rows whose outcome differs, described."""
        from roboview.eval.running.rollout import WorkItem

        items = {i.record["instance_id"]: i for items in bench.splits.values() for i in items}
        reproducible = bool(getattr(policy, "reproducible", True))
        differ = []
        for row in sample:
            item, repeat = items[row["instance_id"]], int(row["repeat"])
            # The instance id names the instance's content: the same id and repeat is the same episode.
            key = (*self._worker_key(run, item.instance.task, False), row["instance_id"], repeat)
            again = self._episodes.get(key) if reproducible else None
            if again is None:
                again = self.worker(run, policy, item.instance.task).run(WorkItem(item, repeat)).row
                self.episodes_run += 1
                if reproducible:
                    self._episodes[key] = again
            changed = [
                f"{k} {row.get(k)!r} → {again.get(k)!r}"
                for k in REPLAYED
                if (row.get(k) or None) != (again.get(k) or None)
            ]
            if changed:
                differ.append(f"{row['instance_id']} repeat {row['repeat']}: {', '.join(changed)}")
        return differ

    def close(self) -> None:
        for worker in self._workers.values():
            worker.close()
        self._workers.clear()
