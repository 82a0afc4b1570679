"""report.html: the report as one self-contained page (the figures inline, no script, no external file but the
episode videos it links).

Every number on the page is read from the same metrics dict as report.md, and the tables both print (the
summary, Table 1, the episode videos) are declared once, in roboview.eval.reporting.tables: the same columns, headings
and cells. Table 1 becomes one block per split: its policies in rows, the split's figures under them, and the
filmed episodes of each value linked. The other sections (directions, interactions, comparisons, rankings,
adaptive sampling, the isolation certificate, provenance) are report.md's own, rendered by markdown-it.
"""

from __future__ import annotations

import base64
import re
from pathlib import Path
from typing import Any

from markdown_it import MarkdownIt

from roboview.eval.reporting import format as fmt
from roboview.eval.reporting import tables
from roboview.eval.reporting.tables import escape as _e
from roboview.eval.running import isolation
from roboview.eval.running.results import VERSION_KEY
from roboview.eval.statistics.metrics import policy_layouts
from roboview.variation.instances import DEFAULT_TASK, split_task

HTML_FILE = "report.html"

_CSS = """
body{font:15px/1.45 system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;color:#1d1d1f;margin:0;background:#f6f6f4}
main{max-width:1120px;margin:0 auto;padding:24px 28px 64px;background:#fff;overflow-wrap:anywhere}
h1{font-size:26px;margin:0 0 4px}h2{font-size:20px;margin:32px 0 8px;border-bottom:1px solid #ddd;padding-bottom:4px}
h3{font-size:17px;margin:0 0 6px}
nav a{margin-right:14px;font-size:14px}
table{border-collapse:collapse;margin:8px 0 12px;font-size:14px;max-width:100%}
th,td{border:1px solid #d8d8d8;padding:4px 8px;text-align:left;vertical-align:top}
th{background:#f0f0ee}td.num{text-align:right;font-variant-numeric:tabular-nums}
.split{border:1px solid #d8d8d8;border-radius:6px;padding:14px 16px;margin:16px 0}
.verdict-bias{color:#b00020;font-weight:600}.verdict-none{color:#3a6b35}
.figures img{max-width:100%;height:auto;display:block;margin:10px 0;border:1px solid #eee}
.note{color:#555;font-size:13px}
code{background:#f2f2f2;padding:0 3px;border-radius:3px;word-break:break-all}
"""


def _image(path: Path, alt: str) -> str:
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    return f'<img alt="{_e(alt)}" src="data:image/png;base64,{data}">'


def _figure_splits(plots: dict[str, str | None]) -> dict[str, list[str]]:
    """split (task-qualified, as in metrics.json) → the figures drawn for it, in drawing order."""
    drawn = [name for name, reason in plots.items() if reason is None]
    if not drawn:
        return {}
    from roboview.eval.reporting.plots import PLOTS  # matplotlib is loaded already when figures were drawn

    found: dict[str, list[str]] = {}
    for name in drawn:
        if name.startswith(ANALYSIS_FIGURE):  # a task analysis's figure: shown in its section
            found.setdefault(ANALYSIS_FIGURE, []).append(name)
            continue
        for base, (split, _, _) in PLOTS.items():
            if name == base or name.endswith(f"_{base}"):
                task = name[: -len(base) - 1]
                found.setdefault(f"{task}_{split}" if task else split, []).append(name)
                break
        else:  # the forest plot of a factor with no figures of its own: [task_]forest_<split>.png
            prefix, _, split = name.removesuffix(".png").partition("forest_")
            found.setdefault(prefix + split, []).append(name)
    return found


def _values_line(m: dict[str, Any]) -> str:
    low, high = fmt.directions(m)

    def text(items):
        return (
            ", ".join(
                f"<code>{_e(v)}</code> (OR {o:.2g}, SR {fmt.pct(m['per_value'][v]['sr'])})" for v, o in items
            )
            or "none"
        )

    return f"below the rest: {text(low)}; above the rest: {text(high)}" + _e(fmt.against_control(m))


def _split_block(
    split: str, layouts: dict[str, dict], metrics: dict[str, Any], figures: list[str], out: Path
) -> str:
    task, factor = split_task(split)
    title = fmt.split_title(factor)
    notes = [
        f"<li>{_e(name)}: {_values_line(m)}{_stop_line(m)}{_isolation_line(m)}{_infra_line(m)}</li>"
        for name, layout in layouts.items()
        if (m := layout["splits"].get(split)) is not None
    ]
    parts = [
        f'<section class="split" id="split-{_e(split)}"><h3>{_e(title)}'
        + (f' <span class="note">task {_e(task)}</span>' if task != DEFAULT_TASK else "")
        + "</h3>",
        tables.to_html(tables.split_table(metrics, layouts, split)),
        f"<ul>{''.join(notes)}</ul>",
    ]
    parts += _videos(metrics, layouts, split)
    if figures:
        parts.append('<div class="figures">' + "".join(_image(out / f, f) for f in figures) + "</div>")
    return "\n".join(parts) + "</section>"


def _stop_line(m: dict[str, Any]) -> str:
    a = m.get("adaptive")
    return (
        ""
        if not a
        else f"; adaptive: stopped <b>{_e(a['stopped'])}</b> after {a['rounds']} round(s), {a['episodes']} episodes"
    )


def _infra_line(m: dict[str, Any]) -> str:
    n = m.get("n_infra_errors")
    return f"; {n} episode(s) ended by infrastructure, not counted" if n else ""


def _isolation_line(m: dict[str, Any]) -> str:
    cert = m.get("isolation")
    if not cert or not cert["recorded"]:
        return ""
    bad = len(cert["violations"])
    changes = "" if cert.get("isolated", True) else f" ({isolation.label(cert)})"
    return f"; isolation: {cert['verified']} / {cert['blocks']} blocks verified{changes}" + (
        f', <span class="verdict-bias">{bad} violation(s) left out</span>' if bad else ""
    )


def _videos(metrics: dict[str, Any], layouts: dict[str, dict], split: str) -> list[str]:
    """The filmed episodes of this split, per policy and value (links relative to the report folder)."""
    table = tables.videos_table(metrics, layouts, split)
    if not table.rows:
        return []
    return ["<details><summary>Episode videos (✗ failed)</summary>", tables.to_html(table), "</details>"]


ANALYSIS_FIGURE = "analysis_"  # the file-name prefix of a task analysis's figures
# report.md's sections the page renders as they are, in this order, with their titles in the page's index.
_MARKDOWN_TITLES = {
    "analyses": "Task analyses",
    "strips": "Where they part",
    "infra": "Episodes ended by infrastructure",
    "copies": "Repeats that were copies",
    "interactions": "Interactions",
    "rankings": "Rankings",
    "comparisons": "Policy comparisons",
    "context": "Success by task context",
    "adaptive": "Adaptive sampling",
    "isolation": "Isolation certificate",
    "diagnostics": "Sample sizes and calibration",
    "agents": "VLM agents",
    "stack": "Simulation stack and conformance",
    "provenance": "Provenance",
}
# Sections whose heading the page writes itself (report.md's sections carry their own).
_OWN_HEADINGS = ("summary", "splits", "skipped")


def render_html(
    metrics: dict[str, Any], plots: dict[str, str | None], out: Path, sections_md: dict[str, list[str]]
) -> str:
    """The page for a metrics dict (every number is read from it) and report.md's sections (`sections_md`,
    roboview.eval.reporting.markdown.markdown_sections); figures are read from `out` and inlined."""
    layouts = policy_layouts(metrics)
    figures = _figure_splits(plots)
    splits = fmt.task_order(fmt.split_order(layouts, "splits"))
    sections = [  # (anchor, title, HTML)
        _summary_section(layouts),
        _splits_section(splits, layouts, metrics, figures, out),
        *_markdown_sections(sections_md, figures, splits, out),
        *_skipped_section(plots),
    ]
    return _page(metrics, layouts, sections)


def _summary_section(layouts: dict[str, dict]) -> tuple[str, str, str]:
    """Is each policy biased: report.md's summary table, with its legend."""
    summary = tables.summary_table(layouts)
    return "summary", "Summary", tables.to_html(summary) + f"<p class=note>{_e(summary.legend())}</p>"


def _splits_section(
    splits: list[str],
    layouts: dict[str, dict],
    metrics: dict[str, Any],
    figures: dict[str, list[str]],
    out: Path,
) -> tuple[str, str, str]:
    """Table 1 as one block per split, under the legend of its columns."""
    legend = (
        f"<p class=note>{_e(tables.Table(tables.SPLIT_COLUMNS).legend())} The CV permutation p is in "
        "metrics.json and the calibration section.</p>"
    )
    blocks = [_split_block(s, layouts, metrics, figures.get(s, []), out) for s in splits]
    return "splits", "Splits", legend + "\n".join(blocks)


def _markdown_sections(
    sections_md: dict[str, list[str]], figures: dict[str, list[str]], splits: list[str], out: Path
) -> list[tuple[str, str, str]]:
    """report.md's own sections rendered by markdown-it; the interactions carry the figures of the splits
    that have no block of their own (the factorial splits)."""
    md_render = MarkdownIt("commonmark", {"html": False}).enable("table")
    sections = []
    for anchor, title in _MARKDOWN_TITLES.items():
        lines = sections_md.get(anchor)
        if not lines:
            continue
        body = md_render.render("\n".join(lines))
        if anchor == "interactions":
            body += "".join(
                '<div class="figures">' + "".join(_image(out / f, f) for f in names) + "</div>"
                for split, names in figures.items()
                if split not in splits and split != ANALYSIS_FIGURE
            )
        if anchor == "strips":  # report.md links the strips; the page carries them
            for name in sorted(set(re.findall(r'src="(strip_\d+\.png)"', body))):
                data = base64.b64encode((out / name).read_bytes()).decode("ascii")
                body = body.replace(f'src="{name}"', f'src="data:image/png;base64,{data}"')
        if anchor == "analyses" and figures.get(ANALYSIS_FIGURE):
            images = "".join(_image(out / f, f) for f in figures[ANALYSIS_FIGURE])
            body += f'<div class="figures">{images}</div>'

        sections.append((anchor, title, body))
    return sections


def _skipped_section(plots: dict[str, str | None]) -> list[tuple[str, str, str]]:
    """The figures not drawn, each with why (none: no section)."""
    skipped = [f"{name}: {reason}" for name, reason in plots.items() if reason is not None]
    if not skipped:
        return []
    return [
        ("skipped", "Figures not drawn", "<ul>" + "".join(f"<li>{_e(s)}</li>" for s in skipped) + "</ul>")
    ]


def _page(metrics: dict[str, Any], layouts: dict[str, dict], sections: list[tuple[str, str, str]]) -> str:
    """The whole document: the heading with the sources, an index of the sections, then the sections."""
    nav = "".join(f'<a href="#{a}">{_e(t)}</a>' for a, t, _ in sections)
    sources = "".join(
        f"<li><code>{_e(s['path'])}</code> (benchmark version {_e(s.get(VERSION_KEY) or 'not recorded')})</li>"
        for s in metrics.get("sources", [])
    )
    head = (
        f"<h1>RoboView-Bias report</h1><p>Policies: {_e(', '.join(layouts))}. ε = {metrics['epsilon']:g}; "
        f"{_e(fmt.resampling_line(metrics['resampling']))}.</p>"
        + (f"<ul>{sources}</ul>" if sources else "")
        + f"<nav>{nav}</nav>"
    )
    body = "".join(
        f'<section id="{a}">' + (f"<h2>{_e(t)}</h2>" if a in _OWN_HEADINGS else "") + html_ + "</section>"
        for a, t, html_ in sections
    )
    return (
        f'<!doctype html>\n<html lang="en"><head><meta charset="utf-8"><meta name="viewport" '
        f'content="width=device-width,initial-scale=1"><title>RoboView-Bias report — {_e(", ".join(layouts))}</title>'
        f"<style>{_CSS}</style></head>\n<body><main>{head}{body}</main></body></html>\n"
    )
