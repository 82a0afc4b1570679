"""Structured Variant-Generation Framework (SVGF, paper §3 and §5.2–5.3).

Every factor is reached through one sampler interface (`SamplerModule`: enumerate or sample its
values). Sampler modules are the leaves of a small tree of `Product` (Cartesian product) and
`Union` (concatenation) nodes; `RecursiveVariantTaskManager` walks such a tree and yields one
factor assignment per task. The benchmark suite is built from these trees only:

- the Generalization Context Space C_Gen as a Structured Union of variation subspaces C_k^gen,
  in `per_subspace` mode (each C_k kept whole: 4 + 4 + 3 = 11 contexts) or `dedupe` mode (the
  set union: 9 contexts);
- per visual factor V_i the task subspace T(V_i) = V_i × C_Gen(V_i), other visual factors at
  their baselines;
- the factorial split color_x_camera_pose in the baseline context c*;
- optional full Cartesian products of chosen factors.

`roboview.variation.instances` turns these assignments into `TaskInstance`s and holds the suite presets:

    >>> tree = task_subspace("dist_scale", context_space("per_subspace"))
    >>> len(list(RecursiveVariantTaskManager(tree).generate()))
    99
"""

from __future__ import annotations

import itertools
from abc import ABC, abstractmethod
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from roboview.variation.factors import (
    DEFAULT_TASK,
    Factor,
    baseline_of,
    baselines,
    context_factors,
    factor_names,
    load_factor,
    swept_values,
    visual_factors,
)

# Assignment key under which a tree labels the C_Gen subspace a context came from.
SUBSPACE_KEY = "context_subspace"
UNION_MODES = ("per_subspace", "dedupe")


# --- the unified sampler interface -------------------------------------------------------------


class SamplerModule(ABC):
    """One factor behind a uniform interface: enumerate its values or draw one at random."""

    @property
    @abstractmethod
    def name(self) -> str:
        """The factor this module assigns."""

    @abstractmethod
    def values(self) -> tuple[str, ...]:
        """Every value, in a fixed order (the enumeration the task manager walks)."""

    def sample(self, rng: np.random.Generator) -> str:
        """One value drawn uniformly with the caller's generator (never a global RNG)."""
        options = self.values()
        return options[int(rng.integers(len(options)))]


class FactorSampler(SamplerModule):
    """Sweeps a registered factor, optionally restricted to a subset of its values. With `task`, its values are
    those the task's split sweeps (`swept_values`: a world's baseline label, LIBERO's color `original`, first)."""

    def __init__(
        self, factor: Factor | str, values: Sequence[str] | None = None, task: str | None = None
    ) -> None:
        self._factor = factor if isinstance(factor, Factor) else load_factor(factor)
        if values is None:
            self._values = swept_values(self._factor.name, task)
        else:
            self._values = tuple(self._factor.validate(v, task) for v in values)
            if not self._values or len(set(self._values)) != len(self._values):
                raise ValueError(f"{self._factor.name}: need distinct values, got {values!r}")

    @property
    def name(self) -> str:
        return self._factor.name

    def values(self) -> tuple[str, ...]:
        return self._values


class FixedSampler(SamplerModule):
    """Holds a factor at one value (usually its baseline) while others vary."""

    def __init__(self, factor: Factor | str, value: str, task: str | None = None) -> None:
        self._factor = factor if isinstance(factor, Factor) else load_factor(factor)
        self._value = self._factor.validate(value, task)

    @property
    def name(self) -> str:
        return self._factor.name

    def values(self) -> tuple[str, ...]:
        return (self._value,)


class ContextSampler:
    """Draws a full random task context with every visual factor at its baseline.

    Data collection randomizes the context only, so a policy trained on the demos never sees
    the visual perturbations the benchmark measures.
    """

    def __init__(self, values: Mapping[str, Sequence[str]] | None = None, task: str = DEFAULT_TASK) -> None:
        values = dict(values or {})
        self.task = task
        unknown = sorted(set(values) - set(context_factors(task)))
        if unknown:
            raise ValueError(f"not context factors: {unknown}; allowed for {task}: {context_factors(task)}")
        self.modules = tuple(FactorSampler(name, values.get(name), task) for name in context_factors(task))

    def sample_context(self, rng: np.random.Generator) -> dict[str, str]:
        """All 7 factor values: visual at baseline, context drawn in context_factors() order."""
        context = baselines(self.task)
        for module in self.modules:
            context[module.name] = module.sample(rng)
        return context


# --- the variant tree and its recursive manager -------------------------------------------------


@dataclass(frozen=True)
class Label:
    """A constant, non-factor annotation merged into every assignment (e.g. the C_Gen subspace)."""

    key: str
    value: str


@dataclass(frozen=True, init=False)
class Product:
    """Cartesian product of its children's assignments (first child varies slowest)."""

    children: tuple[VariantNode, ...]

    def __init__(self, *children: VariantNode) -> None:
        object.__setattr__(self, "children", tuple(children))
        seen: set[str] = set()
        for child in children:
            keys = node_keys(child)
            if seen & keys:
                raise ValueError(f"Product children assign {sorted(seen & keys)} twice")
            seen |= keys


@dataclass(frozen=True, init=False)
class Union:
    """Concatenation of its children's assignments; all children assign the same keys."""

    children: tuple[VariantNode, ...]

    def __init__(self, *children: VariantNode) -> None:
        object.__setattr__(self, "children", tuple(children))
        if not children:
            raise ValueError("Union needs at least one child")
        key_sets = {frozenset(node_keys(child)) for child in children}
        if len(key_sets) != 1:
            raise ValueError(f"Union children assign different keys: {sorted(map(sorted, key_sets))}")


VariantNode = SamplerModule | Label | Product | Union


def node_keys(node: VariantNode) -> frozenset[str]:
    """The assignment keys a node produces."""
    if isinstance(node, SamplerModule):
        return frozenset((node.name,))
    if isinstance(node, Label):
        return frozenset((node.key,))
    if isinstance(node, (Product, Union)):
        return frozenset().union(*(node_keys(child) for child in node.children))
    raise TypeError(f"not a variant node: {node!r}")


@dataclass(frozen=True)
class RecursiveVariantTaskManager:
    """Recursively walks a variant tree and yields one dict of assignments per task variant."""

    root: VariantNode

    def generate(self) -> Iterator[dict[str, str]]:
        """Every assignment of the tree, in a fixed order."""
        yield from self._walk(self.root)

    def _walk(self, node: VariantNode) -> Iterator[dict[str, str]]:
        if isinstance(node, SamplerModule):
            for value in node.values():
                yield {node.name: value}
        elif isinstance(node, Label):
            yield {node.key: node.value}
        elif isinstance(node, Product):
            parts = [list(self._walk(child)) for child in node.children]
            for combo in itertools.product(*parts):
                merged: dict[str, str] = {}
                for part in combo:
                    merged.update(part)
                yield merged
        elif isinstance(node, Union):
            for child in node.children:
                yield from self._walk(child)
        else:
            raise TypeError(f"not a variant node: {node!r}")


# --- the Structured Union, task subspaces and splits --------------------------------------------


def _sampler(name: str, subsets: Mapping[str, Sequence[str]], task: str = DEFAULT_TASK) -> FactorSampler:
    return FactorSampler(name, subsets.get(name), task)


def _fixed_at_baseline(names: Sequence[str], task: str = DEFAULT_TASK) -> tuple[FixedSampler, ...]:
    return tuple(FixedSampler(name, baseline_of(name, task), task) for name in names)


def baseline_context(task: str = DEFAULT_TASK) -> Product:
    """The baseline context G (c* of the factorial split), labelled "base"."""
    return Product(Label(SUBSPACE_KEY, "base"), *_fixed_at_baseline(context_factors(task), task))


def context_space(
    union_mode: str = "per_subspace",
    subsets: Mapping[str, Sequence[str]] | None = None,
    task: str = DEFAULT_TASK,
) -> Union:
    """D_context = ∪_k C_k^gen: vary one context factor at a time, the others at baseline.

    `per_subspace` keeps each C_k whole, so G recurs once per context factor, labelled by it;
    `dedupe` is the set union: G once, labelled "base", and each C_k without its baseline value.
    """
    if union_mode not in UNION_MODES:
        raise ValueError(f"unknown union_mode {union_mode!r}; allowed: {', '.join(UNION_MODES)}")
    subsets = subsets or {}
    subspaces: list[VariantNode] = []
    contains_baseline = False
    for name in context_factors(task):
        values = _sampler(name, subsets, task).values()
        if union_mode == "dedupe":
            contains_baseline |= baseline_of(name, task) in values
            values = tuple(v for v in values if v != baseline_of(name, task))
            if not values:
                continue
        others = [other for other in context_factors(task) if other != name]
        subspaces.append(
            Product(
                Label(SUBSPACE_KEY, name),
                FactorSampler(name, values, task),
                *_fixed_at_baseline(others, task),
            )
        )
    if contains_baseline:
        subspaces.insert(0, baseline_context(task))
    return Union(*subspaces)


def task_subspace(
    factor: str,
    c_gen: VariantNode,
    subsets: Mapping[str, Sequence[str]] | None = None,
    task: str = DEFAULT_TASK,
) -> Product:
    """T(V_i) = V_i × C_Gen(V_i), the other visual factors held at their baselines B_{-i} (in `task`'s world).

    Context-major order (all values of V_i within one context, then the next context), so the
    first N instances of a split already give a per-context spread over V_i.
    """
    if factor not in visual_factors():
        raise ValueError(f"task subspaces exist for visual factors {visual_factors()}, not {factor!r}")
    others = [name for name in visual_factors() if name != factor]
    return Product(c_gen, _sampler(factor, subsets or {}, task), *_fixed_at_baseline(others, task))


def factorial_subspace(
    colors: Sequence[str], subsets: Mapping[str, Sequence[str]] | None = None, task: str = DEFAULT_TASK
) -> Product:
    """color × camera_pose in the single baseline context c*, color-major."""
    others = [name for name in visual_factors() if name not in ("color", "camera_pose")]
    return Product(
        baseline_context(task),
        FactorSampler("color", colors, task),
        _sampler("camera_pose", subsets or {}, task),
        *_fixed_at_baseline(others, task),
    )


def cartesian_split_name(factors: Sequence[str]) -> str:
    """Split name of a full Cartesian product, e.g. "cartesian_color_x_shape"."""
    return "cartesian_" + "_x_".join(factors)


def cartesian_subspace(
    factors: Sequence[str], subsets: Mapping[str, Sequence[str]] | None = None, task: str = DEFAULT_TASK
) -> Product:
    """Full Cartesian product over `factors` (first slowest); every other factor at baseline."""
    others = [name for name in factor_names(task) if name not in factors]
    return Product(
        Label(SUBSPACE_KEY, "cartesian"),
        *(_sampler(name, subsets or {}, task) for name in factors),
        *_fixed_at_baseline(others, task),
    )
