"""Conformance: does this machine render and simulate the benchmark as the machine that built it?

At build time a small reference set is stored in the benchmark folder:

    conformance/reference.json     the sample (instances across splits and values), the rollout length,
                                   the stored image side, the tolerances, and per physics instance the state
                                   after the scripted expert's first `ROLLOUT_STEPS` steps
    conformance/<instance_id>.png  the observed cameras' reset images, side by side, down-sampled

`check(benchmark)` re-renders and re-simulates the sample on this machine and measures, per image, the share
of pixels that differ, the largest level difference, PSNR and the pixels of differing *regions* (what is left
of the map of differing pixels after a 3×3 erosion: a rasterizer's edge pixels are lines one or two pixels
wide and erode away, a changed color, texture, light or camera leaves whole regions); per physics instance,
the largest joint difference and the object's position error. Each check, and the whole, gets a verdict:

    identical    bit for bit
    equivalent   images: at most `pixel_fraction` of the pixels differ and no differing region survives the
                 erosion; physics: joints within `joint_rad`, the object within `object_m`
    different    anything more: results from this stack must not be compared with the benchmark's

What the tolerances admit, measured: docs/benchmark.md, "Conformance".
"""

from __future__ import annotations

import hashlib
import io
import json
import logging
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image
from scipy import ndimage

from roboview.benchmark.format import CONFORMANCE as FOLDER
from roboview.benchmark.format import (
    REFERENCE,
    Benchmark,
    BenchmarkError,
    benchmark_format,
    instance_from_record,
)
from roboview.core import files
from roboview.core.files import files_sha256
from roboview.variation.factors import DEFAULT_TASK

log = logging.getLogger(__name__)

FORMAT = 1
SAMPLE_SIZE = 24  # instances whose reset images are compared
PHYSICS_SAMPLE = 12  # of those, instances whose expert rollout is compared
ROLLOUT_STEPS = 40  # control steps: approach, grasp and lift (the object is in the air by step 30)
STORED_SIDE = 112  # stored images are box-downsampled by an integer factor to at most this side

VERDICTS = ("identical", "equivalent", "different")


@dataclass(frozen=True)
class Tolerances:
    """What `equivalent` admits (docs/benchmark.md, "Conformance", says what they were measured against)."""

    # Largest share of an image's pixels that may differ (a rasterizer's edge pixels: ≈ 0.1 % measured).
    pixel_fraction: float = 0.01
    # Pixels of differing regions (left after a 3×3 erosion of the differing-pixel map) an image may hold.
    region_pixels: int = 0
    # Largest joint difference (rad) and object position error (m) after the rollout.
    joint_rad: float = 1e-3
    object_m: float = 1e-3


class ConformanceError(RuntimeError):
    """This machine's stack renders or simulates the benchmark differently from the one that built it."""


def worst(verdicts) -> str:
    """The worst of `verdicts` (identical < equivalent < different); identical for none."""
    return max(verdicts, key=VERDICTS.index, default="identical")


def downsample(image: np.ndarray, side: int = STORED_SIDE) -> np.ndarray:
    """Box-average `image` by the smallest integer factor that brings its side to at most `side`."""
    factor = max(1, -(-image.shape[0] // side))
    h, w = (image.shape[0] // factor) * factor, (image.shape[1] // factor) * factor
    blocks = image[:h, :w].reshape(h // factor, factor, w // factor, factor, -1).astype(np.float64)
    return np.rint(blocks.mean(axis=(1, 3))).astype(np.uint8)


def _png(frames: list[np.ndarray]) -> bytes:
    buf = io.BytesIO()
    Image.fromarray(np.concatenate(frames, axis=1)).save(buf, format="PNG", optimize=False, compress_level=6)
    return buf.getvalue()


def _unpng(data: bytes, n: int) -> list[np.ndarray]:
    sheet = np.asarray(Image.open(io.BytesIO(data)).convert("RGB"))
    return np.split(sheet, n, axis=1)


# --- the sample and what is measured on it ---------------------------------------------------------------


def sample(by_split: dict[str, list[dict]], size: int = SAMPLE_SIZE) -> list[dict]:
    """A fixed sample of accepted rows: round-robin over the splits, each split's picks spread evenly over its
    rows in their stored order (so over its values and contexts), last row first: a split's first pick is its
    last context's last value, away from the baseline every split shares. A pure function of the rows: the
    builder and every checker take the same sample."""
    picks: dict[str, list[dict]] = {}
    splits = sorted(by_split)
    per_split = -(-size // max(1, len(splits)))
    for split in splits:
        rows = by_split[split]
        k = min(per_split, len(rows))
        idx = (
            sorted({round(i * (len(rows) - 1) / max(1, k - 1)) for i in range(k)}, reverse=True) if k else []
        )
        picks[split] = [rows[i] for i in idx]
    out: list[dict] = []
    while len(out) < size and any(picks.values()):
        for split in splits:
            if picks[split] and len(out) < size:
                out.append(picks[split].pop(0))
    return out


def observe(env, expert, instance, steps: int = 0) -> tuple[list[np.ndarray], dict[str, list[float]] | None]:
    """The observed cameras' reset images (down-sampled) of `instance` at its seed, and with `steps` > 0 the
    state after `expert` (the task's scripted expert, bound to `env`) ran that many steps: 7 joints + gripper,
    object position and orientation."""
    from roboview.tasks.env import IMAGE_KEY

    obs, _ = env.reset(seed=instance.seed, options={"instance": instance})
    images = [downsample(np.asarray(obs[IMAGE_KEY.format(cam)])) for cam in env.world.observed_cameras]
    if not steps:
        return images, None
    expert.reset()
    for _ in range(steps):
        env.step(expert.select_action(None))
    pos, quat = env.object_pose()
    return images, {
        "state": env.state().astype(float).tolist(),
        "object_pos": pos.tolist(),
        "object_quat": quat.tolist(),
    }


class _Envs:
    """One env and its scripted expert per task (the observed cameras at the benchmark's image size, rendering
    when read), made on first use."""

    def __init__(self, image_size: int) -> None:
        self.image_size, self.envs, self.experts = image_size, {}, {}
        self.stack: dict | None = None  # the stack, described from the first env before any instance
        self.cameras: tuple[str, ...] = ()  # the observed cameras of the benchmark's world (its first env's)

    def __call__(self, task: str):
        from roboview.sim import stack
        from roboview.tasks import load_task, make_env

        if task not in self.envs:
            self.cameras = load_task(task).env_class().world.observed_cameras
            self.envs[task] = make_env(task, cameras=self.cameras, image_size=self.image_size, lazy=True)
            self.experts[task] = load_task(task).make_expert(self.envs[task])
            if self.stack is None:
                self.stack = stack.describe(self.envs[task])
        return self.envs[task], self.experts[task]

    def close(self) -> None:
        for env in self.envs.values():
            env.close()


# --- building the reference -----------------------------------------------------------------------------


def write_reference(
    out: Path, by_split: dict[str, list[dict]], image_size: int, tolerances: Tolerances = Tolerances()
) -> dict:
    """Store the reference sample of the rows `by_split` (accepted rows, as written) under out/conformance;
    returns the simulation stack that rendered it (roboview.sim.stack)."""
    folder = Path(out) / FOLDER
    folder.mkdir(parents=True, exist_ok=True)
    envs = _Envs(image_size)
    entries, physics = [], {}
    try:
        for row in sample(by_split):
            instance = instance_from_record(row)
            env, expert = envs(instance.task)
            # The first PHYSICS_SAMPLE instances the task's expert scripts (LIBERO's: not libero_goal, libero_10).
            scripted = expert.scripts(instance)
            steps = ROLLOUT_STEPS if scripted and len(physics) < PHYSICS_SAMPLE else 0
            images, state = observe(env, expert, instance, steps)
            (folder / f"{row['instance_id']}.png").write_bytes(_png(images))
            entries.append({k: v for k, v in row.items() if k not in ("fairness", "preview")})
            if state is not None:
                physics[row["instance_id"]] = state
    finally:
        envs.close()
    reference = {
        "format": FORMAT,
        "cameras": list(envs.cameras),
        "image_size": image_size,
        "stored_side": STORED_SIDE,
        "rollout_steps": ROLLOUT_STEPS,
        "tolerances": asdict(tolerances),
        "instances": entries,
        "physics": physics,
    }
    (folder / REFERENCE).write_text(json.dumps(reference, indent=2, sort_keys=True) + "\n")
    return envs.stack


# --- checking -------------------------------------------------------------------------------------------


def compare_images(ref: np.ndarray, new: np.ndarray, tol: Tolerances) -> dict[str, Any]:
    """Pixels that differ (share), largest level difference, PSNR (dB; null when identical), pixels of
    differing regions, and the verdict."""
    if ref.shape != new.shape:
        return {
            "fraction": 1.0,
            "max_diff": 255,
            "psnr": 0.0,
            "region_pixels": int(np.prod(ref.shape[:2])),
            "verdict": "different",
            "note": f"shape {new.shape} vs {ref.shape}",
        }
    diff = np.abs(ref.astype(np.int16) - new.astype(np.int16))
    mask = diff.max(axis=-1) > 0
    fraction = float(mask.mean())
    mse = float((diff.astype(np.float64) ** 2).mean())
    regions = int(ndimage.binary_erosion(mask, structure=np.ones((3, 3), bool)).sum())
    if not mask.any():
        verdict = "identical"
    elif fraction <= tol.pixel_fraction and regions <= tol.region_pixels:
        verdict = "equivalent"
    else:
        verdict = "different"
    return {
        "fraction": fraction,
        "max_diff": int(diff.max()),
        "psnr": None if mse == 0 else float(10 * np.log10(255.0**2 / mse)),
        "region_pixels": regions,
        "verdict": verdict,
    }


def compare_physics(ref: dict, new: dict, tol: Tolerances) -> dict[str, Any]:
    """Largest joint / gripper difference, object position error (m), and the verdict."""
    joint = float(np.max(np.abs(np.subtract(ref["state"], new["state"]))))
    obj = float(np.linalg.norm(np.subtract(ref["object_pos"], new["object_pos"])))
    same = ref == new
    verdict = (
        "identical"
        if same
        else "equivalent"
        if joint <= tol.joint_rad and obj <= tol.object_m
        else "different"
    )
    return {"joint_max": joint, "object_error_m": obj, "verdict": verdict}


@dataclass
class Report:
    """The outcome of a conformance check: one row per check, the verdict, and a summary of the drift."""

    verdict: str
    checks: list[dict] = field(default_factory=list)
    seconds: float = 0.0
    tolerances: dict = field(default_factory=dict)
    # The stack the check ran on (roboview.sim.stack), and how it differs from the one that built the benchmark.
    stack: dict = field(default_factory=dict)
    stack_differences: list[str] = field(default_factory=list)

    @property
    def drift(self) -> dict[str, Any]:
        """The largest deviations measured (what results files record)."""
        images = [c for c in self.checks if c["check"] == "image"]
        physics = [c for c in self.checks if c["check"] == "physics"]
        psnrs = [c["psnr"] for c in images if c["psnr"] is not None]
        return {
            "images": len(images),
            "images_identical": sum(c["verdict"] == "identical" for c in images),
            "pixel_fraction_max": max((c["fraction"] for c in images), default=0.0),
            "max_level_diff": max((c["max_diff"] for c in images), default=0),
            "psnr_min": min(psnrs) if psnrs else None,
            "region_pixels_max": max((c["region_pixels"] for c in images), default=0),
            "physics": len(physics),
            "physics_identical": sum(c["verdict"] == "identical" for c in physics),
            "joint_max": max((c["joint_max"] for c in physics), default=0.0),
            "object_error_m_max": max((c["object_error_m"] for c in physics), default=0.0),
        }

    def record(self) -> dict[str, Any]:
        """What provenance and results record: verdict, drift, seconds."""
        return {
            "verdict": self.verdict,
            "drift": self.drift,
            "seconds": round(self.seconds, 2),
            "stack": self.stack,
            "stack_differences": self.stack_differences,
        }

    def lines(self) -> list[str]:
        """One line per check with its measured figures, then the verdict."""
        out = []
        for c in self.checks:
            where = f"{c['split']}={c['value']}"
            if c["check"] == "image":
                psnr = "inf" if c["psnr"] is None else f"{c['psnr']:.1f}"
                out.append(
                    f"{c['verdict']:<10}  image    {c['camera']:<8} {where:<34} differing {c['fraction']:7.3%}  "
                    f"max Δ {c['max_diff']:3d}  PSNR {psnr:>5} dB  region px {c['region_pixels']}"
                )
            else:
                out.append(
                    f"{c['verdict']:<10}  physics  {'':<8} {where:<34} max |Δq| {c['joint_max']:.2e} rad  "
                    f"object Δ {c['object_error_m']:.2e} m"
                )
        d = self.drift
        out.append(
            f"conformance: {self.verdict} — {d['images_identical']}/{d['images']} images and "
            f"{d['physics_identical']}/{d['physics']} rollouts bit-identical; at most "
            f"{d['pixel_fraction_max']:.3%} of an image's pixels differ (max Δ {d['max_level_diff']}, region px "
            f"{d['region_pixels_max']}), joints within {d['joint_max']:.1e} rad, object within "
            f"{d['object_error_m_max']:.1e} m ({self.seconds:.1f} s)"
        )
        return out


def read_reference(root: Path) -> dict:
    path = Path(root) / FOLDER / REFERENCE
    if not path.is_file():
        raise BenchmarkError(
            f"{root} holds no conformance reference ({FOLDER}/{REFERENCE} missing); rebuild the "
            "benchmark with `roboview-build-benchmark`"
        )
    return json.loads(path.read_text())


def check(
    root: Path, tolerances: Tolerances | None = None, envs: _Envs | None = None, limit: int | None = None
) -> Report:
    """Re-render and re-simulate the benchmark's reference sample here (its records are in reference.json,
    covered by the benchmark version, which `read_manifest` checks); `limit`: only its first instances."""
    start = time.perf_counter()
    reference = read_reference(root)
    if limit is not None:
        reference["instances"] = reference["instances"][:limit]
    tol = tolerances or Tolerances(**reference["tolerances"])
    envs = envs or _Envs(reference["image_size"])
    checks = []
    # A format-4 LIBERO row's `red` baseline is rendered as it was built: the object's own texture (`original`).
    fmt = benchmark_format(root)
    try:
        for entry in reference["instances"]:
            iid = entry["instance_id"]
            instance = instance_from_record(entry, fmt)
            ref_state = reference["physics"].get(iid)
            steps = reference["rollout_steps"] if ref_state is not None else 0
            images, state = observe(*envs(instance.task), instance, steps)
            stored = _unpng((Path(root) / FOLDER / f"{iid}.png").read_bytes(), len(reference["cameras"]))
            for camera, ref, new in zip(reference["cameras"], stored, images):
                checks.append(
                    {
                        "check": "image",
                        "instance_id": iid,
                        "split": entry["split"],
                        "value": entry["value"],
                        "camera": camera,
                        **compare_images(ref, new, tol),
                    }
                )
            if ref_state is not None:
                checks.append(
                    {
                        "check": "physics",
                        "instance_id": iid,
                        "split": entry["split"],
                        "value": entry["value"],
                        **compare_physics(ref_state, state, tol),
                    }
                )
    finally:
        envs.close()
    return Report(
        worst(c["verdict"] for c in checks),
        checks,
        time.perf_counter() - start,
        asdict(tol),
        envs.stack or {},
    )


def _code_hash() -> str:
    """SHA-256 over RoboView's simulation code (the rooms core, sim, variation, tasks and benchmark): a changed
    applier can change the pixels."""
    root = Path(__file__).parents[1]
    rooms = ("core", "sim", "variation", "tasks", "benchmark")
    return files_sha256(root, sorted(p for room in rooms for p in (root / room).rglob("*.py")))


def at_start(root: Path, version: str, cache_dir: Path | None = None) -> Report:
    """The check an evaluation runs before its first episode. The stack is described (one env, about a second);
    a verdict already measured for this benchmark version, this exact stack record and this simulation code is
    read from the cache, anything else is measured (a few seconds) and cached."""
    reference = read_reference(root)
    envs = _Envs(reference["image_size"])
    first = reference["instances"][0].get("task") or DEFAULT_TASK
    envs(first)
    key = hashlib.sha256(
        json.dumps({"version": version, "stack": envs.stack, "code": _code_hash()}, sort_keys=True).encode()
    ).hexdigest()[:32]
    path = Path(cache_dir or files.cache_dir("conformance")) / f"{key}.json"
    if path.is_file():
        envs.close()
        return Report(**json.loads(path.read_text()))
    report = check(root, envs=envs)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps(asdict(report)))
        tmp.replace(path)
    except OSError as exc:  # a read-only cache only costs the next run the check
        log.warning("could not cache the conformance verdict in %s: %s", path, exc)
    return report


def gate(bench: Benchmark, allow_drift: bool, flag: str) -> Report:
    """`at_start` on the loaded benchmark, logged; `different` raises ConformanceError (its message names `flag`,
    the switch that runs anyway) unless `allow_drift`, in which case it warns that every row will be marked."""
    from roboview.sim import stack

    root = Path(bench.path)
    report = at_start(root, bench.version)
    report.stack_differences = stack.differences(bench.manifest.get("stack"), report.stack)
    log.info(
        "conformance with the benchmark's stack: %s (%s)%s",
        report.verdict,
        stack.summary(report.stack),
        f"; stack differs: {'; '.join(report.stack_differences)}" if report.stack_differences else "",
    )
    if report.verdict == "different":
        if not allow_drift:
            raise ConformanceError(refusal(report, root, flag))
        log.warning(
            "running on a stack whose conformance is `different` (%s=true): every row is marked; these "
            "results do not compare with others on this benchmark",
            flag,
        )
    return report


def refusal(report: Report, root: Path, flag: str = "--benchmark.allow_drift") -> str:
    """The message that stops an evaluation on a stack whose conformance is `different`."""
    bad = [c for c in report.checks if c["verdict"] == "different"]
    kinds = sorted({c["check"] for c in bad})
    d = report.drift
    return (
        f"this machine renders or simulates the benchmark at {root} differently from the machine that built it "
        f"({len(bad)} of {len(report.checks)} reference checks different: {', '.join(kinds)}; up to "
        f"{d['pixel_fraction_max']:.2%} of an image's pixels differ with {d['region_pixels_max']} pixels of "
        f"differing regions, joints up to {d['joint_max']:.1e} rad, object up to {d['object_error_m_max']:.1e} m). "
        f"Results from this stack would not compare with others on this benchmark. See each check with "
        f"`roboview-verify --benchmark.path={root}`; run on the stack the benchmark records "
        f'(benchmark.json, "stack"), or pass {flag}=true to run anyway with every row marked '
        f"`different`"
    )
