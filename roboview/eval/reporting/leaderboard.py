"""A leaderboard that ranks only what the episodes support: leaderboard.json and one static leaderboard.html.

The board is built from result bundles of one benchmark version that `roboview.pipelines.verify` passed (the command,
`roboview.pipelines.leaderboard`, verifies them and lists the rest apart with the reason). Their episodes are
pooled and measured exactly as `roboview.pipelines.report` measures several policies (`compute_all_metrics`): per
split the success rate with its Wilson 95 % interval and `cv_excess` (bias beyond binomial noise) with its
interval; paired tests between every two policies on the episodes they share (McNemar for SR, the swap
permutation test for cv_excess), Holm-adjusted per split and metric. The ranks follow the values; the
**groups** are a compact letter display of those tests: two policies that share a letter are not
significantly different at `alpha` (roboview.eval.statistics.ranking). Overall, SR pools every paired episode of every
split; cv_excess is the mean over splits with no overall test (its differences are tested per split), so
every policy shares its letter there.
"""

from __future__ import annotations

import html
import json
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from roboview.eval.reporting.format import pct, pct_ci, split_title
from roboview.eval.statistics.ranking import ALPHA, pooled_p_sr, rank_table
from roboview.eval.statistics.tables import wilson_ci95

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
    counted = episodes[episodes.get("status", pd.Series("ok", index=episodes.index)) != "infra_error"]
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
    Wilson intervals, McNemar on the (instance, repeat) pairs two bundles share, Holm-adjusted."""
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
    wilson = {x: list(wilson_ci95(k[x], n[x])) for x in names if n[x]}
    overall = {"sr": _rows(sr, pooled, True, wilson, n, alpha, reference)}
    mean_cv = {
        x: float(np.mean(v))
        for x in names
        if (v := [m["cv_excess"] for m in layouts[x]["splits"].values() if m["cv_excess"] is not None])
    }
    if mean_cv:  # no overall test of cv_excess: one group, every rank possible
        overall["cv_excess"] = _rows(mean_cv, {}, False, {}, n, alpha, reference)
    return overall


def annotate(board: Board) -> None:
    """Every table row carries its bundle's protocol, partial, replayed and replay_note."""
    entries = {e.label: e for e in board.entries}
    tables = [board.overall, *board.splits.values()]
    for table in tables:
        for rows in table.values():
            for row in rows:
                e = entries.get(row["policy"])
                if e is not None:
                    row.update(
                        protocol=e.protocol, partial=e.partial, replayed=e.replayed, replay_note=e.replay_note
                    )


def write_board(board: Board, output_dir: Path) -> tuple[Path, Path]:
    annotate(board)
    output_dir.mkdir(parents=True, exist_ok=True)
    json_path, html_path = output_dir / BOARD_JSON, output_dir / BOARD_HTML
    json_path.write_text(json.dumps(board.to_json(), indent=2, default=float) + "\n")
    html_path.write_text(render_board(board))
    return json_path, html_path


# --- the page ---------------------------------------------------------------------------------------

_CSS = """
body { font: 15px/1.45 system-ui, -apple-system, "Segoe UI", sans-serif; margin: 2em auto; max-width: 1100px;
       padding: 0 1em; color: #222; }
h1 { font-size: 1.6em; margin-bottom: .2em; } h2 { margin-top: 2em; } h3 { margin: 1.2em 0 .3em; }
table { border-collapse: collapse; margin: .4em 0 1em; font-variant-numeric: tabular-nums; }
th, td { padding: .3em .7em; border-bottom: 1px solid #ddd; text-align: right; }
th { background: #f4f4f4; cursor: pointer; user-select: none; white-space: nowrap; }
th.sorted-asc::after { content: " ▲"; } th.sorted-desc::after { content: " ▼"; }
td.name, th.name { text-align: left; } td.group { font-family: ui-monospace, monospace; text-align: center; }
tr.privileged td { color: #777; font-style: italic; }
.note { color: #555; max-width: 60em; } .rejected td { text-align: left; }
"""

# Sort a table by the clicked column: numbers by their data-sort value, text by its text; a second click reverses.
_JS = """
document.querySelectorAll('table.ranked').forEach(function (table) {
  table.querySelectorAll('th').forEach(function (th, col) {
    th.addEventListener('click', function () {
      var asc = !th.classList.contains('sorted-asc');
      table.querySelectorAll('th').forEach(function (h) { h.classList.remove('sorted-asc', 'sorted-desc'); });
      th.classList.add(asc ? 'sorted-asc' : 'sorted-desc');
      var body = table.tBodies[0];
      var rows = Array.prototype.slice.call(body.rows);
      rows.sort(function (a, b) {
        var x = a.cells[col].dataset.sort, y = b.cells[col].dataset.sort;
        var nx = parseFloat(x), ny = parseFloat(y);
        var d = (isNaN(nx) || isNaN(ny)) ? String(x).localeCompare(String(y)) : nx - ny;
        return asc ? d : -d;
      });
      rows.forEach(function (r) { body.appendChild(r); });
    });
  });
});
"""

_METRIC_TITLES = {
    "sr": ("Success rate", "SR ×100 [95 % CI]", "higher is better"),
    "cv_excess": ("Bias beyond noise", "cv_excess ×100 [95 % CI]", "lower is better"),
}


def _table(rows: list[dict[str, Any]], metric: str, entries: dict[str, Entry]) -> str:
    _, column, _ = _METRIC_TITLES[metric]
    if not any(r.get("ci95") for r in rows):  # the header claims no interval the statistics do not give
        column = column.replace(" [95 % CI]", " (no interval)")
    head = (
        '<tr><th data-key="rank">Rank</th><th class="name" data-key="policy">Policy</th>'
        f'<th data-key="value">{column}</th><th data-key="group">Group</th>'
        '<th data-key="range">Possible ranks</th><th data-key="episodes">Episodes</th>'
        '<th data-key="replay">Replayed</th></tr>'
    )
    control = metric == "sr" and any(r.get("sr_control") is not None for r in rows)
    if control:
        head = head.replace(
            '<th data-key="group">',
            '<th data-key="control">Control SR ×100 [95 % CI]</th><th data-key="group">',
        )
    body = []
    for r in rows:
        e = entries.get(r["policy"])
        label = html.escape(r["policy"]) + (
            " (privileged: reference, not ranked)" if e and e.privileged else ""
        )
        label += " (partial)" if e and e.partial else ""
        name = f'<a href="{html.escape(e.report)}">{label}</a>' if e and e.report else label
        lo, hi = r["rank_range"] or ("—", "—")
        rank = "ref" if r["rank"] is None else r["rank"]
        replay = ("yes" if e.replayed else "no") if e else ""
        body.append(
            f'<tr class="{"privileged" if e and e.privileged else ""}">'
            f'<td data-sort="{r["rank"] if r["rank"] is not None else 0}">{rank}</td>'
            f'<td class="name" data-sort="{html.escape(r["policy"])}">{name}</td>'
            f'<td data-sort="{r["value"]:.10g}">{pct(r["value"])}{html.escape(pct_ci(r["ci95"]))}</td>'
            + (_control_cell(r) if control else "")
            + f'<td class="group" data-sort="{html.escape(r["group"])}">{html.escape(r["group"])}</td>'
            f'<td data-sort="{lo}">{lo}–{hi}</td>'
            f'<td data-sort="{r["episodes"]}">{r["episodes"]}</td>'
            f'<td data-sort="{replay}" title="{html.escape(e.replay_note if e else "")}">{replay}</td></tr>'
        )
    return f'<table class="ranked" data-metric="{metric}"><thead>{head}</thead><tbody>{"".join(body)}</tbody></table>'


def _control_cell(r: dict[str, Any]) -> str:
    value = r.get("sr_control")
    sort = -1 if value is None else value
    return f'<td data-sort="{sort:.10g}">{pct(value)}{html.escape(pct_ci(r.get("sr_control_ci95")))}</td>'


def _section(title: str, tables: dict[str, list], entries: dict[str, Entry], level: str = "h3") -> list[str]:
    out = []
    for metric in ("sr", "cv_excess"):
        if metric in tables:
            name, _, direction = _METRIC_TITLES[metric]
            out.append(f"<{level}>{html.escape(title)}: {name} ({direction})</{level}>")
            out.append(_table(tables[metric], metric, entries))
    return out


def render_board(board: Board) -> str:
    entries = {e.label: e for e in board.entries}
    parts = [
        "<!doctype html><html lang=en><head><meta charset=utf-8>",
        f"<title>RoboView-Bias leaderboard — {html.escape(board.benchmark_version)}</title>",
        f"<style>{_CSS}</style></head><body>",
        "<h1>RoboView-Bias leaderboard</h1>",
        f"<p class=note>Benchmark <code>{html.escape(board.benchmark_version)}</code>, protocol "
        f"<code>{html.escape(board.protocol or 'none')}</code>; "
        f"{len(board.entries)} verified bundle(s), {len(board.rejected)} listed apart; generated "
        f"{html.escape(board.generated)}.</p>",
        "<p class=note>Ranked by success rate (higher first) and by <code>cv_excess</code>, the spread of "
        "success across the factor's values beyond what binomial noise explains (lower first), each with its "
        "95 % interval. <b>Group</b>: policies that share a letter are not significantly different "
        f"(paired tests on the same instances and seeds, Holm-adjusted, α = {board.alpha}); "
        "<b>possible ranks</b>: the ranks those tests leave open. Overall cv_excess is the mean over splits "
        "and has no overall test: its differences are tested per split. Click a column to sort. Each name "
        "links to the bundle's report. A privileged policy (it reads the simulator's state) is a reference line, "
        "not ranked; a partial bundle (some of the protocol's splits) is ranked on those splits only, never "
        "overall. <b>Replayed</b>: whether the board re-ran a random sample of the bundle's episodes here "
        "(hover for the guarantee, or why not).</p>",
    ]
    parts += _section("Overall", board.overall, entries, "h2")
    if board.splits:
        parts.append("<h2>Per split</h2>")
        for split, tables in board.splits.items():
            parts += _section(split_title(split), tables, entries)
    if board.rejected:
        parts.append(
            "<h2>Listed apart (not ranked)</h2><table class=rejected><tr><th>Bundle</th><th>Why</th></tr>"
        )
        parts += [
            f"<tr><td>{html.escape(r.source)}</td><td>{html.escape(r.reason)}</td></tr>"
            for r in board.rejected
        ]
        parts.append("</table>")
    parts.append(f"<script>{_JS}</script></body></html>\n")
    return "\n".join(parts)


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
