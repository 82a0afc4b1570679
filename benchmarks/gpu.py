"""The GPU layouts on a machine with an NVIDIA GPU: where the model sits and what each layout delivers.

    python -m benchmarks.gpu --output=outputs/bench/gpu.json [--checkpoint=CKPT] [--benchmark.path=DIR] [--episodes=200]

The same episodes (first `--episodes` instances of `--split`, one repeat) under four layouts, C = the cores:

- `cpu`: every worker holds its model on the CPU (`--policy.device=cpu`, C workers): the baseline.
- `gpu_per_worker`: every worker holds its own copy on the GPU (`--policy.device=cuda`, C workers).
- `gpu_policy_server`: one policy server holds the only copy on the GPU; C − 1 render workers with
  `--envs_per_worker` envs each send it their chunk requests, batched into one forward pass
  (`--eval.policy_server=true`).
- `gpu_served`: `roboview.pipelines.serve_policy` holds the model on the GPU and batches across connections; C − 1
  workers reach it over openpi's websocket protocol (`--policy.type=openpi`).

Rendering uses EGL, which runs on the NVIDIA driver where one is installed. Writes episodes/hour per layout,
each over `cpu`, the successes and whether the rows equal `cpu`'s. Refuses to start without CUDA.
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

from benchmarks.cluster import frames_equal
from benchmarks.serving import REFERENCE_CHECKPOINT, free_port, stop
from roboview.eval.running.results import PARQUET
from roboview.pipelines._cli import BenchmarkPath, cli_main

ROOT = Path(__file__).parents[1]


@dataclass
class GpuBenchConfig:
    # JSON file to write.
    output: str = "outputs/bench/gpu.json"
    # LeRobot checkpoint (default: the reference ACT).
    checkpoint: str = REFERENCE_CHECKPOINT
    # Benchmark folder (default: the tiny preset built here).
    benchmark: BenchmarkPath = field(default_factory=BenchmarkPath)
    # Split evaluated per layout.
    split: str = "color"
    # Number of the split's instances evaluated (one repeat each) per layout.
    episodes: int = 200
    # Envs per render worker in the policy-server layout.
    envs_per_worker: int = 4

    def __post_init__(self) -> None:
        if self.episodes < 8:
            raise ValueError(f"--episodes={self.episodes} must be ≥ 8")
        if not Path(self.checkpoint).is_dir():
            raise ValueError(
                f"--checkpoint={self.checkpoint} is not a checkpoint folder (a lerobot-train "
                "pretrained_model); train one with roboview.pipelines.train or pass its path"
            )


def _evaluate(cfg: GpuBenchConfig, bench: str, out: Path, flags: list[str]) -> dict:
    import pandas as pd

    cmd = [
        sys.executable,
        "-m",
        "roboview.pipelines.evaluate",
        f"--benchmark.path={bench}",
        f"--benchmark.splits={cfg.split}",
        f"--eval.limit={cfg.episodes}",
        "--eval.n_repeats=1",
        *flags,
        f"--output_dir={out}",
    ]
    start = time.perf_counter()
    proc = subprocess.run(
        cmd, cwd=ROOT, env=os.environ | {"PYTHONPATH": str(ROOT)}, capture_output=True, text=True
    )
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{proc.stdout[-2000:]}{proc.stderr[-2000:]}")
    rows = (
        pd.read_parquet(out / PARQUET)
        .drop(columns=["duration_s"])
        .sort_values(["instance_id", "repeat"])
        .reset_index(drop=True)
    )
    return {
        "wall_s": round(wall, 1),
        "episodes_per_hour": round(3600 * len(rows) / wall),
        "successes": int(rows["success"].sum()),
        "command": " ".join(cmd),
        "_rows": rows,
    }


def run(cfg: GpuBenchConfig) -> dict:
    import torch

    if not torch.cuda.is_available():
        raise RuntimeError(
            "no CUDA device: benchmarks.gpu measures the GPU layouts and needs an NVIDIA GPU "
            "(the CPU figures are make bench's)"
        )
    cores = os.cpu_count() or 2
    scratch = Path(tempfile.mkdtemp(prefix="roboview-gpu-bench-"))
    bench = cfg.benchmark.path
    if not bench:
        from roboview.pipelines.build_benchmark import BuildConfig
        from roboview.pipelines.build_benchmark import run as build

        bench = str(scratch / "bench")
        build(BuildConfig(output_dir=bench, preset="tiny", image_size=64))
    model = ["--policy.type=lerobot", f"--policy.path={cfg.checkpoint}"]
    layouts = {
        "cpu": _evaluate(
            cfg, bench, scratch / "cpu", [*model, "--policy.device=cpu", f"--eval.num_workers={cores}"]
        ),
        "gpu_per_worker": _evaluate(
            cfg,
            bench,
            scratch / "gpu_per_worker",
            [*model, "--policy.device=cuda", f"--eval.num_workers={cores}"],
        ),
        "gpu_policy_server": _evaluate(
            cfg,
            bench,
            scratch / "gpu_policy_server",
            [
                *model,
                "--policy.device=cuda",
                "--eval.policy_server=true",
                f"--eval.num_workers={cores - 1}",
                f"--eval.envs_per_worker={cfg.envs_per_worker}",
            ],
        ),
    }
    from roboview.policies.lerobot_policy import checkpoint_cameras, checkpoint_image_size

    port = free_port()
    log = scratch / "serve_policy.log"
    server = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "roboview.pipelines.serve_policy",
            *model,
            "--policy.device=cuda",
            f"--port={port}",
        ],
        stdout=log.open("w"),
        stderr=subprocess.STDOUT,
        cwd=ROOT,
        env=os.environ | {"PYTHONPATH": str(ROOT)},
    )
    try:
        import urllib.request

        deadline = time.time() + 300
        while True:
            try:
                urllib.request.urlopen(f"http://127.0.0.1:{port}/healthz", timeout=1)
                break
            except OSError:
                if server.poll() is not None or time.time() > deadline:
                    raise RuntimeError(f"serve_policy did not start:\n{log.read_text()[-2000:]}") from None
                time.sleep(0.5)
        layouts["gpu_served"] = _evaluate(
            cfg,
            bench,
            scratch / "gpu_served",
            [
                "--policy.type=openpi",
                f"--policy.url=ws://127.0.0.1:{port}",
                f"--policy.cameras={','.join(checkpoint_cameras(cfg.checkpoint))}",
                f"--policy.image_size={checkpoint_image_size(cfg.checkpoint)}",
                f"--eval.num_workers={cores - 1}",
            ],
        )
    finally:
        stop(server)
    reference = layouts["cpu"]["_rows"]
    for name, layout in layouts.items():
        rows = layout.pop("_rows")
        layout["over_cpu"] = round(layout["episodes_per_hour"] / layouts["cpu"]["episodes_per_hour"], 3)
        layout["rows_equal_cpu"] = frames_equal(rows, reference)
        print(
            f"[gpu] {name}: {layout['episodes_per_hour']} episodes/h ({layout['over_cpu']}× cpu), "
            f"{layout['successes']}/{cfg.episodes} successes",
            flush=True,
        )
    out = {
        "device": torch.cuda.get_device_name(0),
        "cores": cores,
        "checkpoint": cfg.checkpoint,
        "benchmark": bench,
        "split": cfg.split,
        "episodes": cfg.episodes,
        "layouts": layouts,
    }
    Path(cfg.output).parent.mkdir(parents=True, exist_ok=True)
    Path(cfg.output).write_text(json.dumps(out, indent=2))
    return out


def main(args: list[str] | None = None) -> dict:
    return cli_main(GpuBenchConfig, run, errors=(ValueError, RuntimeError), args=args)


if __name__ == "__main__":
    main()
