"""Render throughput: the env's observation path vs a bare `mujoco.Renderer` loop on the same scene.

    python -m benchmarks.render_rate [--frames=200] [--size=224] [--rounds=3]

Prints frames per second for (a) a bare Renderer loop, (b) the env's observation rendering (all
four cameras, as collection uses it), (c) the high-quality preset, and the ratio (b)/(a).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from roboview.pipelines._cli import cli_main  # first: it sets the headless GL defaults before MuJoCo loads
from roboview.sim.cameras import ALL_CAMERAS  # noqa: E402
from roboview.tasks import make_env  # noqa: E402
from roboview.tasks.env import TaskEnv  # noqa: E402


@dataclass
class RenderRateConfig:
    # Frames rendered per measurement.
    frames: int = 200
    # Side of the square camera images (pixels).
    size: int = 224
    # Interleaved rounds per quality preset; the medians are reported.
    rounds: int = 3


def bare_fps(env: TaskEnv, frames: int) -> float:
    renderer = mujoco.Renderer(env.model, env.image_size, env.image_size)
    cams = [env.scene.ids.cameras[c] for c in ALL_CAMERAS]
    renderer.update_scene(env.data, camera=cams[0])
    renderer.render()
    start = time.perf_counter()
    for i in range(frames):
        renderer.update_scene(env.data, camera=cams[i % len(cams)])
        renderer.render()
    fps = frames / (time.perf_counter() - start)
    renderer.close()
    return fps


def pipeline_fps(env: TaskEnv, frames: int) -> float:
    env._observation()
    calls = max(1, frames // len(env.cameras))
    start = time.perf_counter()
    for _ in range(calls):
        env._observation()
    return calls * len(env.cameras) / (time.perf_counter() - start)


def run(cfg: RenderRateConfig) -> dict:
    if cfg.frames < 1 or cfg.rounds < 1:
        raise ValueError(f"--frames={cfg.frames} and --rounds={cfg.rounds} must be positive counts")
    results = {}
    for quality in ("fast", "high"):
        env = make_env(image_size=cfg.size, quality=quality)
        env.reset()
        # Interleaved rounds and medians: llvmpipe timings drift with whatever else the machine does.
        rounds = [(bare_fps(env, cfg.frames), pipeline_fps(env, cfg.frames)) for _ in range(cfg.rounds)]
        results[quality] = {
            "bare_fps": float(np.median([r[0] for r in rounds])),
            "pipeline_fps": float(np.median([r[1] for r in rounds])),
        }
        env.close()
    fast = results["fast"]
    results["pipeline_over_bare"] = fast["pipeline_fps"] / fast["bare_fps"]
    return results


def _summary(cfg: RenderRateConfig, results: dict) -> None:
    print(json.dumps(results, indent=2))


def main(args: list[str] | None = None) -> dict:
    return cli_main(RenderRateConfig, run, _summary, args=args)


if __name__ == "__main__":
    main()
