"""LIBERO build and evaluation throughput: one compiled model per task, reset in place, against LeRobot's hard reset.

    python -m benchmarks.libero_throughput [--build_preset=libero_small] [--tasks=1] [--eval_preset=libero_tiny]
        [--n_repeats=3] [--num_workers=1] [--paths=soft,hard] [--output=outputs/bench/libero_throughput.json]

Why: a LIBERO episode's hard reset compiles a new MuJoCo model (3–4 s here), more than the scripted expert's whole
rollout; RoboView's LIBERO env compiles one model per task and restores it in place between episodes
(bit-identical: tests/libero/test_task.py, tests/libero/test_world.py). This runs the same commands both ways in
one run, `soft` (the default) and `hard` (`ROBOVIEW_LIBERO_HARD_RESET=1`, LeRobot's path), and, for a path
`git:REV`, RoboView's code at that git revision (a detached worktree of this checkout, run with this interpreter:
`--paths=[soft,hard,git:9eea313~1]` adds the release before one model per task), and writes:

- build: `roboview-build-benchmark` of `--build_preset` (or, with `--tasks=N`, the `libero` preset's every value on
  the first N tasks of libero_object and libero_spatial, init state 0, the gate's pass rate reported but not
  enforced): instances/hour, the gate's pass rate, and whether both paths built the same benchmark version (same
  suite hash, same gate records);
- evaluate: `roboview-evaluate` of the privileged expert on `--eval_preset` with `--n_repeats` (distinct init
  states): whole-command seconds, episodes/hour of the whole command and of the episode loop alone (per worker).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from roboview.core.cli import cli_main  # first: it sets the headless GL defaults before MuJoCo loads
from roboview.eval.running.results import PARQUET
from roboview.libero.task import HARD_RESET_ENV


@dataclass
class LiberoThroughputConfig:
    # Preset built both ways (ignored with --tasks).
    build_preset: str = "libero_small"
    # >0: build the `libero` preset's every value on this many LIBERO tasks instead (197 instances a task).
    tasks: int = 0
    # Preset the expert is evaluated on.
    eval_preset: str = "libero_tiny"
    # Repeats of each instance (distinct LIBERO init states).
    n_repeats: int = 3
    # Worker processes of the build and of the evaluation.
    num_workers: int = 1
    # Image side the benchmarks are built at (LeRobot's LiberoEnv renders 256).
    image_size: int = 256
    # Paths to run, in this order: soft (one model per task, reset in place), hard (LeRobot's hard reset), and
    # git:REV (the code at git revision REV, e.g. git:9eea313~1).
    paths: list[str] = field(default_factory=lambda: ["soft", "hard"])
    # JSON file the results are written to.
    output: str = "outputs/bench/libero_throughput.json"


TASK_SUBSET = [f"libero_object/{i}" for i in range(10)] + [f"libero_spatial/{i}" for i in range(10)]
# Builds the `libero` preset restricted to the first N tasks in a fresh interpreter (the preset is registered there).
_SUBSET_BUILD = """
import sys
from dataclasses import replace
from roboview.pipelines.build_benchmark import BuildConfig, run
from roboview.tasks.presets import PRESETS, register_preset
tasks, out, size, workers = sys.argv[1].split(","), sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
register_preset(replace(PRESETS["libero"], preset="libero_subset",
    value_subsets=(("init_state", ("0",)), ("libero_task", tuple(tasks)))))
# The gate's verdicts are reported, not enforced: the full preset's color split does not pass it on every task.
run(BuildConfig(output_dir=out, preset="libero_subset", image_size=size, num_workers=workers, min_pass_rate=0.01))
"""


ROOT = Path(__file__).resolve().parents[1]


def _checkout(path: str, root: Path) -> Path | None:
    """The worktree a `git:REV` path runs from (made once under `root`), None for this checkout's code."""
    if not path.startswith("git:"):
        return None
    tree = root / f"tree_{path[4:].replace('/', '_').replace('~', '_')}"
    if not tree.exists():
        add = ["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree), path[4:]]
        subprocess.run(add, check=True, capture_output=True, text=True)
    return tree


def _run(cmd: list[str], path: str, tree: Path | None = None) -> float:
    env = os.environ | {HARD_RESET_ENV: "1" if path == "hard" else "0"}
    if tree is not None:  # its roboview ahead of the editable install (cwd and PYTHONPATH)
        env["PYTHONPATH"] = str(tree)
    start = time.perf_counter()
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=tree)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd[:3])} … failed ({path}):\n{proc.stderr[-3000:]}")
    return time.perf_counter() - start


def _build(cfg: LiberoThroughputConfig, out: Path, path: str, tree: Path | None) -> dict:
    bin_dir = Path(sys.executable).parent
    if cfg.tasks:
        tasks = ",".join(TASK_SUBSET[: cfg.tasks])
        cmd = [
            sys.executable,
            "-c",
            _SUBSET_BUILD,
            tasks,
            str(out),
            str(cfg.image_size),
            str(cfg.num_workers),
        ]
    else:
        cmd = [
            str(bin_dir / "roboview-build-benchmark"),
            f"--preset={cfg.build_preset}",
            f"--image_size={cfg.image_size}",
            f"--num_workers={cfg.num_workers}",
            f"--output_dir={out}",
        ]
    seconds = _run(cmd, path, tree)
    manifest = json.loads((out / "benchmark.json").read_text())
    n = manifest["candidates"]
    return {
        "instances": n,
        "seconds": round(seconds, 1),
        "instances_per_hour": round(3600 * n / seconds),
        "benchmark_version": manifest["benchmark_version"],
        "gate_pass_rate": round(manifest["gate_pass_rate"], 4),
    }


def _evaluate(cfg: LiberoThroughputConfig, bench: Path, out: Path, path: str, tree: Path | None) -> dict:
    cmd = [
        str(Path(sys.executable).parent / "roboview-evaluate"),
        f"--benchmark.path={bench}",
        "--policy.type=expert",
        "--policy.control=ee_delta",
        f"--eval.n_repeats={cfg.n_repeats}",
        f"--eval.num_workers={cfg.num_workers}",
        f"--output_dir={out}",
    ]
    seconds = _run(cmd, path, tree)
    rows = pd.read_parquet(out / PARQUET)
    loop = float(rows["duration_s"].sum()) / cfg.num_workers
    return {
        "episodes": len(rows),
        "success_rate": float(rows["success"].mean()),
        "seconds": round(seconds, 1),
        "episodes_per_hour_command": round(3600 * len(rows) / seconds),
        "episodes_per_hour_per_worker_loop": round(3600 * len(rows) / loop / cfg.num_workers),
        "mean_episode_s": round(float(rows["duration_s"].mean()), 2),
    }


def run(cfg: LiberoThroughputConfig) -> dict:
    results: dict = {"config": cfg.__dict__, "cpu_count": os.cpu_count(), "build": {}, "evaluate": {}}
    with tempfile.TemporaryDirectory(prefix="libero-throughput-") as tmp:
        root = Path(tmp)
        eval_bench = root / "eval_bench"
        _run(
            [
                str(Path(sys.executable).parent / "roboview-build-benchmark"),
                f"--preset={cfg.eval_preset}",
                f"--image_size={cfg.image_size}",
                "--num_workers=1",
                f"--output_dir={eval_bench}",
            ],
            "soft",
        )
        for i, path in enumerate(cfg.paths):
            tree = _checkout(path, root)
            results["build"][path] = _build(cfg, root / f"build_{i}", path, tree)
            results["evaluate"][path] = _evaluate(cfg, eval_bench, root / f"eval_{i}", path, tree)
            print(path, json.dumps({"build": results["build"][path], "evaluate": results["evaluate"][path]}))
        for tree in root.glob("tree_*"):
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)], check=False)
    if {"soft", "hard"} <= set(cfg.paths):
        b, e = results["build"], results["evaluate"]
        results["same_benchmark"] = b["soft"]["benchmark_version"] == b["hard"]["benchmark_version"]
        results["speedup"] = {
            "build": round(b["soft"]["instances_per_hour"] / b["hard"]["instances_per_hour"], 2),
            "evaluate_loop": round(
                e["soft"]["episodes_per_hour_per_worker_loop"]
                / e["hard"]["episodes_per_hour_per_worker_loop"],
                2,
            ),
            "evaluate_command": round(
                e["soft"]["episodes_per_hour_command"] / e["hard"]["episodes_per_hour_command"], 2
            ),
        }
    for path in cfg.paths:
        if path.startswith("git:") and "soft" in cfg.paths:
            b, e = results["build"], results["evaluate"]
            results.setdefault("speedup_over", {})[path] = {
                "build": round(b["soft"]["instances_per_hour"] / b[path]["instances_per_hour"], 2),
                "evaluate_loop": round(
                    e["soft"]["episodes_per_hour_per_worker_loop"]
                    / e[path]["episodes_per_hour_per_worker_loop"],
                    2,
                ),
            }
    out = Path(cfg.output)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=2))
    print(json.dumps({k: v for k, v in results.items() if k != "config"}, indent=2))
    return results


def main() -> None:
    cli_main(LiberoThroughputConfig, run)


if __name__ == "__main__":
    main()
