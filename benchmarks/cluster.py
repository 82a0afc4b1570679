"""Going distributed on one machine: the same episodes on the local backend, on a one-node Ray cluster and on
a two-node Ray cluster with the same cores in total (each node a separate raylet started by `ray start`).

    python -m benchmarks.cluster --output=outputs/bench/cluster.json [--checkpoint=CKPT] [--benchmark.path=DIR]

LIBERO's scenes, the scripted expert from 3 init states an instance, and the benchmark built on each layout too:

    python -m benchmarks.cluster --benchmark.path=outputs/libero/tiny --split= --episodes=4 --n_repeats=3 \
        --policy_type=expert --policy_control=ee_delta --build_preset=libero_tiny --build_image_size=256 \
        --output=outputs/bench/cluster_libero.json

Writes episodes/hour per layout, each Ray layout's rate over the local backend's (`over_local`), where the
episodes ran (episodes per node) and whether the rows equal the local backend's; with `--build_preset`, that
preset's build on each layout (`roboview-build-benchmark`, `--ray_address` on the clusters): seconds and whether
its benchmark version is the local build's. The policy: `--policy_type`, else `--checkpoint` (default: the
reference ACT, `outputs/train_act96/checkpoints/last/pretrained_model`), else the scripted `expert` when it is
absent. `LocalCluster` is also what the multi-node tests start.
"""

from __future__ import annotations

import json
import os
import secrets
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import psutil

from benchmarks.serving import free_port
from roboview.eval.running.results import PARQUET
from roboview.pipelines._cli import BenchmarkPath, cli_main

ROOT = Path(__file__).parents[1]
RAY = Path(sys.executable).parent / "ray"
REFERENCE_CHECKPOINT = "outputs/train_act96/checkpoints/last/pretrained_model"


def frames_equal(a, b) -> bool:
    """Two episode tables with the same rows (pandas' own comparison: NaNs and list cells included)."""
    import pandas as pd

    try:
        pd.testing.assert_frame_equal(a, b)
        return True
    except AssertionError:
        return False


class LocalCluster:
    """A Ray head and worker nodes on 127.0.0.1, started with Ray's own CLI (`ray start --block`, one raylet each),
    token-authenticated. `kill(node)` ends a node as a lost machine ends: every process under it at once."""

    def __init__(
        self,
        workers: int = 1,
        cpus: int = 1,
        head_cpus: int | None = None,
        scratch: Path | None = None,
        timeout_s: float = 120,
    ) -> None:
        scratch = Path(scratch or tempfile.mkdtemp(prefix="roboview-ray-"))
        token = scratch / f"ray_token_{secrets.token_hex(4)}"
        token.write_text(secrets.token_hex(32))
        self.env = os.environ | {
            "RAY_AUTH_MODE": "token",
            "RAY_AUTH_TOKEN_PATH": str(token),
            "PYTHONPATH": str(ROOT),
            "RAY_USAGE_STATS_ENABLED": "0",
            "MUJOCO_GL": "egl",
            "PYOPENGL_PLATFORM": "egl",
        }
        self.port = free_port()
        self.address = f"127.0.0.1:{self.port}"
        self.head = self._start(
            [
                "--head",
                f"--port={self.port}",
                "--include-dashboard=false",
                f"--num-cpus={cpus if head_cpus is None else head_cpus}",
                f"--node-manager-port={free_port()}",
                f"--object-manager-port={free_port()}",
            ]
        )
        self.workers = [
            self._start([f"--address={self.address}", f"--num-cpus={cpus}"]) for _ in range(workers)
        ]
        deadline = time.time() + timeout_s
        while self.alive_nodes() < 1 + workers:
            if time.time() > deadline:
                self.close()
                raise TimeoutError(
                    f"Ray did not start {1 + workers} nodes on this machine within {timeout_s:.0f} s"
                )
            time.sleep(1)

    def _start(self, args: list[str]) -> subprocess.Popen:
        return subprocess.Popen(
            [str(RAY), "start", "--block", "--node-ip-address=127.0.0.1", *args],
            env=self.env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
        )

    def alive_nodes(self) -> int:
        code = (
            f"import ray; ray.init(address={self.address!r}, log_to_driver=False); "
            "print(sum(n['Alive'] for n in ray.nodes()))"
        )
        proc = subprocess.run(
            [sys.executable, "-c", code], env=self.env, capture_output=True, text=True, timeout=120
        )
        return (
            int(proc.stdout.strip().splitlines()[-1]) if proc.returncode == 0 and proc.stdout.strip() else 0
        )

    @staticmethod
    def kill(proc: subprocess.Popen) -> None:
        try:
            tree = [psutil.Process(proc.pid), *psutil.Process(proc.pid).children(recursive=True)]
        except psutil.NoSuchProcess:
            tree = []
        for p in tree:
            try:
                p.send_signal(signal.SIGKILL)
            except psutil.NoSuchProcess:
                pass
        proc.wait(30)

    def close(self) -> None:
        for proc in [*self.workers, self.head]:
            self.kill(proc)

    def __enter__(self) -> LocalCluster:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


@dataclass
class ClusterBenchConfig:
    # JSON file to write.
    output: str = "outputs/bench/cluster.json"
    # Benchmark folder (default: the `paper` build at outputs/benchmark_paper, else the tiny preset built here).
    benchmark: BenchmarkPath = field(default_factory=BenchmarkPath)
    # LeRobot checkpoint to evaluate (default: the reference ACT when present, else the scripted expert).
    checkpoint: str = ""
    # Split evaluated per layout ("": every split).
    split: str = "color"
    # Number of the split's instances evaluated per layout (--eval.limit).
    episodes: int = 48
    # Repeats of each instance (on LIBERO's scenes: distinct init states).
    n_repeats: int = 1
    # A policy type instead of the checkpoint (e.g. expert); "": the checkpoint, else the expert.
    policy_type: str = ""
    # That policy's control (e.g. ee_delta on LIBERO's scenes); "": its default.
    policy_control: str = ""
    # A preset also built on each layout (its benchmark version compared with the local build's); "": none.
    build_preset: str = ""
    # Image side that preset is built at (pixels).
    build_image_size: int = 64
    # Cores in total, in every layout.
    cores: int = 2

    def __post_init__(self) -> None:
        if self.episodes < 4 or self.cores < 2:
            raise ValueError(f"--episodes={self.episodes} must be ≥ 4 and --cores={self.cores} ≥ 2")


def _evaluate(
    cfg: ClusterBenchConfig, bench: str, policy: list[str], out: Path, env: dict, extra: list[str]
) -> float:
    cmd = [
        sys.executable,
        "-m",
        "roboview.pipelines.evaluate",
        f"--benchmark.path={bench}",
        *([f"--benchmark.splits={cfg.split}"] if cfg.split else []),
        f"--eval.limit={cfg.episodes}",
        f"--eval.n_repeats={cfg.n_repeats}",
        f"--eval.num_workers={cfg.cores}",
        *policy,
        *extra,
        f"--output_dir={out}",
    ]
    return _timed(cmd, env)


def _timed(cmd: list[str], env: dict) -> float:
    """Seconds `cmd` ran, from the checkout's root; RuntimeError with its output's tail if it failed."""
    start = time.perf_counter()
    proc = subprocess.run(cmd, env=env, cwd=ROOT, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{proc.stdout[-2000:]}{proc.stderr[-2000:]}")
    return time.perf_counter() - start


def _build(cfg: ClusterBenchConfig, out: Path, env: dict, extra: list[str]) -> dict:
    cmd = [
        sys.executable,
        "-m",
        "roboview.pipelines.build_benchmark",
        f"--preset={cfg.build_preset}",
        f"--image_size={cfg.build_image_size}",
        f"--num_workers={cfg.cores}",
        *extra,
        f"--output_dir={out}",
    ]
    seconds = _timed(cmd, env)
    version = json.loads((out / "benchmark.json").read_text())["benchmark_version"]
    return {"seconds": round(seconds, 1), "benchmark_version": version}


def run(cfg: ClusterBenchConfig) -> dict:
    import pandas as pd

    scratch = Path(tempfile.mkdtemp(prefix="roboview-cluster-bench-"))
    bench = cfg.benchmark.path or (
        "outputs/benchmark_paper" if Path("outputs/benchmark_paper").is_dir() else ""
    )
    if not bench:
        from roboview.pipelines.build_benchmark import BuildConfig
        from roboview.pipelines.build_benchmark import run as build

        bench = str(scratch / "bench")
        build(BuildConfig(output_dir=bench, preset="tiny", image_size=64))
    checkpoint = cfg.checkpoint or (REFERENCE_CHECKPOINT if Path(REFERENCE_CHECKPOINT).is_dir() else "")
    policy = (
        ["--policy.type=lerobot", f"--policy.path={checkpoint}"]
        if checkpoint
        else ["--policy.type=expert", "--eval.image_size=96"]
    )
    if cfg.policy_type:
        policy = [f"--policy.type={cfg.policy_type}"]
        policy += [f"--policy.control={cfg.policy_control}"] if cfg.policy_control else []
    layouts: dict[str, dict] = {}
    base_env = os.environ | {"PYTHONPATH": str(ROOT)}
    seconds = _evaluate(cfg, bench, policy, scratch / "local", base_env, [])
    layouts["local"] = {"seconds": round(seconds, 1)}
    if cfg.build_preset:
        layouts["local"]["build"] = _build(cfg, scratch / "local_build", base_env, [])
    for name, workers, cpus in (("ray_1_node", 0, cfg.cores), (f"ray_{cfg.cores}_nodes", cfg.cores - 1, 1)):
        with LocalCluster(workers=workers, cpus=cpus, scratch=scratch) as cluster:
            seconds = _evaluate(
                cfg,
                bench,
                policy,
                scratch / name,
                cluster.env,
                ["--eval.backend=ray", f"--eval.ray_address={cluster.address}"],
            )
            built = (
                _build(cfg, scratch / f"{name}_build", cluster.env, [f"--ray_address={cluster.address}"])
                if cfg.build_preset
                else None
            )
        record = json.loads((scratch / name / "provenance.json").read_text())[-1]["ray"]
        layouts[name] = {"seconds": round(seconds, 1), "episodes_per_node": sorted(record["nodes"].values())}
        if built:
            local_version = layouts["local"]["build"]["benchmark_version"]
            layouts[name]["build"] = built | {"same_version": built["benchmark_version"] == local_version}

    def table(name: str):
        return (
            pd.read_parquet(scratch / name / PARQUET)
            .drop(columns=["duration_s"])
            .sort_values(["instance_id", "repeat"])
            .reset_index(drop=True)
        )

    reference = table("local")
    for name, layout in layouts.items():
        layout["episodes"] = len(table(name))
        layout["episodes_per_hour"] = round(3600 * layout["episodes"] / layout["seconds"])
        layout["over_local"] = round(layouts["local"]["seconds"] / layout["seconds"], 3)
        layout["rows_equal_local"] = frames_equal(table(name), reference)
        print(
            f"[cluster] {name}: {layout['episodes_per_hour']} episodes/h ({layout['over_local']}× local), "
            f"rows equal: {layout['rows_equal_local']}",
            flush=True,
        )
    out = {
        "policy": checkpoint or "expert",
        "benchmark": bench,
        "split": cfg.split,
        "episodes": len(reference),
        "n_repeats": cfg.n_repeats,
        "cores": cfg.cores,
        "cpu": os.cpu_count(),
        "layouts": layouts,
        "note": "wall clock of the whole evaluate command, start-up (model load, Ray connect) included",
    }
    Path(cfg.output).parent.mkdir(parents=True, exist_ok=True)
    Path(cfg.output).write_text(json.dumps(out, indent=2))
    return out


def main(args: list[str] | None = None) -> dict:
    return cli_main(ClusterBenchConfig, run, args=args)


if __name__ == "__main__":
    main()
