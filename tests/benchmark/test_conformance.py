"""Benchmark identity over every cell, render/physics conformance, and `roboview.pipelines.verify` on benchmarks and
result bundles."""

from __future__ import annotations

import json
import os
import shutil
from collections import Counter
from pathlib import Path

import mujoco
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from roboview.benchmark import conformance
from roboview.benchmark.format import BenchmarkError, instance_from_record, load_benchmark, read_rows
from roboview.tasks.env import TaskEnv
from tests.helpers import cli

pytestmark = pytest.mark.slow


@pytest.fixture()
def copy(tiny_benchmark, tmp_path) -> Path:
    out = tmp_path / "bench"
    shutil.copytree(tiny_benchmark, out)
    return out


def _edit_cell(path: Path, row: int, column: str, edit) -> None:
    table = pq.read_table(path)
    rows = table.to_pylist()
    rows[row][column] = edit(rows[row][column])
    pq.write_table(pa.Table.from_pylist(rows, schema=table.schema), path)


EDITS = {
    "value": lambda v: "blue",
    "context_id": lambda v: "0" * 16,
    "seed": lambda v: v + 1,
    "color_hex": lambda v: "#0000ff",
    "fairness": lambda v: {
        **v,
        "cameras": [
            {**v["cameras"][0], "object_pixels": v["cameras"][0]["object_pixels"] + 1},
            *v["cameras"][1:],
        ],
    },
    "preview": lambda v: {**v, "bytes": v["bytes"][:-1] + bytes([v["bytes"][-1] ^ 1])},
    "color": lambda v: "blue",
    "cameras": lambda v: [{**v[0], "fovy": v[0]["fovy"] + 1e-9}, *v[1:]],
}


@pytest.mark.parametrize("column", sorted(EDITS))
def test_an_edited_cell_is_refused_naming_its_row_and_column(copy, column):
    _edit_cell(copy / "data" / "color.parquet", 3, column, EDITS[column])
    with pytest.raises(
        BenchmarkError, match=rf"'data/color'.*column\(s\) '{column}' of row\(s\) 3 no longer match"
    ):
        load_benchmark(copy, ["color"])
    load_benchmark(copy, ["camera_pose"])  # the other splits still load: each is checked on its own


def test_a_row_whose_derived_columns_disagree_with_its_parameters_is_refused(tiny_benchmark):
    row = read_rows(tiny_benchmark / "data" / "color.parquet")[2]
    assert instance_from_record(row).instance_id == row["instance_id"]
    for column, wrong in (("value", "no-such-value"), ("context_id", "0" * 16), ("seed", row["seed"] + 1)):
        with pytest.raises(BenchmarkError, match=rf"column '{column}' holds {wrong!r}"):
            instance_from_record({**row, column: wrong})
    with pytest.raises(BenchmarkError, match="does not hash to its id"):
        instance_from_record({**row, "color": "blue" if row["color"] != "blue" else "green"})


def test_edited_manifest_checksums_or_reference_are_refused(copy):
    manifest = json.loads((copy / "benchmark.json").read_text())
    (copy / "benchmark.json").write_text(json.dumps({**manifest, "benchmark_version": "tiny-000000000000"}))
    with pytest.raises(BenchmarkError, match="names version 'tiny-000000000000'"):
        load_benchmark(copy)
    (copy / "benchmark.json").write_text(json.dumps(manifest))
    png = next((copy / "conformance").glob("*.png"))
    png.write_bytes(png.read_bytes() + b"\0")
    with pytest.raises(BenchmarkError, match="conformance folder was edited"):
        load_benchmark(copy)


def test_the_manifest_records_the_stack_and_every_table(tiny_benchmark):
    manifest = json.loads((tiny_benchmark / "benchmark.json").read_text())
    stack = manifest["stack"]
    assert stack["mujoco"] == mujoco.__version__ and stack["image_size"] == 64
    assert stack["physics"]["timestep"] == 0.002 and stack["renderer"]["renderer"]
    assert len(stack["assets"]["sha256"]) == 64 and len(stack["scene"]["sha256"]) == 64
    assert sorted(manifest["content"]) == [f"data/{s}" for s in sorted(manifest["splits"])]
    reference = json.loads((tiny_benchmark / "conformance" / "reference.json").read_text())
    assert len(reference["instances"]) == conformance.SAMPLE_SIZE
    assert len(reference["physics"]) == conformance.PHYSICS_SAMPLE
    assert {e["split"] for e in reference["instances"]} == set(manifest["splits"])  # every split sampled


def test_sample_spreads_over_splits_and_values():
    by_split = {"a": [{"id": f"a{i}"} for i in range(10)], "b": [{"id": f"b{i}"} for i in range(3)]}
    picked = [r["id"] for r in conformance.sample(by_split, 6)]
    assert picked == ["a9", "b2", "a4", "b1", "a0", "b0"]


def test_compare_images_tells_edges_from_regions():
    tol = conformance.Tolerances()
    ref = np.zeros((64, 64, 3), np.uint8)
    edge = ref.copy()
    edge[10, 5:40] = 130  # a one-pixel line: what another rasterizer changes
    blob = ref.copy()
    blob[20:26, 20:26] = 30  # a 6×6 patch: what another color or texture changes
    assert conformance.compare_images(ref, ref, tol)["verdict"] == "identical"
    line = conformance.compare_images(ref, edge, tol)
    assert line["verdict"] == "equivalent" and line["region_pixels"] == 0 and line["max_diff"] == 130
    patch = conformance.compare_images(ref, blob, tol)
    assert (
        patch["verdict"] == "different" and patch["region_pixels"] == 16 and patch["fraction"] == 36 / 64**2
    )


def _inject(monkeypatch, change) -> None:
    """A test hook: `change(env)` applied to the compiled model after every reset (then forwarded)."""
    reset = TaskEnv.reset

    def patched(self, *args, **kwargs):
        out = reset(self, *args, **kwargs)
        change(self)
        mujoco.mj_forward(self.model, self.data)
        return out

    monkeypatch.setattr(TaskEnv, "reset", patched)


def _texture(env):
    env.model.geom_matid[env.scene.ids.table_geom] = env.model.material("table_checker_light").id


def _color(env):
    env.model.geom_rgba[env.scene.active_geom][:3] = np.clip(
        env.model.geom_rgba[env.scene.active_geom][:3] + 0.06, 0, 1
    )


def _camera(env):
    for name in ("front", "left_top"):
        env.model.cam_pos[env.scene.ids.cameras[name]] += [0.01, 0.0, 0.0]


def _timestep(env):
    env.model.opt.timestep = 0.0025


def _friction(env):
    if not hasattr(env, "_friction"):
        env._friction = env.model.geom_friction[:, 0].copy()
    env.model.geom_friction[:, 0] = 0.5 * env._friction


@pytest.mark.parametrize(
    "change,kind",
    [
        (_texture, "image"),
        (_color, "image"),
        (_camera, "image"),
        (_timestep, "physics"),
        (_friction, "physics"),
    ],
)
def test_an_injected_change_is_different(tiny_benchmark, monkeypatch, change, kind):
    _inject(monkeypatch, change)
    # The reference sample's first 6 instances (every split, each with its expert rollout): each change shows there.
    report = conformance.check(tiny_benchmark, limit=6)
    assert Counter(c["check"] for c in report.checks) == {"image": 6 * 3, "physics": 6}
    assert report.verdict == "different"
    different = {c["check"] for c in report.checks if c["verdict"] == "different"}
    assert different == {kind}
    d = report.drift
    if kind == "image":
        assert d["region_pixels_max"] > 0 and d["physics_identical"] == d["physics"]
    else:
        assert (
            d["joint_max"] > conformance.Tolerances().joint_rad
            or d["object_error_m_max"] > conformance.Tolerances().object_m
        )
        assert d["images_identical"] == d["images"]


def test_softpipe_is_equivalent_with_its_drift_reported(tiny_benchmark):
    """Mesa's other software rasterizer draws edges differently: measured, within the tolerances."""
    env = {**os.environ, "GALLIUM_DRIVER": "softpipe", "MUJOCO_GL": "egl"}
    proc = cli.run("roboview.pipelines.verify", f"--benchmark.path={tiny_benchmark}", "--sample=4", env=env)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    last = [line for line in proc.stdout.splitlines() if line.startswith("conformance:")][0]
    assert last.startswith("conformance: equivalent")
    assert "renderer: llvmpipe" in proc.stdout and "vs softpipe" in proc.stdout
    images = [line for line in proc.stdout.splitlines() if " image " in line]
    assert len(images) == 3 * 4  # --sample=4: the first 4 instances of the reference sample
    assert any(line.startswith("equivalent") for line in images)  # not bit-identical ...
    assert all("region px 0" in line for line in images)  # ... but only edges differ


def _evaluate(bench: Path, out: Path, *flags: str) -> None:
    from roboview.pipelines.evaluate import main

    main(
        [
            f"--benchmark.path={bench}",
            "--policy.type=expert",
            "--eval.n_repeats=1",
            "--eval.num_workers=1",
            "--benchmark.splits=camera_pose,dist_scale",
            f"--output_dir={out}",
            *flags,
        ]
    )


def test_a_different_stack_stops_the_run_unless_drift_is_allowed(
    tiny_benchmark, tmp_path, monkeypatch, capsys
):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    _inject(monkeypatch, _texture)
    with pytest.raises(SystemExit):
        _evaluate(tiny_benchmark, tmp_path / "refused")
    err = capsys.readouterr().err
    assert "renders or simulates the benchmark" in err and "--benchmark.allow_drift=true" in err
    assert not (tmp_path / "refused" / "episodes.parquet").exists()  # stopped before any episode
    _evaluate(
        tiny_benchmark, tmp_path / "drift", "--benchmark.allow_drift=true", "--benchmark.values=0,orbit_r0_0"
    )
    rows = pq.read_table(tmp_path / "drift" / "episodes.parquet").to_pylist()
    assert rows and {r["conformance"] for r in rows} == {"different"}
    entry = json.loads((tmp_path / "drift" / "provenance.json").read_text())[-1]["conformance"]
    assert entry["verdict"] == "different" and entry["drift"]["region_pixels_max"] > 0
    from roboview.pipelines._cli import BenchmarkPath
    from roboview.pipelines.verify import VerifyConfig, run

    failed = [
        c
        for c in run(VerifyConfig(BenchmarkPath(str(tiny_benchmark)), str(tmp_path / "drift"))).checks
        if not c.passed
    ]
    assert [c.name for c in failed] == ["conformance"] and "rows different" in failed[0].detail


def test_verify_results_passes_a_clean_run_and_names_each_fault(tiny_benchmark, tmp_path):
    from roboview.pipelines._cli import BenchmarkPath
    from roboview.pipelines.verify import VerifyConfig, main
    from roboview.pipelines.verify import run as verify
    from roboview.tasks import load_preset
    from roboview.variation.instances import generate_suite

    clean = tmp_path / "clean"
    _evaluate(tiny_benchmark, clean)
    rows = pq.read_table(clean / "episodes.parquet")
    assert set(rows.column("conformance").to_pylist()) == {"identical"}
    entry = json.loads((clean / "provenance.json").read_text())[-1]
    assert (
        entry["conformance"]["verdict"] == "identical"
        and entry["conformance"]["stack"]["mujoco"] == mujoco.__version__
    )
    assert main([f"--results={clean}"]).passed  # the benchmark path comes from provenance

    def broken(name: str, edit) -> list[str]:
        folder = tmp_path / name
        shutil.copytree(clean, folder)
        table = pq.read_table(folder / "episodes.parquet")
        out = edit(table.to_pylist())
        pq.write_table(
            pa.Table.from_pylist(out).replace_schema_metadata(table.schema.metadata),
            folder / "episodes.parquet",
        )
        with pytest.raises(SystemExit) as exit_:
            main([f"--results={folder}", f"--benchmark.path={tiny_benchmark}"])
        assert exit_.value.code == 1
        result = verify(VerifyConfig(BenchmarkPath(str(tiny_benchmark)), str(folder)))
        return sorted(c.name for c in result.checks if not c.passed)

    def seed(rows):
        rows[0]["episode_seed"] += 1
        return rows

    assert broken("seed", seed) == ["seeds"]
    assert broken("duplicate", lambda rows: rows + [rows[4]]) == ["duplicates"]
    foreign = next(
        i
        for i in generate_suite(load_preset("paper"))
        if i.split == "dist_scale" and i.value == "3" and i.get("shape") == "cylinder"
    )

    def other(rows):
        rows[1] |= foreign.to_record()
        return rows

    assert "instances" in broken("foreign", other)
    assert broken("missing", lambda rows: [r for r in rows if r["split"] != "dist_scale"]) == ["complete"]


def test_the_lerobot_eval_plugin_checks_conformance_before_making_envs(tiny_benchmark, tmp_path, monkeypatch):
    from roboview.integrations.lerobot import RoboViewEnv

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    _inject(monkeypatch, _camera)
    with pytest.raises(conformance.ConformanceError, match="--env.allow_drift=true"):
        RoboViewEnv(benchmark_path=str(tiny_benchmark), task="dist_scale").create_envs(1)
    envs = RoboViewEnv(benchmark_path=str(tiny_benchmark), task="dist_scale", allow_drift=True).create_envs(1)
    assert list(envs) == ["dist_scale"]
    envs["dist_scale"][0].close()


def test_publish_refuses_an_edited_benchmark(copy):
    from roboview.pipelines.publish import PublishConfig

    _edit_cell(copy / "data" / "dist_scale.parquet", 0, "value", lambda v: "7")
    with pytest.raises(ValueError, match=r"--path: benchmark table 'data/dist_scale'.*'value' of row\(s\) 0"):
        PublishConfig(path=str(copy), repo_id="org/bench", dry_run=True)
