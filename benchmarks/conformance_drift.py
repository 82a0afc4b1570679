"""What the conformance tolerances admit: the check's figures under deliberate changes to the scene and physics.

    python -m benchmarks.conformance_drift --benchmark.path=outputs/demo/benchmark \
        [--output=outputs/bench/conformance_drift.json]

Each change is applied to the compiled model right after every reset of the check's envs (in this process), and
the benchmark's reference sample is re-rendered and re-simulated as `roboview.pipelines.verify --benchmark.path` does:
the object's color +0.04 in sRGB, every light's level −10 %, a checker material on the table, the scene cameras
moved 1 cm, every geom's friction × 0.9 and × 0.7, a 0.0021 s timestep. Prints the verdict and the largest
deviations per change (docs/benchmark.md, "Identity and conformance"). Another renderer or MuJoCo is measured by
running `roboview.pipelines.verify` under it (GALLIUM_DRIVER=softpipe; PYTHONPATH with another mujoco).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np

from roboview.pipelines._cli import BenchmarkPath, cli_main


def _color(env) -> None:
    geom = env.scene.active_geom
    env.model.geom_rgba[geom][:3] = np.clip(env.model.geom_rgba[geom][:3] + 0.04, 0, 1)


def _light(env) -> None:
    env.model.light_diffuse[:] *= 0.9


def _texture(env) -> None:
    env.model.geom_matid[env.scene.ids.table_geom] = env.model.material("table_checker_light").id


def _camera(env) -> None:
    for name in ("front", "left_top"):
        env.model.cam_pos[env.scene.ids.cameras[name]] += [0.01, 0.0, 0.0]


def _friction(scale: float):
    def change(env) -> None:
        if not hasattr(env, "_built_friction"):
            env._built_friction = env.model.geom_friction[:, 0].copy()
        env.model.geom_friction[:, 0] = scale * env._built_friction

    return change


def _timestep(env) -> None:
    env.model.opt.timestep = 0.0021


CHANGES = {
    "object color +0.04": _color,
    "lights -10 %": _light,
    "table material": _texture,
    "cameras +1 cm": _camera,
    "friction x0.9": _friction(0.9),
    "friction x0.7": _friction(0.7),
    "timestep 0.0021 s": _timestep,
}


@dataclass
class DriftConfig:
    benchmark: BenchmarkPath = field(default_factory=lambda: BenchmarkPath("outputs/demo/benchmark"))
    # Where the figures go (JSON).
    output: str = "outputs/bench/conformance_drift.json"


def run(cfg: DriftConfig) -> dict:
    from roboview.benchmark import conformance
    from roboview.tasks.env import TaskEnv

    reset = TaskEnv.reset
    out = {}
    for name, change in {"none": None, **CHANGES}.items():

        def patched(self, *args, _change=change, **kwargs):
            obs = reset(self, *args, **kwargs)
            if _change is not None:
                _change(self)
                mujoco.mj_forward(self.model, self.data)
            return obs

        TaskEnv.reset = patched
        try:
            report = conformance.check(Path(cfg.benchmark.path))
        finally:
            TaskEnv.reset = reset
        out[name] = {"verdict": report.verdict, **report.drift}
        d = report.drift
        print(
            f"[conformance_drift] {name:<20} {report.verdict:<10} images identical {d['images_identical']}/{d['images']}, "
            f"≤ {d['pixel_fraction_max']:.2%} differing, region px ≤ {d['region_pixels_max']}; rollouts identical "
            f"{d['physics_identical']}/{d['physics']}, joints ≤ {d['joint_max']:.1e} rad, object ≤ "
            f"{d['object_error_m_max']:.1e} m",
            flush=True,
        )
    Path(cfg.output).parent.mkdir(parents=True, exist_ok=True)
    Path(cfg.output).write_text(json.dumps(out, indent=2))
    return out


def main(args: list[str] | None = None) -> dict:
    return cli_main(DriftConfig, run, None, (ValueError,), args)


if __name__ == "__main__":
    main()
