"""Collect scripted-expert demos into a LeRobotDataset v3 (context-only randomization).

    roboview-collect --dataset.repo_id=roboview/pick_place --dataset.root=outputs/demos \
        --dataset.num_episodes=350 --num_workers=2

Each attempt draws a task context (object position, shape, instruction) at random with every
visual factor at its baseline, as the paper did for its π0 training demos (add
`--dataset.randomize=color,camera_pose` for visual domain randomization); only successful
episodes are kept and failures are counted. `--dataset.control=ee_delta` (or ee_abs) records
end-effector demos, LIBERO-style: `observation.state` is the EE state and `action` the EE action. Rerunning with the same root resumes where a killed
run stopped. Load the result with `LeRobotDataset(repo_id, root=root)`.
"""

from __future__ import annotations

import itertools
import logging
import shutil
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from tqdm import tqdm

from roboview.core.cli_errors import flag_errors
from roboview.core.workers import WorkerPool
from roboview.demos.dataset import (
    CollectionSignature,
    DatasetRootError,
    Progress,
    add_episode,
    check_root,
    demo_features,
    load_provenance,
    roll_back,
    write_card,
    write_checkpoint,
)
from roboview.demos.recorder import DemoCollector, DemoEpisode
from roboview.pipelines._cli import cli_main, interrupted
from roboview.sim.cameras import ALL_CAMERAS, IMAGE_SIZE_MIN, check_image_size
from roboview.tasks import DEFAULT_TASK, load_task
from roboview.variation.factors import FACTORS, context_factors
from roboview.variation.randomization import validate_randomize

log = logging.getLogger(__name__)

VCODECS = ("libsvtav1", "h264", "hevc")
# roboview.pipelines.train's ACT reads the images at their collected size through a ResNet that downsamples by 32:
# a collected image is at least one backbone stride wide.
ACT_BACKBONE_STRIDE = 32
TRAIN_IMAGE_MIN = max(IMAGE_SIZE_MIN, ACT_BACKBONE_STRIDE)


def parse_contexts(text: str, task: str) -> tuple[tuple[str, tuple[str, ...]], ...]:
    """`FACTOR=V1|V2,FACTOR=V` → ((factor, values), …), each a context factor of `task` and each value one of
    its values; a one-line error naming the bad entry otherwise."""
    out = []
    for item in filter(None, (x.strip() for x in text.split(","))):
        name, sep, values = item.partition("=")
        if not sep or name not in context_factors(task):
            raise ValueError(
                f"{item!r}: expected FACTOR=V1|V2 with FACTOR one of {task}'s context factors "
                f"({', '.join(context_factors(task))})"
            )
        chosen = tuple(v.strip() for v in values.split("|"))
        for value in chosen:
            FACTORS[name].validate(value)
        out.append((name, chosen))
    return tuple(out)


@dataclass
class DatasetConfig:
    # Dataset id (ORG/NAME), written into the dataset's metadata and used by push_to_hub.
    repo_id: str = "roboview/pick_place_demos"
    # Local folder of the dataset. A new or empty folder starts a collection; a folder from an
    # earlier run with the same settings resumes it.
    root: str = "outputs/demos"
    # Number of successful episodes the dataset should hold when the run ends.
    num_episodes: int = 50
    # Control and recording rate (Hz); must divide the 500 Hz physics rate.
    fps: int = 10
    # Side of the square camera images (pixels).
    image_size: int = 224
    # Cameras recorded as videos (any of front, left_top, right_top, wrist; LIBERO's scenes: image, image2 — LeRobot's
    # names of agentview and the wrist camera, the layout of LeRobot-format LIBERO datasets).
    cameras: list[str] = field(default_factory=lambda: list(ALL_CAMERAS))
    # Video codec for lerobot's encoder: libsvtav1 (LeRobot's default), h264 or hevc.
    vcodec: str = "libsvtav1"
    # Visual domain randomization, drawn per episode from continuous ranges (never the benchmark's
    # named test values): any of color (object sRGB uniform in the unit cube), camera_pose (front and
    # left_top on the continuous orbital surface). What was drawn is recorded per episode in
    # meta/roboview/episodes.parquet. Empty: context-only randomization, as in the paper.
    randomize: list[str] = field(default_factory=list)
    # Task the expert demonstrates: pick_place (the paper's), push or libero (roboview.tasks).
    task: str = DEFAULT_TASK
    # Draw these context factors among the values named only: FACTOR=V1|V2,FACTOR=V (e.g.
    # libero_task=libero_object/0|libero_object/1); empty: every value of every context factor.
    contexts: str = ""
    # Control the demos are recorded in: joint (observation.state = joints, action = 7 joint targets + gripper),
    # ee_delta or ee_abs (observation.state = the EE state, action = the 7-d EE action; docs/control.md).
    control: str = "joint"

    def __post_init__(self) -> None:
        if "/" not in self.repo_id or self.repo_id.startswith("/") or self.repo_id.endswith("/"):
            raise ValueError(f"--dataset.repo_id={self.repo_id!r} must look like ORG/NAME")
        if self.num_episodes <= 0:
            raise ValueError(f"--dataset.num_episodes={self.num_episodes} must be a positive count")
        if self.fps <= 0 or 500 % self.fps:
            raise ValueError(
                f"--dataset.fps={self.fps} must be a positive divisor of 500 (e.g. 5, 10, 20, 25)"
            )
        check_image_size(
            self.image_size,
            "--dataset.image_size",
            TRAIN_IMAGE_MIN,
            f"training reads the images at this size, and ACT's ResNet backbone downsamples "
            f"them by {ACT_BACKBONE_STRIDE}",
        )
        with flag_errors("--dataset.task"):
            env_class = load_task(self.task).env_class()
        unknown = [c for c in self.cameras if c not in env_class.camera_names]
        if unknown or not self.cameras or len(set(self.cameras)) != len(self.cameras):
            raise ValueError(
                f"--dataset.cameras={self.cameras}: unknown or repeated camera(s) {unknown}; "
                f"allowed for --dataset.task={self.task}: {', '.join(env_class.camera_names)}"
            )
        if self.vcodec not in VCODECS:
            raise ValueError(f"--dataset.vcodec={self.vcodec!r} unknown; allowed: {', '.join(VCODECS)}")
        with flag_errors("--dataset.randomize"):
            self.randomize = list(validate_randomize(self.randomize))
        if self.randomize and env_class.world != "roboview":
            raise ValueError(
                f"--dataset.randomize={','.join(self.randomize)}: domain randomization draws RoboView's scene's "
                f"colors and camera poses; --dataset.task={self.task} runs in the {env_class.world} world"
            )
        if self.control not in env_class.controls:
            raise ValueError(
                f"--dataset.control={self.control!r} is not a control of --dataset.task={self.task}; allowed: "
                f"{', '.join(env_class.controls)}"
            )
        with flag_errors("--dataset.contexts"):
            self.context_values = parse_contexts(self.contexts, self.task)


@dataclass
class CollectConfig:
    dataset: DatasetConfig = field(default_factory=DatasetConfig)
    # Collection seed: attempt i runs with episode seed SHA-256("collect:{seed}:{i}").
    seed: int = 0
    # Simulation worker processes (spawned; one renderer each). 1 runs in this process.
    num_workers: int = 2
    # Steps after which an attempt counts as a failure.
    max_steps: int = 120
    # Finalize the dataset every this many saved episodes; a killed run resumes from there.
    checkpoint_every: int = 25
    # Give up (with an error) when this many attempts have failed in total.
    max_failures: int = 50

    def __post_init__(self) -> None:
        for name in ("num_workers", "max_steps", "checkpoint_every", "max_failures"):
            if getattr(self, name) <= 0:
                raise ValueError(f"--{name}={getattr(self, name)} must be a positive count")
        if self.seed < 0:
            raise ValueError(f"--seed={self.seed} must be ≥ 0")

    @property
    def signature(self) -> CollectionSignature:
        d = self.dataset
        return CollectionSignature(
            d.repo_id,
            d.fps,
            d.image_size,
            tuple(d.cameras),
            self.seed,
            self.max_steps,
            tuple(d.randomize),
            d.task,
            d.control,
            d.context_values,
        )


@dataclass(frozen=True)
class CollectResult:
    root: Path
    episodes: int
    new_episodes: int
    attempts: int
    failures: int
    elapsed_s: float

    @property
    def success_rate(self) -> float:
        return (self.attempts - self.failures) / self.attempts if self.attempts else float("nan")

    @property
    def demos_per_hour(self) -> float:
        return 3600 * self.new_episodes / self.elapsed_s if self.elapsed_s else float("nan")


def _episodes(cfg: CollectConfig, first_attempt: int) -> Iterator[DemoEpisode]:
    """Attempts first_attempt, first_attempt+1, … in order, computed by the worker pool."""
    d = cfg.dataset
    args = (
        cfg.seed,
        tuple(d.cameras),
        d.image_size,
        d.fps,
        cfg.max_steps,
        tuple(d.randomize),
        d.task,
        d.control,
        d.context_values,
    )
    attempt = first_attempt
    if cfg.num_workers == 1:
        collector = DemoCollector(*args)
        try:
            while True:
                yield collector.run(attempt)
                attempt += 1
        finally:
            collector.env.close()
    with WorkerPool(cfg.num_workers, DemoCollector, args) as pool:
        yield from pool.imap(itertools.count(attempt))


def _open_dataset(cfg: CollectConfig, create: bool):
    from lerobot.configs.video import RGBEncoderConfig
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    d = cfg.dataset
    # lerobot's streaming encoder silently *drops* a frame when its queue stays full for 0.1 s (it
    # was made for live capture); we feed frames faster than real time, so under CPU load frames went
    # missing (1 of ~13,000 per camera in a 250-demo run: an episode's video one frame short of its
    # parquet rows). A queue that holds a whole episode can never fill: no frame can be dropped.
    kwargs = dict(
        rgb_encoder=RGBEncoderConfig(vcodec=d.vcodec),
        streaming_encoding=True,
        encoder_threads=1,
        encoder_queue_maxsize=cfg.max_steps + 1,
    )
    if create:
        return LeRobotDataset.create(
            d.repo_id,
            d.fps,
            demo_features(tuple(d.cameras), d.image_size, d.control, d.task),
            root=d.root,
            robot_type=load_task(d.task).env_class().robot_type,
            use_videos=True,
            **kwargs,
        )
    return LeRobotDataset.resume(d.repo_id, root=d.root, **kwargs)  # reopened for writing: new files


def run(cfg: CollectConfig) -> CollectResult:
    root = Path(cfg.dataset.root)
    with flag_errors("--dataset.root"):
        progress = check_root(root, cfg.signature)  # every input error surfaces here, before work
    if progress is not None:
        roll_back(root, progress)
        if progress.episodes_saved == 0:  # nothing complete yet: start over cleanly
            shutil.rmtree(root)
            progress = None
    if progress is not None and progress.episodes_saved >= cfg.dataset.num_episodes:
        log.info(
            "%s already holds %d episodes (asked for %d); nothing to do",
            root,
            progress.episodes_saved,
            cfg.dataset.num_episodes,
        )
        return CollectResult(root, progress.episodes_saved, 0, 0, 0, 0.0)
    if progress is None:
        if root.exists():
            root.rmdir()  # empty (check_root verified); lerobot creates the folder itself
        dataset = _open_dataset(cfg, create=True)
        progress = Progress(cfg.signature)
        write_checkpoint(root, progress, [])
    else:
        dataset = _open_dataset(cfg, create=False)
    provenance = load_provenance(root)
    start_saved, start_attempt, start_failures = (
        progress.episodes_saved,
        progress.next_attempt,
        progress.failures,
    )
    target = cfg.dataset.num_episodes
    t0 = time.perf_counter()

    bar = tqdm(total=target, initial=start_saved, desc="collect", unit="demo", dynamic_ncols=True)
    episodes = _episodes(cfg, progress.next_attempt)
    checkpointed = progress.episodes_saved  # what a rerun resumes from
    try:
        for ep in episodes:
            progress.next_attempt = ep.attempt + 1
            if ep.success:
                add_episode(dataset, ep)
                provenance.append({"episode_index": progress.episodes_saved, **ep.provenance()})
                progress.episodes_saved += 1
                bar.update(1)
            else:
                progress.failures += 1
                log.info(
                    "attempt %d failed after %d steps (context %s)", ep.attempt, ep.steps, ep.instance.context
                )
            tried = progress.next_attempt - start_attempt
            bar.set_postfix(
                success=f"{(tried - progress.failures + start_failures) / tried:.1%}",
                failed=progress.failures,
            )
            done = progress.episodes_saved >= target
            if ep.success and (done or progress.episodes_saved % cfg.checkpoint_every == 0):
                dataset.finalize()
                write_checkpoint(root, progress, provenance)
                checkpointed = progress.episodes_saved
                write_card(root, cfg.dataset.repo_id, cfg.dataset.task, len(provenance), cfg.dataset.control)
                if done:
                    break
                dataset = _open_dataset(cfg, create=False)
            if progress.failures >= cfg.max_failures:
                raise RuntimeError(
                    f"{progress.failures} attempts failed (limit --max_failures={cfg.max_failures}); "
                    f"the {progress.episodes_saved} episodes checkpointed so far are kept. "
                    "Check the scene or raise --max_steps / --max_failures."
                )
    except KeyboardInterrupt as exc:  # Ctrl-C: cli_main ends with this line instead of a traceback
        since = progress.episodes_saved - checkpointed
        lost = (
            f" (the {since} collected since its last checkpoint are collected again; "
            f"--checkpoint_every={cfg.checkpoint_every})"
            if since
            else ""
        )
        raise interrupted(
            exc,
            f"{checkpointed} demo{'s' * (checkpointed != 1)} saved in {root}{lost}; "
            "rerun the same command to resume",
        ) from exc
    finally:
        episodes.close()
        bar.close()
    return CollectResult(
        root,
        progress.episodes_saved,
        progress.episodes_saved - start_saved,
        progress.next_attempt - start_attempt,
        progress.failures - start_failures,
        time.perf_counter() - t0,
    )


def summary(cfg: CollectConfig, result: CollectResult) -> None:
    """The line the command prints when it ends: demos, where, attempts, the expert's success, the rate."""
    if not result.attempts:
        print(
            f"[collect] {result.episodes} episodes in {result.root}: already complete, nothing new to collect"
        )
        return
    print(
        f"[collect] {result.episodes} episodes in {result.root} "
        f"({result.new_episodes} new; {result.attempts} attempts, {result.failures} failed, "
        f"expert success {result.success_rate:.1%}; {result.demos_per_hour:.0f} demos/h)"
    )


def main(args: list[str] | None = None) -> CollectResult:
    return cli_main(CollectConfig, run, summary, (DatasetRootError,), args)


if __name__ == "__main__":
    main()
