"""Expert demonstrations: one seeded attempt = one episode, run in whichever process calls it.

`demo_attempt(i)` is a pure function of (collection seed, attempt index): the same pair gives the
same context, the same frames and the same actions on any machine and in any worker, which is
what makes parallel collection deterministic and resumable.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass, field

import numpy as np

from roboview.tasks import DEFAULT_TASK, load_task, make_env
from roboview.tasks.env import EE_STATE_KEY, IMAGE_KEY, STATE_KEY
from roboview.variation.factors import FACTORS, context_factors
from roboview.variation.instances import TaskInstance, seed_from_text
from roboview.variation.randomization import Randomization, sample_randomization
from roboview.variation.svgf import ContextSampler


def attempt_seed(seed: int, attempt: int) -> int:
    """Episode seed of collection attempt `attempt`: SHA-256 of "collect:{seed}:{attempt}" (as episode_seed)."""
    return seed_from_text(f"collect:{seed}:{attempt}")


def training_instance(
    rng: np.random.Generator, task: str = DEFAULT_TASK, contexts: dict[str, tuple[str, ...]] | None = None
) -> TaskInstance:
    """Context-only randomization: the task's context factors drawn at random (among `contexts`' values for the
    factors it names), visual factors at baseline."""
    values = ContextSampler(contexts, task=task).sample_context(rng)
    return TaskInstance(
        split="train", varied=context_factors(task), factors=values, context_subspace="cartesian", task=task
    )


def attempt_contexts(
    contexts: dict[str, tuple[str, ...]], attempt: int, cover: bool
) -> dict[str, tuple[str, ...]]:
    """The context values attempt `attempt` draws from. `cover`: the attempt-th combination of the listed values (their
    cartesian product, in the order listed, cycling), so N attempts over N combinations run each once; else all of
    them, drawn at random."""
    if not cover or not contexts:
        return contexts
    combos = list(itertools.product(*contexts.values()))
    return {name: (value,) for name, value in zip(contexts, combos[attempt % len(combos)], strict=True)}


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
class DemoEpisode:
    """What one attempt produced. Frames are (observation_t, action_t) pairs, t = 0 … steps−1."""

    attempt: int
    episode_seed: int
    instance: TaskInstance
    success: bool
    steps: int
    duration_s: float
    images: dict[str, np.ndarray] = field(default_factory=dict)  # camera -> (T, H, W, 3) uint8
    states: np.ndarray | None = None  # (T, 8) float32: joints, or the EE state in an end-effector control
    actions: np.ndarray | None = None  # (T, 8) float32 joint actions, or (T, 7) EE actions
    visuals: Randomization | None = None  # the object color and camera poses the frames show
    randomized: tuple[str, ...] = ()
    instruction: str = ""  # the episode's instruction (the dataset's `task`)

    def provenance(self) -> dict:
        row = {
            "attempt": self.attempt,
            "episode_seed": self.episode_seed,
            "instance_id": self.instance.instance_id,
            **self.instance.context,
            "steps": self.steps,
            "randomized": list(self.randomized),
        }
        return row | (self.visuals.record() if self.visuals is not None else {})


class DemoCollector:
    """Owns one env + expert (one renderer) per process; reused for every attempt it runs."""

    def __init__(
        self,
        seed: int,
        cameras: tuple[str, ...],
        image_size: int,
        fps: int,
        max_steps: int,
        randomize: tuple[str, ...] = (),
        task: str = DEFAULT_TASK,
        control: str = "joint",
        contexts: tuple[tuple[str, tuple[str, ...]], ...] = (),
        cover: bool = False,
    ) -> None:
        self.seed = seed
        self.cover = cover
        self.randomize = randomize
        self.task = task
        self.contexts = dict(contexts)
        self.env = make_env(
            task, cameras=cameras, image_size=image_size, fps=fps, max_steps=max_steps, control=control
        )
        self.expert = load_task(task).make_expert(self.env)  # its actions are in the env's control
        self.episode_visuals = self.env.world.episode_visuals
        # The state recorded with each action: the one the control's policies read (LIBERO-style for EE).
        self.state_key = STATE_KEY if control == "joint" else EE_STATE_KEY

    def run(self, attempt: int) -> DemoEpisode:
        start = time.perf_counter()
        ep_seed = attempt_seed(self.seed, attempt)
        contexts = attempt_contexts(self.contexts, attempt, self.cover)
        instance = training_instance(np.random.default_rng(ep_seed), self.task, contexts)
        # A world that draws per-episode visuals records the colors and camera poses its frames show; another
        # world's are its own.
        visuals = sample_randomization(ep_seed, self.randomize) if self.episode_visuals else None
        options = {"instance": instance}
        if self.randomize:  # context-only collections reset exactly as before
            options |= {"object_rgb": visuals.object_rgb, "cameras": visuals.cameras}
        obs, _ = self.env.reset(seed=ep_seed, options=options)
        self.expert.reset()
        frames: dict[str, list[np.ndarray]] = {c: [] for c in self.env.cameras}
        states, actions = [], []
        success = False
        for _ in range(self.env.max_steps):
            action = self.expert.select_action(obs)
            for cam in self.env.cameras:
                frames[cam].append(obs[IMAGE_KEY.format(cam)])
            states.append(obs[self.state_key])
            actions.append(action)
            obs, _, success, truncated, _ = self.env.step(action)
            if success or truncated:
                break
        episode = DemoEpisode(
            attempt,
            ep_seed,
            instance,
            success,
            len(actions),
            time.perf_counter() - start,
            visuals=visuals,
            randomized=self.randomize,
            instruction=self.env.instruction,
        )
        if success:  # failures are only counted, so their frames never cross the process boundary
            episode.images = {c: np.stack(v) for c, v in frames.items()}
            episode.states = np.stack(states).astype(np.float32)
            episode.actions = np.stack(actions).astype(np.float32)
        return episode
