"""Throughput on the machine it runs on, side by side with lerobot-eval — one JSON file.

    python -m benchmarks.throughput [--quick=true] --output=FILE.json [--checkpoint=CKPT/pretrained_model]
    make bench                      # the same, full size, into outputs/bench/throughput.json

Writes (rates are per hour of wall-clock time, each phase in its own process so memory and timings
do not leak between phases):

- `render_fps_bare`, `render_fps_pipeline`, `render_ratio`: a bare `mujoco.Renderer` loop against the
  env's observation rendering (224², all four cameras; `benchmarks.render_rate`).
- `collect_demos_per_hour`: `roboview.pipelines.collect`, four cameras at 224², 2 workers, encoding included.
- `eval_episodes_per_hour` (vision agent, 2 workers), `eval_episodes_per_hour_1_worker`, `speedup_2_workers`,
  `eval_episodes_per_hour_eager` (every camera rendered every step, the pre-lazy behaviour),
  `peak_rss_mb_per_worker` (largest worker's peak resident memory).
- `learned_eval_episodes_per_hour`: `{"unbatched": …, "batched": …}` for the checkpoint (2 workers; batched =
  4 envs per worker in lockstep, one forward pass per step for the slots that need a chunk).
- `vs_lerobot_eval`: RoboView's episodes per hour over lerobot-eval's, same checkpoint, instances and episode
  count, measured here in the same run (both wall clock of the whole command, start-up included), with both
  success counts (`lerobot_eval` block: its own numbers).
- `breakdown`: where one worker's episode time goes (render, physics, policy, encoding, I/O, other) for the
  vision agent and for the checkpoint.

The checkpoint: `--checkpoint`, else `outputs/train_act96/checkpoints/last/pretrained_model` when present
(the reference ACT, docs/results/act_ref.md), else a 2-step ACT trained here (it fails every episode, so its episodes run
the full 120 steps: a worst case, not a result). `--quick=true` (smaller counts) finishes in under 10
minutes on 2 cores.
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

from roboview.pipelines._cli import BenchmarkPath, cli_main

REFERENCE_CHECKPOINT = Path("outputs/train_act96/checkpoints/last/pretrained_model")
# (quick, full) sizes.
SIZES = {
    "render_frames": (100, 300),
    "collect_episodes": (6, 20),
    "vision_repeats": (2, 6),
    "learned_episodes": (8, 24),
    "breakdown_episodes": (6, 20),
}


def _child(*args: str) -> dict:
    """Run one phase in a fresh process; its last stdout line is its JSON result."""
    proc = subprocess.run(
        [sys.executable, "-m", "benchmarks.throughput", *args],
        capture_output=True,
        text=True,
        env=os.environ | {"PYTHONPATH": str(Path(__file__).resolve().parents[1])},
    )
    if proc.returncode != 0:
        raise RuntimeError(f"phase {' '.join(args)} failed:\n{proc.stderr[-3000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _children_peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024  # KiB on Linux


# -- phases (each runs in its own process) ----------------------------------------------------------------------


def phase_render(frames: int) -> dict:
    import numpy as np

    from benchmarks.render_rate import bare_fps, pipeline_fps
    from roboview.tasks import make_env

    env = make_env(image_size=224)
    env.reset()
    # interleaved: drift-robust
    rounds = [(bare_fps(env, frames), pipeline_fps(env, frames)) for _ in range(3)]
    env.close()
    bare, pipeline = float(np.median([r[0] for r in rounds])), float(np.median([r[1] for r in rounds]))
    return {"render_fps_bare": bare, "render_fps_pipeline": pipeline, "render_ratio": pipeline / bare}


def phase_collect(episodes: int, scratch: Path) -> dict:
    from roboview.pipelines.collect import CollectConfig, DatasetConfig, run

    cfg = CollectConfig(
        dataset=DatasetConfig(
            repo_id="bench/demos", root=str(scratch / "demos"), num_episodes=episodes, image_size=224
        ),
        num_workers=2,
    )
    start = time.perf_counter()
    result = run(cfg)
    wall = time.perf_counter() - start
    return {
        "collect_demos_per_hour": 3600 * result.new_episodes / wall,
        "demos": result.new_episodes,
        "attempts": result.attempts,
        "wall_s": wall,
    }


def phase_eval(
    bench: str,
    policy: str,
    path: str,
    splits: str,
    limit: int,
    repeats: int,
    workers: int,
    envs_per_worker: int,
    eager: bool,
    out: Path,
) -> dict:
    from roboview.pipelines.evaluate import BenchmarkConfig, EvalConfig, EvaluateConfig, run
    from roboview.policies.types import policy_config

    cfg = EvaluateConfig(
        BenchmarkConfig(bench, splits),
        policy_config(policy, **({"path": path} if path else {})),
        EvalConfig(
            n_repeats=repeats,
            limit=limit,
            num_workers=workers,
            envs_per_worker=envs_per_worker,
            eager_render=eager,
        ),
        str(out),
    )
    start = time.perf_counter()
    result = run(cfg)
    wall = time.perf_counter() - start
    return {
        "episodes": result.new_episodes,
        "successes": round(result.success_rate * result.episodes),
        "wall_s": wall,
        "episodes_per_hour": 3600 * result.new_episodes / wall,
        "peak_rss_mb_per_worker": _children_peak_rss_mb(),
    }


def phase_lerobot_eval(bench: str, path: str, split: str, episodes: int, batch: int, out: Path) -> dict:
    from roboview.policies.devices import resolve_device
    from roboview.policies.lerobot_policy import checkpoint_cameras, checkpoint_image_size

    cmd = [
        str(Path(sys.executable).parent / "lerobot-eval"),
        "--env.type=roboview",
        f"--env.benchmark_path={bench}",
        f"--env.task={split}",
        f"--env.limit={episodes}",
        f"--env.cameras={','.join(checkpoint_cameras(path))}",
        f"--env.image_size={checkpoint_image_size(path)}",
        f"--policy.path={path}",
        f"--policy.device={resolve_device('auto')}",
        f"--eval.n_episodes={episodes}",
        f"--eval.batch_size={batch}",
        f"--output_dir={out}",
    ]
    start = time.perf_counter()
    proc = subprocess.run(
        cmd,
        capture_output=True,
        text=True,
        env=os.environ | {"PYTHONPATH": str(Path(__file__).resolve().parents[1])},
    )
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        raise RuntimeError(f"lerobot-eval failed:\n{proc.stderr[-3000:]}")
    info = json.loads((out / "eval_info.json").read_text())["overall"]
    return {
        "episodes": info["n_episodes"],
        "successes": round(info["pc_success"] * info["n_episodes"] / 100),
        "wall_s": wall,
        "episodes_per_hour": 3600 * info["n_episodes"] / wall,
        "loop_s": info["eval_s"],
        "command": " ".join(cmd),
    }


def phase_breakdown(bench: str, policy: str, path: str, splits: str, episodes: int, out: Path) -> dict:
    """One worker in this process, timers around rendering, physics, the policy and the results' I/O."""
    from roboview.benchmark.format import load_benchmark
    from roboview.eval.campaign.plan import resolve_image_size
    from roboview.eval.running.results import EpisodeStore
    from roboview.eval.running.rollout import EvalWorker, WorkerSpec, WorkItem
    from roboview.policies.types import policy_config

    config = policy_config(policy, **({"path": path} if path else {}))
    worker = EvalWorker(WorkerSpec(config, resolve_image_size(config, 0), torch_threads=1))
    seconds: dict[str, float] = defaultdict(float)
    state = {"in_policy": False}
    env, batch = worker.env, worker.batch

    def timed(key, fn):
        def wrapper(*args, **kwargs):
            start = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                elapsed = time.perf_counter() - start
                seconds[key] += elapsed
                if key == "render" and state["in_policy"]:
                    seconds["render_in_policy"] += elapsed

        return wrapper

    def policy_call(fn):
        def wrapper(*args):
            state["in_policy"] = True
            try:
                return timed("policy_total", fn)(*args)
            finally:
                state["in_policy"] = False

        return wrapper

    env.render_camera = timed("render", env.render_camera)
    env.step = timed("step_total", env.step)
    batch.select_actions = policy_call(batch.select_actions)
    items = [
        i
        for its in load_benchmark(bench, [s for s in splits.split(",") if s] or None).splits.values()
        for i in its
    ][:episodes]
    store = EpisodeStore(out, {"benchmark_version": "bench", "policy": policy})
    steps, start = 0, time.perf_counter()
    for item in items:
        row = worker.run(WorkItem(item, 0)).row
        io_start = time.perf_counter()
        store.add(row)
        seconds["io"] += time.perf_counter() - io_start
        steps += row["steps"]
    io_start = time.perf_counter()
    store.close()
    seconds["io"] += time.perf_counter() - io_start
    total = time.perf_counter() - start
    worker.close()
    # Lazy rendering: a frame is rendered inside the policy call that reads it (or at reset), never in step.
    parts = {
        "render": seconds["render"],
        "physics": seconds["step_total"],
        "policy": seconds["policy_total"] - seconds["render_in_policy"],
        "encoding": 0.0,
        "io": seconds["io"],
    }
    parts["other"] = total - sum(parts.values())
    return {
        "policy": policy,
        "episodes": len(items),
        "steps": steps,
        "ms_per_episode": 1000 * total / len(items),
        "ms_per_step": 1000 * total / steps,
        "share": {k: round(v / total, 3) for k, v in parts.items()},
        "ms_per_episode_by_part": {k: round(1000 * v / len(items), 1) for k, v in parts.items()},
        "note": "encoding is 0: no videos or Rerun recording requested (--eval.videos / --eval.rerun add it)",
    }


# -- orchestration ------------------------------------------------------------------------------------------------


def tiny_checkpoint(scratch: Path) -> str:
    """A 2-step ACT on 2 demos (96², left_top + wrist): the reference recipe at its smallest."""
    root = scratch / "ckpt"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "roboview.pipelines.collect",
            "--dataset.repo_id=bench/ckpt_demos",
            f"--dataset.root={root / 'ds'}",
            "--dataset.num_episodes=2",
            "--dataset.image_size=96",
            "--dataset.cameras=[left_top,wrist]",
            "--num_workers=1",
        ],
        check=True,
        capture_output=True,
    )
    subprocess.run(
        [
            sys.executable,
            "-m",
            "roboview.pipelines.train",
            "--dataset.repo_id=bench/ckpt_demos",
            f"--dataset.root={root / 'ds'}",
            f"--output_dir={root / 'train'}",
            "--steps=2",
            "--batch_size=2",
            "--save_freq=2",
            "--device=cpu",
        ],
        check=True,
        capture_output=True,
    )
    return str(root / "train" / "checkpoints" / "last" / "pretrained_model")


def run_all(quick: bool, output: Path, checkpoint: str, benchmark: str) -> dict:
    from roboview.eval.running.provenance import now, start_entry
    from roboview.pipelines._cli import setup_environment

    setup_environment()
    pick = 0 if quick else 1
    size = {k: v[pick] for k, v in SIZES.items()}
    scratch = Path(tempfile.mkdtemp(prefix="roboview_throughput_"))
    started = time.perf_counter()
    entry = start_entry(benchmark or "tiny (built here)", None)
    try:
        bench = benchmark
        if not bench:
            bench = str(scratch / "bench")
            _child("--phase=build", f"--scratch={bench}")
        if not checkpoint:
            checkpoint = str(REFERENCE_CHECKPOINT) if (REFERENCE_CHECKPOINT / "config.json").is_file() else ""
        trained_here = not checkpoint
        if trained_here:
            checkpoint = tiny_checkpoint(scratch)
        results: dict = {
            "quick": quick,
            "benchmark": bench,
            "checkpoint": checkpoint,
            "checkpoint_trained_here_2_steps": trained_here,
        }
        print("[throughput] render …", flush=True)
        results |= _child("--phase=render", f"--frames={size['render_frames']}")
        print("[throughput] collect …", flush=True)
        results |= {
            k: v
            for k, v in _child(
                "--phase=collect", f"--episodes={size['collect_episodes']}", f"--scratch={scratch}"
            ).items()
            if k == "collect_demos_per_hour"
        }

        def evaluate(
            name: str,
            policy: str,
            path: str = "",
            splits: str = "",
            limit: int = 0,
            repeats: int = 1,
            workers: int = 2,
            envs: int = 1,
            eager: bool = False,
        ) -> dict:
            print(f"[throughput] eval {name} …", flush=True)
            return _child(
                "--phase=eval",
                f"--bench={bench}",
                f"--policy={policy}",
                f"--path={path}",
                f"--splits={splits}",
                f"--limit={limit}",
                f"--repeats={repeats}",
                f"--workers={workers}",
                f"--envs={envs}",
                f"--eager={eager}",
                f"--scratch={scratch / name}",
            )

        two = evaluate("vision_2", "vision", repeats=size["vision_repeats"])
        one = evaluate("vision_1", "vision", repeats=size["vision_repeats"], workers=1)
        eager = evaluate("vision_eager", "vision", repeats=max(1, size["vision_repeats"] // 2), eager=True)
        results |= {
            "eval_episodes_per_hour": two["episodes_per_hour"],
            "eval_episodes_per_hour_1_worker": one["episodes_per_hour"],
            "eval_episodes_per_hour_eager": eager["episodes_per_hour"],
            "speedup_2_workers": two["episodes_per_hour"] / one["episodes_per_hour"],
            "lazy_over_eager": two["episodes_per_hour"] / eager["episodes_per_hour"],
            "peak_rss_mb_per_worker": max(two["peak_rss_mb_per_worker"], one["peak_rss_mb_per_worker"]),
            "vision": {"2_workers": two, "1_worker": one, "eager_2_workers": eager},
        }
        n = size["learned_episodes"]
        unbatched = evaluate("learned_1", "lerobot", checkpoint, "color", limit=n)
        batched = evaluate("learned_4", "lerobot", checkpoint, "color", limit=n, envs=4)
        print("[throughput] lerobot-eval …", flush=True)
        lerobot = _child(
            "--phase=lerobot_eval",
            f"--bench={bench}",
            f"--path={checkpoint}",
            "--splits=color",
            f"--episodes={n}",
            f"--batch={min(n, 8)}",
            f"--scratch={scratch / 'lerobot_eval'}",
        )
        best = max(unbatched, batched, key=lambda r: r["episodes_per_hour"])
        results |= {
            "learned_eval_episodes_per_hour": {
                "unbatched": unbatched["episodes_per_hour"],
                "batched": batched["episodes_per_hour"],
            },
            "batching_speedup": batched["episodes_per_hour"] / unbatched["episodes_per_hour"],
            "vs_lerobot_eval": best["episodes_per_hour"] / lerobot["episodes_per_hour"],
            "vs_lerobot_eval_successes": {
                "roboview_unbatched": unbatched["successes"],
                "roboview_batched": batched["successes"],
                "lerobot_eval": lerobot["successes"],
                "episodes": n,
            },
            "learned": {"unbatched": unbatched, "batched_4_envs_per_worker": batched},
            "lerobot_eval": lerobot,
        }
        print("[throughput] breakdown …", flush=True)
        results["breakdown"] = {
            "vision": _child(
                "--phase=breakdown",
                f"--bench={bench}",
                "--policy=vision",
                "--path=",
                "--splits=",
                f"--episodes={size['breakdown_episodes']}",
                f"--scratch={scratch / 'bd_vision'}",
            ),
            "learned": _child(
                "--phase=breakdown",
                f"--bench={bench}",
                "--policy=lerobot",
                f"--path={checkpoint}",
                "--splits=color",
                f"--episodes={max(2, size['breakdown_episodes'] // 3)}",
                f"--scratch={scratch / 'bd_learned'}",
            ),
        }
        results["provenance"] = entry | {"ended": now()}
        results["harness_wall_s"] = time.perf_counter() - started
        output.parent.mkdir(parents=True, exist_ok=True)
        output.write_text(json.dumps(results, indent=2))
        return results
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


@dataclass
class ThroughputConfig:
    # Smaller counts (under 10 minutes on 2 cores).
    quick: bool = False
    # The JSON file to write.
    output: str = "outputs/bench/throughput.json"
    # LeRobot checkpoint (a `pretrained_model` folder) for the learned and lerobot-eval rows; default: the
    # reference ACT when present, else a 2-step ACT trained here.
    checkpoint: str = ""
    # Benchmark folder (default: the tiny preset built here).
    benchmark: BenchmarkPath = field(default_factory=BenchmarkPath)

    def __post_init__(self) -> None:
        from roboview.benchmark.format import MANIFEST

        if self.checkpoint and not (Path(self.checkpoint) / "config.json").is_file():
            raise ValueError(
                f"--checkpoint={self.checkpoint}: no config.json there (give a `pretrained_model` folder)"
            )
        if self.benchmark.path and not (Path(self.benchmark.path) / MANIFEST).is_file():
            raise ValueError(
                f"--benchmark.path={self.benchmark.path}: not a benchmark folder ({MANIFEST} missing)"
            )


@dataclass
class PhaseConfig:
    """One phase of the harness, run in its own process by `_child` (not a user-facing command)."""

    phase: str = ""
    bench: str = ""
    policy: str = ""
    path: str = ""
    splits: str = ""
    scratch: str = ""
    frames: int = 0
    episodes: int = 0
    limit: int = 0
    repeats: int = 0
    workers: int = 0
    envs: int = 0
    batch: int = 0
    eager: bool = False


def run_phase(args: PhaseConfig) -> dict:
    os.environ.setdefault("MUJOCO_GL", "egl")
    scratch = Path(args.scratch)
    if args.phase == "build":
        from roboview.pipelines.build_benchmark import BuildConfig
        from roboview.pipelines.build_benchmark import run as build

        build(BuildConfig(output_dir=args.scratch, preset="tiny", num_workers=2))
        return {"built": args.scratch}
    if args.phase == "render":
        return phase_render(args.frames)
    if args.phase == "collect":
        return phase_collect(args.episodes, scratch)
    if args.phase == "eval":
        return phase_eval(
            args.bench,
            args.policy,
            args.path,
            args.splits,
            args.limit,
            args.repeats,
            args.workers,
            args.envs,
            args.eager,
            scratch,
        )
    if args.phase == "lerobot_eval":
        return phase_lerobot_eval(args.bench, args.path, args.splits, args.episodes, args.batch, scratch)
    if args.phase == "breakdown":
        return phase_breakdown(args.bench, args.policy, args.path, args.splits, args.episodes, scratch)
    raise ValueError(f"unknown --phase={args.phase!r}")


def run(cfg: ThroughputConfig) -> dict:
    results = run_all(cfg.quick, Path(cfg.output), cfg.checkpoint, cfg.benchmark.path)
    keys = (
        "render_ratio",
        "collect_demos_per_hour",
        "eval_episodes_per_hour",
        "speedup_2_workers",
        "peak_rss_mb_per_worker",
        "learned_eval_episodes_per_hour",
        "vs_lerobot_eval",
        "vs_lerobot_eval_successes",
    )
    print(json.dumps({k: results[k] for k in keys}, indent=2))
    print(f"[throughput] {cfg.output} ({results['harness_wall_s']:.0f} s)")
    return results


def main(argv: list[str] | None = None) -> dict:
    argv = sys.argv[1:] if argv is None else argv
    if not any(a.startswith("--phase=") for a in argv):
        return cli_main(ThroughputConfig, run, args=argv)
    # A child process of the harness: print its JSON result.
    result = cli_main(PhaseConfig, run_phase, args=argv)
    print(json.dumps(result))
    return result


if __name__ == "__main__":
    main()
