"""Replay a pair: an episode and its twin under another value of its factor, side by side in one Rerun recording.

    roboview-pair --results=outputs/eval/vision --split=color --value=gold
    roboview-pair --results=outputs/eval/vision --instance=INSTANCE_ID --repeat=0 [--against=red]

An episode is a function of (instance, repeat): the context, the seed and the policy run.json records. Its twin is
the same (context, repeat) with the factor set otherwise: the control arm (the context's all-baseline instance,
every visual factor at its baseline) unless `--against` names another value of the split. Both are re-run here with
the recorded policy and written to one recording (`<output_dir>/<instance>_r<repeat>.rrd`, `rerun FILE` opens it):
each camera the policy saw, its actions, the end effector's path, the outcomes, and the first step where their
actions differ by more than `--tolerance` (where the two episodes part).

`--split --value` picks the value's discordant pairs, the episodes that ended otherwise than their twin (the value's
failures first), `--pairs` of them.

Each replay is compared with its recorded row (success, steps, failure reason). The line printed says whether both
reproduce their rows. Where they do not, it says what the folder records about why: a policy not reproducible from
the episode seed (a served or sampled model), or episodes run on a stack whose conformance was `different`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from roboview.pipelines._cli import BenchmarkPath, cli_main


@dataclass
class PairConfig:
    # A results folder (roboview-evaluate's --output_dir).
    results: str = ""
    # Its benchmark (default: the one its provenance names).
    benchmark: BenchmarkPath = field(default_factory=BenchmarkPath)
    # One episode: its instance id (the `instance_id` column of episodes.parquet).
    instance: str = ""
    # That episode's repeat.
    repeat: int = 0
    # Or a value of a split: the split (the `split` column) whose value's discordant pairs to replay.
    split: str = ""
    # That value (the `value` column).
    value: str = ""
    # How many discordant pairs of --split --value to replay (the value's failures first).
    pairs: int = 1
    # The twin's value, in the same split and context; empty: the control arm (the all-baseline instance).
    against: str = ""
    # Actions part where they differ by more than this (the largest absolute difference of any dimension).
    tolerance: float = 1e-6
    # Folder the recordings go to (empty: <results>/pairs).
    output_dir: str = ""

    def __post_init__(self) -> None:
        if not self.results:
            raise ValueError("--results is required: the results folder whose episodes to replay")
        if self.instance and (self.split or self.value):
            raise ValueError(
                "name one episode (--instance, --repeat) or a split's value (--split, --value), not both"
            )
        if not self.instance and not (self.split and self.value):
            raise ValueError(
                "name one episode (--instance, --repeat), or a split's value (--split and --value go together)"
            )
        if self.repeat < 0 or self.pairs < 1:
            raise ValueError(f"--repeat={self.repeat} must be ≥ 0 and --pairs={self.pairs} ≥ 1")
        if self.tolerance < 0:
            raise ValueError(f"--tolerance={self.tolerance} must be ≥ 0")


def run(cfg: PairConfig) -> list[dict]:
    from roboview.eval.verification.pairs import discordant, load, record, replay_pair
    from roboview.eval.verification.replay import Replayer

    results = Path(cfg.results)
    loaded = load(results, cfg.benchmark.path or None)  # the folder and its benchmark, read once
    if cfg.instance:
        episodes = [(cfg.instance, cfg.repeat)]
    else:
        episodes = discordant(loaded.rows, loaded.bench, cfg.split, cfg.value, cfg.against, cfg.pairs)
        if not episodes:
            twin = cfg.against or "the control arm"
            raise ValueError(
                f"every episode of {cfg.split}={cfg.value} ended as its twin's ({twin}): no pair to replay"
            )
    out = Path(cfg.output_dir) if cfg.output_dir else results / "pairs"
    replayer = Replayer()
    done = []
    try:
        for instance, repeat in episodes:
            pair = replay_pair(
                results,
                instance,
                repeat,
                cfg.against,
                tolerance=cfg.tolerance,
                replayer=replayer,
                loaded=loaded,
            )
            path = record(pair, out / f"{instance}_r{repeat}.rrd")
            done.append({"pair": pair, "recording": str(path)})
    finally:
        replayer.close()
    return done


def _summary(cfg: PairConfig, done: list[dict]) -> None:
    for entry in done:
        pair = entry["pair"]
        ends = [
            f"{s.label} {'succeeds' if s.replayed['success'] else 'fails (' + str(s.replayed['failure_reason']) + ')'} "
            f"in {s.replayed['steps']} steps"
            for s in (pair.value, pair.other)
        ]
        parting = (
            "their actions never differ"
            if pair.parting is None
            else f"their actions part at step {pair.parting} (|Δ| {pair.parting_gap:.3g} > {pair.tolerance:g})"
        )
        print(f"[pair] {pair.value.record['instance_id']} repeat {pair.repeat}: {'; '.join(ends)}; {parting}")
        print(
            "[pair] both replays end as their rows record"
            if pair.faithful
            else "[pair] NOT faithful: " + "; ".join(pair.why)
        )
        for note in pair.why if pair.faithful else ():
            print(f"[pair] note: {note}")
        print(f"[pair] recording: {entry['recording']} (open it with: rerun {entry['recording']})")


def main(args: list[str] | None = None) -> list[dict]:
    return cli_main(PairConfig, run, _summary, args=args)


if __name__ == "__main__":
    main()
