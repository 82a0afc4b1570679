"""Observations whose camera images are rendered when read, not when the env steps.

Rendering is most of an episode's cost on a CPU (≈ 20 ms a camera at 224² with llvmpipe) while
physics is ≈ 1 ms a step, and most agents look far less often than the env steps: the `vision`
agent reads one frame per episode, a chunked policy (ACT, π0, SmolVLA with `n_action_steps` > 1)
one per chunk, the scripted expert none. A `LazyObservation` is a `dict` (so code that checks
`isinstance(obs, dict)`, iterates it or copies it keeps working) whose image entries are rendered on
first access and cached. Rendering reads the simulation *now*, so an observation may only be read
before the env steps again; reading a stale one raises instead of silently returning the wrong frame.
The pixels are the ones eager rendering would have produced at that step (same model, same data).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import numpy as np


class StaleObservation(RuntimeError):
    """A lazy observation was read after the env stepped on (its step's state is gone)."""


class LazyObservation(dict):
    """`dict` of observation arrays; the keys in `lazy` are rendered on first read (then cached).

    `current()` says whether the env is still at the step this observation was taken at.
    """

    def __init__(
        self,
        eager: dict[str, np.ndarray],
        lazy: dict[str, Callable[[], np.ndarray]],
        current: Callable[[], bool],
    ) -> None:
        super().__init__(eager)
        self._lazy = dict(lazy)
        self._order = tuple(lazy) + tuple(k for k in eager if k not in lazy)
        self._current = current

    def __missing__(self, key: str) -> np.ndarray:
        render = self._lazy.get(key)
        if render is None:
            raise KeyError(key)
        if not self._current():
            raise StaleObservation(
                f"observation key {key!r} was read after the env stepped on; read images before "
                "the next env.step()/reset() (or make the env with lazy=False)"
            )
        value = render()
        dict.__setitem__(self, key, value)
        return value

    def rendered(self) -> tuple[str, ...]:
        """The lazy keys rendered so far (for the time breakdown and tests)."""
        return tuple(k for k in self._lazy if dict.__contains__(self, k))

    def materialize(self) -> dict[str, np.ndarray]:
        """A plain dict with every key rendered (what an eager env returns)."""
        return {k: self[k] for k in self._order}

    # The mapping protocol over every key, rendered or not (dict's own would see only the rendered).
    def __iter__(self) -> Iterator[str]:
        return iter(self._order)

    def __len__(self) -> int:
        return len(self._order)

    def __contains__(self, key: object) -> bool:
        return key in self._lazy or dict.__contains__(self, key)

    def keys(self):  # type: ignore[override]
        return dict.fromkeys(self._order).keys()

    def items(self):  # type: ignore[override]
        return self.materialize().items()

    def values(self):  # type: ignore[override]
        return self.materialize().values()

    def get(self, key: str, default=None):  # type: ignore[override]
        return self[key] if key in self else default

    def copy(self) -> dict[str, np.ndarray]:  # type: ignore[override]
        return self.materialize()

    def __repr__(self) -> str:
        return f"LazyObservation(keys={list(self._order)}, rendered={list(self.rendered())})"
