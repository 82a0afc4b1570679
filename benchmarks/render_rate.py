"""Render throughput: the env's observation path vs a bare `mujoco.Renderer` loop on the same scene.

    python -m benchmarks.render_rate [--frames 200] [--size 224]

Prints frames per second for (a) a bare Renderer loop, (b) the env's observation rendering (all
four cameras, as collection uses it), (c) the high-quality preset, and the ratio (b)/(a).
"""

from __future__ import annotations

import argparse
import json
import os
import time

os.environ.setdefault("MUJOCO_GL", "egl")

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from roboview_data.sim.cameras import ALL_CAMERAS  # noqa: E402
from roboview_data.tasks.env import TaskEnv  # noqa: E402
from roboview_data.tasks import make_env  # noqa: E402


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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=200)
    parser.add_argument("--size", type=int, default=224)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    results = {}
    for quality in ("fast", "high"):
        env = make_env(image_size=args.size, quality=quality)
        env.reset()
        # Interleaved rounds and medians: llvmpipe timings drift with whatever else the machine does.
        rounds = [(bare_fps(env, args.frames), pipeline_fps(env, args.frames)) for _ in range(args.rounds)]
        results[quality] = {"bare_fps": float(np.median([r[0] for r in rounds])),
                            "pipeline_fps": float(np.median([r[1] for r in rounds]))}
        env.close()
    fast = results["fast"]
    results["pipeline_over_bare"] = fast["pipeline_fps"] / fast["bare_fps"]
    print(json.dumps(results, indent=2))


if __name__ == "__main__":
    main()
