"""The board written: leaderboard.json (every number) and one static leaderboard.html rendered from the same `Board`.

Its title says whether the board re-ran the bundles' episodes; the ranked tables hold only bundles whose replay
passed; the claims (verified, not re-run here) and the rejected bundles follow in tables of their own, never ranked.
"""

from __future__ import annotations

import html
import json
from pathlib import Path
from typing import Any

from roboview.eval.reporting.format import pct, pct_ci, split_title
from roboview.eval.reporting.leaderboard import BOARD_HTML, BOARD_JSON, Board, Entry, annotate


def write_board(board: Board, output_dir: Path) -> tuple[Path, Path]:
    annotate(board)
    output_dir.mkdir(parents=True, exist_ok=True)
    json_path, html_path = output_dir / BOARD_JSON, output_dir / BOARD_HTML
    json_path.write_text(json.dumps(board.to_json(), indent=2, default=float) + "\n")
    html_path.write_text(render_board(board))
    return json_path, html_path


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
table.claims td.name { max-width: 40em; }
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


def title(board: Board) -> str:
    """The page's title: a board that replayed nothing says so."""
    name = "RoboView-Bias leaderboard"
    return name if board.replayed else f"{name} (not replayed: outcomes as the bundles report them)"


def _replay_note(board: Board) -> str:
    if not board.replayed:
        return (
            "<p class=note><b>Not replayed.</b> This board was built with <code>--replay=0</code>: no episode of any "
            "bundle was re-run here, so a bundle whose outcomes were edited to match its own files ranks like an "
            "honest one: only the bundles' own files were checked.</p>"
        )
    return (
        f"<p class=note><b>Replayed here</b>: {html.escape(board.replay['guarantee'])} "
        f"(checking and replaying the {len(board.entries) + len(board.claims) + len(board.rejected)} bundle(s) took "
        f"{board.replay['seconds']:.0f} s on {html.escape(board.replay.get('stack') or 'this machine')}). Only "
        "bundles whose replay passed are ranked; "
        "those whose episodes could not be re-run here are listed apart as claims, and a bundle whose replay "
        "disagrees with its rows is rejected.</p>"
    )


def _claims(board: Board) -> list[str]:
    if not board.claims:
        return []
    out = [
        "<h2>Claims (not replayed here: not ranked, not compared)</h2>",
        "<p class=note>These bundles pass every check of their files, but their outcomes could not be re-run on "
        "this board's machine. Each is measured alone, as it reports itself; no letter, no rank, no test against "
        "another bundle.</p>",
        "<table class=claims><tr><th class=name>Policy</th><th>Claimed SR ×100 [95 % CI]</th><th>Episodes</th>"
        "<th class=name>Splits</th><th class=name>Why not replayed</th></tr>",
    ]
    for c in board.claims:
        name = f'<a href="{html.escape(c.report)}">{html.escape(c.label)}</a>'
        name += " (privileged)" if c.privileged else ""
        splits = ", ".join(c.covered) + (" (partial)" if c.partial else "")
        out.append(
            f'<tr><td class="name">{name}</td><td>{pct(c.sr)}{html.escape(pct_ci(c.sr_ci95))}</td>'
            f'<td>{c.episodes}</td><td class="name">{html.escape(splits)}</td>'
            f'<td class="name">{html.escape(c.replay_note)}</td></tr>'
        )
    out.append("</table>")
    return out


def render_board(board: Board) -> str:
    entries = {e.label: e for e in board.entries}
    parts = [
        "<!doctype html><html lang=en><head><meta charset=utf-8>",
        f"<title>{html.escape(title(board))} — {html.escape(board.benchmark_version)}</title>",
        f"<style>{_CSS}</style></head><body>",
        f"<h1>{html.escape(title(board))}</h1>",
        f"<p class=note>Benchmark <code>{html.escape(board.benchmark_version)}</code>, protocol "
        f"<code>{html.escape(board.protocol or 'none')}</code>; "
        + (
            f"{len(board.entries)} ranked bundle(s) (replay passed), {len(board.claims)} claim(s) listed apart, "
            if board.replayed
            else f"{len(board.entries)} bundle(s) checked but not replayed, "
        )
        + f"{len(board.rejected)} rejected; generated {html.escape(board.generated)}.</p>",
        _replay_note(board),
        "<p class=note>Ranked by success rate (higher first) and by <code>cv_excess</code>, the spread of "
        "success across the factor's values beyond what binomial noise explains (lower first), each with its "
        "95 % interval. <b>Group</b>: policies that share a letter are not significantly different "
        f"(paired tests on the same instances and seeds, Holm-adjusted, α = {board.alpha}); "
        "<b>possible ranks</b>: the ranks those tests leave open. Overall cv_excess is the mean over splits "
        "and has no overall test: its differences are tested per split. Click a column to sort. Each name "
        "links to the bundle's report. A privileged policy (it reads the simulator's state) is a reference line, "
        "not ranked; a partial bundle (some of the protocol's splits) is ranked on those splits only, never "
        "overall. <b>Replayed</b>: whether the board re-ran a random sample of the bundle's episodes here "
        "(hover for the guarantee).</p>",
    ]
    parts += _section("Overall", board.overall, entries, "h2")
    if board.splits:
        parts.append("<h2>Per split</h2>")
        for split, tables in board.splits.items():
            parts += _section(split_title(split), tables, entries)
    parts += _claims(board)
    if board.rejected:
        parts.append(
            "<h2>Rejected (not ranked)</h2><table class=rejected><tr><th>Bundle</th><th>Why</th></tr>"
        )
        parts += [
            f"<tr><td>{html.escape(r.source)}</td><td>{html.escape(r.reason)}</td></tr>"
            for r in board.rejected
        ]
        parts.append("</table>")
    parts.append(f"<script>{_JS}</script></body></html>\n")
    return "\n".join(parts)
