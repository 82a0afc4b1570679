"""roboview.pipelines.report end to end on synthetic episode files of the tiny suite (no simulator needed)."""

from __future__ import annotations

import json
import re

import pandas as pd
import pytest
from PIL import Image

from roboview.eval.reporting.plots import PLOTS
from roboview.eval.reporting.report import VERSION_KEY, load_results
from roboview.eval.statistics.metrics import EpisodesError, policy_layouts
from roboview.pipelines.report import ReportConfig, main, run
from tests.helpers.episodes import FAST, make_episodes, write

pytestmark = pytest.mark.fast


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("report")
    a = write(make_episodes("expert", 0), tmp / "expert.parquet")
    b = write(make_episodes("random", 1).assign(success=False), tmp / "random.parquet")
    return run(ReportConfig(results=f"{a},{b}", output_dir=str(tmp / "rep"), **FAST))


def test_files_and_plots_are_written(report):
    out = report.output_dir
    # Every figure of the splits present is drawn; the new factors' figures are skipped, saying why.
    present = {"color", "camera_pose", "camera_euler", "dist_scale", "color_x_camera_pose"}
    drawn = {name for name, (split, _, _) in PLOTS.items() if split in present}
    assert len(drawn) == 10 and {n for n, reason in report.plots.items() if reason is None} == drawn
    assert all("no policy has the" in report.plots[n] for n in set(PLOTS) - drawn)
    assert {p.name for p in out.iterdir()} == {"metrics.json", "report.md", "report.html", *drawn}
    for name in drawn:
        with Image.open(out / name) as image:
            image.verify()
            assert image.format == "PNG" and image.size[0] > 200


def test_forest_plots_follow_the_factor_registry():
    from roboview.variation.factors import visual_factors

    forests = [
        split for name, (split, key, _) in PLOTS.items() if name == f"forest_{split}.png" and key == "splits"
    ]
    assert forests == list(visual_factors())
    assert forests[:8] == [
        "color",
        "camera_pose",
        "camera_euler",
        "dist_scale",
        "lighting",
        "table_texture",
        "distractors",
        "object_size",
    ]


def test_metrics_json_holds_both_policies(report):
    metrics = json.loads((report.output_dir / "metrics.json").read_text())
    assert metrics == report.metrics
    layouts = policy_layouts(metrics)
    assert set(layouts) == {"expert", "random"}
    assert [s[VERSION_KEY] for s in metrics["sources"]] == ["tiny-abc", "tiny-abc"]
    assert set(layouts["expert"]["splits"]) == {"color", "camera_pose", "camera_euler", "dist_scale"}
    # The always-failing policy: SR 0, CV null, and N/A in the table.
    assert layouts["random"]["splits"]["color"]["cv"] is None
    assert layouts["random"]["interactions"]["color_x_camera_pose"]["iec"]["color|camera_pose"] is None


def _section(markdown: str, heading: str) -> str:
    return markdown.split(f"## {heading}", 1)[1].split("\n## ", 1)[0]


def _rows(markdown: str, heading: str) -> list[list[str]]:
    """Cells of every row (header first) of the tables under the heading that starts with `heading`."""
    lines = _section(markdown, heading).splitlines()
    rows = [line.strip("|").split(" | ") for line in lines if line.startswith("| ")]
    return [[c.strip() for c in cells] for cells in rows if cells[0].strip() != "---"]


def _table_rows(markdown: str, heading: str) -> dict[str, list[str]]:
    """First column → cells of the table under the heading that starts with `heading`."""
    rows = _rows(markdown, heading)
    return {cells[0]: [c.strip("*") for c in cells[1:]] for cells in rows[1:]}


def _pct(x: float | None) -> str:
    return "N/A" if x is None else f"{100 * x:.2f}"


def _with_ci(x: float | None, ci: list[float] | None) -> str:
    return _pct(x) + ("" if ci is None else f" [{_pct(ci[0])}, {_pct(ci[1])}]")


def test_report_tables_equal_metrics(report):
    markdown = (report.output_dir / "report.md").read_text()
    layouts = policy_layouts(report.metrics)
    header, *table1 = _rows(markdown, "Table 1")
    assert header == [
        "Split",
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
    table1 = {(row[0], row[1]): [c.strip("*") for c in row[2:]] for row in table1}
    titles = {
        "color": "Color",
        "camera_pose": "Camera Pose",
        "camera_euler": "Camera Euler",
        "dist_scale": "Dist Scale",
    }
    assert len(table1) == len(titles) * len(layouts)
    summary = _table_rows(markdown, "Summary")
    table2 = _table_rows(markdown, "Table 2")
    for policy, layout in layouts.items():
        for split, title in titles.items():
            m = layout["splits"][split]
            p = "N/A" if m["p_value"] is None else f"{m['p_value']:.4f}"
            expected = [
                _with_ci(m["sr"], m["sr_ci95"]),
                _with_ci(m["sr_control"], m["sr_control_ci95"]),
                _pct(m["cv"]),
                _pct(m["cv_null"]),
                _with_ci(m["cv_excess"], m["cv_excess_ci95"]),
                p,
                str(m["n_episodes"]),
            ]
            assert table1[title, policy][:7] == expected
        label = "expert (privileged)" if policy == "expert" else policy
        assert summary[label][:3] == [_pct(layout["average"][k]) for k in ("sr", "cv", "cv_excess")]
        f = layout["interactions"]["color_x_camera_pose"]
        assert table2[policy][:2] == [_with_ci(f["sr"], f["sr_ci95"]), _pct(f["cv"]["color"])]
        assert table2[policy][5:7] == [
            _pct(f["iec"]["color|camera_pose"]),
            _pct(f["iec_null"]["color|camera_pose"]),
        ]
    assert table1["Color", "random"][2] == "N/A"
    assert table1["Color", "random"][7] == "not testable: every episode failed"
    comparisons = _table_rows(markdown, "Policy comparisons")
    color = next(c for c in report.metrics["comparisons"] if c["split"] == "color")
    assert comparisons["color"][:3] == ["random − expert", str(color["n_pairs"]), _pct(color["delta_sr"])]


def _numbers(obj) -> set[str]:
    """Every way report.md may print a number of the metrics dict."""
    if isinstance(obj, dict):
        return set().union(*map(_numbers, obj.values())) if obj else set()
    if isinstance(obj, list):
        return set().union(*map(_numbers, obj)) if obj else set()
    if isinstance(obj, bool) or obj is None or isinstance(obj, str):
        return set()
    if isinstance(obj, int):
        return {str(obj)}
    return {f"{100 * obj:.2f}", f"{obj:.4f}", f"{obj:.1e}"}


def test_every_number_in_report_tables_comes_from_metrics(report):
    allowed = _numbers(report.metrics)
    markdown = (report.output_dir / "report.md").read_text()
    lines = markdown.splitlines()
    body = [
        line
        for i, line in enumerate(lines)  # table rows below a header's "| --- |" line
        if line.startswith("| ")
        and not line.startswith("| ---")
        and i > 0
        and lines[i - 1].startswith("| ")
        and not (i + 1 < len(lines) and lines[i + 1].startswith("| ---"))
    ]
    cells = [cell for line in body for cell in line.split(" | ")[1:]]
    found = [n for cell in cells for n in re.findall(r"-?\d+\.\d+e[+-]\d+|-?\d+\.\d+|-?\d+", cell)]
    assert found and set(found) <= allowed


def test_missing_split_skips_its_plots(tmp_path):
    path = write(make_episodes("expert", 0, splits=("color",)), tmp_path / "color.parquet")
    result = run(ReportConfig(results=str(path), output_dir=str(tmp_path / "rep"), **FAST))
    assert result.metrics["policy"] == "expert" and set(result.metrics["splits"]) == {"color"}
    assert result.plots["sr_by_color_category.png"] is None
    assert result.plots["sr_camera_pose.png"] == "no policy has the camera_pose split"
    assert not (tmp_path / "rep" / "sr_camera_pose.png").exists()
    assert (
        "sr_camera_pose.png skipped: no policy has the camera_pose split"
        in (tmp_path / "rep/report.md").read_text()
    )


def test_bad_inputs_name_the_offender(tmp_path, capsys):
    good = write(make_episodes("expert", 0, splits=("color",)), tmp_path / "good.parquet")
    with pytest.raises(FileNotFoundError, match="nowhere.parquet"):
        load_results([good, tmp_path / "nowhere.parquet"])
    lacking = write(
        make_episodes("x", 0, splits=("color",)).drop(columns=["context_id", "repeat"]),
        tmp_path / "lacking.parquet",
    )
    with pytest.raises(EpisodesError, match=r"lacking.parquet lacks column\(s\) context_id, repeat"):
        load_results([lacking])
    other = write(
        make_episodes("random", 1, splits=("color",)), tmp_path / "other.parquet", version="paper-999"
    )
    with pytest.raises(EpisodesError, match="tiny-abc.*paper-999"):
        load_results([good, other])
    with pytest.raises(EpisodesError, match="occur twice"):
        load_results([good, good])
    with pytest.raises(SystemExit):
        main([f"--results={tmp_path / 'nowhere.parquet'}", f"--output_dir={tmp_path / 'rep'}"])
    assert "nowhere.parquet" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main([f"--results={good}", "--metrics.n_glm=0"])
    assert "n_glm=0" in capsys.readouterr().err
    old = write(make_episodes("expert", 0, splits=("color",)), tmp_path / "old.parquet", results_format=b"1")
    with pytest.raises(EpisodesError, match="results format 1.*seeds hashed instance_id"):
        load_results([good, old])


def test_cli_without_plots(tmp_path, capsys):
    path = write(make_episodes("expert", 0, splits=("dist_scale",)), tmp_path / "e.parquet", version=None)
    result = main(
        [
            f"--results={path}",
            f"--output_dir={tmp_path / 'rep'}",
            "--plots=false",
            "--metrics.n_glm=20",
            "--metrics.n_perm=20",
        ]
    )
    assert sorted(p.name for p in result.output_dir.iterdir()) == ["metrics.json", "report.html", "report.md"]
    assert result.metrics["sources"][0][VERSION_KEY] is None
    assert "[report]" in capsys.readouterr().out


def test_named_results_make_one_file_two_policies(tmp_path):
    good = write(make_episodes("lerobot:act", 0, splits=("color",)), tmp_path / "good.parquet")
    main(
        [
            f"--results=ref={good},again={good}",
            f"--output_dir={tmp_path / 'rep'}",
            "--plots=false",
            "--metrics.n_perm=50",
            "--metrics.n_glm=20",
        ]
    )
    metrics = json.loads((tmp_path / "rep" / "metrics.json").read_text())
    assert sorted(metrics["policies"]) == ["again", "ref"]
    pair = metrics["comparisons"][0]
    assert (
        pair["split"] == "color" and pair["n_pairs"] == 72 and pair["delta_sr"] == 0.0 and pair["p_sr"] == 1.0
    )
    mixed = write(
        pd.concat([make_episodes("a", 0, splits=("color",)), make_episodes("b", 1, splits=("color",))]),
        tmp_path / "mixed.parquet",
    )
    with pytest.raises(EpisodesError, match="holds several policies"):
        load_results([mixed], ["c"])


def test_a_factor_without_figures_of_its_own_gets_its_forest_plot(tmp_path):
    """A registered extension factor (here a renamed color split) is drawn as a forest plot, on the page too."""
    frame = make_episodes("expert", 0, splits=("color",))
    frame["split"] = "tint"
    frame["factor"] = "tint"
    path = write(frame, tmp_path / "e.parquet")
    result = run(ReportConfig(results=str(path), output_dir=str(tmp_path / "rep"), **FAST))
    assert result.plots["forest_tint.png"] is None
    with Image.open(tmp_path / "rep" / "forest_tint.png") as image:
        assert image.size[0] > 200
    page = (tmp_path / "rep" / "report.html").read_text()
    block = page[page.index('id="split-tint"') :]
    assert 'alt="forest_tint.png"' in block[: block.index("</section>")]
