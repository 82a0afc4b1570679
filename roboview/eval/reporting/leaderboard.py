"""A leaderboard that ranks only what the episodes support: leaderboard.json and one static leaderboard.html.

The board is built from result bundles of one benchmark version that `roboview.pipelines.verify` passed (the command,
`roboview.pipelines.leaderboard`, verifies them, re-runs a sample of each, and lists the rest apart with the
reason). Two tables, never mixed: the ranked bundles (their replay passed) and the claims (verified, but not re-run
here), each measured alone and never compared. The ranked bundles' episodes are pooled and measured exactly as `roboview.pipelines.report` measures several policies (`compute_all_metrics`): per
split the success rate with its Clopper–Pearson 95 % interval and `cv_excess` (bias beyond binomial noise) with its
interval; paired tests between every two policies on the episodes they share (McNemar for SR, the swap
permutation test for cv_excess), Holm-adjusted per split and metric. The ranks follow the values; the
**groups** are a compact letter display of those tests: two policies that share a letter are not
significantly different at `alpha` (roboview.eval.statistics.ranking). Overall, SR pools every paired episode of every
split; cv_excess is the mean over splits with no overall test (its differences are tested per split), so
every policy shares its letter there.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from roboview.eval.running.results import infra_mask
from roboview.eval.statistics.ranking import ALPHA, pooled_p_sr, rank_table
from roboview.eval.statistics.tables import rate_ci95

BOARD_JSON = "leaderboard.json"
BOARD_HTML = "leaderboard.html"
BOARD_FORMAT = 1


@dataclass
class Entry:
    """One bundle on the board: its label (the policy's name on the board), where it came from and its report."""

    label: str
    source: str
    policy: str
    report: str  # report.html, relative to the board's folder
    episodes: int = 0
    privileged: bool = False
    # The benchmark protocol the bundle claims; partial: it covers only some of its splits (ranked per split only).
    protocol: str = ""
    partial: bool = False
    # Whether the board re-ran a random sample of its episodes here, and the guarantee or why not.
    replayed: bool = False
    replay_note: str = ""
    # The board's table it is in: `ranked` (its replay passed, or the board replayed nothing) or `claims`.
    table: str = "ranked"


@dataclass
class Claim(Entry):
    """A bundle that verified but whose outcomes could not be re-run here (an unreachable or stochastic policy,
    another simulation stack; `replay_note` says which): shown with what it claims, measured alone, never ranked,
    lettered or compared with another bundle."""

    table: str = "claims"
    # Its success rate over every counted episode of the splits it covers, with its Clopper–Pearson 95 % interval.
    sr: float | None = None
    sr_ci95: list[float] | None = None
    covered: list[str] = field(default_factory=list)


@dataclass
class Rejected:
    """A bundle the board lists apart, never ranked, and why."""

    source: str
    reason: str


@dataclass
class Board:
    benchmark_version: str
    entries: list[Entry]
    rejected: list[Rejected] = field(default_factory=list)
    overall: dict[str, list[dict[str, Any]]] = field(default_factory=dict)
    splits: dict[str, dict[str, list[dict[str, Any]]]] = field(default_factory=dict)
    alpha: float = ALPHA
    resampling: dict[str, Any] = field(default_factory=dict)
    generated: str = ""
    # The protocol every ranked bundle claims: overall figures are computed on it alone.
    protocol: str = ""
    # The bundles listed apart as claims (verified, not re-run here), never ranked.
    claims: list[Claim] = field(default_factory=list)
    # How the board replayed: n episodes per bundle (0: none), detect, confidence, the guarantee in words, the
    # seconds every bundle's checks and replay took, this machine's stack.
    replay: dict[str, Any] = field(default_factory=dict)

    @property
    def replayed(self) -> bool:
        """Whether the board re-ran a sample of every bundle (its ranked rows are then verified)."""
        return bool(self.replay.get("n"))

    def to_json(self) -> dict[str, Any]:
        return {"format": BOARD_FORMAT, "adjustment": "holm"} | asdict(self)


def _rows(
    values: dict[str, float],
    pvalues: dict[frozenset[str], float | None],
    higher_better: bool,
    ci: dict[str, Any],
    episodes: dict[str, int],
    alpha: float,
    reference: set[str] | frozenset[str] = frozenset(),
) -> list[dict[str, Any]]:
    """The ranked rows, then the reference rows (privileged policies: shown, never ranked)."""
    ranked_values = {n: v for n, v in values.items() if n not in reference}
    ranked = rank_table(ranked_values, pvalues, higher_better, alpha)
    # Tied values share a rank (1, 1, 3): the order among them is alphabetical, not a claim.
    rows = [
        r
        | {
            "ci95": ci.get(r["policy"]),
            "episodes": episodes[r["policy"]],
            "rank": 1
            + sum((v > r["value"]) if higher_better else (v < r["value"]) for v in ranked_values.values()),
        }
        for r in ranked
    ]
    for name in sorted(set(values) & set(reference)):
        rows.append(
            {
                "policy": name,
                "value": values[name],
                "group": "ref",
                "rank_range": None,
                "rank": None,
                "reference": True,
                "ci95": ci.get(name),
                "episodes": episodes[name],
            }
        )
    return rows


def rank_metrics(
    layouts: dict[str, Any],
    comparisons: list[dict],
    episodes: pd.DataFrame,
    partial: set[str] | frozenset[str] = frozenset(),
    reference: set[str] | frozenset[str] = frozenset(),
    alpha: float = ALPHA,
) -> tuple[dict[str, list], dict[str, dict[str, list]]]:
    """Per split and overall, the board's rows for SR and cv_excess: `layouts` are each policy's metrics
    (`compute_all_metrics`), `comparisons` the paired tests between them, `episodes` what they came from
    (infrastructure errors left out). Partial bundles are ranked per split only; `reference` policies are shown
    beside each ranking, never in it. Overall SR pools every counted episode of each complete bundle, one way for
    one policy or many."""
    counted = episodes[~infra_mask(episodes)]
    splits: dict[str, dict[str, list]] = {}
    for split in sorted({s for layout in layouts.values() for s in layout["splits"]}):
        comps = {frozenset(c["policies"]): c for c in comparisons if c["split"] == split}
        have = {n: layout["splits"][split] for n, layout in layouts.items() if split in layout["splits"]}
        n_eps = {n: int(m["n_episodes"]) for n, m in have.items()}
        entry: dict[str, list] = {}
        for metric, p_key, higher in (("sr", "p_sr", True), ("cv_excess", "p_cv_excess", False)):
            values = {n: m[metric] for n, m in have.items() if m[metric] is not None}
            if values:
                pvalues = {pair: c[p_key] for pair, c in comps.items()}
                ci = {n: have[n][f"{metric}_ci95"] for n in values}
                entry[metric] = _rows(values, pvalues, higher, ci, n_eps, alpha, reference)
        for row in entry.get("sr", []):  # the control arm beside each SR: same contexts, same seeds
            row["sr_control"] = have[row["policy"]].get("sr_control")
            row["sr_control_ci95"] = have[row["policy"]].get("sr_control_ci95")
        splits[split] = entry
    splits |= _factorial(layouts, counted, reference, alpha)
    return _overall(
        layouts, counted, sorted(n for n in layouts if n not in partial), reference, alpha
    ), splits


def _factorial(layouts, counted: pd.DataFrame, reference, alpha: float) -> dict[str, dict[str, list]]:
    """Each factorial split's SR table (its bias measures are interaction coefficients, reported per bundle):
    Clopper–Pearson intervals, McNemar on the (instance, repeat) pairs two bundles share, Holm-adjusted."""
    out: dict[str, dict[str, list]] = {}
    for split in sorted({s for layout in layouts.values() for s in layout.get("interactions", {})}):
        have = {
            n: layout["interactions"][split]
            for n, layout in layouts.items()
            if split in layout.get("interactions", {})
        }
        rows = counted[counted["split"] == split]
        names = sorted(have)
        pvalues = {
            frozenset((a, b)): pooled_p_sr(rows, a, b) for i, a in enumerate(names) for b in names[i + 1 :]
        }
        values = {n: m["sr"] for n, m in have.items() if m.get("sr") is not None}
        if values:
            ci = {n: have[n].get("sr_ci95") for n in values}
            n_eps = {n: int(have[n]["n_episodes"]) for n in have}
            out[split] = {"sr": _rows(values, pvalues, True, ci, n_eps, alpha, reference)}
    return out


def _overall(layouts, counted: pd.DataFrame, names: list[str], reference, alpha: float) -> dict[str, list]:
    """Overall SR (every counted episode pooled, paired tests on the shared ones) and mean cv_excess."""
    if not names:
        return {}
    k = {n: int(counted.loc[counted["policy"] == n, "success"].sum()) for n in names}
    n = {n: int((counted["policy"] == n).sum()) for n in names}
    pooled = {
        frozenset((a, b)): pooled_p_sr(counted, a, b) for i, a in enumerate(names) for b in names[i + 1 :]
    }
    sr = {x: k[x] / n[x] for x in names if n[x]}
    ci = {x: rate_ci95(k[x], n[x]) for x in names if n[x]}
    overall = {"sr": _rows(sr, pooled, True, ci, n, alpha, reference)}
    mean_cv = {
        x: float(np.mean(v))
        for x in names
        if (v := [m["cv_excess"] for m in layouts[x]["splits"].values() if m["cv_excess"] is not None])
    }
    if mean_cv:  # no overall test of cv_excess: one group, every rank possible
        overall["cv_excess"] = _rows(mean_cv, {}, False, {}, n, alpha, reference)
    return overall


def annotate(board: Board) -> None:
    """Every table row carries its bundle's protocol, partial, replayed, replay_note and table."""
    entries = {e.label: e for e in board.entries}
    tables = [board.overall, *board.splits.values()]
    for table in tables:
        for rows in table.values():
            for row in rows:
                e = entries.get(row["policy"])
                if e is not None:
                    row.update(
                        protocol=e.protocol,
                        partial=e.partial,
                        replayed=e.replayed,
                        replay_note=e.replay_note,
                        table=e.table,
                    )


def labels_for(policies: Sequence[str], sources: Sequence[str]) -> list[str]:
    """Board labels: each bundle's policy name, made unique by its folder's name where two bundles share one."""
    counts = pd.Series(list(policies)).value_counts()
    out = []
    for policy, source in zip(policies, sources):
        label = policy if counts[policy] == 1 else f"{policy}@{Path(source).name}"
        out.append(label)
    if len(set(out)) != len(out):
        raise ValueError(f"bundles with the same policy and folder name: {sorted(out)}; rename a folder")
    return out
