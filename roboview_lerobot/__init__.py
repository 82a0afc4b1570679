"""RoboView inside lerobot's own tools, unpatched: `lerobot-eval --env.type=roboview`.

    lerobot-eval --env.discover_packages_path=roboview_lerobot --env.type=roboview \
        --env.benchmark_path=outputs/benchmark --env.split=color --env.cameras=left_top,wrist --env.image_size=96 \
        --policy.path=CKPT/pretrained_model --eval.n_episodes=141 --eval.batch_size=8 --output_dir=outputs/lerobot_eval
    python -m roboview_lerobot.convert --eval_info=outputs/lerobot_eval/eval_info.json \
        --env.benchmark_path=outputs/benchmark --env.split=color --output_dir=outputs/eval/lerobot_eval

lerobot imports this package (and its submodules) for `--env.discover_packages_path`; importing it
registers the `roboview` `EnvConfig` and the gymnasium id `RoboView/LeRobotEval-v0`. lerobot-eval then
runs its own loop: episode i is reset with seed `--seed + i` (lerobot's rule), which this env maps to
the i-th (instance, repeat) of the split — the order `pipelines.evaluate` uses — and runs it with
RoboView's own episode seed, so both tools run the same episodes. `lerobot-train --env.type=roboview`
takes the same flags for its periodic evals. `roboview_lerobot.convert` turns lerobot-eval's
`eval_info.json` into a RoboView results folder that `pipelines.report` reads.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import gymnasium as gym
from lerobot.configs.types import FeatureType, PolicyFeature
from lerobot.envs.configs import EnvConfig
from lerobot.utils.constants import ACTION, OBS_IMAGES, OBS_STATE

GYM_ID = "RoboView/LeRobotEval-v0"

if GYM_ID not in gym.registry:
    # No TimeLimit/OrderEnforcing wrappers: the env truncates at max_steps itself and exposes
    # `_max_episode_steps` and `task_description`, which lerobot's loop reads from each sub-env.
    gym.register(id=GYM_ID, entry_point="roboview_lerobot.env:RoboViewEvalEnv", order_enforce=False)


@EnvConfig.register_subclass("roboview")
@dataclass
class RoboViewEnv(EnvConfig):
    """A frozen RoboView split as a lerobot env (`--env.type=roboview`)."""

    task: str | None = "LeRobotEval-v0"
    fps: int = 10
    # Benchmark folder (pipelines.build_benchmark) and the split to run.
    benchmark_path: str = "outputs/benchmark"
    split: str = "color"
    # The checkpoint's cameras (comma-separated) and square image side: what it was trained on.
    cameras: str = "left_top,wrist"
    image_size: int = 96
    # Episodes: every selected instance × n_repeats, in the order pipelines.evaluate uses
    # (--eval.n_episodes should equal their count, printed when the env is made).
    n_repeats: int = 1
    contexts: int = 0
    limit: int = 0
    max_steps: int = 120
    # Must equal lerobot-eval's --seed (default 1000): episode i is the one reset with seed start_seed + i.
    start_seed: int = 1000
    features: dict[str, PolicyFeature] = field(default_factory=dict)
    features_map: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        from roboview_data.sim.cameras import ALL_CAMERAS

        cams = self.camera_list
        unknown = [c for c in cams if c not in ALL_CAMERAS]
        if unknown or not cams:
            raise ValueError(f"--env.cameras={self.cameras!r}: unknown camera(s) {unknown or cams}; "
                             f"allowed: {', '.join(ALL_CAMERAS)}")
        for name in ("image_size", "n_repeats", "max_steps"):
            if getattr(self, name) <= 0:
                raise ValueError(f"--env.{name}={getattr(self, name)} must be positive")
        self.features = {ACTION: PolicyFeature(type=FeatureType.ACTION, shape=(8,)),
                         "agent_pos": PolicyFeature(type=FeatureType.STATE, shape=(8,))}
        self.features_map = {ACTION: ACTION, "agent_pos": OBS_STATE}
        for cam in cams:
            self.features[f"pixels/{cam}"] = PolicyFeature(type=FeatureType.VISUAL,
                                                           shape=(self.image_size, self.image_size, 3))
            self.features_map[f"pixels/{cam}"] = f"{OBS_IMAGES}.{cam}"

    @property
    def camera_list(self) -> tuple[str, ...]:
        return tuple(c.strip() for c in self.cameras.split(",") if c.strip())

    @property
    def package_name(self) -> str:
        return "roboview_lerobot"

    @property
    def gym_id(self) -> str:
        return GYM_ID

    @property
    def gym_kwargs(self) -> dict:
        return {"benchmark_path": self.benchmark_path, "split": self.split, "cameras": self.camera_list,
                "image_size": self.image_size, "n_repeats": self.n_repeats, "contexts": self.contexts,
                "limit": self.limit, "max_steps": self.max_steps, "start_seed": self.start_seed, "fps": self.fps}
