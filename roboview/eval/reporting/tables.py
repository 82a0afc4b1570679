"""The tables report.md and report.html both print, each declared once: its columns (heading, the metrics.json
key it prints, how a cell is written, what the column means) and how its rows are read from the metrics dict.
markdown.py and html.py only lay a `Table` out (`to_markdown`, `to_html`), so the two pages cannot differ in
a heading or a number.

- `SPLIT_COLUMNS`, per policy in one split (`split_table`): report.md's Table 1 (one table per task, a row per
  split and policy) and report.html's block per split.
- `SUMMARY_COLUMNS`, per policy (`summary_table`): both pages' Summary.
- `VIDEO_COLUMNS`, per filmed value (`videos_table`): report.md's video table and each split block's videos
  on the page.
"""

from __future__ import annotations

import html
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from roboview.eval.reporting.format import ALPHA, bias_status, p_fmt, pct, pct_ci, policy_label

TONES = ("", "bias", "none", "note")  # how the page colours a cell; report.md prints the text alone


@dataclass(frozen=True)
class Cell:
    """One cell: its text as both pages print it, and how each marks it up."""

    text: str
    strong: bool = False  # bold on both pages
    tone: str = ""  # one of TONES: the page colours the text (a verdict)
    code: bool = False  # a factor value: monospace on the page
    links: tuple[tuple[str, str], ...] = ()  # (label, href) printed after the text

    def __post_init__(self) -> None:
        if self.tone not in TONES:
            raise ValueError(f"tone={self.tone!r}; allowed: {', '.join(map(repr, TONES))}")


@dataclass(frozen=True)
class Column:
    """A column of a report table: its heading, the metrics.json key it prints (None where it is derived),
    how a row's item becomes its cell, and its meaning (the legend under report.md's table, the tooltip
    of the page's heading)."""

    heading: str
    key: str | None
    cell: Callable[[Any], Cell | str]
    note: str = ""
    numeric: bool = True  # right-aligned on the page

    def __call__(self, item: Any) -> Cell:
        out = self.cell(item)
        return out if isinstance(out, Cell) else Cell(out)


@dataclass(frozen=True)
class Table:
    """Columns and rows of cells, laid out by `to_markdown` and `to_html`."""

    columns: tuple[Column, ...]
    rows: list[list[Cell]] = field(default_factory=list)

    @classmethod
    def of(cls, columns: Sequence[Column], items: Sequence[Any]) -> Table:
        """A row per item, each column's cell of it."""
        return cls(tuple(columns), [[column(item) for column in columns] for item in items])

    @property
    def headings(self) -> list[str]:
        return [c.heading for c in self.columns]

    def legend(self) -> str:
        """ "heading: meaning" of every column that has one, as one sentence list."""
        return "; ".join(f"{c.heading}: {c.note}" for c in self.columns if c.note) + "."

    def stacked(self, heading: str, groups: Sequence[tuple[str, Table]]) -> Table:
        """Several tables of these columns as one, a first column `heading` naming each row's group."""
        for name, table in groups:
            if table.columns != self.columns:
                raise ValueError(f"group {name!r} has columns {table.headings}; expected {self.headings}")
        lead = Column(heading, None, str, numeric=False)
        rows = [[Cell(name), *row] for name, table in groups for row in table.rows]
        return Table((lead, *self.columns), rows)


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    """A Markdown pipe table (then a blank line) of cells that are Markdown already."""

    def line(cells: Sequence[str]) -> str:
        return "| " + " | ".join(cells) + " |"

    return [line(header), line(["---"] * len(header)), *(line(r) for r in rows), ""]


def _markdown_cell(cell: Cell) -> str:
    text = cell.text.replace("|", "\\|")
    text = f"**{text}**" if cell.strong and text else text
    return " ".join([text, *(f"[{label}]({href})" for label, href in cell.links)]).strip()


def to_markdown(table: Table) -> list[str]:
    """The table as report.md prints it (bold for `strong`; links as Markdown links)."""
    return markdown_table(table.headings, [[_markdown_cell(c) for c in row] for row in table.rows])


def escape(text: Any) -> str:
    """Text for an HTML page (quotes escaped too)."""
    return html.escape(str(text), quote=True)


def _html_cell(cell: Cell) -> str:
    text = escape(cell.text)
    if cell.code and text:
        text = f"<code>{text}</code>"
    if cell.strong and text:
        text = f"<b>{text}</b>"
    if cell.tone:
        text = f'<span class="{"note" if cell.tone == "note" else "verdict-" + cell.tone}">{text}</span>'
    links = " ".join(f'<a href="{escape(href)}">{escape(label)}</a>' for label, href in cell.links)
    return " ".join(t for t in (text, links) if t)


def to_html(table: Table) -> str:
    """The table as report.html prints it: each heading's meaning as its tooltip, numeric columns
    right-aligned."""
    head = "".join(
        f'<th title="{escape(c.note)}">{escape(c.heading)}</th>'
        if c.note
        else f"<th>{escape(c.heading)}</th>"
        for c in table.columns
    )
    body = "".join(
        "<tr>"
        + "".join(
            f"<td{' class=num' if col.numeric else ''}>{_html_cell(cell)}</td>"
            for col, cell in zip(table.columns, row)
        )
        + "</tr>"
        for row in table.rows
    )
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


# -- per split: Table 1 and the page's split blocks --------------------------------------------------


def verdict(m: dict[str, Any]) -> Cell:
    """What the split's test says (`bias_status`): bias with its p, no bias detected, or not testable and
    why."""
    status, why = bias_status(m)
    if status == "not testable":
        return Cell(f"not testable: {why}", tone="note")
    if status == "bias":
        return Cell(f"bias (p {p_fmt(m['p_value'], m.get('p_value_at_floor'))})", tone="bias")
    return Cell("no bias detected", tone="none")


POLICY = Column("Policy", "policy", lambda row: row[0], numeric=False)
SPLIT_COLUMNS: tuple[Column, ...] = (
    Column(
        "SR [95 % CI]",
        "sr",
        lambda row: pct(row[1]["sr"]) + pct_ci(row[1]["sr_ci95"]),
        "success rate, successes / episodes of the split, ×100, with its Clopper–Pearson 95 % interval",
    ),
    Column(
        "control SR [95 % CI]",
        "sr_control",
        lambda row: pct(row[1].get("sr_control")) + pct_ci(row[1].get("sr_control_ci95")),
        "the control arm: success of the all-baseline instance (or the value its factor compares against: "
        "scene_text's blank card) on the same contexts and seeds, ×100, with its "
        "Clopper–Pearson 95 % interval; N/A: none of it was run",
    ),
    Column(
        "CV",
        "cv",
        lambda row: pct(row[1]["cv"]),
        "the paper's Bias Coefficient, mean over contexts of σ_v SR(v,c) / (μ_v SR(v,c) + ε), ×100; "
        "a context where everything failed enters as 0; N/A: every episode failed",
    ),
    Column(
        "noise floor",
        "cv_null",
        lambda row: pct(row[1]["cv_null"]),
        "the CV this table shows when the value does not matter (value labels permuted within context and "
        "repeat), ×100; N/A with one episode per cell, where every permutation leaves the CV as it is",
    ),
    Column(
        "cv_excess [95 % CI]",
        "cv_excess",
        lambda row: pct(row[1]["cv_excess"]) + pct_ci(row[1].get("cv_excess_ci95")),
        "√max(0, CV² − noise floor²), the bias beyond binomial noise, ×100, with its bootstrap 95 % interval "
        "(docs/statistics.md): rank policies on it, not on CV; bold: the lowest, where it is significantly lower "
        "than the next policy's (paired test, p < 0.05)",
    ),
    Column(
        "p",
        "p_value",
        lambda row: p_fmt(row[1]["p_value"], row[1].get("p_value_at_floor")),
        "likelihood-ratio test of a binomial GLM value + context against context (permutation-calibrated "
        "where cells are sparse); N/A: no context holds both outcomes",
    ),
    Column("episodes", "n_episodes", lambda row: str(row[1]["n_episodes"]), "episodes counted"),
    Column(
        "verdict",
        None,
        lambda row: verdict(row[1]),
        "bias where p < 0.05; not testable where every episode failed or succeeded, or too few ran",
        numeric=False,
    ),
)


def _significant_pairs(metrics: dict[str, Any], split: str) -> dict[frozenset[str], float | None]:
    return {
        frozenset(c["policies"]): c["p_cv_excess"]
        for c in metrics.get("comparisons", [])
        if c["split"] == split
    }


def _best(metrics: dict[str, Any], split: str, values: dict[str, float | None]) -> str | None:
    """The policy with the lowest cv_excess, only where it is significantly lower than the runner-up's
    (paired p_cv_excess < ALPHA): a lower CV within noise is not a less biased policy."""
    ranked = sorted((v, name) for name, v in values.items() if v is not None)
    if len(ranked) < 2:
        return None
    (_, best), (_, second) = ranked[:2]
    p = _significant_pairs(metrics, split).get(frozenset((best, second)))
    return best if p is not None and p < ALPHA else None


def split_table(metrics: dict[str, Any], layouts: dict[str, dict], split: str) -> Table:
    """One split's row per policy that has it: `POLICY` then `SPLIT_COLUMNS`; the significantly lowest
    cv_excess bold."""
    rows = [(name, layout["splits"][split]) for name, layout in layouts.items() if split in layout["splits"]]
    table = Table.of((POLICY, *SPLIT_COLUMNS), rows)
    best = _best(metrics, split, {name: m["cv_excess"] for name, m in rows})
    j = table.headings.index("cv_excess [95 % CI]")
    for (name, _), cells in zip(rows, table.rows):
        if name == best:
            cells[j] = replace(cells[j], strong=True)
    return table


# -- per policy: the summary ----------------------------------------------------------------------


def _splits_by_status(layout: dict[str, Any], wanted: str) -> list[str]:
    status = {s: bias_status(m) for s, m in layout["splits"].items()}
    return [f"{s} ({why})" if why else s for s, (v, why) in status.items() if v == wanted]


SUMMARY_COLUMNS: tuple[Column, ...] = (
    Column("Policy", "policy", lambda row: policy_label(row[0]), numeric=False),
    *(
        Column(
            f"Average {label}",
            key,
            lambda row, key=key: pct((row[1].get("average") or {}).get(key)),
            f"mean {label} over the policy's single-factor splits, ×100",
        )
        for key, label in (("sr", "SR"), ("cv", "CV"), ("cv_excess", "cv_excess"))
    ),
    Column(
        "Splits with bias (p < 0.05)",
        None,
        lambda row: ", ".join(_splits_by_status(row[1], "bias")) or "none",
        numeric=False,
    ),
    Column(
        "No bias detected",
        None,
        lambda row: ", ".join(_splits_by_status(row[1], "no bias detected")) or "—",
        numeric=False,
    ),
    Column(
        "Not testable",
        None,
        lambda row: ", ".join(_splits_by_status(row[1], "not testable")) or "—",
        "every episode failed or succeeded, or too few ran: a policy that fails everything is not called "
        "unbiased",
        numeric=False,
    ),
)


def summary_table(layouts: dict[str, dict]) -> Table:
    """Per policy: its averages and its splits by what the test says (bias, no bias detected, not
    testable)."""
    return Table.of(SUMMARY_COLUMNS, list(layouts.items()))


# -- per filmed value: the episode videos ------------------------------------------------------------

VIDEO_COLUMNS: tuple[Column, ...] = (
    Column("Policy", "policy", lambda row: row[0], numeric=False),
    Column("Value", "value", lambda row: Cell(row[1], code=True), numeric=False),
    Column("SR", "sr", lambda row: pct(row[2])),
    Column(
        "Videos (instance, repeat, camera; ✗ failed)",
        "video",
        lambda row: Cell(
            "",
            links=tuple(
                (f"{e['label']} {camera}", path)
                for e in row[3]
                for camera, path in zip(e["cameras"], e["paths"])
            ),
        ),
        numeric=False,
    ),
)


def videos_table(metrics: dict[str, Any], layouts: dict[str, dict], split: str) -> Table:
    """The filmed episodes of one split (`metrics["videos"]`), a row per policy and value, each video linked
    relative to the report folder."""
    rows = []
    for name, splits in (metrics.get("videos") or {}).items():
        per_value = layouts.get(name, {}).get("splits", {}).get(split, {}).get("per_value", {})
        for value, episodes in splits.get(split, {}).items():
            rows.append((name, value, per_value.get(value, {}).get("sr"), episodes))
    return Table.of(VIDEO_COLUMNS, rows)


def video_splits(metrics: dict[str, Any]) -> list[str]:
    """Splits with a filmed episode, in the order they were filmed."""
    return list(dict.fromkeys(s for splits in (metrics.get("videos") or {}).values() for s in splits))
