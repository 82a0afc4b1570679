"""RoboView inside lerobot's own tools, unpatched: `lerobot-eval --env.type=roboview`.

    lerobot-eval --env.type=roboview \
        --env.benchmark_path=outputs/benchmark --env.task=color,camera_pose --env.cameras=left_top,wrist \
        --policy.path=CKPT/pretrained_model --eval.n_episodes=141 --eval.batch_size=8 \
        --output_dir=outputs/lerobot_eval
    python -m roboview.integrations.lerobot.convert --eval_info=outputs/lerobot_eval/eval_info.json \
        --env.benchmark_path=outputs/benchmark --output_dir=outputs/eval/lerobot_eval

As LeRobot's LIBERO / RoboCasa integrations do with their suites, `--env.task` names the benchmark's splits
to run (comma-separated, or `all`): each split is one task group of `eval_info.json` (`per_group.<split>`
holds its success rate), and its episodes are the split's instances × `--env.n_repeats` in the order
`roboview.pipelines.evaluate` uses. lerobot-eval resets episode i of a group with seed `--seed + i` (lerobot's
rule); the env maps that to the split's i-th (instance, repeat) and runs it with RoboView's own episode
seed, so both tools run the same episodes. Every sub-env exposes `task` (the split), `task_description`
(the episode's instruction, which reaches language-conditioned policies) and `_max_episode_steps`.

Importing this package registers the `roboview` `EnvConfig` and the gymnasium id `RoboView/LeRobotEval-v0`.
lerobot-eval and lerobot-train import it at start-up through the `lerobot_env_roboview` distribution
(plugins/lerobot_env_roboview, installed by `make install`: LeRobot imports every installed `lerobot_env_*`),
so no flag is needed; `--env.discover_packages_path=roboview.integrations.lerobot` still works where that distribution is
not installed. `lerobot-train --env.type=roboview --env_eval_freq=N` takes the same flags for its periodic
evals, one success rate per split. The same env is offered as a LeRobot EnvHub env: `roboview/integrations/lerobot/hub/`.
"""

from __future__ import annotations

import functools
import logging
from dataclasses import dataclass, field
from pathlib import Path

import gymnasium as gym
from lerobot.configs.types import FeatureType, PolicyFeature
from lerobot.envs.configs import EnvConfig
from lerobot.utils.constants import ACTION, OBS_IMAGES, OBS_STATE

GYM_ID = "RoboView/LeRobotEval-v0"

if GYM_ID not in gym.registry:
    # No TimeLimit/OrderEnforcing wrappers: the env truncates at max_steps itself and exposes
    # `_max_episode_steps`, `task` and `task_description`, which lerobot's loop reads from each sub-env.
    gym.register(
        id=GYM_ID, entry_point="roboview.integrations.lerobot.env:RoboViewEvalEnv", order_enforce=False
    )


DEFAULT_IMAGE_SIZE = 96
log = logging.getLogger(__name__)


def checkpoint_features(path: str | None) -> tuple[int | None, int | None]:
    """(image side, action width) of a local LeRobot checkpoint folder (one holding config.json), read as
    `roboview-evaluate` reads it; (None, None) without one."""
    if not path or not (Path(path) / "config.json").is_file():
        return None, None
    from roboview.policies.lerobot_policy import checkpoint_image_size, load_config

    _, config = load_config(path)
    action = config.output_features.get(ACTION)
    return checkpoint_image_size(path), (int(action.shape[0]) if action is not None else None)


def episode_task(benchmark_path: str, split: str) -> str:
    """The task of a split's episodes."""
    from roboview.integrations.lerobot.env import episode_plan

    return episode_plan(benchmark_path, split, 1, 0, 1)[1][0][0].instance.task


def checkpoint_cameras(path: str | None) -> tuple[str, ...]:
    """The cameras a local LeRobot checkpoint folder reads (its image features); () without one."""
    if not path or not (Path(path) / "config.json").is_file():
        return ()
    from roboview.policies.lerobot_policy import load_config
    from roboview.tasks.world import camera_of_feature

    _, config = load_config(path)
    return tuple(c for c in map(camera_of_feature, config.input_features) if c)


@EnvConfig.register_subclass("roboview")
@dataclass
class RoboViewEnv(EnvConfig):
    """Splits of a frozen RoboView benchmark as lerobot envs (`--env.type=roboview`)."""

    # Splits to run, comma-separated (color,camera_pose), or `all`: one task group per split.
    task: str | None = "color"
    # Control rate (Hz) of the env, as the benchmark's episodes run.
    fps: int = 10
    # Benchmark folder (roboview.pipelines.build_benchmark).
    benchmark_path: str = "outputs/benchmark"
    # The checkpoint's cameras (comma-separated): what it was trained on (LIBERO's scenes: image,image2; Meta-World's:
    # top). Empty: read from the checkpoint lerobot-eval loads (--policy.path), else left_top,wrist.
    cameras: str = ""
    # The checkpoint's square image side (pixels): what it was trained on. 0: read from the checkpoint lerobot-eval
    # loads (--policy.path, its config.json), else 96; a side that disagrees with the checkpoint's is refused.
    image_size: int = 0
    # Episodes of a split: its selected instances × n_repeats, in the order roboview.pipelines.evaluate uses
    # (--eval.n_episodes runs that many per split; the count is printed when the envs are made).
    n_repeats: int = 1
    # Only the first N task contexts of each split, every value of each (as --eval.contexts); 0: all.
    contexts: int = 0
    # Only the first N instances of each split (as --eval.limit); 0: all.
    limit: int = 0
    # Steps before an episode is cut (lerobot reads it as the env's _max_episode_steps).
    max_steps: int = 120
    # The checkpoint's control: joint (8-d action: 7 joint targets + gripper; agent_pos the joint state) or ee_delta /
    # ee_abs (7-d LIBERO-convention action; agent_pos the end-effector state), as its dataset was collected; Meta-World's
    # xyz_delta (4-d). Empty: the benchmark's world's only control (LIBERO's ee_delta, Meta-World's), else joint.
    control: str = ""
    # Must equal lerobot-eval's --seed (default 1000): episode i is the one reset with seed start_seed + i.
    start_seed: int = 1000
    # Run even when this machine renders or simulates the benchmark `different`ly from the machine that built it
    # (the conformance check that runs before the first episode; `roboview-verify` shows its figures).
    allow_drift: bool = False
    features: dict[str, PolicyFeature] = field(default_factory=dict)
    features_map: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        from roboview.sim.cameras import check_image_size
        from roboview.tasks import camera_names

        if not self.cameras:
            from lerobot.configs import parser

            self.cameras = ",".join(checkpoint_cameras(parser.get_path_arg("policy"))) or "left_top,wrist"
        cams = self.camera_list
        unknown = [c for c in cams if c not in camera_names()]
        if unknown or not cams:
            raise ValueError(
                f"--env.cameras={self.cameras!r}: unknown camera(s) {unknown or cams}; "
                f"allowed: {', '.join(camera_names())}"
            )
        for name in ("n_repeats", "max_steps", "fps"):
            if getattr(self, name) <= 0:
                raise ValueError(f"--env.{name}={getattr(self, name)} must be positive")
        from roboview.tasks.base import feature_dims
        from roboview.tasks.world import all_controls, feature_key

        if self.control and self.control not in all_controls():
            raise ValueError(f"--env.control={self.control!r} unknown; allowed: {', '.join(all_controls())}")
        if not self.split_names_given:
            raise ValueError("--env.task is empty: name the splits to run (color,camera_pose) or `all`")
        if not self.control:  # the benchmark's world's only control, else joint
            from roboview.tasks import load_task

            task = episode_task(self.benchmark_path, self.splits()[0])
            self.control = load_task(task).env_class().world.default_control or "joint"
        self._fit_checkpoint()
        check_image_size(self.image_size, "--env.image_size")
        _, state_width, action_width = next(d for d in feature_dims() if d[0] == self.control)
        self.features = {
            ACTION: PolicyFeature(type=FeatureType.ACTION, shape=(action_width,)),
            "agent_pos": PolicyFeature(type=FeatureType.STATE, shape=(state_width,)),
        }
        self.features_map = {ACTION: ACTION, "agent_pos": OBS_STATE}
        image = PolicyFeature(type=FeatureType.VISUAL, shape=(self.image_size, self.image_size, 3))
        from roboview.integrations.lerobot.env import single_image

        if single_image(cams):  # a world's one camera under its own key (Meta-World's observation.image)
            self.features["pixels"] = image
            self.features_map["pixels"] = feature_key(cams[0])
        for cam in cams if not single_image(cams) else ():
            self.features[f"pixels/{cam}"] = image
            self.features_map[f"pixels/{cam}"] = f"{OBS_IMAGES}.{cam}"

    def _fit_checkpoint(self) -> None:
        """The pre-flight against the checkpoint lerobot-eval will load (`--policy.path`, read as lerobot's own parser
        reads it): its image side is adopted when --env.image_size is 0 and refused when it differs; an action width
        that is not --env.control's is refused naming the flag. Nothing to read (training, a Hub id): 96, no check."""
        from lerobot.configs import parser

        path = parser.get_path_arg("policy")
        side, width = checkpoint_features(path)
        if self.image_size == 0:
            self.image_size = side or DEFAULT_IMAGE_SIZE
            if side:
                log.info("--env.image_size: %d, the checkpoint's own (%s)", side, path)
        elif side and side != self.image_size:
            raise ValueError(
                f"--env.image_size={self.image_size} but the checkpoint {path} was trained on {side}×{side} images; "
                f"drop the flag (its size is used) or pass {side}"
            )
        from roboview.tasks.base import feature_dims

        takes = next(a for c, _, a in feature_dims() if c == self.control)
        if width and width != takes:
            fits = list(dict.fromkeys(c for c, _, a in feature_dims() if a == width))
            fix = (
                " (or ".join(f"--env.control={c}" for c in fits) + ")" * (len(fits) - 1)
                if fits
                else "another checkpoint"
            )
            raise ValueError(
                f"--env.control={self.control} takes {takes}-d actions but the checkpoint {path} answers {width}: "
                f"pass {fix}, as its dataset was collected"
            )

    @property
    def camera_list(self) -> tuple[str, ...]:
        return tuple(c.strip() for c in self.cameras.split(",") if c.strip())

    @property
    def split_names_given(self) -> tuple[str, ...]:
        return tuple(s.strip() for s in (self.task or "").split(",") if s.strip())

    def splits(self) -> list[str]:
        """The splits `--env.task` names, checked against the benchmark (an unknown one fails here)."""
        from roboview.benchmark.format import available_splits

        available = available_splits(self.benchmark_path)
        names = self.split_names_given
        if names == ("all",):
            return available
        unknown = [s for s in names if s not in available]
        if unknown:
            raise ValueError(
                f"--env.task: unknown split(s) {unknown}; the benchmark at {self.benchmark_path} has: "
                f"{', '.join(available)} (or `all`)"
            )
        return list(names)

    @property
    def package_name(self) -> str:
        return "roboview.integrations.lerobot"

    @property
    def gym_id(self) -> str:
        return GYM_ID

    @property
    def gym_kwargs(self) -> dict:
        """The env's arguments for the first split (`create_envs` makes one env set per split)."""
        return self.split_kwargs(self.splits()[0])

    def split_kwargs(self, split: str) -> dict:
        return {
            "benchmark_path": self.benchmark_path,
            "split": split,
            "cameras": self.camera_list,
            "image_size": self.image_size,
            "n_repeats": self.n_repeats,
            "contexts": self.contexts,
            "limit": self.limit,
            "max_steps": self.max_steps,
            "start_seed": self.start_seed,
            "fps": self.fps,
            "control": self.control,
        }

    def check_conformance(self) -> dict:
        """roboview.pipelines.evaluate's start-of-run check: `different` raises (unless --env.allow_drift=true) before any
        env is made; the verdict and drift are logged."""
        from roboview.benchmark import conformance
        from roboview.benchmark.format import Benchmark, read_manifest

        manifest = read_manifest(Path(self.benchmark_path))  # the splits are loaded with the envs
        bench = Benchmark(Path(self.benchmark_path), manifest["benchmark_version"], {}, manifest=manifest)
        return conformance.gate(bench, self.allow_drift, "--env.allow_drift").record()

    def create_envs(
        self, n_envs: int, use_async_envs: bool = False
    ) -> dict[str, dict[int, gym.vector.VectorEnv]]:
        """{split: {0: VectorEnv of n_envs}}: lerobot-eval runs --eval.n_episodes episodes of each split.

        Async envs start their worker processes only when lerobot reaches that split (lerobot's lazy
        wrapper, as its LIBERO integration uses), so at most n_envs simulators are alive at a time."""
        from lerobot.envs.utils import _LazyAsyncVectorEnv

        from roboview.core.workers import start_context
        from roboview.integrations.lerobot.env import RoboViewEvalEnv

        self.check_conformance()
        if use_async_envs and n_envs > 1:
            # LeRobot starts them from the process's fork server: the one RoboView's pools use, whose preload
            # (start_context) names the running program's module and this env, so no worker imports LeRobot again.
            start_context(("roboview.integrations.lerobot.env",))

        envs: dict[str, dict[int, gym.vector.VectorEnv]] = {}
        spaces: tuple = (None, None, None)  # probed from one env of the first split; every split shares them
        for split in self.splits():
            fns = [functools.partial(RoboViewEvalEnv, **self.split_kwargs(split)) for _ in range(n_envs)]
            if use_async_envs and n_envs > 1:
                vec = _LazyAsyncVectorEnv(fns, *spaces)
                spaces = (vec.observation_space, vec.action_space, vec.metadata)
            else:
                vec = gym.vector.SyncVectorEnv(fns, autoreset_mode=gym.vector.AutoresetMode.NEXT_STEP)
            envs[split] = {0: vec}
        return envs
