"""Coverage audit on a tiny dataset and the tiny benchmark: exact, nearby and never, and the CLI."""

import json
from pathlib import Path

import numpy as np
import pytest

from roboview.demos.coverage import Radii, audit, load_training_visuals
from roboview.pipelines.collect import CollectConfig, DatasetConfig
from roboview.pipelines.collect import run as collect
from tests.helpers import cli

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def bench(tiny_benchmark) -> Path:
    return tiny_benchmark


def _collect(root: Path, randomize: list[str]) -> Path:
    collect(
        CollectConfig(
            DatasetConfig(
                repo_id="t/cov",
                root=str(root),
                num_episodes=3,
                image_size=64,
                cameras=["left_top", "wrist"],
                randomize=randomize,
            ),
            num_workers=1,
            max_steps=100,
        )
    )
    return root


@pytest.fixture(scope="module")
def datasets(tmp_path_factory) -> dict[str, Path]:
    base = tmp_path_factory.mktemp("cov")
    return {
        "context": _collect(base / "context", []),
        "random": _collect(base / "random", ["color", "camera_pose"]),
    }


def _records(bench: Path) -> list[dict]:
    from roboview.benchmark.format import load_benchmark

    return [item.record for items in load_benchmark(bench).splits.values() for item in items]


def _status(table, split: str) -> dict[str, str]:
    sub = table[table["split"] == split]
    return dict(zip(sub["value"], sub["status"]))


def test_context_only_data_covers_exactly_the_baselines(bench, datasets):
    table = audit(load_training_visuals(datasets["context"]), _records(bench))
    color = _status(table, "color")
    assert color.pop("red") == "exact" and set(color.values()) == {"never"}
    # orbital poses are not the original camera
    assert set(_status(table, "camera_pose").values()) == {"never"}
    euler = _status(table, "camera_euler")
    # (±6°, ±6°) is 8.5° away: beyond the 5° radius
    assert euler.pop("0,0") == "exact" and set(euler.values()) == {"never"}
    dist = table[table["split"] == "dist_scale"].set_index("value")
    assert dist.loc["0", "status"] == "exact"
    assert np.isclose(dist.loc["4", "nearest_pos_m"], 0.20) and dist.loc["4", "status"] == "never"
    assert np.isclose(dist.loc["4", "nearest_angle_deg"], 0.0, atol=1e-3)
    assert (table.loc[table["split"] == "color", "n_nearby"] <= 3).all()
    # A wider radius turns the ±6° Euler values nearby, but never exact.
    wide = _status(
        audit(load_training_visuals(datasets["context"]), _records(bench), Radii(pose_deg=9.0)),
        "camera_euler",
    )
    assert wide.pop("0,0") == "exact" and set(wide.values()) == {"nearby"}


def test_randomized_data_is_never_exact_and_nearby_grows_with_the_radius(bench, datasets):
    visuals = load_training_visuals(datasets["random"])
    assert visuals.randomized == ("color", "camera_pose") and visuals.camera == "left_top"
    records = _records(bench)
    tight = audit(visuals, records, Radii(color_delta_e=1e-3, pose_m=1e-4, pose_deg=1e-3))
    assert set(tight["status"]) == {"never"}
    loose = audit(visuals, records, Radii(color_delta_e=500.0, pose_m=10.0, pose_deg=180.0))
    assert set(loose["status"]) == {"nearby"} and (loose["n_nearby"] == 3).all()
    # Distances reported are those to the nearest episode (checked against a direct computation).
    from roboview.variation.colors import delta_e_2000

    row = next(r for r in records if r["split"] == "color" and r["value"] == "blue")
    expected = delta_e_2000(visuals.lab, np.asarray(row["color_lab"])[None]).min()
    got = tight.set_index(["split", "value"]).loc[("color", "blue"), "nearest_delta_e"]
    assert np.isclose(got, expected) and got > 1.0


def test_cli_writes_json_markdown_and_plot(bench, datasets, tmp_path):
    out = tmp_path / "cov"
    proc = cli.run(
        "roboview.pipelines.coverage",
        f"--dataset.root={datasets['context']}",
        f"--benchmark.path={bench}",
        f"--output_dir={out}",
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "[coverage] color: 1 exact, 0 nearby," in proc.stdout
    payload = json.loads((out / "coverage.json").read_text())
    assert payload["summary"]["color"]["exact"] == 1 and payload["episodes"] == 3
    assert "| color | 1 | 0 |" in (out / "coverage.md").read_text()
    assert (out / "coverage.png").stat().st_size > 10_000
    bad = cli.run(
        "roboview.pipelines.coverage", f"--dataset.root={tmp_path}", f"--benchmark.path={bench}", timeout=120
    )
    assert bad.returncode == 2 and "is not a roboview.pipelines.collect dataset" in bad.stderr
