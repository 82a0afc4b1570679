"""lerobot-eval's `eval_info.json` → a RoboView results folder (`episodes.parquet`) for `pipelines.report`.

    python -m roboview_lerobot.convert --eval_info=OUT/eval_info.json --env.benchmark_path=BENCH \
        [--env.n_repeats=1 --env.contexts=0 --env.limit=0 --env.start_seed=1000] \
        --output_dir=outputs/eval/lerobot_eval [--policy_name=lerobot-eval]

Pass the `--env.*` flags given to lerobot-eval: every split lerobot-eval ran (a `per_task` entry of
eval_info.json) is converted; lerobot's episode i of a split is the split's i-th (instance, repeat) (reset
seed start_seed + i), and its success is that entry's `successes[i]`. lerobot-eval records
no step counts or failure reasons, so those columns say so.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

from eval.results import EpisodeStore
from roboview_data.variation.instances import episode_seed
from roboview_lerobot import RoboViewEnv
from roboview_lerobot.env import episode_plan

NO_REASON = "failed in lerobot-eval (it records no failure reason)"


def successes(eval_info: dict) -> dict[str, list[bool]]:
    """Per-split successes in episode order: eval_info.json's `per_task` entries, one per split (task group)."""
    tasks = eval_info.get("per_task") or []
    if not tasks:
        raise ValueError("eval_info.json holds no per_task entries; is it lerobot-eval's output?")
    out: dict[str, list[bool]] = {}
    for entry in tasks:
        split = entry["task_group"]
        if split in out:
            raise ValueError(f"eval_info.json holds split {split!r} twice; a RoboView split is one task group")
        out[split] = [bool(s) for s in entry["metrics"]["successes"]]
    return out


def convert(eval_info: Path, benchmark_path: str, output_dir: Path, n_repeats: int = 1, contexts: int = 0,
            limit: int = 0, start_seed: int = 1000, policy_name: str = "lerobot-eval", max_steps: int = 120,
            image_size: int = 96) -> Path:
    info = json.loads(Path(eval_info).read_text())
    per_split = successes(info)
    plans = {split: episode_plan(benchmark_path, split, n_repeats, contexts, limit) for split in per_split}
    for split, done in per_split.items():
        if len(done) > len(plans[split][1]):
            raise ValueError(f"eval_info.json has {len(done)} episodes of split {split!r}, which selects "
                             f"{len(plans[split][1])}: run lerobot-eval with --eval.n_episodes at most that")
    version = next(iter(plans.values()))[0]
    store = EpisodeStore(Path(output_dir), {"benchmark_version": version, "policy": policy_name, "policy_path": None,
                                            "policy_options": {"source": str(Path(eval_info).resolve()),
                                                               "start_seed": start_seed},
                                            "n_repeats": {split: n_repeats for split in per_split},
                                            "max_steps": max_steps, "image_size": image_size, "values": None})
    for split, done in per_split.items():
        for (item, repeat), success in zip(plans[split][1], done):
            store.add({**item.record, "repeat": repeat,
                       "episode_seed": episode_seed(item.record["context_id"], repeat), "success": success,
                       "steps": None, "duration_s": None, "policy": policy_name,
                       "failure_reason": "" if success else NO_REASON})
    store.close()
    return Path(output_dir) / "episodes.parquet"


def main(argv: list[str] | None = None) -> Path:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--eval_info", required=True, help="lerobot-eval's OUT/eval_info.json")
    parser.add_argument("--output_dir", required=True, help="RoboView results folder to write")
    parser.add_argument("--policy_name", default="lerobot-eval", help="the results' policy column")
    parser.add_argument("--env.benchmark_path", dest="benchmark_path", required=True, help="as given to lerobot-eval")
    # The plugin config's own defaults, so both tools agree on an omitted flag.
    defaults = {f.name: f.default for f in dataclasses.fields(RoboViewEnv)}
    for flag in ("n_repeats", "contexts", "limit", "start_seed", "max_steps", "image_size"):
        parser.add_argument(f"--env.{flag}", dest=flag, default=defaults[flag], type=int,
                            help=f"as given to lerobot-eval (default {defaults[flag]})")
    args = parser.parse_args(argv)
    if not Path(args.eval_info).is_file():
        parser.error(f"--eval_info={args.eval_info}: no such file (lerobot-eval writes OUT/eval_info.json)")
    path = convert(Path(args.eval_info), args.benchmark_path, Path(args.output_dir), args.n_repeats,
                   args.contexts, args.limit, args.start_seed, args.policy_name, args.max_steps, args.image_size)
    print(f"[convert] {path}")
    return path


if __name__ == "__main__":
    main()
