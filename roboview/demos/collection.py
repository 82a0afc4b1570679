"""Fill a LeRobot dataset with successful scripted-expert demos, resumably.

The worker pool runs attempts in order (attempt i's seed is fixed by the collection seed); successful episodes
are written, failed ones counted. Every `checkpoint_every` saved episodes the dataset is finalized and its
progress recorded (roboview.demos.dataset), so a killed run resumes from the last checkpoint.
"""

from __future__ import annotations

import dataclasses
import itertools
import logging
import shutil
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tqdm import tqdm

from roboview.core.cli import interrupted
from roboview.core.workers import WorkerPool
from roboview.demos.dataset import (
    CollectionSignature,
    Progress,
    add_episode,
    demo_features,
    load_provenance,
    roll_back,
    write_card,
    write_checkpoint,
)
from roboview.demos.recorder import DemoCollector, DemoEpisode
from roboview.tasks import load_task

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class CollectionJob:
    """One collection run: the dataset's signature (what must match to resume it), its folder and size, and how
    this run writes it (video codec, worker processes, checkpoint interval, failure limit)."""

    signature: CollectionSignature
    root: Path
    num_episodes: int
    vcodec: str = "libsvtav1"
    num_workers: int = 2
    checkpoint_every: int = 25
    max_failures: int = 50


@dataclass(frozen=True)
class CollectResult:
    """What a collection run did: the dataset's folder and episodes, those new, the attempts and failures of this
    run, and its time."""

    root: Path
    episodes: int
    new_episodes: int
    attempts: int
    failures: int
    elapsed_s: float

    @property
    def success_rate(self) -> float:
        """The expert's success over this run's attempts."""
        return (self.attempts - self.failures) / self.attempts if self.attempts else float("nan")

    @property
    def demos_per_hour(self) -> float:
        """New demos per hour of this run."""
        return 3600 * self.new_episodes / self.elapsed_s if self.elapsed_s else float("nan")


def attempts(job: CollectionJob, first_attempt: int) -> Iterator[DemoEpisode]:
    """Attempts first_attempt, first_attempt+1, … in order, computed by the worker pool."""
    sig = job.signature
    args = (
        sig.seed,
        sig.cameras,
        sig.image_size,
        sig.fps,
        sig.max_steps,
        sig.randomize,
        sig.task,
        sig.control,
        sig.contexts,
        sig.cover,
    )
    attempt = first_attempt
    if job.num_workers == 1:
        collector = DemoCollector(*args)
        try:
            while True:
                yield collector.run(attempt)
                attempt += 1
        finally:
            collector.env.close()
    with WorkerPool(job.num_workers, DemoCollector, args) as pool:
        yield from pool.imap(itertools.count(attempt))


def open_dataset(job: CollectionJob, create: bool):
    """The job's LeRobotDataset: created, or reopened for writing (lerobot's resume: new files)."""
    from lerobot.configs.video import RGBEncoderConfig
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    sig = job.signature
    # lerobot's streaming encoder silently *drops* a frame when its queue stays full for 0.1 s (it
    # was made for live capture); we feed frames faster than real time, so under CPU load frames went
    # missing (1 of ~13,000 per camera in a 250-demo run: an episode's video one frame short of its
    # parquet rows). A queue that holds a whole episode can never fill: no frame can be dropped.
    kwargs = dict(
        rgb_encoder=RGBEncoderConfig(vcodec=job.vcodec),
        streaming_encoding=True,
        encoder_threads=1,
        encoder_queue_maxsize=sig.max_steps + 1,
    )
    if create:
        return LeRobotDataset.create(
            sig.repo_id,
            sig.fps,
            demo_features(sig.cameras, sig.image_size, sig.control, sig.task),
            root=job.root,
            robot_type=load_task(sig.task).env_class().robot_type,
            use_videos=True,
            **kwargs,
        )
    return LeRobotDataset.resume(sig.repo_id, root=job.root, **kwargs)


@dataclass
class Filling:
    """A dataset being filled: the open dataset, its progress and provenance, and the episodes saved at the last
    checkpoint (what a rerun resumes from)."""

    job: CollectionJob
    dataset: Any  # lerobot LeRobotDataset
    progress: Progress
    provenance: list[dict]
    checkpointed: int

    def add(self, ep: DemoEpisode) -> None:
        """Write a successful episode, or count a failed attempt."""
        progress = self.progress
        progress.next_attempt = ep.attempt + 1
        if ep.success:
            add_episode(self.dataset, ep)
            self.provenance.append({"episode_index": progress.episodes_saved, **ep.provenance()})
            progress.episodes_saved += 1
        else:
            progress.failures += 1
            log.info(
                "attempt %d failed after %d steps (context %s)", ep.attempt, ep.steps, ep.instance.context
            )

    def checkpoint_if_due(self, ep: DemoEpisode) -> bool:
        """After a saved episode that fills the dataset or ends a checkpoint interval: finalize, record progress
        and the card, and reopen unless full. True once the dataset is full."""
        saved, job = self.progress.episodes_saved, self.job
        done = saved >= job.num_episodes
        if ep.success and (done or saved % job.checkpoint_every == 0):
            self.dataset.finalize()
            write_checkpoint(job.root, self.progress, self.provenance)
            self.checkpointed = saved
            sig = job.signature
            write_card(job.root, sig.repo_id, sig.task, len(self.provenance), sig.control)
            if done:
                return True
            self.dataset = open_dataset(job, create=False)
        return False

    def check_failures(self) -> None:
        """RuntimeError once the failed attempts reach the limit (the checkpointed episodes are kept)."""
        if self.progress.failures >= self.job.max_failures:
            raise RuntimeError(
                f"{self.progress.failures} attempts failed (limit --max_failures={self.job.max_failures}); "
                f"the {self.progress.episodes_saved} episodes checkpointed so far are kept. "
                "Check the scene or raise --max_steps / --max_failures."
            )

    def kept(self) -> str:
        """What an interrupted run keeps, and how to go on."""
        since = self.progress.episodes_saved - self.checkpointed
        lost = (
            f" (the {since} collected since its last checkpoint are collected again; "
            f"--checkpoint_every={self.job.checkpoint_every})"
            if since
            else ""
        )
        n = self.checkpointed
        return f"{n} demo{'s' * (n != 1)} saved in {self.job.root}{lost}; rerun the same command to resume"


def start(job: CollectionJob, progress: Progress | None) -> Filling | None:
    """The dataset opened where `progress` (check_root's) left it, its partial episodes rolled back, or created
    afresh; None when it already holds the episodes asked for."""
    root = job.root
    if progress is not None:
        roll_back(root, progress)
        if progress.episodes_saved == 0:  # nothing complete yet: start over cleanly
            shutil.rmtree(root)
            progress = None
    if progress is not None and progress.episodes_saved >= job.num_episodes:
        log.info(
            "%s already holds %d episodes (asked for %d); nothing to do",
            root,
            progress.episodes_saved,
            job.num_episodes,
        )
        return None
    if progress is None:
        if root.exists():
            root.rmdir()  # empty (check_root verified); lerobot creates the folder itself
        dataset = open_dataset(job, create=True)
        progress = Progress(job.signature)
        write_checkpoint(root, progress, [])
    else:
        dataset = open_dataset(job, create=False)
    return Filling(job, dataset, progress, load_provenance(root), progress.episodes_saved)


def collect(job: CollectionJob, progress: Progress | None) -> CollectResult:
    """Fill the dataset to `job.num_episodes` demos, resuming from `progress` (check_root's answer for the root);
    RuntimeError past the failure limit, and Ctrl-C says how many demos a rerun keeps."""
    filling = start(job, progress)
    if filling is None:
        return CollectResult(job.root, progress.episodes_saved, 0, 0, 0, 0.0)
    first = dataclasses.replace(filling.progress)
    t0 = time.perf_counter()
    bar = tqdm(
        total=job.num_episodes, initial=first.episodes_saved, desc="collect", unit="demo", dynamic_ncols=True
    )
    episodes = attempts(job, first.next_attempt)
    now = filling.progress
    try:
        for ep in episodes:
            filling.add(ep)
            if ep.success:
                bar.update(1)
            tried = now.next_attempt - first.next_attempt
            bar.set_postfix(
                success=f"{(tried - now.failures + first.failures) / tried:.1%}", failed=now.failures
            )
            if filling.checkpoint_if_due(ep):
                break
            filling.check_failures()
    except KeyboardInterrupt as exc:  # Ctrl-C: cli_main ends with this line instead of a traceback
        raise interrupted(exc, filling.kept()) from exc
    finally:
        episodes.close()
        bar.close()
    return CollectResult(
        job.root,
        now.episodes_saved,
        now.episodes_saved - first.episodes_saved,
        now.next_attempt - first.next_attempt,
        now.failures - first.failures,
        time.perf_counter() - t0,
    )
