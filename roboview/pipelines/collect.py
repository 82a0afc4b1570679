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

from dataclasses import dataclass, field
from pathlib import Path

from roboview.core.cli_errors import flag_errors
from roboview.demos.collection import CollectionJob, CollectResult, collect
from roboview.demos.dataset import CollectionSignature, DatasetRootError, check_root
from roboview.demos.recorder import parse_contexts
from roboview.pipelines._cli import cli_main
from roboview.sim.cameras import ALL_CAMERAS, IMAGE_SIZE_MIN, check_image_size
from roboview.tasks import DEFAULT_TASK, TASKS, load_task
from roboview.variation.randomization import validate_randomize

VCODECS = ("libsvtav1", "h264", "hevc")
# roboview.pipelines.train's ACT reads the images at their collected size through a ResNet that downsamples by 32:
# a collected image is at least one backbone stride wide.
ACT_BACKBONE_STRIDE = 32
TRAIN_IMAGE_MIN = max(IMAGE_SIZE_MIN, ACT_BACKBONE_STRIDE)


@dataclass
class DatasetConfig:
    # Dataset id (ORG/NAME), written into the dataset's metadata and used by push_to_hub.
    repo_id: str = "roboview/pick_place_demos"
    # Local folder of the dataset. A new or empty folder starts a collection; a folder from an
    # earlier run with the same settings resumes it.
    root: str = "outputs/demos"
    # Number of successful episodes the dataset should hold when the run ends.
    num_episodes: int = 50
    # Control and recording rate (Hz); must divide the 500 Hz physics rate. 0: the world's own rate where it has one
    # (Meta-World's 80 Hz), else 10.
    fps: int = 0
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
    # Task the expert demonstrates (pick_place: the paper's; roboview.tasks).
    task: str = DEFAULT_TASK
    # Draw these context factors among the values named only: FACTOR=V1|V2,FACTOR=V (e.g.
    # libero_task=libero_object/0|libero_object/1); empty: every value of every context factor.
    contexts: str = ""
    # Cover the combinations of --dataset.contexts' values in turn instead of drawing them: attempt a runs the a-th
    # combination (their cartesian product, in the order listed, cycling), so 10 tasks × 40 init states in 400
    # attempts run each once. Needs --dataset.contexts.
    cover_contexts: bool = False
    # Control the demos are recorded in: joint (observation.state = joints, action = 7 joint targets + gripper),
    # ee_delta or ee_abs (observation.state = the EE state, action = the 7-d EE action; docs/control.md).
    control: str = ""

    # --help appends the registry's tasks to the description of --dataset.task.
    help_details = {"task": lambda: f"One of: {', '.join(TASKS)}."}

    def __post_init__(self) -> None:
        if "/" not in self.repo_id or self.repo_id.startswith("/") or self.repo_id.endswith("/"):
            raise ValueError(f"--dataset.repo_id={self.repo_id!r} must look like ORG/NAME")
        if self.num_episodes <= 0:
            raise ValueError(f"--dataset.num_episodes={self.num_episodes} must be a positive count")
        check_image_size(
            self.image_size,
            "--dataset.image_size",
            TRAIN_IMAGE_MIN,
            f"training reads the images at this size, and ACT's ResNet backbone downsamples "
            f"them by {ACT_BACKBONE_STRIDE}",
        )
        with flag_errors("--dataset.task"):
            env_class = load_task(self.task).env_class()
        unknown = [c for c in self.cameras if c not in env_class.world.cameras]
        if unknown or not self.cameras or len(set(self.cameras)) != len(self.cameras):
            raise ValueError(
                f"--dataset.cameras={self.cameras}: unknown or repeated camera(s) {unknown}; "
                f"allowed for --dataset.task={self.task}: {', '.join(env_class.world.cameras)}"
            )
        if self.vcodec not in VCODECS:
            raise ValueError(f"--dataset.vcodec={self.vcodec!r} unknown; allowed: {', '.join(VCODECS)}")
        with flag_errors("--dataset.randomize"):
            self.randomize = list(validate_randomize(self.randomize))
        if self.randomize and not env_class.world.episode_visuals:
            raise ValueError(
                f"--dataset.randomize={','.join(self.randomize)}: domain randomization draws RoboView's scene's "
                f"colors and camera poses; --dataset.task={self.task} runs in the {env_class.world.name} world"
            )
        world = env_class.world
        if world.fps and self.fps not in (0, world.fps):
            raise ValueError(
                f"--dataset.fps={self.fps}: the {world.name} world runs at {world.fps} Hz; drop the flag"
            )
        self.fps = self.fps or world.fps or 10
        if not world.fps and (self.fps <= 0 or 500 % self.fps):
            raise ValueError(
                f"--dataset.fps={self.fps} must be a positive divisor of 500 (e.g. 5, 10, 20, 25)"
            )
        # No control given: the world's only one (LIBERO's ee_delta), or joint where the world takes several.
        self.control = self.control or env_class.world.default_control or "joint"
        if self.control not in env_class.world.controls:
            raise ValueError(
                f"--dataset.control={self.control!r} is not a control of --dataset.task={self.task}; allowed: "
                f"{', '.join(env_class.world.controls)}"
            )
        with flag_errors("--dataset.contexts"):
            self.context_values = parse_contexts(self.contexts, self.task)
        if self.cover_contexts and not self.contexts:
            raise ValueError(
                "--dataset.cover_contexts=true needs --dataset.contexts=FACTOR=V1|V2,… (the values to cover)"
            )


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
            d.cover_contexts,
        )


def run(cfg: CollectConfig) -> CollectResult:
    d = cfg.dataset
    job = CollectionJob(
        cfg.signature,
        Path(d.root),
        d.num_episodes,
        d.vcodec,
        cfg.num_workers,
        cfg.checkpoint_every,
        cfg.max_failures,
    )
    with flag_errors("--dataset.root"):
        progress = check_root(job.root, job.signature)  # every input error surfaces here, before work
    return collect(job, progress)


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
