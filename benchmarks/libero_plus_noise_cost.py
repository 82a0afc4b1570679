"""What LIBERO-plus's sensor noise costs a step: a `liberoplus` env at 256² stepped with the agentview and wrist frames
read every step (as a policy reads them), clean and under each noise type, and each corruption alone on a 256² frame,
RoboView's (roboview.libero.corruptions) and, where its package's functions load, LIBERO-plus's own.

    python -m benchmarks.libero_plus_noise_cost [--severity=5] [--steps=20] [--frames=5]
        [--output=outputs/liberoplus/noise_bench/cost.json]

Writes a JSON (per type: ms per env step, ms per corruption, RoboView's and LIBERO-plus's) and prints a table.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from roboview.core.cli import cli_main


@dataclass
class NoiseCostConfig:
    # The severity (1–10) of each type measured.
    severity: int = 5
    # Env steps timed per type (after a reset and one untimed step).
    steps: int = 20
    # Corruptions timed per type on a rendered frame.
    frames: int = 5
    # The task the env runs.
    task: str = "libero_object/2"
    # The JSON file the timings are written to.
    output: str = "outputs/liberoplus/noise_bench/cost.json"

    def __post_init__(self) -> None:
        if not 1 <= self.severity <= 10:
            raise ValueError(f"--severity={self.severity}; allowed: 1–10")
        if self.steps < 1 or self.frames < 1:
            raise ValueError(f"--steps={self.steps} and --frames={self.frames} must be ≥ 1")


def step_ms(env, instance, steps: int) -> float:
    """Mean wall time of one env step with both frames read, after a reset and one untimed step."""
    obs, _ = env.reset(seed=instance.seed, options={"instance": instance})
    env.step(np.zeros(7))
    start = time.perf_counter()
    for _ in range(steps):
        obs, *_ = env.step(np.zeros(7))
        obs["observation.images.agentview"], obs["observation.images.wrist"]
    return 1000 * (time.perf_counter() - start) / steps


def theirs() -> dict | None:
    """LIBERO-plus's own noise functions, or None where scikit-image (which they import) is missing."""
    from roboview.libero.corruptions import liberoplus_functions

    try:
        return liberoplus_functions()
    except ImportError:
        return None


def corruption_ms(function, frame: np.ndarray, severity: int, frames: int, pil: bool) -> float:
    from PIL import Image

    image = Image.fromarray(frame) if pil else frame
    start = time.perf_counter()
    for i in range(frames):
        if pil:
            np.random.seed(i)
            function(image, severity=severity)
        else:
            function(image, severity, np.random.RandomState(i))
    return 1000 * (time.perf_counter() - start) / frames


def run(cfg: NoiseCostConfig) -> dict:
    from roboview.libero import corruptions
    from roboview.libero.plus_task import LiberoPlusTaskEnv, baseline_liberoplus_instance
    from roboview.variation.instances import TaskInstance

    env = LiberoPlusTaskEnv(image_size=256)
    base = baseline_liberoplus_instance(cfg.task)
    out: dict = {"config": vars(cfg), "clean_step_ms": step_ms(env, base, cfg.steps), "types": {}}
    frame = np.ascontiguousarray(env.render_camera("agentview")[::-1, ::-1])
    own = theirs()
    for kind in corruptions.TYPES:
        values = base.factor_values | {f"noise_{kind}": str(cfg.severity)}
        instance = TaskInstance("noise", (f"noise_{kind}",), values, "base", "liberoplus")
        corruptions.corrupt(
            frame, corruptions.code_of(kind, cfg.severity), np.random.RandomState(0)
        )  # compiles
        row = {
            "step_ms": step_ms(env, instance, cfg.steps),
            "roboview_ms": corruption_ms(corruptions.FUNCTIONS[kind], frame, cfg.severity, cfg.frames, False),
            "liberoplus_ms": None,
        }
        if own is not None:
            row["liberoplus_ms"] = corruption_ms(own[kind], frame, cfg.severity, cfg.frames, True)
        out["types"][kind] = row
    env.close()
    Path(cfg.output).parent.mkdir(parents=True, exist_ok=True)
    Path(cfg.output).write_text(json.dumps(out, indent=2))
    print(f"clean step: {out['clean_step_ms']:.1f} ms (256², both frames read)")
    for kind, row in out["types"].items():
        theirs_ms = "—" if row["liberoplus_ms"] is None else f"{row['liberoplus_ms']:.1f}"
        print(
            f"{kind:14s} step {row['step_ms']:7.1f} ms  corruption: RoboView {row['roboview_ms']:7.1f} ms, "
            f"LIBERO-plus {theirs_ms} ms"
        )
    return out


def main(argv: list[str] | None = None) -> dict:
    return cli_main(NoiseCostConfig, run, argv)


if __name__ == "__main__":
    main()
