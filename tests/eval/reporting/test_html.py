"""report.html: one self-contained page whose numbers are metrics.json's, loaded in headless Chromium."""

from __future__ import annotations

import json
import re
from html.parser import HTMLParser

import numpy as np
import pytest

from roboview.eval.reporting.format import bias_status, p_fmt, pct, pct_ci
from roboview.pipelines.report import ReportConfig, run
from tests.helpers.browser import chromium_binary, load_page
from tests.helpers.episodes import FAST, make_episodes, write

pytestmark = pytest.mark.slow

needs_chromium = pytest.mark.skipif(
    chromium_binary() is None, reason="no chromium on PATH (make sysdeps installs Debian's chromium package)"
)


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    """Three policies (so the page has a ranking); 'biased' fails on half the colors, so its color split is biased."""
    tmp = tmp_path_factory.mktemp("html")
    biased = make_episodes("biased", 3)
    color = biased["split"] == "color"
    biased.loc[color, "success"] = biased.loc[color, "value"].map(lambda v: sum(map(ord, v)) % 2 == 0)
    biased["video"] = None
    filmed = biased.index[color][:2]
    biased.loc[filmed, "video"] = [f"videos/{i}_front.mp4" for i in range(len(filmed))]
    paths = [
        write(make_episodes("expert", 0), tmp / "expert.parquet"),
        write(make_episodes("random", 1).assign(success=False), tmp / "random.parquet"),
        write(biased, tmp / "biased.parquet"),
    ]
    result = run(ReportConfig(results=",".join(map(str, paths)), output_dir=str(tmp / "rep"), **FAST))
    return result, (result.output_dir / "report.html").read_text()


class _Sections(HTMLParser):
    """Text of every table cell, grouped by the nearest enclosing <section id=…> and table; with `bold`,
    bold text is wrapped in ** as report.md writes it."""

    def __init__(self, bold: bool = False) -> None:
        super().__init__()
        self.stack: list[str] = []
        self.tables: dict[str, list[list[list[str]]]] = {}
        self.cell: list[str] | None = None
        self.bold = bold

    def handle_starttag(self, tag, attrs):
        if tag == "section":
            self.stack.append(dict(attrs).get("id", ""))
        elif tag == "table":
            self.tables.setdefault(self.stack[-1], []).append([])
        elif tag == "tr":
            self.tables[self.stack[-1]][-1].append([])
        elif tag in ("td", "th"):
            self.cell = []
        elif tag == "b" and self.bold and self.cell is not None:
            self.cell.append("**")

    def handle_endtag(self, tag):
        if tag == "section":
            self.stack.pop()
        elif tag in ("td", "th") and self.cell is not None:
            self.tables[self.stack[-1]][-1][-1].append("".join(self.cell).strip())
            self.cell = None
        elif tag == "b" and self.bold and self.cell is not None:
            self.cell.append("**")

    def handle_data(self, data):
        if self.cell is not None:
            self.cell.append(data)


def test_split_blocks_print_metrics_json(report):
    result, page = report
    metrics = json.loads((result.output_dir / "metrics.json").read_text())
    parser = _Sections()
    parser.feed(page)
    policies = metrics["policies"]
    splits = sorted({s for layout in policies.values() for s in layout["splits"]})
    assert {f"split-{s}" for s in splits} <= set(parser.tables)
    for split in splits:
        header, *rows = parser.tables[f"split-{split}"][0]
        assert header == [
            "Policy",
            "SR [95 % CI]",
            "control SR [95 % CI]",
            "CV",
            "noise floor",
            "cv_excess [95 % CI]",
            "p",
            "episodes",
            "verdict",
        ]
        assert sorted(r[0] for r in rows) == sorted(policies)
        for row in rows:
            m = policies[row[0]]["splits"][split]
            assert row[1:8] == [
                pct(m["sr"]) + pct_ci(m["sr_ci95"]),
                pct(m["sr_control"]) + pct_ci(m["sr_control_ci95"]),
                pct(m["cv"]),
                pct(m["cv_null"]),
                pct(m["cv_excess"]) + pct_ci(m.get("cv_excess_ci95")),
                p_fmt(m["p_value"], m["p_value_at_floor"]),
                str(m["n_episodes"]),
            ]
            expected = (
                "not testable"
                if m["p_value"] is None or m["sr"] in (0, 1)
                else "bias"
                if m["p_value"] < 0.05
                else "no bias detected"
            )
            assert row[8].startswith(expected)
    # The value-dependent policy is flagged on color; the all-failing one is not testable, never "no bias".
    color = {r[0]: r for r in parser.tables["split-color"][0][1:]}
    assert (
        color["biased"][8].startswith("bias (p")
        and color["random"][8] == "not testable: every episode failed"
    )
    summary = {r[0]: r for r in parser.tables["summary"][0][1:]}
    n = len(policies["random"]["splits"])
    assert summary["random"][4] == "none" and summary["random"][5] == "—"
    assert summary["random"][6].count("(every episode failed)") == n
    flagged = [s for s, m in policies["biased"]["splits"].items() if bias_status(m)[0] == "bias"]
    assert "color" in flagged
    assert summary["biased"][4] == ", ".join(flagged)
    # The ranking and the comparisons are on the page, the filmed episodes linked relative to it.
    assert "Rankings" in page and "Policy comparisons" in page
    assert 'href="../videos/0_front.mp4"' in page


def _markdown_tables(markdown: str, heading: str) -> list[list[str]]:
    """Rows (header first) of the table under the section whose title starts with `heading`; links as their
    labels, as the page shows them."""
    section = markdown.split(f"## {heading}", 1)[1].split("\n## ", 1)[0]
    rows = [
        [re.sub(r"\[([^]]*)\]\([^)]*\)", r"\1", c).strip() for c in line.strip("|").split(" | ")]
        for line in section.splitlines()
        if line.startswith("| ")
    ]
    return [r for r in rows if r[0] != "---"]


def test_report_md_and_html_print_the_same_tables(report):
    """Table 1, the summary and the video tables: the same headings and cells on both pages, bold included;
    a column one page dropped, renamed or printed differently fails here."""
    from roboview.eval.reporting.format import split_title

    result, page = report
    markdown = (result.output_dir / "report.md").read_text()
    parser = _Sections(bold=True)
    parser.feed(page)
    policies = result.metrics["policies"]
    splits = {split_title(s): s for s in next(iter(policies.values()))["splits"]}

    header, *rows = _markdown_tables(markdown, "Table 1")
    assert header[:2] == ["Split", "Policy"]
    seen = 0
    for title, split in splits.items():
        html_header, *html_rows = parser.tables[f"split-{split}"][0]
        assert (
            header[1:]
            == html_header
            == [
                "Policy",
                "SR [95 % CI]",
                "control SR [95 % CI]",
                "CV",
                "noise floor",
                "cv_excess [95 % CI]",
                "p",
                "episodes",
                "verdict",
            ]
        )
        md_rows = [r[1:] for r in rows if r[0] == title]
        assert md_rows == html_rows and len(md_rows) == len(policies)
        seen += len(md_rows)
    assert seen == len(rows)
    # The color split's lowest cv_excess is significantly lower than the next: bold on both pages.
    assert any(cell.startswith("**") for r in rows for cell in r)

    md_summary = _markdown_tables(markdown, "Summary")
    assert md_summary == parser.tables["summary"][0]
    assert md_summary[0] == [
        "Policy",
        "Average SR",
        "Average CV",
        "Average cv_excess",
        "Splits with bias (p < 0.05)",
        "No bias detected",
        "Not testable",
    ]

    header, *rows = _markdown_tables(markdown, "Episode videos")
    filmed = {r[0] for r in rows}
    assert filmed == {"color"} and len(rows) == 1
    html_videos = parser.tables["split-color"][1]
    assert header[1:] == html_videos[0] and [r[1:] for r in rows] == html_videos[1:]
    assert rows[0][1:4] == ["biased", html_videos[1][1], html_videos[1][2]] and "r0" in rows[0][4]


def test_page_is_self_contained(report):
    result, page = report
    sources = re.findall(r'<img[^>]*src="([^"]*)"', page)
    drawn = [name for name, reason in result.plots.items() if reason is None]
    assert len(sources) == len(drawn) > 0 and all(s.startswith("data:image/png;base64,") for s in sources)
    assert "<script" not in page and "<link" not in page


@needs_chromium
def test_page_loads_in_chromium_and_shows_its_figures(report):
    result, _ = report
    page = load_page(result.output_dir / "report.html")
    assert page.errors == []
    drawn = [name for name, reason in result.plots.items() if reason is None]
    assert sorted(i["alt"] for i in page.images) == sorted(drawn)
    for image in page.images:
        assert image["natural_width"] > 200 and image["width"] > 200, image
        x, y, w, h = (int(round(image[k])) for k in ("x", "y", "width", "height"))
        crop = page.screenshot[y : y + h, x : x + w].astype(int)
        assert crop.shape[0] > 100, image  # inside the screenshot
        saturated = (crop.max(axis=2) - crop.min(axis=2)) > 80  # colored marks: bars, markers, legend patches
        assert crop.std() > 20 and saturated.sum() > 50, image["alt"]
    # Elsewhere the page is black text on white: the colour sits in the figures.
    mask = np.ones(page.screenshot.shape[:2], bool)
    for image in page.images:
        mask[
            int(image["y"]) : int(image["y"] + image["height"]),
            int(image["x"]) : int(image["x"] + image["width"]),
        ] = False
    text = page.screenshot[mask].astype(int)
    assert ((text.max(axis=1) - text.min(axis=1)) > 80).mean() < 0.01


@needs_chromium
def test_the_page_fits_a_1280_px_window(report):
    result, _ = report
    page = load_page(result.output_dir / "report.html", width=1280)
    assert page.layout["page"] <= 1280, page.layout
    assert page.layout["tables"] and max(page.layout["tables"]) <= 1280, page.layout


@needs_chromium
def test_the_chromium_check_sees_a_broken_page(tmp_path):
    """The loader reports what a broken page raises, so an empty error list above means something."""
    (tmp_path / "bad.html").write_text(
        '<!doctype html><html><body><img alt="gone" src="missing.png">'
        "<script>not_defined()</script></body></html>"
    )
    page = load_page(tmp_path / "bad.html")
    assert any("not_defined" in e for e in page.errors)
    assert any("missing.png" in e for e in page.errors)
    assert page.images[0]["natural_width"] == 0
