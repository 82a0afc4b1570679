"""LIBERO render rate: RoboView's observation path against a bare render of the same scene.

    python -m benchmarks.libero_render [--task=libero_object/0] [--steps=30] [--image_size=256]
        [--output=outputs/bench/libero_render.json]

Why: the `libero` task hands policies frames rendered from the snapshot robosuite's camera sample took (so they are
the frames eager rendering gives), flipped upright. This measures what that costs over rendering the live scene
directly with robosuite's own camera sensors, both cameras per step, same env, same steps (target ≥ 0.9). Also
reports physics alone (no frame read) and a reset's time. Writes a JSON and prints one line per rate.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

from roboview.core.cli import cli_main  # first: it sets the headless GL defaults before MuJoCo loads


@dataclass
class LiberoRenderConfig:
    # The LIBERO task (`<suite>/<task id>`) whose scene is rendered.
    task: str = "libero_object/0"
    # Control steps timed per mode.
    steps: int = 30
    # Image side of both cameras (LeRobot's LiberoEnv renders 256).
    image_size: int = 256
    # JSON file the rates are written to.
    output: str = "outputs/bench/libero_render.json"

    def __post_init__(self) -> None:
        if self.steps < 1 or self.image_size < 16:
            raise ValueError(f"--steps={self.steps} must be ≥ 1 and --image_size={self.image_size} ≥ 16")


def _rate(env, steps: int, read) -> float:
    """Steps per second of `steps` zero actions, calling `read(obs)` after each."""
    import numpy as np

    action = np.zeros(7, np.float32)
    start = time.perf_counter()
    for _ in range(steps):
        obs, *_ = env.step(action)
        read(obs)
    return steps / (time.perf_counter() - start)


def run(cfg: LiberoRenderConfig) -> dict:
    from roboview.libero.task import CAMERAS, baseline_libero_instance
    from roboview.tasks import make_env

    env = make_env("libero", cameras=("agentview", "wrist"), image_size=cfg.image_size)
    try:
        start = time.perf_counter()
        env.reset(seed=0, options={"instance": baseline_libero_instance(cfg.task)})
        reset_s = time.perf_counter() - start
        world = env.libero_world
        physics = _rate(env, cfg.steps, lambda obs: None)
        pipeline = _rate(
            env, cfg.steps, lambda obs: [obs[f"observation.images.{c}"] for c in ("agentview", "wrist")]
        )
        bare = _rate(env, cfg.steps, lambda obs: [world.render(CAMERAS[c]) for c in ("agentview", "wrist")])
    finally:
        env.close()
    out = {
        "task": cfg.task,
        "image_size": cfg.image_size,
        "reset_s": round(reset_s, 2),
        "steps_per_s_physics": round(physics, 2),
        "steps_per_s_observation_path": round(pipeline, 2),
        "steps_per_s_bare_render": round(bare, 2),
        "ratio": round(pipeline / bare, 3),
    }
    Path(cfg.output).parent.mkdir(parents=True, exist_ok=True)
    Path(cfg.output).write_text(json.dumps(out, indent=2) + "\n")
    return out


def _summary(cfg: LiberoRenderConfig, out: dict) -> None:
    print(
        f"[libero_render] {out['task']} at {out['image_size']}²: physics alone {out['steps_per_s_physics']} steps/s; "
        f"both cameras read through the observation path {out['steps_per_s_observation_path']}/s, rendered bare "
        f"{out['steps_per_s_bare_render']}/s: {out['ratio']}× (target ≥ 0.9); reset {out['reset_s']} s → {cfg.output}"
    )


def main(args: list[str] | None = None) -> dict:
    return cli_main(LiberoRenderConfig, run, _summary, (ValueError,), args)


if __name__ == "__main__":
    main()
