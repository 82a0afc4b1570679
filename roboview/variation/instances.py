"""Task instances (v, c) of the benchmark, their stable identities, and the suites of them.

A task instance fixes the value of every factor. Its id is a hash of its canonical parameters,
so the same instance gets the same id on any machine and any backend; episode seeds come from
(context, repeat), shared by every value of a context (docs/formats.md, "Identity and seeds"). A `SuiteConfig` (or a named preset) says which SVGF
variant trees (`roboview.variation.svgf`) make up a benchmark; `generate_suite` walks them.

    >>> from roboview.tasks import load_preset
    >>> len(generate_suite(load_preset("paper")))
    2127
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cached_property
from typing import Any

from roboview.variation.colors import get_color
from roboview.variation.factors import (
    DEFAULT_TASK,
    FACTORS,
    baseline_of,
    context_factors,
    factor_names,
    load_factor,
    record_columns,
    swept_values,
    visual_factors,
)
from roboview.variation.svgf import (
    SUBSPACE_KEY,
    UNION_MODES,
    FactorSampler,
    RecursiveVariantTaskManager,
    VariantNode,
    cartesian_split_name,
    cartesian_subspace,
    context_space,
    factorial_subspace,
    task_subspace,
)

# Which variation subspace of C_Gen a context came from: a context factor's C_k^gen, "base" (the
# baseline context G, in dedupe mode or as the factorial split's c*), or "cartesian".
SEED_MODULUS = 2**31
FACTORIAL_SPLIT = "color_x_camera_pose"
# The paper's splits: its four visual factors and their factorial (the `paper` preset's default).
SPLITS = ("color", "camera_pose", "camera_euler", "dist_scale", FACTORIAL_SPLIT)


def context_subspaces(task: str = DEFAULT_TASK) -> tuple[str, ...]:
    """Where a context can come from: "base" (G), "cartesian", or one context factor's C_k^gen."""
    return ("base", "cartesian", *context_factors(task))


def known_splits() -> tuple[str, ...]:
    """Every split a suite may generate: one per registered visual factor, and the factorial."""
    return (*visual_factors(), FACTORIAL_SPLIT)


# Saturated (red, green, blue), achromatic (black, white, gray) and low-saturation (rosybrown).
DEFAULT_FACTORIAL_COLORS = ("red", "green", "blue", "black", "white", "gray", "rosybrown")


def _round_floats(obj: Any) -> Any:
    """Round floats to 9 decimals so ids do not depend on the last bits of a float."""
    if isinstance(obj, float):
        return round(obj, 9)
    if isinstance(obj, Mapping):
        return {str(k): _round_floats(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_round_floats(v) for v in obj]
    return obj


def canonical_json(params: Mapping[str, Any]) -> str:
    """Canonical JSON of parameters: sorted keys, compact separators, floats rounded to 9 places."""
    return json.dumps(_round_floats(params), sort_keys=True, separators=(",", ":"))


def stable_id(params: Mapping[str, Any]) -> str:
    """First 16 hex digits of SHA-256 over the canonical JSON of `params`."""
    return hashlib.sha256(canonical_json(params).encode("utf-8")).hexdigest()[:16]


def seed_from_text(text: str) -> int:
    digest = hashlib.sha256(text.encode("utf-8")).digest()
    return int.from_bytes(digest[:8], "big") % SEED_MODULUS


def episode_seed(context_id: str, repeat: int) -> int:
    """Seed of repeat `repeat` in context `context_id`: SHA-256("context_id:repeat"), 8 bytes, mod 2**31.

    Common random numbers: every instance of one context (any value, any split) runs repeat r with
    the same seed, so two episodes of one (c, r) differ only in the visual factor under study.
    Derived from ids alone so local pools, Ray workers and other machines agree on it.
    """
    return seed_from_text(f"{context_id}:{repeat}")


@dataclass(frozen=True)
class TaskInstance:
    """One benchmark task instance: every factor's value plus where it sits in the suite.

    `factors` may be given as a mapping or as (name, value) pairs; it is stored as pairs in the
    canonical factor order (visual, then context) so instances are hashable and compare equal
    whatever order they were built in. The paper's seven factors must all be given; a factor
    registered later may be left out, which means its baseline (in the task's world: `baseline_of`).

    Policies never see an instance: its factor values name the object's color and shape
    (`roboview.policies.base.Episode` is what they get).
    """

    # Split the instance belongs to (color, camera_pose, ..., color_x_camera_pose, cartesian_*).
    split: str
    # The factor(s) this split varies, in the order of the `value` column.
    varied: tuple[str, ...]
    # Every factor's value, as (name, value) pairs in factor_names(task) order.
    factors: tuple[tuple[str, str], ...]
    # Variation subspace of C_Gen the context came from (one of context_subspaces(task)).
    context_subspace: str
    # The task (roboview.tasks); kept out of the id for the paper's pick_place.
    task: str = DEFAULT_TASK

    def __post_init__(self) -> None:
        pairs = dict(self.factors.items() if isinstance(self.factors, Mapping) else self.factors)
        names = factor_names(self.task)
        for name in names:
            if name not in pairs and not load_factor(name).always_in_id:
                pairs[name] = baseline_of(name, self.task)
        if set(pairs) != set(names):
            missing = sorted(set(names) - set(pairs))
            extra = sorted(set(pairs) - set(names))
            raise ValueError(
                f"instance of split {self.split!r} must set every factor exactly once; "
                f"missing {missing}, unknown {extra}"
            )
        for name, value in pairs.items():
            load_factor(name).validate(value, self.task)
        object.__setattr__(self, "factors", tuple((name, pairs[name]) for name in names))
        object.__setattr__(self, "varied", tuple(self.varied))
        if not self.varied or len(set(self.varied)) != len(self.varied):
            raise ValueError(f"varied must name distinct factors, got {self.varied!r}")
        for name in self.varied:
            load_factor(name)
        if self.context_subspace not in context_subspaces(self.task):
            raise ValueError(
                f"unknown context_subspace {self.context_subspace!r}; "
                f"allowed: {', '.join(context_subspaces(self.task))}"
            )

    @property
    def factor_values(self) -> dict[str, str]:
        """All factor values as a dict in canonical factor order."""
        return dict(self.factors)

    def get(self, name: str) -> str:
        """The value of factor `name` (unknown names raise listing the valid factors)."""
        return self.factor_values[load_factor(name).name]

    @property
    def context(self) -> dict[str, str]:
        """The task context c: the context factor values of this instance."""
        values = self.factor_values
        return {name: values[name] for name in context_factors(self.task)}

    @property
    def id_factors(self) -> dict[str, str]:
        """The factor values an id hashes: the paper's seven always, any later factor only off its baseline
        (so registering a factor changes no existing id; docs/formats.md, "Identity and seeds")."""
        return {
            name: value
            for name, value in self.factors
            if load_factor(name).always_in_id or value != baseline_of(name, self.task)
        }

    def _with_task(self, params: dict[str, Any]) -> dict[str, Any]:
        return params if self.task == DEFAULT_TASK else params | {"task": self.task}

    @cached_property
    def instance_id(self) -> str:
        """Stable id over split, varied, the factor values, the context subspace and a non-default task."""
        return stable_id(
            self._with_task(
                {
                    "split": self.split,
                    "varied": list(self.varied),
                    "factors": self.id_factors,
                    "context_subspace": self.context_subspace,
                }
            )
        )

    @cached_property
    def context_id(self) -> str:
        """Stable id of the context c; shared by every instance that runs in the same context."""
        return stable_id(
            self._with_task({"context": self.context, "context_subspace": self.context_subspace})
        )

    @property
    def factor(self) -> str:
        """The varied factor names, "|"-joined (the record's `factor` column)."""
        return "|".join(self.varied)

    @property
    def value(self) -> str:
        """The varied values, "|"-joined in the order of `factor`."""
        values = self.factor_values
        return "|".join(values[name] for name in self.varied)

    @property
    def seed(self) -> int:
        """The repeat-0 episode seed (the env's reset default for this instance)."""
        return episode_seed(self.context_id, 0)

    def to_record(self) -> dict[str, Any]:
        """The instance-record columns that need no simulator (docs/formats.md, "Benchmark folder")."""
        return {
            "instance_id": self.instance_id,
            "task": self.task,
            "split": self.split,
            "factor": self.factor,
            "value": self.value,
            "context_id": self.context_id,
            "context_subspace": self.context_subspace,
            **self.factor_values,
            **record_columns(self.factor_values),
            "seed": self.seed,
        }


# --- suite configuration, presets and generation ------------------------------------------------


@dataclass(frozen=True)
class SuiteConfig:
    """Which task instances a benchmark suite holds. Presets are `dataclasses.replace` of it."""

    # Name of the preset this configuration came from (recorded with the benchmark).
    preset: str = "paper"
    # How C_Gen unites the variation subspaces: per_subspace (paper, 11 contexts) or dedupe (9).
    union_mode: str = "per_subspace"
    # Splits to generate, in this order: any of color, camera_pose, camera_euler, dist_scale,
    # color_x_camera_pose.
    splits: tuple[str, ...] = SPLITS
    # Colors crossed with the orbital camera poses in the color_x_camera_pose split.
    factorial_colors: tuple[str, ...] = DEFAULT_FACTORIAL_COLORS
    # Extra full-Cartesian-product splits, each a tuple of factor names (others at baseline).
    cartesian: tuple[tuple[str, ...], ...] = ()
    # Restrictions of factors to some of their values, as (factor, values) pairs; a small suite
    # for demos and tests without changing the registry.
    value_subsets: tuple[tuple[str, tuple[str, ...]], ...] = ()
    # Tasks (roboview.tasks): every split is built for each, over the task's own contexts.
    # Splits of a task other than pick_place are named "<task>_<split>" (push_color, ...).
    tasks: tuple[str, ...] = (DEFAULT_TASK,)
    # "module:function" that lists the suite's instances itself (`function(cfg)`), for a suite that is not a product
    # of factor values, e.g. LIBERO-plus's camera variants (roboview.libero.plus.camera_suite); its `splits` then
    # name the splits it makes (without their task prefix).
    generator: str = ""
    # Splits that hold an external benchmark's own variants (LIBERO-plus's camera variants, each context's no-change
    # view among them), named as in `splits`: a build keeps every instance of them whatever the fairness gate says,
    # its verdict recorded (`fairness.passed`), so a number over them is over that benchmark's whole set; the report
    # gives it over all of them and over the fair ones. The other splits (RoboView's own additions) stay gated.
    ungated_splits: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        # Config parsers may hand in lists; tuples keep the config frozen and hashable.
        object.__setattr__(self, "splits", tuple(self.splits))
        object.__setattr__(self, "tasks", tuple(self.tasks))
        object.__setattr__(self, "ungated_splits", tuple(self.ungated_splits))
        stray = [s for s in self.ungated_splits if s not in self.splits]
        if stray:
            raise ValueError(
                f"ungated_splits {stray} are not splits of the suite; allowed: {', '.join(self.splits)}"
            )
        if (
            not self.tasks
            or len(set(self.tasks)) != len(self.tasks)
            or any(not context_factors(t) for t in self.tasks)
        ):
            known = sorted({f.task for f in FACTORS.values() if f.task})
            raise ValueError(
                f"tasks {self.tasks!r}: give distinct registered tasks; allowed: "
                f"{', '.join(known) or 'none registered (import roboview.tasks first)'}"
            )
        object.__setattr__(self, "factorial_colors", tuple(self.factorial_colors))
        object.__setattr__(self, "cartesian", tuple(tuple(f) for f in self.cartesian))
        subsets = tuple((name, tuple(values)) for name, values in self.value_subsets)
        object.__setattr__(self, "value_subsets", subsets)
        if self.union_mode not in UNION_MODES:
            raise ValueError(f"unknown union_mode {self.union_mode!r}; allowed: {UNION_MODES}")
        for split in () if self.generator else self.splits:
            if split not in known_splits():
                raise ValueError(f"unknown split {split!r}; allowed: {', '.join(known_splits())}")
        if len(set(self.splits)) != len(self.splits):
            raise ValueError(f"splits listed twice in {self.splits!r}")
        if not self.factorial_colors and FACTORIAL_SPLIT in self.splits:
            raise ValueError(f"{FACTORIAL_SPLIT} needs at least one factorial color")
        for name in self.factorial_colors:
            get_color(name)
        if len(set(self.factorial_colors)) != len(self.factorial_colors):
            raise ValueError(f"factorial_colors listed twice in {self.factorial_colors!r}")
        for factors in self.cartesian:
            for name in factors:
                load_factor(name)
            if not factors or len(set(factors)) != len(factors):
                raise ValueError(f"a cartesian split needs distinct factors, got {factors!r}")
        if len(set(self.cartesian)) != len(self.cartesian):
            raise ValueError(f"cartesian splits listed twice in {self.cartesian!r}")
        for name, values in self.value_subsets:
            # Subsets may only hold swept values: camera_pose 'original' is a baseline, not a pose; color 'original'
            # (a world's own look, `swept_values`) is swept where every task of the suite labels its baseline so.
            owner = load_factor(name).task
            for task in [owner] if owner else self.tasks:
                FactorSampler(name, values, task)
                bad = [v for v in values if v not in swept_values(name, task)]
                if bad:
                    raise ValueError(
                        f"value_subsets[{name!r}]: {bad} are not swept values of {name}"
                        + ("" if owner else f" in the {task} task")
                    )
        if len({name for name, _ in self.value_subsets}) != len(self.value_subsets):
            raise ValueError("value_subsets names a factor twice")

    @property
    def subsets(self) -> dict[str, tuple[str, ...]]:
        """value_subsets as a dict."""
        return dict(self.value_subsets)


def split_name(split: str, task: str) -> str:
    """A split's name in the benchmark: bare for pick_place (the paper's names), "<task>_<split>" otherwise."""
    return split if task == DEFAULT_TASK else f"{task}_{split}"


def split_task(split: str) -> tuple[str, str]:
    """Inverse of `split_name`: "push_color" → ("push", "color"); a bare name is pick_place's."""
    for task in {f.task for f in FACTORS.values() if f.task and f.task != DEFAULT_TASK}:
        if split.startswith(f"{task}_"):
            return task, split.removeprefix(f"{task}_")
    return DEFAULT_TASK, split


def split_trees(cfg: SuiteConfig, task: str = DEFAULT_TASK) -> dict[str, tuple[tuple[str, ...], VariantNode]]:
    """Each split's name → (varied factors, variant tree) for one task, in generation order."""
    subsets = {k: v for k, v in cfg.subsets.items() if load_factor(k).task in (None, task)}
    c_gen = context_space(cfg.union_mode, subsets, task)
    trees: dict[str, tuple[tuple[str, ...], VariantNode]] = {}
    for split in cfg.splits:
        if split == FACTORIAL_SPLIT:
            tree = factorial_subspace(cfg.factorial_colors, subsets, task)
            trees[split_name(split, task)] = (("color", "camera_pose"), tree)
        else:
            trees[split_name(split, task)] = ((split,), task_subspace(split, c_gen, subsets, task))
    for factors in cfg.cartesian:
        tree = cartesian_subspace(factors, subsets, task)
        trees[split_name(cartesian_split_name(factors), task)] = (tuple(factors), tree)
    return trees


def generate_suite(cfg: SuiteConfig) -> list[TaskInstance]:
    """All task instances of a suite, task by task and split by split, in a fixed, deterministic order."""
    instances = []
    if cfg.generator:
        import importlib

        module, _, function = cfg.generator.partition(":")
        instances = list(getattr(importlib.import_module(module), function)(cfg))
    for task in () if cfg.generator else cfg.tasks:
        for split, (varied, tree) in split_trees(cfg, task).items():
            for assignment in RecursiveVariantTaskManager(tree).generate():
                subspace = assignment.pop(SUBSPACE_KEY)
                instances.append(TaskInstance(split, varied, tuple(assignment.items()), subspace, task))
    ids = [instance.instance_id for instance in instances]
    if len(set(ids)) != len(ids):
        raise RuntimeError(f"suite {cfg.preset!r} produced duplicate instance ids")
    return instances
