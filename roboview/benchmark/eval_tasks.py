"""The task ids of a benchmark's Hub listing (`eval.yaml`, written beside its card): each one leaderboard on the
Hub, and the `dataset.task_id` a model repo's `.eval_results` entry names (roboview.eval.reporting.eval_results).

- `<split>`: the split's success rate (every split, single-factor and factorial);
- `<split>/control`: the split's control arm, the all-baseline instance on the (context, repeat) seeds the split
  ran (metrics.json `sr_control`);
- `<split>=<value>`: one value of a single-factor split (metrics.json `per_value.<value>`);
- `<key>`, `<key>/<sub-factor column>` and `<key>/no_change`, for a factor a task takes apart (`Task.analyses`,
  metrics.json `analyses.<key>`; LIBERO-plus's camera is `liberoplus_camera`): the factor's total as its source
  benchmark totals it, each single change, and the no-change view.

`/` joins a part of a factor (its control arm, a sub-factor), `=` a value, so no value can take a part's id.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from roboview.tasks.decomposition import Decomposition

CONTROL = "control"
NO_CHANGE = "no_change"


def control_task_id(split: str) -> str:
    """The control arm of `split`."""
    return f"{split}/{CONTROL}"


def value_task_id(split: str, value: str) -> str:
    """One value of a single-factor split."""
    return f"{split}={value}"


def sub_factor_task_id(key: str, column: str) -> str:
    """One single change (sub-factor) of the factor an analysis takes apart."""
    return f"{key}/{column}"


def no_change_task_id(key: str) -> str:
    """The no-change view of the factor an analysis takes apart (its control arm)."""
    return f"{key}/{NO_CHANGE}"


def analysis_task_ids(design: Decomposition) -> list[tuple[str, str]]:
    """(task id, what it measures) of an analysis: its total, each single change of its kinds, its no-change view."""
    singles = [kind[0] for kind in design.kinds if len(kind) == 1]
    return [
        (design.key, f"{design.name} success rate ×100 over {design.source}'s variants, {design.micro[1]}"),
        *(
            (
                sub_factor_task_id(design.key, c),
                f"success rate ×100 of the {design.kind_name((c,))} changes alone",
            )
            for c in singles
        ),
        (no_change_task_id(design.key), "success rate ×100 of the no-change view"),
    ]
