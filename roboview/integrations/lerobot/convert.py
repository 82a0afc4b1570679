"""lerobot-eval's `eval_info.json` → a RoboView results folder (`episodes.parquet`) for `roboview.pipelines.report`.

    python -m roboview.integrations.lerobot.convert --eval_info=OUT/eval_info.json --env.benchmark_path=BENCH \
        [--env.n_repeats=1 --env.contexts=0 --env.limit=0 --env.start_seed=1000] \
        --output_dir=outputs/eval/lerobot_eval [--policy_name=lerobot-eval]

Pass the `--env.*` flags given to lerobot-eval: every split lerobot-eval ran (a `per_task` entry of
eval_info.json) is converted; lerobot's episode i of a split is the split's i-th (instance, repeat) (reset
seed start_seed + i), and its success is that entry's `successes[i]`. lerobot-eval records
no step counts or failure reasons, so those columns say so. eval_info.json's `per_group.<split>` then carries the
split's control arm beside `pc_success` (`sr_control`, `sr_control_ci95`, `n_control_episodes`) and, for a
single-factor split, each value's paired difference to it (`per_value.<v>`: `delta_control`, `delta_control_ci95`,
`n_control_pairs`, `p_control`), as metrics.json has them.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from pathlib import Path

from roboview.eval.running.results import PARQUET, EpisodeStore
from roboview.eval.running.row import EpisodeRow
from roboview.integrations.lerobot import RoboViewEnv
from roboview.integrations.lerobot.env import episode_plan
from roboview.variation.instances import episode_seed

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
            raise ValueError(
                f"eval_info.json holds split {split!r} twice; a RoboView split is one task group"
            )
        out[split] = [bool(s) for s in entry["metrics"]["successes"]]
    return out


def convert(
    eval_info: Path,
    benchmark_path: str,
    output_dir: Path,
    n_repeats: int = 1,
    contexts: int = 0,
    limit: int = 0,
    start_seed: int = 1000,
    policy_name: str = "lerobot-eval",
    max_steps: int = 120,
    image_size: int = 96,
) -> Path:
    info = json.loads(Path(eval_info).read_text())
    per_split = successes(info)
    plans = {split: episode_plan(benchmark_path, split, n_repeats, contexts, limit) for split in per_split}
    for split, done in per_split.items():
        if len(done) > len(plans[split][1]):
            raise ValueError(
                f"eval_info.json has {len(done)} episodes of split {split!r}, which selects "
                f"{len(plans[split][1])}: run lerobot-eval with --eval.n_episodes at most that"
            )
    version = next(iter(plans.values()))[0]
    store = EpisodeStore(
        Path(output_dir),
        {
            "benchmark_version": version,
            "policy": policy_name,
            "policy_path": None,
            "policy_options": {"source": str(Path(eval_info).resolve()), "start_seed": start_seed},
            "n_repeats": {split: n_repeats for split in per_split},
            "max_steps": max_steps,
            "image_size": image_size,
            "values": None,
        },
    )
    for split, done in per_split.items():
        for (item, repeat), success in zip(plans[split][1], done):
            store.add(
                EpisodeRow(
                    item.record,
                    repeat=repeat,
                    episode_seed=episode_seed(item.record["context_id"], repeat),
                    success=success,
                    steps=None,
                    duration_s=None,
                    policy=policy_name,
                    failure_reason="" if success else NO_REASON,
                    unit=item.repetition.unit(item.instance, repeat),
                ).as_dict()
            )
    store.close()
    add_control_arm(Path(eval_info), info, list(store.rows.values()))
    return Path(output_dir) / PARQUET


def add_control_arm(path: Path, info: dict, rows: list[dict]) -> None:
    """eval_info.json's `per_group.<split>` gains the split's control arm beside `pc_success`: `sr_control` (the
    all-baseline instance of each (context, repeat) the split ran, on the same seed), `sr_control_ci95`
    (Clopper–Pearson) and `n_control_episodes`; a single-factor split also `per_value.<v>`, each value against the
    control arm on the pairs both ran: `delta_control`, `delta_control_ci95` (Newcombe's paired interval),
    `n_control_pairs`, `p_control` (McNemar), the numbers metrics.json holds. A factor a task takes apart (`analyses`:
    LIBERO-plus's camera and noise, their number over its own variants beside RoboView's isolated ones) is written
    under `analyses.<key>`, as metrics.json has it. Written back atomically."""
    import pandas as pd

    from roboview.eval.statistics.analyses import task_analyses
    from roboview.eval.statistics.compare import all_baseline, control_arm, control_deltas

    episodes = pd.DataFrame(rows)
    base = all_baseline(episodes)
    for split, split_rows in episodes.groupby("split", sort=False):
        group = (info.get("per_group") or {}).get(str(split))
        if isinstance(group, dict):
            group.update(control_arm(base, split_rows))
            if "|" not in str(split_rows["factor"].iloc[0]):
                group["per_value"] = control_deltas(base, split_rows)
    analyses = task_analyses(episodes)
    if analyses:
        info["analyses"] = analyses
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(info, indent=2))
    tmp.replace(path)


_ENV_DEFAULTS = {f.name: f.default for f in dataclasses.fields(RoboViewEnv)}


@dataclass
class ConvertEnvConfig:
    """The `--env.*` flags given to lerobot-eval (the plugin config's own defaults, so both tools agree)."""

    # Benchmark folder, as given to lerobot-eval.
    benchmark_path: str = ""
    # Repeats per instance, as given to lerobot-eval.
    n_repeats: int = _ENV_DEFAULTS["n_repeats"]
    # Task contexts kept per split (0: all), as given to lerobot-eval.
    contexts: int = _ENV_DEFAULTS["contexts"]
    # Instances kept per split (0: all), as given to lerobot-eval.
    limit: int = _ENV_DEFAULTS["limit"]
    # lerobot's first reset seed (lerobot-eval's --seed), as given to lerobot-eval.
    start_seed: int = _ENV_DEFAULTS["start_seed"]
    # Control steps per episode, as given to lerobot-eval.
    max_steps: int = _ENV_DEFAULTS["max_steps"]
    # Camera image side (pixels), as given to lerobot-eval.
    image_size: int = _ENV_DEFAULTS["image_size"]


@dataclass
class ConvertConfig:
    # lerobot-eval's OUT/eval_info.json.
    eval_info: str = ""
    # RoboView results folder to write.
    output_dir: str = ""
    # The results' policy column.
    policy_name: str = "lerobot-eval"
    # The `--env.*` flags lerobot-eval was given.
    env: ConvertEnvConfig = field(default_factory=ConvertEnvConfig)

    def __post_init__(self) -> None:
        if not self.eval_info or not Path(self.eval_info).is_file():
            raise ValueError(
                f"--eval_info={self.eval_info!r}: no such file (lerobot-eval writes OUT/eval_info.json)"
            )
        if not self.output_dir:
            raise ValueError("--output_dir is required: the RoboView results folder to write")
        if not self.env.benchmark_path:
            raise ValueError("--env.benchmark_path is required: the benchmark folder given to lerobot-eval")


def run(cfg: ConvertConfig) -> Path:
    e = cfg.env
    return convert(
        Path(cfg.eval_info),
        e.benchmark_path,
        Path(cfg.output_dir),
        e.n_repeats,
        e.contexts,
        e.limit,
        e.start_seed,
        cfg.policy_name,
        e.max_steps,
        e.image_size,
    )


def main(argv: list[str] | None = None) -> Path:
    from roboview.core.cli import cli_main

    return cli_main(ConvertConfig, run, lambda cfg, path: print(f"[convert] {path}"), args=argv)


if __name__ == "__main__":
    main()
