"""Adaptive evaluation in rounds: repeat r of every instance of the splits still running, the splits' test
deciding before each round which stop (roboview.eval.statistics.adaptive)."""

from __future__ import annotations

import logging
from pathlib import Path

from roboview.eval.campaign.config import EvaluateConfig
from roboview.eval.running.results import EpisodeStore, is_counted
from roboview.eval.running.rollout import WorkItem

log = logging.getLogger(__name__)


def run_rounds(
    cfg: EvaluateConfig,
    chosen: dict[str, list],
    repeats: dict[str, int],
    adaptive: set[str],
    store: EpisodeStore,
    execute,
    bar,
) -> None:
    """Adaptive evaluation: round r runs repeat r of every instance of the splits still running (and of the
    fixed splits); before each round the splits' test decides who stops. A rerun recomputes the same
    decisions from the rows already written, so it resumes mid-split where it stopped."""
    from roboview.eval.statistics.adaptive import decide_split, write_record

    design = cfg.eval.design
    out = Path(cfg.output_dir)
    active = set(adaptive)
    records: dict[str, dict] = {}
    for r in range(design.max_repeats + 1):
        for split in sorted(active):
            rows = _counted_rows(chosen[split], r, store)
            decision = decide_split(rows, r, design)
            if decision.stopped:
                records[split] = decision.record(len(rows))
                active.discard(split)
                bar.total -= len(chosen[split]) * (design.max_repeats - r)
                bar.refresh()
                log.info(
                    "split %s: stopped after %d round(s): %s (LRT %s)",
                    split,
                    r,
                    decision.stopped,
                    "—" if decision.statistic is None else f"{decision.statistic:.1f}",
                )
                write_record(out, design, records)
        if r == design.max_repeats:
            break
        execute(
            [
                WorkItem(item, r)
                for split, items in chosen.items()
                for item in items
                if (split in active or (split not in adaptive and r < repeats[split]))
                and not store.done((item.record["instance_id"], r))
            ]
        )
    execute(
        [
            WorkItem(item, rep)
            for split, items in chosen.items()
            if split not in adaptive
            for item in items
            for rep in range(design.max_repeats, repeats[split])
            if not store.done((item.record["instance_id"], rep))
        ]
    )


def _counted_rows(items: list, rounds: int, store: EpisodeStore) -> list[dict]:
    """The rows of `items`' first `rounds` repeats that count: rows infrastructure ended (still so after their
    re-runs) enter no decision."""
    return [
        row
        for item in items
        for rep in range(rounds)
        if (row := store.rows.get((item.record["instance_id"], rep))) is not None and is_counted(row)
    ]
