"""How many repeats each split needs: the power of the GLM likelihood-ratio test of `value + context` against
`context`, planned before any rollout from a split's layout (its values and strata)."""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass

from roboview.eval.statistics.significance import lrt_power, repeats_needed


@dataclass(frozen=True)
class SplitPlan:
    """One tested factor of a split: its values and strata, the repeats it needs and the power at 5 repeats."""

    split: str
    factor: str
    n_values: int
    n_strata: int
    repeats: int | None  # None: more than 1,000 would be needed
    power_at_5: float  # power with the paper's 5 repeats, for comparison


def split_layouts(benchmark_path: str = "", preset: str = "paper") -> list[tuple[str, str, int, int]]:
    """(split, factor, |V|, strata) for every tested factor of every split of a built benchmark (its folder), else
    of a suite preset. A factorial split is laid out per factor: its strata are (other value, context)."""
    if benchmark_path:
        from roboview.benchmark.format import load_benchmark

        items = {s: [i.instance for i in v] for s, v in load_benchmark(benchmark_path).splits.items()}
    else:
        from roboview.tasks import load_preset
        from roboview.variation.instances import generate_suite

        items = defaultdict(list)
        for instance in generate_suite(load_preset(preset)):
            items[instance.split].append(instance)
    out = []
    for split, instances in items.items():
        varied = instances[0].varied
        for factor in varied:
            others = [f for f in varied if f != factor]
            values = {i.get(factor) for i in instances}
            strata = {(tuple(i.get(f) for f in others), i.context_id) for i in instances}
            out.append((split, factor, len(values), len(strata)))
    return out


def plan_splits(
    layouts: list[tuple[str, str, int, int]], tau: float, sr: float, power: float, alpha: float
) -> list[SplitPlan]:
    """The repeats each tested factor (two values or more) needs for `power` against a logit-SD `tau` bias at
    level `alpha`, for a policy of success rate `sr`; and the power the paper's 5 repeats give."""
    return [
        SplitPlan(
            split,
            factor,
            n_values,
            n_strata,
            repeats_needed(n_values, n_strata, tau, sr, power, alpha),
            lrt_power(n_values, n_strata, 5, tau, sr, alpha),
        )
        for split, factor, n_values, n_strata in layouts
        if n_values >= 2
    ]
