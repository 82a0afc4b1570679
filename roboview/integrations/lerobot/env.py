"""The gymnasium env lerobot-eval steps: one frozen split, episode i ↔ reset seed start_seed + i."""

from __future__ import annotations

import logging
from collections.abc import Sequence

import gymnasium as gym
import numpy as np

from roboview.benchmark.format import BenchmarkItem, load_benchmark, select_items
from roboview.tasks import make_env
from roboview.tasks.env import EE_STATE_KEY, IMAGE_KEY, STATE_KEY
from roboview.tasks.world import feature_key
from roboview.variation.instances import episode_seed

log = logging.getLogger(__name__)


def single_image(cameras: tuple[str, ...]) -> bool:
    """Whether `cameras` is one camera whose LeRobot feature is its world's own single-image key (Meta-World's `top`:
    `observation.image`): lerobot then reads `pixels` as one array, not a dict of cameras."""
    return len(cameras) == 1 and feature_key(cameras[0]) != IMAGE_KEY.format(cameras[0])


def episode_plan(
    benchmark_path: str, split: str, n_repeats: int = 1, contexts: int = 0, limit: int = 0
) -> tuple[str, list[tuple[BenchmarkItem, int]]]:
    """(benchmark version, [(item, repeat)]) in roboview.pipelines.evaluate's order: items × repeats."""
    bench = load_benchmark(benchmark_path, [split])
    items = select_items(bench.splits[split], contexts, limit)
    return bench.version, [(item, r) for item in items for r in range(n_repeats)]


class RoboViewEvalEnv(gym.Env):
    """lerobot's observation keys (`pixels` dict of cameras, `agent_pos`) over a RoboView env.

    `reset(seed=start_seed + i)` starts the split's i-th episode (its instance, with RoboView's own episode
    seed for its repeat); `reset()` without a seed (the vector env's autoreset after an episode ended)
    restarts the current one, whose steps lerobot discards. An index past the last episode wraps around
    (lerobot pads its last batch and discards those too).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(
        self,
        benchmark_path: str,
        split: str,
        cameras: Sequence[str] = ("left_top", "wrist"),
        image_size: int = 96,
        n_repeats: int = 1,
        contexts: int = 0,
        limit: int = 0,
        max_steps: int = 120,
        start_seed: int = 1000,
        fps: int = 10,
        render_mode: str = "rgb_array",
        control: str = "joint",
    ) -> None:
        self.version, self.episodes = episode_plan(benchmark_path, split, n_repeats, contexts, limit)
        if not self.episodes:
            raise ValueError(
                f"split {split!r} of {benchmark_path} selects no episodes (contexts={contexts}, "
                f"limit={limit})"
            )
        task = self.episodes[0][0].instance.task
        self.env = make_env(
            task, cameras=tuple(cameras), image_size=image_size, max_steps=max_steps, fps=fps, control=control
        )
        # agent_pos: the joint state, or the end-effector state for a checkpoint that acts in an EE control.
        self.state_key = STATE_KEY if control == "joint" else EE_STATE_KEY
        self.cameras = tuple(cameras)
        self.split = split
        self.start_seed = start_seed
        self.render_mode = render_mode
        self._max_episode_steps = max_steps
        self.index = 0
        log.info(
            "RoboView split %s: %d episodes (set --eval.n_episodes=%d)",
            split,
            len(self.episodes),
            len(self.episodes),
        )
        self.action_space = self.env.action_space
        pixels = {c: self.env.observation_space[IMAGE_KEY.format(c)] for c in self.cameras}
        # A world's one camera under its own feature key (Meta-World's observation.image): one array, as LeRobot's
        # own env of that world hands it; else a dict of cameras.
        self.single = single_image(self.cameras)
        pixel_space = pixels[self.cameras[0]] if self.single else gym.spaces.Dict(pixels)
        self.observation_space = gym.spaces.Dict(
            {"pixels": pixel_space, "agent_pos": self.env.observation_space[self.state_key]}
        )

    @property
    def task(self) -> str:
        """The split this env runs (lerobot's task group)."""
        return self.split

    @property
    def task_description(self) -> str:
        """The current episode's instruction: what lerobot-eval hands a language-conditioned policy."""
        return self.env.instruction

    def _convert(self, obs: dict) -> dict:
        pixels = {c: obs[IMAGE_KEY.format(c)] for c in self.cameras}
        return {
            "pixels": pixels[self.cameras[0]] if self.single else pixels,
            "agent_pos": obs[self.state_key],
        }

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        super().reset(seed=seed)
        if seed is not None:
            index = seed - self.start_seed
            if index < 0:
                raise ValueError(
                    f"reset seed {seed} is below --env.start_seed={self.start_seed}: episode i is reset "
                    "with seed start_seed + i, so --env.start_seed must equal lerobot-eval's --seed"
                )
            self.index = index % len(self.episodes)
        item, repeat = self.episodes[self.index]
        obs, info = self.env.reset(
            seed=episode_seed(item.record["context_id"], repeat), options={"instance": item.episode(repeat)}
        )
        return self._convert(obs), info | {"episode_index": self.index}

    def step(self, action: np.ndarray) -> tuple[dict, float, bool, bool, dict]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        return self._convert(obs), reward, terminated, truncated, info | {"episode_index": self.index}

    def render(self) -> np.ndarray:
        return self.env.render_camera(self.cameras[0])

    def close(self) -> None:
        self.env.close()
