"""Replay: re-run a sample of a results folder's episodes here with the policy its run.json records, and
require each to end as its row says."""

from __future__ import annotations

from roboview.eval.verification.report import Check, listed

REPLAYED = ("success", "steps", "failure_reason")  # what a replayed episode must reproduce


def replay_sample(rows: list[dict], n: int) -> list[dict]:
    """`n` rows in a fixed order (by a hash of instance and repeat): the same sample on every machine."""
    import hashlib

    def key(row: dict) -> str:
        return hashlib.sha256(f"{row['instance_id']}:{row['repeat']}".encode()).hexdigest()

    return sorted((r for r in rows if r.get("status") != "infra_error"), key=key)[:n]


def check_replay(rows: list[dict], bench, run: dict, n: int) -> Check:
    """Re-run a sample of the episodes with the recorded policy; every one must end as its row says."""
    from roboview.eval.running.rollout import EvalWorker, WorkerSpec, WorkItem
    from roboview.policies.types import policy_config

    sample = replay_sample(rows, n)
    try:
        settings = dict(run.get("policy_options") or {})
        if run.get("policy_path"):
            settings["path"] = run["policy_path"]
        if run.get("policy_name"):
            settings["name"] = run["policy_name"]
        policy = policy_config(run["policy"], **settings)
    except Exception as exc:  # any failure to rebuild the policy is the check's answer
        return Check("replay", False, f"cannot rebuild policy {run.get('policy')!r} from run.json: {exc}")
    items = {i.record["instance_id"]: i for items in bench.splits.values() for i in items}
    workers: dict[str, EvalWorker] = {}
    differ = []
    try:
        for row in sample:
            item = items[row["instance_id"]]
            task = item.instance.task
            if task not in workers:
                workers[task] = EvalWorker(
                    WorkerSpec(policy, run.get("image_size", 224), run.get("max_steps", 120), task=task)
                )
            again = workers[task].run(WorkItem(item, int(row["repeat"]))).row
            changed = [
                f"{k} {row.get(k)!r} → {again.get(k)!r}"
                for k in REPLAYED
                if (row.get(k) or None) != (again.get(k) or None)
            ]
            if changed:
                differ.append(f"{row['instance_id']} repeat {row['repeat']}: {', '.join(changed)}")
    finally:
        for worker in workers.values():
            worker.close()
    return Check(
        "replay",
        not differ,
        f"{len(sample)} episodes re-run with {run['policy']}, each ended as recorded"
        if not differ
        else f"{len(differ)} of {len(sample)} re-run episodes end differently from their rows: {listed(differ)}",
    )
