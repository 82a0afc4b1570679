"""A factor decomposition's design, as data: what a task declares (`Task.analyses`) for the statistics room
(`roboview.eval.statistics.decompose`) to take one factor of its episodes apart, and for the report
(`roboview.eval.reporting.decomposition`) to say it in the task's words.

A decomposed factor is a product of integer *sub-factors*, each an episode column with its value in the no-change
view. A *variant* changes one or more of them; its *kind* is the set it changes. The design names the kinds tested
against the no-change view, the sub-factors whose severity a dose–response is fitted over, the splits that hold the
external benchmark's own variants (what its headline number is over) and the groups it averages over, and the words
the report prints. Nothing here computes: a wing declares its design without importing the statistics, and the
statistics read it from the task registry without importing the wing. LIBERO-plus's camera and sensor-noise
dimensions (`roboview.libero.decomposition`) are two.

A design may declare a *twin*: the external variants run again with one more sub-factor changed (LIBERO-plus's noise
on the wrist camera too, where LIBERO-plus leaves that camera clean), whose totals the result gives beside the
external number and each against its original, paired by block.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SubFactor:
    """One sub-factor of a decomposed factor."""

    # The episode column holding its value (an integer, as a string or a number).
    column: str
    # Its name in the result and the report ("azimuth").
    name: str
    # Its value in the no-change view.
    no_change: int
    # How far a value is from the no-change view (its severity): value − no_change, or, over a period (an angle's
    # 360), the shorter way round the circle.
    period: int = 0
    # The unit its severity is counted in ("degrees"); a sub-factor with one gets a dose–response over its severity.
    unit: str = ""
    # The dose–response figure's x-axis label ("|azimuth| (degrees)").
    axis: str = ""

    def severity(self, values) -> np.ndarray:
        """How far each of `values` is from the no-change view, as floats."""
        d = np.asarray(values, dtype=float) - self.no_change
        if self.period:
            d = d % self.period
            d = np.minimum(d, self.period - d)
        return d


@dataclass(frozen=True)
class Twin:
    """Every variant run again with one more sub-factor changed (its `column` away from its no-change value)."""

    # The sub-factor column the twins change.
    column: str
    # The twins in a few words ("on both cameras") and in a sentence for the report.
    name: str
    words: str


@dataclass(frozen=True)
class Decomposition:
    """How one task's factor is taken apart (module docstring)."""

    # metrics.json's `analyses.<key>` and the report section's title.
    key: str
    title: str
    # The task whose episodes it reads (rows with `task` == it).
    task: str
    # The decomposed factor's name: the result's key of its totals and the report's "<Name> success rate".
    name: str
    sub_factors: tuple[SubFactor, ...]
    # The kinds tested against the no-change view, in the report's order: each the sub-factor columns it changes.
    # A two-change kind also gets its interaction with its single-change parts.
    kinds: tuple[tuple[str, ...], ...]
    # The splits (without the `<task>_` prefix) holding the external benchmark's own variants: its number is over
    # them; the others hold the single-change parts added beside them.
    variant_splits: tuple[str, ...]
    # The context column naming a variant's context ("libero_spatial/3"); its part before "/" is the variant's group,
    # one of `groups`, over which the macro total averages; `groups_word` names them in the report ("suites").
    group_column: str
    groups: tuple[str, ...]
    groups_word: str
    # The external benchmark's name ("LIBERO-plus"), and the result's keys and the report's words of the two totals:
    # the micro total (every variant episode alike) and the macro one (the groups' mean).
    source: str
    micro: tuple[str, str]
    macro: tuple[str, str]
    # The context column naming the instruction the policy got, and the words for each of its values, the first one
    # that ran said (the last where none did); "": no such column.
    instruction_column: str = ""
    instructions: tuple[tuple[str, str], ...] = ()
    # Every split (without the `<task>_` prefix) whose episodes it reads; empty: all of the task's. Two designs on one
    # task (LIBERO-plus's camera and noise) each read their own, so one's variants are never the other's no-change
    # view.
    splits: tuple[str, ...] = ()
    # The variants' twins (`Twin`), or None.
    twin: Twin | None = None
    # The dose–response figure's file name; "": `analysis_<task>_dose_response.png`.
    figure_name: str = ""

    def __post_init__(self) -> None:
        columns = [f.column for f in self.sub_factors]
        if len(set(columns)) != len(columns):
            raise ValueError(f"decomposition {self.key!r}: a sub-factor column twice in {columns}")
        unknown = sorted({c for kind in self.kinds for c in kind} - set(columns))
        if self.twin is not None and self.twin.column not in columns:
            unknown.append(self.twin.column)
        if unknown:
            raise ValueError(
                f"decomposition {self.key!r}: kinds or twin name {unknown}, not its sub-factors {columns}"
            )

    def sub_factor(self, column: str) -> SubFactor:
        return next(f for f in self.sub_factors if f.column == column)

    def kind_name(self, kind: tuple[str, ...]) -> str:
        """A kind in words: its sub-factors' names, " + "-joined ("azimuth + elevation")."""
        return " + ".join(self.sub_factor(c).name for c in kind)

    @property
    def dose_factors(self) -> tuple[SubFactor, ...]:
        """The sub-factors a dose–response is fitted over (those with a unit)."""
        return tuple(f for f in self.sub_factors if f.unit)

    @property
    def figure(self) -> str:
        """The dose–response figure's file name."""
        return self.figure_name or f"analysis_{self.task}_dose_response.png"

    def reads(self, split: str) -> bool:
        """Whether a benchmark split (`<task>_<split>`) is one the design reads."""
        return not self.splits or str(split).removeprefix(f"{self.task}_") in self.splits
