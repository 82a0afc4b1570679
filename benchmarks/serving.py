"""Served policies on loopback: what going over a socket costs, and what batching across connections buys.

    python -m benchmarks.serving --output=outputs/bench/serving.json [--checkpoint=CKPT] [--benchmark.path=DIR]

Writes one JSON file with:

- `episodes_per_hour`: the same checkpoint, the same episodes (`--split`, first `--episodes` instances,
  2 workers) evaluated in-process (`lerobot`), through `roboview.pipelines.serve_policy` (`openpi` client, one
  server batching both workers' requests), through openpi-server's own `WebsocketPolicyServer`
  (`--server=openpi`: one request at a time), through LeRobot's async policy server (`lerobot_async`,
  one server per worker) and through vla-eval's `LeRobotModelServer` (`vla_eval`, one server per worker:
  it has no batched predict). `--paths` picks some of them. Every server runs one torch thread per model, as each in-process worker does,
  so rows can be compared: `rows_equal_in_process` per path. `over_in_process`: each path's rate over the
  in-process rate (wall clock of the whole evaluate call; server start-up excluded).
- `requests_per_second`: `--clients` threads, each with openpi-client's own `WebsocketClientPolicy`, send
  `--requests` real observations (one at a time, waiting for each answer) to `serve_policy` and to
  openpi-server's server holding the same checkpoint (both with torch's default threads: all cores);
  `batching_speedup` is the ratio.

The checkpoint: `--checkpoint`, else `outputs/train_act96/checkpoints/last/pretrained_model` (the
reference ACT). The benchmark: `--benchmark.path`, else the `tiny` preset built here.
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request
from dataclasses import dataclass, field
from pathlib import Path

from roboview.eval.running.results import PARQUET
from roboview.pipelines._cli import BenchmarkPath, cli_main

REFERENCE_CHECKPOINT = "outputs/train_act96/checkpoints/last/pretrained_model"
ROOT = Path(__file__).resolve().parents[1]
ROW = ["instance_id", "repeat", "episode_seed", "success", "steps", "failure_reason"]
PATHS = ("serve_policy", "openpi_server", "lerobot_async", "vla_eval", "requests_per_second")


@dataclass
class ServingConfig:
    # JSON file to write.
    output: str = "outputs/bench/serving.json"
    # LeRobot checkpoint (a chunked one: act, pi0, pi05, smolvla); default: the reference ACT (docs/results/act_ref.md).
    checkpoint: str = REFERENCE_CHECKPOINT
    # Benchmark folder; empty: build the tiny preset in a scratch folder.
    benchmark: BenchmarkPath = field(default_factory=BenchmarkPath)
    # Split evaluated on every path.
    split: str = "color"
    # Number of the split's instances evaluated on every path (one repeat each).
    episodes: int = 48
    # Concurrent clients for the requests-per-second comparison.
    clients: int = 4
    # Requests each client sends in the requests-per-second comparison.
    requests: int = 40
    # Comma-separated paths to measure (in_process always runs: the others are compared with it): serve_policy,
    # openpi_server, lerobot_async, vla_eval, and requests_per_second.
    paths: str = ",".join(PATHS)
    # How the vla_eval path sends images (its --policy.image_format): png (vla-eval's default), raw or jpeg.
    vla_eval_image_format: str = "png"
    # The vla_eval path's --policy.images_every: images only every N-th step (the checkpoint's n_action_steps).
    vla_eval_images_every: int = 1

    def __post_init__(self) -> None:
        if (
            not (Path(self.checkpoint) / "config.json").is_file()
            and not (Path(self.checkpoint) / "pretrained_model").is_dir()
        ):
            raise ValueError(
                f"--checkpoint={self.checkpoint} is not a LeRobot checkpoint folder (no config.json); "
                "train one with roboview.pipelines.train or pass its pretrained_model folder"
            )
        for name in ("episodes", "clients", "requests"):
            if getattr(self, name) < 1:
                raise ValueError(f"--{name}={getattr(self, name)} must be ≥ 1")
        unknown = [p for p in self.path_list if p not in PATHS]
        if unknown:
            raise ValueError(f"--paths={self.paths!r}: unknown {unknown}; allowed: {', '.join(PATHS)}")

    @property
    def path_list(self) -> tuple[str, ...]:
        return tuple(p.strip() for p in self.paths.split(",") if p.strip())


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _env() -> dict:
    return os.environ | {"PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1", "HF_HUB_OFFLINE": "1"}


def serve_policy(
    checkpoint: str, port: int, log: Path, server: str = "roboview", threads: int = 1
) -> subprocess.Popen:
    env = _env() if threads == 1 else {k: v for k, v in _env().items() if k != "OMP_NUM_THREADS"}
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "roboview.pipelines.serve_policy",
            "--policy.type=lerobot",
            f"--policy.path={checkpoint}",
            f"--port={port}",
            f"--threads={threads}",
            f"--server={server}",
        ],
        stdout=log.open("w"),
        stderr=subprocess.STDOUT,
        env=env,
    )
    deadline = time.time() + 180
    while time.time() < deadline:
        try:
            urllib.request.urlopen(f"http://127.0.0.1:{port}/healthz", timeout=1)
            return proc
        except OSError:
            time.sleep(0.3)
        if proc.poll() is not None:
            break
    proc.kill()
    raise RuntimeError(f"serve_policy did not start:\n{log.read_text()[-2000:]}")


def lerobot_server(port: int, cwd: Path) -> subprocess.Popen:
    from roboview.policies.lerobot_async_connection import check_reachable

    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "lerobot.async_inference.policy_server",
            "--host=127.0.0.1",
            f"--port={port}",
            "--fps=10",
            "--inference_latency=0",
            "--obs_queue_timeout=2",
        ],
        cwd=cwd,
        stdout=(cwd / f"server_{port}.log").open("w"),
        stderr=subprocess.STDOUT,
        env=_env(),
    )
    deadline = time.time() + 180
    while time.time() < deadline:
        try:
            check_reachable(f"127.0.0.1:{port}", timeout_s=2)
            return proc
        except ValueError:
            if proc.poll() is not None:
                break
            time.sleep(0.5)
    proc.kill()
    raise RuntimeError(
        f"lerobot policy server did not start:\n{(cwd / f'server_{port}.log').read_text()[-2000:]}"
    )


def vla_eval_server(checkpoint: str, port: int, log: Path) -> subprocess.Popen:
    """vla-eval's own LeRobot model server (`python -m vla_eval.model_servers.lerobot`) on 127.0.0.1:port."""
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "vla_eval.model_servers.lerobot",
            f"--address=127.0.0.1:{port}",
            "--args.policy_type=act",
            f"--args.checkpoint={checkpoint}",
            "--args.device=cpu",
        ],
        stdout=log.open("w"),
        stderr=subprocess.STDOUT,
        env=_env(),
    )
    deadline = time.time() + 180
    while time.time() < deadline:
        try:
            urllib.request.urlopen(f"http://127.0.0.1:{port}/health", timeout=1)
            return proc
        except OSError:
            time.sleep(0.3)
        if proc.poll() is not None:
            break
    proc.kill()
    raise RuntimeError(f"vla-eval's LeRobot model server did not start:\n{log.read_text()[-2000:]}")


def stop(*procs: subprocess.Popen) -> None:
    for proc in procs:
        proc.terminate()
    for proc in procs:
        try:
            proc.wait(30)
        except subprocess.TimeoutExpired:
            proc.kill()


def evaluate(cfg: ServingConfig, bench: str, policy, out: Path) -> dict:
    import pandas as pd

    from roboview.pipelines.evaluate import BenchmarkConfig, EvalConfig, EvaluateConfig, run

    start = time.perf_counter()
    result = run(
        EvaluateConfig(
            BenchmarkConfig(bench, cfg.split),
            policy,
            EvalConfig(n_repeats=1, limit=cfg.episodes, num_workers=2),
            str(out),
        )
    )
    wall = time.perf_counter() - start
    rows = pd.read_parquet(out / PARQUET).sort_values(["instance_id", "repeat"]).reset_index(drop=True)
    return {
        "episodes": result.new_episodes,
        "successes": int(rows["success"].sum()),
        "wall_s": round(wall, 2),
        "episodes_per_hour": round(3600 * result.new_episodes / wall, 1),
        "_rows": rows[ROW],
    }


def requests_per_second(cfg: ServingConfig, port: int, observations: list[dict]) -> dict:
    from openpi_client.websocket_client_policy import WebsocketClientPolicy

    clients = [WebsocketClientPolicy("127.0.0.1", port) for _ in range(cfg.clients)]
    for c in clients:  # warm-up: one request each
        c.infer(observations[0])
    barrier = threading.Barrier(cfg.clients + 1)

    def loop(i: int) -> None:
        barrier.wait()
        for r in range(cfg.requests):
            clients[i].infer(observations[(i * cfg.requests + r) % len(observations)])

    threads = [threading.Thread(target=loop, args=(i,)) for i in range(cfg.clients)]
    for t in threads:
        t.start()
    barrier.wait()
    start = time.perf_counter()
    for t in threads:
        t.join()
    wall = time.perf_counter() - start
    n = cfg.clients * cfg.requests
    return {"requests": n, "wall_s": round(wall, 3), "requests_per_second": round(n / wall, 2)}


def observations_for(cfg: ServingConfig, bench: str, image_size: int, cameras: tuple[str, ...]) -> list[dict]:
    """Real first observations of the split's instances, in the droid wire layout."""
    from roboview.benchmark.format import load_benchmark
    from roboview.policies.serving.openpi_wire import wire_format
    from roboview.tasks import make_env

    items = load_benchmark(bench, [cfg.split]).splits[cfg.split][:16]
    env = make_env(cameras=cameras, image_size=image_size)
    fmt = wire_format("droid", cameras)
    out = []
    for seed, item in enumerate(items):
        obs, _ = env.reset(seed=seed, options={"instance": item.instance})
        out.append(fmt.encode(obs, env.instruction))
    env.close()
    return out


def rps_only(cfg: ServingConfig, bench: str, scratch: Path) -> dict:
    from roboview.policies.lerobot_policy import checkpoint_cameras, checkpoint_image_size

    observations = observations_for(
        cfg, bench, checkpoint_image_size(cfg.checkpoint), checkpoint_cameras(cfg.checkpoint)
    )
    rps = {}
    for name, server in (("serve_policy", "roboview"), ("openpi_server", "openpi")):
        port = free_port()
        proc = serve_policy(cfg.checkpoint, port, scratch / f"rps_{name}.log", server, threads=0)
        try:
            rps[name] = requests_per_second(cfg, port, observations)
        finally:
            stop(proc)
        rps[name]["server_log"] = (scratch / f"rps_{name}.log").read_text().strip().splitlines()[-1]
    return rps | {
        "clients": cfg.clients,
        "batching_speedup": round(
            rps["serve_policy"]["requests_per_second"] / rps["openpi_server"]["requests_per_second"], 2
        ),
    }


def run(cfg: ServingConfig) -> dict:
    from roboview.eval.running.provenance import now, start_entry
    from roboview.policies.lerobot_policy import checkpoint_cameras, checkpoint_image_size
    from roboview.policies.types import load_policy_types, policy_config

    load_policy_types()
    scratch = Path(tempfile.mkdtemp(prefix="roboview_serving_"))
    entry = start_entry(cfg.benchmark.path or "tiny (built here)", cfg.checkpoint)
    try:
        bench = cfg.benchmark.path
        if not bench:
            from roboview.pipelines.build_benchmark import BuildConfig
            from roboview.pipelines.build_benchmark import run as build

            bench = str(scratch / "bench")
            build(BuildConfig(output_dir=bench, preset="tiny", image_size=64))
        cameras, size = checkpoint_cameras(cfg.checkpoint), checkpoint_image_size(cfg.checkpoint)
        openpi = dict(cameras=",".join(cameras), image_size=size)
        results: dict = {
            "checkpoint": cfg.checkpoint,
            "benchmark": bench,
            "split": cfg.split,
            "cameras": list(cameras),
            "image_size": size,
        }
        paths: dict[str, dict] = {}
        print("[serving] in-process …", flush=True)
        paths["in_process"] = evaluate(
            cfg, bench, policy_config("lerobot", path=cfg.checkpoint), scratch / "inproc"
        )
        for name, server in (("serve_policy", "roboview"), ("openpi_server", "openpi")):
            if name not in cfg.path_list:
                continue
            print(f"[serving] {name} …", flush=True)
            port = free_port()
            proc = serve_policy(cfg.checkpoint, port, scratch / f"{name}.log", server)
            try:
                paths[name] = evaluate(
                    cfg,
                    bench,
                    policy_config("openpi", url=f"ws://127.0.0.1:{port}", **openpi),
                    scratch / name,
                )
            finally:
                stop(proc)
        if "lerobot_async" in cfg.path_list:
            print("[serving] lerobot_async …", flush=True)
            ports = [free_port(), free_port()]
            procs = [lerobot_server(p, scratch) for p in ports]
            try:
                policy = policy_config(
                    "lerobot_async", server=",".join(f"127.0.0.1:{p}" for p in ports), path=cfg.checkpoint
                )
                paths["lerobot_async"] = evaluate(cfg, bench, policy, scratch / "lerobot_async")
            finally:
                stop(*procs)
        if "vla_eval" in cfg.path_list:
            print("[serving] vla_eval …", flush=True)
            ports = [free_port(), free_port()]
            procs = [vla_eval_server(cfg.checkpoint, p, scratch / f"vla_eval_{p}.log") for p in ports]
            try:
                urls = ",".join(f"ws://127.0.0.1:{p}" for p in ports)
                policy = policy_config(
                    "vla_eval",
                    url=urls,
                    image_format=cfg.vla_eval_image_format,
                    images_every=cfg.vla_eval_images_every,
                    **openpi,
                )
                paths["vla_eval"] = evaluate(cfg, bench, policy, scratch / "vla_eval")
            finally:
                stop(*procs)
        reference = paths["in_process"]["_rows"]
        for path in paths.values():
            rows = path.pop("_rows")
            path["over_in_process"] = round(
                path["episodes_per_hour"] / paths["in_process"]["episodes_per_hour"], 3
            )
            path["rows_equal_in_process"] = bool(rows.equals(reference))
            path["rows_differing"] = int((rows != reference).any(axis=1).sum())
        results["episodes_per_hour"] = paths

        if "requests_per_second" in cfg.path_list:
            print("[serving] requests per second …", flush=True)
            results["requests_per_second"] = rps_only(cfg, bench, scratch)
        results["provenance"] = entry | {"ended": now()}
        Path(cfg.output).parent.mkdir(parents=True, exist_ok=True)
        Path(cfg.output).write_text(json.dumps(results, indent=2))
        return results
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


def _summary(cfg: ServingConfig, results: dict) -> None:
    for name, path in results["episodes_per_hour"].items():
        print(
            f"[serving] {name:14s} {path['episodes_per_hour']:8.0f} episodes/h  ({path['over_in_process']:.2f}× "
            f"in-process; rows equal: {path['rows_equal_in_process']})"
        )
    rps = results.get("requests_per_second")
    if rps is None:
        return
    print(
        f"[serving] {rps['clients']} clients: serve_policy {rps['serve_policy']['requests_per_second']} req/s, "
        f"openpi-server {rps['openpi_server']['requests_per_second']} req/s ({rps['batching_speedup']}×) → {cfg.output}"
    )


def main(args: list[str] | None = None) -> dict:
    return cli_main(ServingConfig, run, _summary, args=args)


if __name__ == "__main__":
    main()
