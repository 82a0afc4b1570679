"""What a factor is, and the live registry of them.

A `Factor` declares everything the rest of RoboView needs to know about one axis of variation: its
values (strings, exactly as stored in the instance records), its baseline, the record columns a
value adds, the title reports give it, and — for a visual factor — how a value changes the compiled
scene. That last part is an *applier* (dm_control's `PhysicsVariator`: `bind_attributes`, then
`apply_variations`): `bind(scene)` looks up and keeps the model attributes it writes, once per env;
`apply(value, rng)` writes them in place at every reset, with the episode's generator. `env.reset`
applies every registered visual factor in registration order, so a factor never needs the env to
know about it.

Context factors (kind "context") belong to one task: they diversify its scenarios (where the object
starts, which solid it is, how the instruction is phrased) and the task's env places them itself.

A task whose world shows its own look at a visual factor's baseline (LIBERO's and Meta-World's objects wear their
own textures: there is no red there) names that baseline for what it is: its world declares a *baseline label*
(`World.baseline_labels`, color → `original`), its wing registers it for each of its tasks here
(`register_baseline_labels`), and every place that asks for a factor's baseline where the task is known asks
`baseline_of(factor, task)`. For such a task the label is the baseline and a swept value (its split's control arm),
and every registered value is a real change (red is a red re-skin).
"""

from __future__ import annotations

import difflib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from roboview.core.registry import Registry

FACTOR_KINDS = ("visual", "context")
DEFAULT_TASK = "pick_place"


class SceneApplier(Protocol):
    """Bound to one env's compiled scene; writes a factor value into it in place."""

    def apply(self, value: str, rng: np.random.Generator) -> None: ...


@dataclass(frozen=True)
class Factor:
    """One variable factor: the values a split sweeps, its baseline, and what a value does.

    `values` are the swept values. The baseline is usually one of them; for `camera_pose` it is
    not (the unperturbed cameras are not an orbital pose), so use `is_valid` / `validate`, which
    accept the baseline too, to check a stored value.
    """

    # Factor name as used in records and split names.
    name: str
    # "visual" (V: bias is measured over it) or "context" (D: diversifies task scenarios).
    kind: str
    # The values a split over this factor sweeps, in their canonical order.
    values: tuple[str, ...]
    # The value held fixed while other factors vary (paper's b_k or g_k).
    baseline: str
    # What a value means physically.
    doc: str
    # Title of the factor's section and column in reports.
    title: str = ""
    # Visual factors: `bind(scene) -> SceneApplier`, the applier in RoboView's own scene. None for context factors
    # (the task places them), and for a visual factor RoboView's scene lacks (one a world's wing declares for its own
    # scenes, which its applier table takes: LIBERO-plus's `view_*`); that scene then refuses a value away from the
    # baseline.
    bind: Callable[[Any], SceneApplier] | None = field(default=None, compare=False, repr=False)
    # Scene additions the applier needs, made once when the scene is built (materials, parked bodies,
    # mesh variants): `extend_spec(spec)`. Compiled with everything else: no recompiles per instance.
    extend_spec: Callable[[Any], None] | None = field(default=None, compare=False, repr=False)
    # Scene additions made only for an instance that sets this factor away from its baseline: `add(spec, task)`. The
    # env compiles them into a scene of its own, so every other instance's scene stays exactly as it was (the text
    # card of `scene_text`, which no other instance's scene may hold).
    extend_spec_when_set: Callable[[Any, str], None] | None = field(default=None, compare=False, repr=False)
    # The swept value a split of this factor compares its values against (its control arm), where that is not the
    # all-baseline instance: `scene_text`'s `blank`, the same card without text, whose baseline has no card. "": the
    # all-baseline instance.
    reference: str = ""
    # A value's own fairness check beyond the gate's measures, run for an instance setting the factor away from its
    # baseline: `gate(env, rgb) -> reasons` (empty: it passes). `scene_text`: the text legible, nothing hidden.
    gate: Callable[[Any, Mapping[str, Any]], list[str]] | None = field(
        default=None, compare=False, repr=False
    )
    # Whether the object's rendered colour stays near its nominal colour away from the baseline; the
    # fairness gate's ΔE-to-nominal check applies only where every factor says so (lighting: False —
    # a dim light darkens every colour by design, which is not a fairness failure).
    keeps_nominal_color: bool = True
    # Extra instance-record columns for a value (e.g. color -> color_hex / color_rgb / color_lab).
    record_columns: Callable[[str], dict[str, Any]] | None = field(default=None, compare=False, repr=False)
    # Context factors: the task they belong to. Visual factors apply to every task (None).
    task: str | None = None
    # The paper's seven factors are always in an instance's canonical JSON (its id); a factor added
    # later is there only when set away from its baseline, so every published id stays the same.
    always_in_id: bool = False
    # What this factor's values may change besides the factor itself, among what the isolation certificate
    # checks stays fixed across the values of one (context, repeat) (eval/running/isolation.py COMPONENTS): the
    # cameras it moves (`camera:front`), `object_height` (a scaled object rests at its own half-height).
    alters: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.kind not in FACTOR_KINDS:
            raise ValueError(f"factor {self.name!r}: kind {self.kind!r} not in {FACTOR_KINDS}")
        if not self.values:
            raise ValueError(f"factor {self.name!r} has no values")
        if len(set(self.values)) != len(self.values):
            raise ValueError(f"factor {self.name!r} has duplicate values")
        if self.kind == "visual" and self.task is not None:
            raise ValueError(f"visual factor {self.name!r} applies to every task: it names none")
        if self.kind == "context" and self.task is None:
            raise ValueError(f"context factor {self.name!r} must name its task")
        if self.reference and (self.reference not in self.values or self.reference == self.baseline):
            raise ValueError(
                f"factor {self.name!r}: reference {self.reference!r} must be a swept value other than the baseline"
            )
        if not self.title:
            object.__setattr__(self, "title", self.name.replace("_", " ").capitalize())

    def is_valid(self, value: str, task: str | None = None) -> bool:
        """True for a swept value or the baseline; with `task`, also the baseline label of `task`'s world
        (`baseline_of`: LIBERO's color `original`)."""
        return value == self.baseline or value in self.values or value == _label(self.name, task)

    def validate(self, value: str, task: str | None = None) -> str:
        """Return `value` if valid (for `task`, where given); otherwise raise naming the value and the allowed set."""
        if self.is_valid(value, task):
            return value
        base = baseline_of(self.name, task)
        allowed = self.values if base in self.values else (base, *self.values)
        close = difflib.get_close_matches(str(value), allowed, n=3)
        hint = f"; did you mean {', '.join(repr(c) for c in close)}?" if close else ""
        raise ValueError(f"unknown {self.name} {value!r}; allowed: {', '.join(allowed)}{hint}")


# The live registry, in registration order: the order of record columns and of appliers at reset. Read, it holds
# every wing's factors (roboview.core.registry.discover).
FACTORS: Registry[Factor] = Registry("factor")


def register_factor(factor: Factor) -> Factor:
    """Add `factor` to the registry (a name can be registered once)."""
    return FACTORS.add(factor.name, factor)


def unregister_factor(name: str) -> None:
    """Remove a factor (tests that register a throwaway factor clean up with this)."""
    FACTORS.remove(name)


def load_factor(name: str) -> Factor:
    """Return the registered factor `name`; unknown names raise listing the valid ones."""
    try:
        return FACTORS[name]
    except KeyError:
        raise ValueError(f"unknown factor {name!r}; valid factors: {', '.join(FACTORS)}") from None


def visual_factors() -> tuple[str, ...]:
    """Names of the visual factors V, in registration order."""
    return tuple(f.name for f in FACTORS.values() if f.kind == "visual")


def context_factors(task: str = DEFAULT_TASK) -> tuple[str, ...]:
    """Names of `task`'s context factors D, in registration order."""
    return tuple(f.name for f in FACTORS.values() if f.kind == "context" and f.task == task)


def factor_names(task: str = DEFAULT_TASK) -> tuple[str, ...]:
    """Every factor an instance of `task` sets: visual, then context."""
    return visual_factors() + context_factors(task)


# task → {visual factor → the label its baseline goes by in that task's world}: filled by each world's wing for each
# of its tasks from its `World.baseline_labels` (LIBERO's `libero` and `liberoplus`, Meta-World's `metaworld`:
# color → original). A task not here takes every factor's registered baseline (RoboView's scene: red).
BASELINE_LABELS: Registry[dict[str, str]] = Registry("baseline labels of task")


def register_baseline_labels(task: str, labels: Mapping[str, str]) -> None:
    """Name the baselines of `task`'s visual factors that are its world's own look (`{"color": "original"}`). A label
    must not be a registered value of its factor (it would mean two things); a task registers its labels once."""
    if task in BASELINE_LABELS.registered:
        raise ValueError(f"task {task!r} already registered its baseline labels")
    for name, label in labels.items():
        factor = FACTORS.registered.get(name) or load_factor(name)
        if factor.kind != "visual":
            raise ValueError(
                f"baseline label of {name!r}: only a visual factor's baseline is a world's own look"
            )
        if label in factor.values:
            raise ValueError(f"baseline label {label!r} of {name!r} is one of its values; name it apart")
    BASELINE_LABELS.add(task, dict(labels))


def _label(name: str, task: str | None) -> str | None:
    return BASELINE_LABELS.get(task, {}).get(name) if task is not None else None


def baseline_of(name: str, task: str | None = None) -> str:
    """Factor `name`'s baseline in `task`'s world: its world's label where it declares one (LIBERO's color:
    `original`), else the registered baseline (also without a task)."""
    label = _label(name, task)
    return load_factor(name).baseline if label is None else label


def swept_values(name: str, task: str | None = None) -> tuple[str, ...]:
    """The values a split of factor `name` sweeps in `task`: its world's baseline label first where it declares one
    (the split's control arm), then every registered value."""
    label = _label(name, task)
    values = load_factor(name).values
    return values if label is None else (label, *values)


def baselines(task: str = DEFAULT_TASK) -> dict[str, str]:
    """Every factor of `task` at its baseline (its world's label where it declares one)."""
    return {name: baseline_of(name, task) for name in factor_names(task)}


def record_columns(values: Mapping[str, str]) -> dict[str, Any]:
    """The extra record columns every factor derives from its value (e.g. the color's hex and Lab)."""
    out: dict[str, Any] = {}
    for name, value in values.items():
        factor = FACTORS[name]
        if factor.record_columns is not None:
            out |= factor.record_columns(value)
    return out
