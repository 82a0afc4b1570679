"""The scenes one env of RoboView's world compiles: the plain scene every instance has, and one per set of factors
set away from their baselines whose additions no other instance's scene may hold (`Factor.extend_spec_when_set`:
scene_text's card). Each is compiled on first use and kept, with the renderers and appliers bound to it, so an env
switching between them at reset recompiles nothing twice; the plain scene is live first and stays exactly as it was.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping
from typing import Any

from roboview.sim.scene import Scene
from roboview.variation.factors import FACTORS, baseline_of, visual_factors


def variant_key(values: Mapping[str, str], task: str) -> tuple[str, ...]:
    """The factors of an instance's `values` whose additions its scene needs (set away from their baselines)."""
    return tuple(
        name
        for name in visual_factors()
        if FACTORS[name].extend_spec_when_set is not None and values[name] != baseline_of(name, task)
    )


def compile_scene(quality: str, add_target: Callable, task: str, key: tuple[str, ...] = ()) -> Scene:
    """The scene with every factor's own additions and those of the factors in `key`, made for `task`."""
    extras = [f.extend_spec for f in FACTORS.values() if f.extend_spec is not None]
    extras += [functools.partial(FACTORS[name].extend_spec_when_set, task=task) for name in key]
    return Scene(quality, target=add_target, extras=extras)


class LiveScenes:
    """An env's compiled scenes by key (`variant_key`), each parked with what was bound to it while another is live."""

    def __init__(self, quality: str, add_target: Callable, task: str) -> None:
        self.quality, self.add_target, self.task = quality, add_target, task
        self.key: tuple[str, ...] = ()
        self.parked: dict[tuple[str, ...], tuple] = {}
        self.cards: dict[tuple[str, ...], Any] = {}

    def switch(self, env: Any, key: tuple[str, ...]) -> None:
        """Make the scene of `key` live in `env` (its scene, renderers, appliers), compiling it on first use."""
        if key == self.key:
            return
        self.parked[self.key] = (env.scene, env._renderer, env._depth_renderer, env._appliers)
        if key in self.parked:
            scene, env._renderer, env._depth_renderer, env._appliers = self.parked.pop(key)
        else:
            scene = self.compile(key)
            env._renderer = env._depth_renderer = None
            env._appliers = {}
        self.key = key
        env.bind_scene(scene)

    def compile(self, key: tuple[str, ...]) -> Scene:
        """The env's scene with the additions of the factors in `key`."""
        return compile_scene(self.quality, self.add_target, self.task, key)

    def plain(self, env: Any) -> Scene:
        """The plain scene (live or parked)."""
        return env.scene if not self.key else self.parked[()][0]

    def card(self, env: Any) -> Any:
        """The live scene's text card (`scene_text`), or None where it holds none."""
        if "scene_text" not in self.key:
            return None
        if self.key not in self.cards:
            from roboview.variation.factors.scene_text import SceneCard

            self.cards[self.key] = SceneCard(env)
        return self.cards[self.key]
