"""Seconds per inference call of LeRobot's ACT with LIBERO's features, per batch size, on the CPU or a GPU.

    python -m benchmarks.policy_latency --device=cpu --batch_sizes=[1,8,16] \
        --output=outputs/bench/policy_latency_cpu.json [--image_size=256] [--calls=20] [--warmup=3] [--threads=N]
    python -m benchmarks.policy_latency --device=cuda --batch_sizes=[1,8,16,32] \
        --output=outputs/bench/policy_latency_cuda.json

Builds LeRobot's own `ACTPolicy` from an `ACTConfig` with untrained weights (no checkpoint, no pretrained backbone)
and the recipe docs/libero.md trains on LIBERO: dim_model 256, dim_feedforward 1024, 2 encoder and 2 VAE-encoder
layers, chunk_size 20, n_action_steps 10 (LeRobot's defaults otherwise: ResNet-18, 8 heads, 1 decoder layer). Its
features are LIBERO's in LeRobot's layout: two cameras `observation.images.image` (agentview) and
`observation.images.image2` (wrist), 3×256×256 (`--image_size`), an 8-D `observation.state`, a 7-D `action`.

Per batch size B it times `predict_action_chunk` (what `select_action` runs when its action queue is empty: one
forward of the model, images to a 20-step chunk) on a batch already on the device, after `--warmup` untimed calls,
with `torch.cuda.synchronize()` around each call on cuda, and writes the median (and min, max) of `--calls` calls.
On cuda it also times the same call with the batch first copied from host memory (`per_call_s_with_h2d`). LeRobot's
pre/post-processors (normalization, device move) are not in the timed call.

Per batch size the JSON holds the seconds per call, the seconds per episode-step-equivalent (per call /
n_action_steps: a policy that asks once per chunk pays this per control step) and per sample (per call / B), and
whether batching pays: the per-sample time at B against batch 1 (`speedup_per_sample_vs_batch_1` > 1 means that B
workers sharing one forward each wait less per step than B single-sample forwards would cost). Also the device name
(torch.cuda.get_device_name, or the CPU model), torch and lerobot versions, torch's thread count, the parameter count.

Imports only torch and LeRobot's ACT modules, so it runs where RoboView's other dependencies are absent. By default
(`--import_mode=act_only`) it loads `lerobot.policies.act.{configuration,modeling}_act` without running the
`__init__` of `lerobot.policies` and `lerobot.policies.act`, which import every policy's config and the processors
(LeRobot's dataset stack: datasets, av); what remains needs draccus, gymnasium, huggingface-hub, safetensors,
einops, torchvision and transformers. `--import_mode=package` imports them the ordinary way.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import json
import os
import platform
import statistics
import sys
import time
import types
from pathlib import Path

CAMERAS = ("observation.images.image", "observation.images.image2")  # LeRobot's LIBERO keys: agentview, wrist
STATE_DIM = 8  # eef pos (3) + axis-angle (3) + gripper qpos (2)
ACTION_DIM = 7  # delta pos (3) + delta rot (3) + gripper
# docs/libero.md's ACT recipe (lerobot-train --policy.type=act ...)
RECIPE = {
    "dim_model": 256,
    "dim_feedforward": 1024,
    "n_encoder_layers": 2,
    "n_vae_encoder_layers": 2,
    "chunk_size": 20,
    "n_action_steps": 10,
    "pretrained_backbone_weights": None,
}


def _bare_package(name: str) -> None:
    """Register package `name` in sys.modules with its path but without running its __init__."""
    if name in sys.modules:
        return
    spec = importlib.util.find_spec(name)
    if spec is None or spec.submodule_search_locations is None:
        raise ImportError(f"no package {name}")
    module = types.ModuleType(name)
    module.__path__ = list(spec.submodule_search_locations)
    module.__spec__ = spec
    module.__file__ = spec.origin
    module.__package__ = name
    sys.modules[name] = module
    parent, _, child = name.rpartition(".")
    if parent:
        setattr(sys.modules[parent], child, module)


def import_act(mode: str):
    """(ACTConfig, ACTPolicy, PolicyFeature, FeatureType, lerobot version)."""
    import lerobot

    if mode == "act_only":
        for package in ("lerobot.policies", "lerobot.policies.act"):
            _bare_package(package)
    configuration = importlib.import_module("lerobot.policies.act.configuration_act")
    modeling = importlib.import_module("lerobot.policies.act.modeling_act")
    from lerobot.configs.types import FeatureType, PolicyFeature

    return configuration.ACTConfig, modeling.ACTPolicy, PolicyFeature, FeatureType, lerobot.__version__


def cpu_model() -> str | None:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or None


def build_policy(args: argparse.Namespace, act):
    import torch

    ACTConfig, ACTPolicy, PolicyFeature, FeatureType, _ = act
    size = args.image_size
    config = ACTConfig(
        input_features={
            **{key: PolicyFeature(type=FeatureType.VISUAL, shape=(3, size, size)) for key in CAMERAS},
            "observation.state": PolicyFeature(type=FeatureType.STATE, shape=(STATE_DIM,)),
        },
        output_features={"action": PolicyFeature(type=FeatureType.ACTION, shape=(ACTION_DIM,))},
        device=args.device,
        push_to_hub=False,
        **RECIPE,
    )
    torch.manual_seed(args.seed)
    policy = ACTPolicy(config).to(args.device)
    policy.eval()
    return policy, config


def make_batch(batch_size: int, image_size: int, device: str, seed: int) -> dict:
    import torch

    generator = torch.Generator().manual_seed(seed)
    batch = {
        key: torch.rand(batch_size, 3, image_size, image_size, generator=generator) for key in CAMERAS
    }  # LeRobot's images: float in [0, 1], channels first
    batch["observation.state"] = torch.randn(batch_size, STATE_DIM, generator=generator)
    return {key: value.to(device) for key, value in batch.items()}


def time_calls(call, n: int, sync) -> list[float]:
    times = []
    for _ in range(n):
        sync()
        start = time.perf_counter()
        call()
        sync()
        times.append(time.perf_counter() - start)
    return times


def measure(args: argparse.Namespace, policy, config, batch_size: int) -> dict:
    import torch

    cuda = args.device.startswith("cuda")
    sync = torch.cuda.synchronize if cuda else (lambda: None)
    batch = make_batch(batch_size, args.image_size, args.device, args.seed + batch_size)
    out = {}

    def call(b=batch):
        return policy.predict_action_chunk(b)

    for _ in range(args.warmup):
        actions = call()
    sync()
    shape = list(actions.shape)
    if shape != [batch_size, config.chunk_size, ACTION_DIM]:
        raise SystemExit(f"predict_action_chunk returned {shape}, not [{batch_size}, {config.chunk_size}, 7]")
    times = time_calls(call, args.calls, sync)
    per_call = statistics.median(times)
    out.update(
        {
            "batch_size": batch_size,
            "per_call_s": per_call,
            "per_call_s_min": min(times),
            "per_call_s_max": max(times),
            "per_step_equivalent_s": per_call / config.n_action_steps,
            "per_sample_s": per_call / batch_size,
            "per_sample_step_equivalent_s": per_call / (batch_size * config.n_action_steps),
            "calls": len(times),
            "chunk_shape": shape,
        }
    )
    if cuda:
        host = {key: value.cpu() for key, value in batch.items()}

        def call_h2d():
            return policy.predict_action_chunk({key: value.to(args.device) for key, value in host.items()})

        for _ in range(max(1, args.warmup // 2)):
            call_h2d()
        out["per_call_s_with_h2d"] = statistics.median(time_calls(call_h2d, args.calls, sync))
        out["peak_memory_bytes"] = torch.cuda.max_memory_allocated()
    return out


def parse_batch_sizes(text: str) -> list[int]:
    sizes = [int(x) for x in text.strip().strip("[]").replace(" ", "").split(",") if x]
    if not sizes or min(sizes) < 1:
        raise argparse.ArgumentTypeError(
            f"--batch_sizes {text!r}: a list of positive integers, like [1,8,16]"
        )
    return sizes


def parse(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--device", default="cpu", help="cpu, cuda or cuda:N")
    parser.add_argument(
        "--batch_sizes",
        "--batch-sizes",
        type=parse_batch_sizes,
        default=[1, 8, 16],
        help="batch sizes timed, comma-separated or [1,8,16]",
    )
    parser.add_argument(
        "--image_size", "--image-size", type=int, default=256, help="square camera side (pixels)"
    )
    parser.add_argument(
        "--calls", type=int, default=20, help="timed calls per batch size (the median is reported)"
    )
    parser.add_argument("--warmup", type=int, default=3, help="untimed calls per batch size before timing")
    parser.add_argument(
        "--threads", type=int, default=None, help="torch.set_num_threads (default: torch's own)"
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the untrained weights and the inputs")
    parser.add_argument(
        "--import_mode",
        choices=("act_only", "package"),
        default="act_only",
        help="act_only: LeRobot's ACT modules alone (no dataset stack); package: LeRobot as a whole",
    )
    parser.add_argument("--output", default=None, help="default: outputs/bench/policy_latency_<device>.json")
    args = parser.parse_args(argv)
    if min(args.calls, args.warmup + 1, args.image_size) < 1:
        parser.error("--calls and --image_size must be ≥ 1, --warmup ≥ 0")
    if args.output is None:
        args.output = f"outputs/bench/policy_latency_{args.device.split(':')[0]}.json"
    return args


def main(argv: list[str] | None = None) -> dict:
    args = parse(argv)
    start = time.perf_counter()
    import torch

    if args.threads is not None:
        torch.set_num_threads(args.threads)
    if args.device.startswith("cuda"):
        if not torch.cuda.is_available():
            raise SystemExit("--device=cuda but torch sees no CUDA device")
        device_name = torch.cuda.get_device_name(torch.device(args.device))
    else:
        device_name = cpu_model()
    t0 = time.perf_counter()
    act = import_act(args.import_mode)
    import_s = time.perf_counter() - t0
    policy, config = build_policy(args, act)
    rows = {}
    for batch_size in args.batch_sizes:
        rows[str(batch_size)] = row = measure(args, policy, config, batch_size)
        print(
            f"B={batch_size:3d}: {1000 * row['per_call_s']:8.2f} ms/call, "
            f"{1000 * row['per_step_equivalent_s']:7.3f} ms/step-equivalent, "
            f"{1000 * row['per_sample_s']:7.3f} ms/sample"
            + (
                f", {1000 * row['per_call_s_with_h2d']:.2f} ms/call with H2D"
                if "per_call_s_with_h2d" in row
                else ""
            ),
            flush=True,
        )
    reference = min(args.batch_sizes, key=lambda b: (b != 1, b))  # batch 1 when measured
    base = rows[str(reference)]["per_sample_s"]
    batching = {
        str(b): {
            "per_sample_s": rows[str(b)]["per_sample_s"],
            f"speedup_per_sample_vs_batch_{reference}": base / rows[str(b)]["per_sample_s"],
            f"per_call_vs_batch_{reference}": rows[str(b)]["per_call_s"] / rows[str(reference)]["per_call_s"],
            "pays": rows[str(b)]["per_sample_s"] < base,
        }
        for b in args.batch_sizes
        if b != reference
    }
    summary = {
        "policy": "lerobot ACTPolicy (untrained, docs/libero.md recipe)",
        "timed": "predict_action_chunk on a batch already on the device",
        "device": args.device,
        "device_name": device_name,
        "config": {
            **{k: getattr(config, k) for k in RECIPE},
            "vision_backbone": config.vision_backbone,
            "n_heads": config.n_heads,
            "n_decoder_layers": config.n_decoder_layers,
            "use_vae": config.use_vae,
            "cameras": list(CAMERAS),
            "image_shape": [3, args.image_size, args.image_size],
            "state_dim": STATE_DIM,
            "action_dim": ACTION_DIM,
        },
        "parameters": sum(p.numel() for p in policy.parameters()),
        "warmup_calls": args.warmup,
        "timed_calls": args.calls,
        "batch_sizes": rows,
        "batching_reference": reference,
        "batching": batching,
        "platform": {
            "python": sys.version.split()[0],
            "platform": platform.platform(),
            "machine": platform.machine(),
            "cpu_model": cpu_model(),
            "cpu_count": os.cpu_count(),
            "torch_threads": torch.get_num_threads(),
            "torch": torch.__version__,
            "cuda": torch.version.cuda,
            "lerobot": act[4],
            "import_mode": args.import_mode,
            "import_s": import_s,
        },
        "total_s": time.perf_counter() - start,
    }
    for b, row in batching.items():
        print(
            f"B={b} vs B={reference}: per-sample speedup "
            f"{row[f'speedup_per_sample_vs_batch_{reference}']:.2f}x ({'pays' if row['pays'] else 'does not pay'})"
        )
    path = Path(args.output)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(summary, indent=2) + "\n")
    print(f"{device_name} ({args.device}), torch {torch.__version__}, lerobot {act[4]}: wrote {path}")
    return summary


if __name__ == "__main__":
    main()
