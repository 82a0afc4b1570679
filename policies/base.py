"""The policy protocol every evaluated agent implements, and the registry `eval/` loads them from.

`eval/` never imports a concrete policy: it asks `make_policy(spec, env)` for one by name.
A policy declares which cameras it consumes (and whether it wants depth) so the evaluator renders
only those; the env is handed to the factory for sensor calibration (camera intrinsics and
extrinsics) and, for the privileged expert only, ground-truth state.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from roboview_data.env import PickPlaceEnv
from roboview_data.instances import TaskInstance


class TransientPolicyError(RuntimeError):
    """A failure worth retrying (an HTTP timeout, a rate limit): raise it from `select_action`/`reset`.

    The evaluator retries such calls a few times (as it does `TimeoutError` and `ConnectionError`);
    any other exception ends the episode as a failure recording the error as its reason.
    """


@runtime_checkable
class Policy(Protocol):
    name: str

    def reset(self, instance: TaskInstance) -> None:
        """Called after every env reset, before the first action of an episode."""

    def select_action(self, observation: dict[str, np.ndarray]) -> np.ndarray:
        """Env action (8,) float32: 7 joint targets (rad) + gripper command (0 open … 1 closed)."""


@dataclass(frozen=True)
class PolicySpec:
    """What the evaluator needs to build a policy and the env it observes."""

    type: str
    path: str | None = None
    options: tuple[tuple[str, str], ...] = field(default_factory=tuple)
    # Name in the results' `policy` column; empty: the policy's own (e.g. lerobot:act).
    name: str = ""


@dataclass(frozen=True)
class PolicyEntry:
    # Builds the policy once the env exists.
    factory: Callable[[PolicySpec, PickPlaceEnv], Policy]
    # Cameras the policy observes (the env renders only these).
    cameras: Callable[[PolicySpec], tuple[str, ...]]
    # Whether it wants depth images as well.
    depth: bool = False
    # One line for --help and error messages.
    doc: str = ""
    # Image side the policy was trained on (the env renders exactly that); None: any size works.
    image_size: Callable[[PolicySpec], int | None] = lambda spec: None


_REGISTRY: dict[str, PolicyEntry] = {}


def register_policy(name: str, entry: PolicyEntry) -> None:
    if name in _REGISTRY:
        raise ValueError(f"policy {name!r} registered twice")
    _REGISTRY[name] = entry


def policy_entry(name: str) -> PolicyEntry:
    _load_builtin()
    if name not in _REGISTRY:
        raise ValueError(f"unknown policy type {name!r}; allowed: {', '.join(sorted(_REGISTRY))}")
    return _REGISTRY[name]


def registered_policies() -> tuple[str, ...]:
    _load_builtin()
    return tuple(sorted(_REGISTRY))


def make_policy(spec: PolicySpec, env: PickPlaceEnv) -> Policy:
    return policy_entry(spec.type).factory(spec, env)


def _load_builtin() -> None:
    # Importing the adapters registers them; kept lazy so `policies.base` stays light.
    import policies.adapters  # noqa: F401
    import policies.vision  # noqa: F401
    import policies.lerobot_policy  # noqa: F401
