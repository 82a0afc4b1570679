"""A model repo's evaluation results on the Hub, `.eval_results/<benchmark>.yaml`, from one policy's metrics.json.

The layout is the Hub's, documented at https://huggingface.co/docs/hub/eval-results ("Adding Evaluation Results")
and specified in https://github.com/huggingface/hub-docs/blob/main/eval_results.yaml: a YAML list of entries,
each `dataset` {`id`: the benchmark's Hub dataset (a Benchmark), `task_id`: a task of its eval.yaml, `revision`},
`value`, and optionally `verifyToken`, `date` (ISO-8601, a string), `source` {`url`, `name`, `user`, `org`} and
`notes`. The entries are huggingface_hub's `EvalResultEntry`, written by its `eval_result_entries_to_yaml` (and read
back by its `parse_eval_result_entries`); RoboView writes no `verifyToken` (the Hub signs only its own jobs).

One entry per factor (a split: its success rate), one per control arm (the split's all-baseline instance on the
seeds it ran, metrics.json `sr_control`), and with `per_value` one per value of each single-factor split; for a
factor a task takes apart (`analyses`: LIBERO-plus's camera), its total, each single change and its no-change view.
Each `value` is a success rate ×100 (two decimals, as the report prints it); its `notes` carry the episodes and
the 95 % interval metrics.json holds for it, and for a value its paired difference to the control arm (interval and
McNemar p). The task ids are those the benchmark's eval.yaml declares (roboview.benchmark.eval_tasks).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import yaml

from roboview.benchmark.eval_tasks import (
    control_task_id,
    no_change_task_id,
    sub_factor_task_id,
    value_task_id,
)
from roboview.eval.reporting.format import p_fmt, pct, pct_ci

if TYPE_CHECKING:
    from roboview.tasks.decomposition import Decomposition

HUB = "https://huggingface.co"
SOURCE_NAME = "RoboView-Bias result bundle (per-episode, verified)"


@dataclass(frozen=True)
class Score:
    """One entry's task id, success rate (a fraction, as metrics.json holds it) and notes."""

    task_id: str
    sr: float
    notes: str


def rate_notes(n: int, ci: Sequence[float] | None) -> str:
    """Episodes and the Clopper–Pearson interval ×100: "n=27 episodes, 95 % Clopper–Pearson [87.23, 100.00]"."""
    interval = f", 95 % Clopper–Pearson{pct_ci(ci)}" if ci is not None else ""
    return f"n={n:,} episodes{interval}"


def _cv_excess(m: dict[str, Any]) -> str:
    """A split's bias beyond noise ×100: one number (single-factor) or one per factor (factorial)."""
    cv = m.get("cv_excess")
    if isinstance(cv, dict):
        return "cv_excess " + ", ".join(f"{f} {pct(v)}" for f, v in cv.items())
    return f"cv_excess {pct(cv)}{pct_ci(m.get('cv_excess_ci95'))}"


def split_scores(split: str, m: dict[str, Any], per_value: bool) -> list[Score]:
    """A split's factor entry, its control arm's (where one ran), and (`per_value`, single-factor splits) each
    value's."""
    control = m.get("sr_control")
    control_words = (
        f"control arm {pct(control)}{pct_ci(m.get('sr_control_ci95'))} (n={m['n_control_episodes']:,} episodes)"
        if control is not None
        else "no control arm ran"
    )
    scores = [
        Score(
            split, m["sr"], f"{rate_notes(m['n_episodes'], m['sr_ci95'])}; {control_words}; {_cv_excess(m)}"
        )
    ]
    if control is not None:
        scores.append(
            Score(
                control_task_id(split),
                control,
                f"control arm of {split} (the all-baseline instance on the (context, repeat) seeds the split ran): "
                + rate_notes(m["n_control_episodes"], m.get("sr_control_ci95")),
            )
        )
    if per_value and "factor" in m:  # a factorial split's values are pairs: its entry and control arm only
        scores += [value_score(split, v, s) for v, s in m["per_value"].items()]
    return scores


def value_score(split: str, value: str, s: dict[str, Any]) -> Score:
    """One value of a single-factor split: its rate, and its paired difference to the control arm."""
    if s.get("delta_control") is None:
        paired = "no control pair ran"
    else:
        paired = (
            f"Δ vs control {100 * s['delta_control']:+.2f}{pct_ci(s.get('delta_control_ci95'))} over "
            f"{s['n_control_pairs']:,} pairs (same seeds), McNemar p={p_fmt(s['p_control'])}"
        )
    return Score(
        value_task_id(split, value),
        s["sr"],
        f"{split}={value}: {rate_notes(s['n_episodes'], s.get('sr_ci95'))}; {paired}",
    )


def analysis_scores(key: str, result: dict[str, Any], design: Decomposition) -> list[Score]:
    """A decomposed factor's total (as its source benchmark totals it), each single change and the no-change view."""
    total = result[design.name]
    (micro, micro_words), (macro, macro_words) = design.micro, design.macro
    base = total["no_change"]
    scores = []
    if total[micro]["sr"] is not None:
        notes = (
            f"{design.name} over {design.source}'s {total['n_variants']:,} variants run, {micro_words}: "
            f"{rate_notes(total[micro]['n'], total[micro]['ci95'])}; {pct(total[macro])} {macro_words}; "
            f"the no-change view {pct(base['sr'])}{pct_ci(base['ci95'])} (n={base['n']:,} episodes)"
        )
        scores.append(Score(key, total[micro]["sr"], notes))
    for name, k in result["kinds"].items():
        if len(k["factors"]) != 1 or k["sr"] is None:
            continue
        effect = "N/A" if k["effect"] is None else f"{100 * k['effect']:+.2f}"
        notes = (
            f"{name} alone ({k['n_variants']:,} variants): {rate_notes(k['n'], k['ci95'])}; effect vs the no-change "
            f"view {effect}{pct_ci(k['ci95_effect'])} points over {k['n_blocks']:,} blocks (BCa bootstrap), "
            f"sign-flip p={p_fmt(k['p'])}"
        )
        scores.append(Score(sub_factor_task_id(key, k["factors"][0]), k["sr"], notes))
    if base["sr"] is not None:
        scores.append(
            Score(
                no_change_task_id(key), base["sr"], f"no-change view: {rate_notes(base['n'], base['ci95'])}"
            )
        )
    return scores


def metric_scores(metrics: dict[str, Any], per_value: bool = False) -> list[Score]:
    """Every entry of one policy's metrics.json: its splits (single-factor, then factorial), then its analyses."""
    from roboview.tasks.base import analysis_designs

    scores = []
    for group in ("splits", "interactions"):
        for split, m in metrics.get(group, {}).items():
            scores += split_scores(split, m, per_value)
    designs = analysis_designs()
    for key, result in (metrics.get("analyses") or {}).items():
        if key in designs:
            scores += analysis_scores(key, result, designs[key])
    return scores


def eval_result_entries(
    metrics: dict[str, Any],
    *,
    benchmark_repo_id: str,
    results_repo_id: str,
    date: str,
    revision: str | None = None,
    per_value: bool = False,
) -> list[Any]:
    """One `huggingface_hub.EvalResultEntry` per score of one policy's metrics (`metric_scores`): the success rate
    ×100, the benchmark's version as the dataset revision, the bundle as the source."""
    from huggingface_hub import EvalResultEntry

    return [
        EvalResultEntry(
            dataset_id=benchmark_repo_id,
            task_id=s.task_id,
            value=round(100 * s.sr, 2),
            dataset_revision=revision,
            date=date,
            source_url=f"{HUB}/datasets/{results_repo_id}",
            source_name=SOURCE_NAME,
            notes=s.notes,
        )
        for s in metric_scores(metrics, per_value)
    ]


def eval_results_yaml(entries: Sequence[Any]) -> str:
    """The file's text: huggingface_hub's serialisation of the entries, as YAML."""
    from huggingface_hub import eval_result_entries_to_yaml

    return yaml.safe_dump(eval_result_entries_to_yaml(list(entries)), sort_keys=False, allow_unicode=True)


def eval_results_name(benchmark_repo_id: str) -> str:
    """The file name in a model repo's `.eval_results/`: the benchmark's repo name."""
    return f"{benchmark_repo_id.split('/')[-1]}.yaml"
