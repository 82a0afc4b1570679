"""The configuration of an evaluation: the benchmark and its selection (`--benchmark.*`), the run
(`--eval.*`: repeats, protocol, workers, backend, adaptive design, shards, recordings) and the policy
(`--policy.*`, one config class per type). `roboview-evaluate` parses it; `roboview.eval.campaign.runner` runs it."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

from roboview.core.cli_errors import flag_errors
from roboview.core.external_assets import LiberoPlusAssets
from roboview.eval.running import videos
from roboview.eval.running.backends import BACKENDS
from roboview.policies.base import PolicyConfig, missing_policy_type
from roboview.policies.vlm.sgl import SGLConfig
from roboview.sim.cameras import check_image_size

log = logging.getLogger(__name__)


@dataclass
class BenchmarkConfig:
    # Benchmark folder written by roboview.pipelines.build_benchmark.
    path: str = "outputs/benchmark"
    # Comma-separated splits to evaluate; empty: every split of the benchmark.
    splits: str = ""
    # Comma-separated values to keep (the `value` column, e.g. the baseline color: red in RoboView's scene, original
    # in LIBERO's and Meta-World's); empty: every value.
    values: str = ""
    # Run even when this machine's conformance check says it renders or simulates the benchmark `different`ly
    # from the machine that built it (roboview.pipelines.verify shows the figures); every row is then marked `different`.
    allow_drift: bool = False

    @property
    def split_list(self) -> list[str] | None:
        return [s.strip() for s in self.splits.split(",") if s.strip()] or None

    @property
    def value_list(self) -> list[str] | None:
        return [v.strip() for v in self.values.split(",") if v.strip()] or None


DEFAULT_IMAGE_SIZE = 224
VIDEO_FPS = 10  # the env's control rate: videos play in real time


@dataclass
class EvalConfig:
    # Episodes per instance, every split without its own entry in split_repeats.
    n_repeats: int = 5
    # Per-split repeats overriding n_repeats, comma-separated split=N (e.g. color_x_camera_pose=10).
    # `roboview-plan` says how many a split needs to detect a given bias.
    split_repeats: str = ""
    # A protocol the benchmark declares (its benchmark.json `protocols`; every benchmark has `paper`: 5 repeats per
    # single-factor instance, 10 per factorial one; and `adaptive`): it sets the repeats, or the adaptive design, of
    # every split, and run.json claims it, so the results can be ranked on a board. Empty: the repeats of the flags
    # (a run no board ranks). Not combined with --eval.n_repeats, split_repeats, adaptive, limit or contexts.
    protocol: str = ""
    # Evaluate only the first N instances of each chosen split (fixed order); 0 = all.
    limit: int = 0
    # Evaluate only the first N task contexts of each chosen split, every value of each (a sample
    # that keeps every value, e.g. --eval.contexts=2 for a quick bias profile); 0 = all.
    contexts: int = 0
    # Worker processes (local) or actors (ray).
    num_workers: int = 2
    # Envs per worker, stepped in lockstep: the policy is called once per step on their batch of
    # observations (one model copy per worker, batched forward passes for checkpoints; see docs/evaluation.md,
    # "Fast evaluation"). 1: one env per worker.
    envs_per_worker: int = 1
    # One policy server process holds the only model copy and answers every worker's envs in one batched
    # forward pass per chunk (the GPU layout: many CPU render workers, one GPU model; local backend,
    # chunked checkpoints). See eval/running/policy_server.py and docs/evaluation.md.
    policy_server: bool = False
    # Episode videos (MP4 per observed camera, linked from the report): N (the first N episodes run),
    # failures, all; empty: none. A video episode renders every camera at every step.
    videos: str = ""
    # Render every camera at every step instead of when a policy reads it (same rows; slower): for
    # measuring what lazy rendering saves.
    eager_render: bool = False
    # local (process pool, spawn) or ray.
    backend: str = "local"
    # Address of an existing Ray cluster (host:port of its head); empty starts a local one.
    ray_address: str = ""
    # i/N: run only shard i of N (0 ≤ i < N): the instances whose id hashes to i, every repeat of each, so N
    # machines or CI jobs each run one deterministic slice; `roboview-merge` joins their folders.
    shard: str = ""
    # Write a Rerun recording of every episode to this .rrd file; when it exists (an earlier run's), the new
    # episodes go to NAME-2.rrd, NAME-3.rrd, … and the earlier recording is kept.
    rerun: str = ""
    # Control steps before an episode counts as a failure; unset: each task's own (120 in RoboView's scene; in
    # LIBERO's, LeRobot's max steps of the episode's suite).
    max_steps: int | None = None
    # Episodes ended by infrastructure, not by the policy (a policy server lost mid-episode, an endpoint still
    # failing after its retries, a worker that died, a render failure) are recorded with status infra_error and
    # counted in no rate; after the pass they run again, at most this many times (0: not in this run). Rerunning
    # the same command runs the ones left again.
    max_infra_retries: int = 2
    # CPU threads of each worker's inference (torch); 0: the cores not already busy (the load average) split between
    # the workers, at least 1.
    torch_threads: int = 0
    # Camera image side (pixels); 0: the policy's own (a checkpoint's input size), else 224.
    # A size that disagrees with the checkpoint's fails before any rollout.
    image_size: int = 0
    # Adaptive evaluation (docs/adaptive.md): repeats run in rounds over every instance of a split; after each
    # round a group-sequential likelihood-ratio test stops the split for "bias" (type-I error ≤ alpha over
    # every look), for "no_bias" (a bias of logit SD tau would have shown, at the target power)
    # or at max_repeats. Two-factor splits run their fixed repeats.
    adaptive: bool = False
    # Adaptive: the most rounds (repeats per instance) a split runs before it stops undecided.
    max_repeats: int = 10
    # Adaptive: type-I error of the "bias" verdict, spent over every look at the split.
    alpha: float = 0.05
    # Adaptive: the bias of interest, as the logit SD of the value effects (as in roboview.pipelines.plan).
    tau: float = 0.3
    # Adaptive: power kept against a bias of size tau before a split may stop for "no_bias".
    power: float = 0.8

    # --help lists these fields after the common ones, under these headings.
    help_groups = {
        "advanced --eval.* (speed, scale and recovery; docs/evaluation.md, docs/scaling.md)": (
            "envs_per_worker",
            "policy_server",
            "eager_render",
            "backend",
            "ray_address",
            "shard",
            "rerun",
            "max_infra_retries",
            "torch_threads",
        ),
        "adaptive evaluation, --eval.adaptive=true (docs/adaptive.md)": (
            "adaptive",
            "max_repeats",
            "alpha",
            "tau",
            "power",
        ),
    }

    def __post_init__(self) -> None:
        if self.image_size:  # 0: the policy's own size
            check_image_size(self.image_size, "--eval.image_size", why="or 0 for the policy's own size")
        for name in ("n_repeats", "num_workers", "max_steps", "envs_per_worker"):
            if getattr(self, name) is not None and getattr(self, name) <= 0:
                raise ValueError(f"--eval.{name}={getattr(self, name)} must be a positive count")
        if self.torch_threads < 0:
            raise ValueError(f"--eval.torch_threads={self.torch_threads} must be ≥ 0 (0 = fit the machine)")
        if self.limit < 0:
            raise ValueError(f"--eval.limit={self.limit} must be ≥ 0 (0 = every instance)")
        if self.max_infra_retries < 0:
            raise ValueError(
                f"--eval.max_infra_retries={self.max_infra_retries} must be ≥ 0 (0 = no re-run in this run)"
            )
        if self.contexts < 0:
            raise ValueError(f"--eval.contexts={self.contexts} must be ≥ 0 (0 = every context)")
        if self.backend not in BACKENDS:
            raise ValueError(f"unknown --eval.backend={self.backend!r}; allowed: {', '.join(BACKENDS)}")
        if self.rerun and not self.rerun.endswith(".rrd"):
            raise ValueError(f"--eval.rerun={self.rerun!r} must name a .rrd file")
        self.split_repeat_table  # noqa: B018  (parses split_repeats now, so a typo fails before any work)
        self.shard_index  # noqa: B018  (parses shard now)
        if self.shard and self.adaptive:
            raise ValueError(
                f"--eval.shard={self.shard} with --eval.adaptive=true: an adaptive split decides on all of "
                "its instances at once, so it cannot be sharded; drop one of the two"
            )
        self.video_mode  # noqa: B018  (parses videos now)
        if self.adaptive:
            self.design  # noqa: B018  (validates alpha, tau, power, max_repeats)

    @property
    def shard_index(self) -> tuple[int, int] | None:
        """(i, N) of --eval.shard=i/N; None when not sharded."""
        if not self.shard:
            return None
        i, sep, n = self.shard.partition("/")
        if not (sep and i.strip().isdigit() and n.strip().isdigit() and 0 <= int(i) < int(n)):
            raise ValueError(
                f"--eval.shard={self.shard!r} must be i/N with 0 ≤ i < N, e.g. 0/4 (the first of four)"
            )
        return int(i), int(n)

    @property
    def design(self):
        from roboview.eval.statistics.adaptive import Design

        return Design(alpha=self.alpha, tau=self.tau, power=self.power, max_repeats=self.max_repeats)

    @property
    def video_mode(self) -> str | int:
        with flag_errors("--eval.videos"):
            return videos.parse(self.videos)

    @property
    def split_repeat_table(self) -> dict[str, int]:
        """split → repeats as given by --eval.split_repeats."""
        table = {}
        for item in filter(None, (x.strip() for x in self.split_repeats.split(","))):
            name, sep, count = item.partition("=")
            if not sep or not count.strip().isdigit() or int(count) <= 0:
                raise ValueError(f"--eval.split_repeats entry {item!r} must be split=N with N ≥ 1")
            table[name.strip()] = int(count)
        return table

    def repeats_for(self, split: str) -> int:
        """Repeats for `split` without a protocol: its split_repeats entry, else n_repeats."""
        return self.split_repeat_table.get(split, self.n_repeats)

    def follow(self, protocol) -> None:
        """Take a declared protocol's repeats or adaptive design (roboview.benchmark.protocols.Protocol); ValueError
        for a flag that would run something else."""
        flag = f"--eval.protocol={protocol.name}"
        clashes = [
            f"--eval.{name}={getattr(self, name)}"
            for name, default in (("n_repeats", 5), ("split_repeats", ""), ("limit", 0), ("contexts", 0))
            if getattr(self, name) != default
        ]
        if self.adaptive and protocol.adaptive is None:
            clashes.append("--eval.adaptive=true")
        if clashes:
            raise ValueError(
                f"{flag} sets every split's repeats and covers each split whole; drop {', '.join(clashes)} "
                "(or drop the protocol: such a run is not ranked on a board)"
            )
        if protocol.adaptive is not None:
            if self.shard:
                raise ValueError(f"{flag} is adaptive: it cannot be sharded (--eval.shard={self.shard})")
            self.adaptive = True
            self.max_repeats = int(protocol.adaptive["max_repeats"])
            self.alpha, self.tau = float(protocol.adaptive["alpha"]), float(protocol.adaptive["tau"])
            self.power = float(protocol.adaptive["power"])
        self.split_repeats = ",".join(f"{s}={n}" for s, n in protocol.n_repeats.items())


@dataclass
class EvaluateConfig:
    # The benchmark to evaluate, and which of its splits and values.
    benchmark: BenchmarkConfig = field(default_factory=BenchmarkConfig)
    # Required: --policy.type=NAME (no default; `expert` is the privileged scripted expert, a ceiling).
    policy: PolicyConfig = None  # type: ignore[assignment]
    # How many episodes run, and how.
    eval: EvalConfig = field(default_factory=EvalConfig)
    # Folder for episodes.parquet (and its journal); rerun the same command to resume.
    output_dir: str = "outputs/eval"
    # The Semantic Grounding Layer around the policy: --sgl.enable=true (docs/vlm.md).
    sgl: SGLConfig = field(default_factory=SGLConfig)
    # LIBERO-plus's asset folder, which its light and background instances load (--liberoplus.assets=DIR).
    liberoplus: LiberoPlusAssets = field(default_factory=LiberoPlusAssets)

    def __post_init__(self) -> None:
        if self.policy is None:
            raise ValueError(missing_policy_type())
