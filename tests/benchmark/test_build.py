"""build_benchmark on the tiny preset: frozen, reproducible, loadable; gate, decisions, publish."""

import csv
import hashlib
import json
import os
import subprocess
from pathlib import Path

import datasets
import mujoco
import numpy as np
import pytest
import yaml

from roboview.benchmark.render import PREVIEW_SIZE, InstanceRenderer
from roboview.pipelines.build_benchmark import BuildConfig, run
from roboview.pipelines.publish import PublishConfig, plan
from roboview.sim.cameras import WORKSPACE_CENTER, quat_to_mat
from roboview.tasks import load_preset
from roboview.tasks.fairness import FairnessThresholds
from roboview.variation.factors import parse_dist_scale, parse_euler
from roboview.variation.instances import generate_suite
from tests.helpers import cli

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]


def tree_digest(path: Path) -> str:
    h = hashlib.sha256()
    for p in sorted(path.rglob("*")):
        if p.is_file():
            h.update(p.relative_to(path).as_posix().encode() + p.read_bytes())
    return h.hexdigest()


@pytest.fixture(scope="module")
def built(tiny_benchmark) -> Path:
    """The run's shared `tiny` build (rendered at 64²): read, never written (the publish tests check its digest)."""
    return tiny_benchmark


def test_splits_load_back_with_datasets_and_counts_match(built):
    ds = datasets.load_dataset(str(built))
    expected = {"color": 24, "camera_pose": 9, "camera_euler": 9, "dist_scale": 9, "color_x_camera_pose": 6}
    assert {k: len(v) for k, v in ds.items()} == expected
    ids = [i for split in ds.values() for i in split["instance_id"]]
    assert len(ids) == len(set(ids)) == 57
    assert ids == [i.instance_id for i in generate_suite(load_preset("tiny"))]  # stable, suite order
    row = ds["color_x_camera_pose"][0]
    assert row["factor"] == "color|camera_pose" and row["value"] == f"{row['color']}|{row['camera_pose']}"
    assert row["preview"].size == (3 * PREVIEW_SIZE, PREVIEW_SIZE)  # whatever the build's render size
    card = (built / "README.md").read_text()
    assert card.startswith("---\nlicense: apache-2.0") and "split: camera_euler" in card
    assert "Suite hash" in card and "| color | 24 | 24 |" in card
    # The Hub's benchmark file: per split a task for the split, its control arm and (single-factor splits) each
    # value its table holds, each with the protocols that cover it: the ids .eval_results entries name.
    listing = yaml.safe_load((built / "eval.yaml").read_text())
    assert listing["evaluation_framework"] == "roboview" and listing["name"] == "RoboView-Bias (tiny)"
    values = {s: list(dict.fromkeys(ds[s]["value"])) for s in expected if "_x_" not in s}
    assert len(values["color"]) == 8 and len(values["camera_pose"]) == 3
    assert [t["id"] for t in listing["tasks"]] == [
        i for s in expected for i in (s, f"{s}/control", *(f"{s}={v}" for v in values.get(s, [])))
    ]
    assert all(t["protocols"] == ["adaptive", "paper", "quick"] for t in listing["tasks"])
    # The protocols the manifest declares, covered by the version.
    manifest = json.loads((built / "benchmark.json").read_text())
    assert manifest["protocols"]["paper"]["n_repeats"] == {s: 10 if "_x_" in s else 5 for s in expected}
    assert manifest["protocols"]["adaptive"]["adaptive"]["max_repeats"] == 10
    assert set(manifest["protocols"]["quick"]["n_repeats"].values()) == {3}
    assert listing["version"] == manifest["benchmark_version"]


def test_building_twice_gives_the_same_bytes(built, tmp_path):
    again = tmp_path / "again"
    result = run(BuildConfig(output_dir=str(again), preset="tiny", image_size=64))
    assert result.candidates == 57 and result.gate_pass_rate >= 0.95
    for split in ("color", "camera_pose", "color_x_camera_pose"):
        assert (again / "data" / f"{split}.parquet").read_bytes() == (
            built / "data" / f"{split}.parquet"
        ).read_bytes()
    assert tree_digest(again) == tree_digest(built)
    assert str(tmp_path) not in (again / "README.md").read_text() + (again / "benchmark.json").read_text()


def test_stored_camera_extrinsics_match_the_factor(built):
    def cam(row, name):
        c = next(c for c in row["cameras"] if c["name"] == name)
        rot = quat_to_mat(np.array(c["quat"]))
        return np.array(c["pos"]), -rot[:, 2]

    base = datasets.load_dataset(str(built), split="color")[0]
    base_front, base_axis = cam(base, "front")
    for row in datasets.load_dataset(str(built), split="camera_euler"):
        yaw, pitch = np.radians(parse_euler(row["camera_euler"]))
        pos, axis = cam(row, "front")
        assert np.degrees(np.arccos(np.clip(axis @ base_axis, -1, 1))) == pytest.approx(
            np.degrees(np.arccos(np.cos(yaw) * np.cos(pitch))), abs=1e-4
        )
        np.testing.assert_allclose(pos, base_front, atol=1e-9)
    for row in datasets.load_dataset(str(built), split="dist_scale"):
        pos, axis = cam(row, "left_top")
        ref_pos, _ = cam(base, "left_top")
        np.testing.assert_allclose(
            pos - ref_pos, -0.05 * parse_dist_scale(row["dist_scale"]) * axis, atol=1e-9
        )
    for row in datasets.load_dataset(str(built), split="camera_pose"):
        for name in ("front", "left_top"):
            pos, axis = cam(row, name)
            to_center = (WORKSPACE_CENTER - pos) / np.linalg.norm(WORKSPACE_CENTER - pos)
            assert axis @ to_center == pytest.approx(1.0, abs=1e-9)
        assert cam(row, "right_top")[0].tolist() == cam(base, "right_top")[0].tolist()


def test_gate_rejects_an_instance_built_to_hide_the_object():
    renderer = InstanceRenderer(128, FairnessThresholds())
    instance = generate_suite(load_preset("tiny"))[0]
    visible = renderer.record(instance)["fairness"]
    assert visible["passed"], visible["reject_reason"]
    env = renderer.env
    env.reset(seed=instance.seed, options={"instance": instance})
    # Hide the object: sink it under the table top, where no camera can see it.
    adr = env.scene.ids.shape_qpos[env.shape]
    env.data.qpos[adr + 2] = -0.1
    mujoco.mj_forward(env.model, env.data)
    rgb = {c: env.render_camera(c) for c in renderer.probe.cameras}
    hidden = renderer.probe.measure(rgb, FairnessThresholds())
    assert not hidden.passed
    assert "front: object visible 0.00 < 0.6" in hidden.reject_reason
    front = next(c for c in hidden.cameras if c.camera == "front")
    assert front.object_pixels == 0 and front.box_visible > 0.5
    renderer.close()


def test_human_decisions_move_instances_to_the_rejected_table(built, tmp_path):
    victim = datasets.load_dataset(str(built), split="dist_scale")[2]["instance_id"]
    decisions = tmp_path / "decisions.csv"
    with decisions.open("w", newline="") as f:
        csv.writer(f).writerows(
            [
                ["instance_id", "verdict", "reviewer", "note"],
                [victim, "reject", "alice", "object looks like a shadow"],
            ]
        )
    out = tmp_path / "reviewed"
    run(BuildConfig(output_dir=str(out), preset="tiny", image_size=64, decisions=str(decisions)))
    assert victim not in datasets.load_dataset(str(out), split="dist_scale")["instance_id"]
    rejected = datasets.load_dataset(str(out), "rejected", split="rejected")
    assert rejected["instance_id"] == [victim]
    assert rejected["rejected_by"] == ["alice: object looks like a shadow"]
    assert "reviewers: alice" in (out / "README.md").read_text()


def _cli(module: str, *args: str, env_extra: dict | None = None) -> subprocess.CompletedProcess:
    return cli.run(module, *args, env=os.environ | (env_extra or {}), timeout=300)


def _build_main(capsys, *args: str) -> subprocess.CompletedProcess:
    """`_cli("roboview.pipelines.build_benchmark", *args)` through its `main`, in this process: status and stderr."""
    from roboview.pipelines.build_benchmark import main

    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_:
        main(list(args))
    return subprocess.CompletedProcess(args, exit_.value.code, "", capsys.readouterr().err)


def test_bad_input_fails_before_work(tmp_path, built, capsys):
    # The command line itself (exit status 2, the message on stderr); the rest through the same `main`.
    proc = _cli("roboview.pipelines.build_benchmark", f"--output_dir={tmp_path / 'x'}", "--preset=huge")
    assert (
        proc.returncode == 2 and "unknown --preset='huge'; allowed: paper, paper_dedupe, tiny" in proc.stderr
    )
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "thesis.tex").write_text("%")
    proc = _build_main(capsys, f"--output_dir={foreign}", "--preset=tiny")
    assert proc.returncode == 2 and "holds no RoboView benchmark" in proc.stderr
    decisions = tmp_path / "d.csv"
    decisions.write_text("instance_id,verdict\n0123456789abcdef,reject\n")
    proc = _build_main(capsys, f"--output_dir={tmp_path / 'y'}", "--preset=tiny", f"--decisions={decisions}")
    assert proc.returncode == 2 and "0123456789abcdef" in proc.stderr and "not in this suite" in proc.stderr
    assert not (tmp_path / "y").exists()
    proc = _build_main(capsys, f"--output_dir={tmp_path / 'z'}", "--union_mode=union")
    assert proc.returncode == 2 and "unknown union_mode 'union'" in proc.stderr


def test_publish_dry_run_lists_exactly_the_files(built):
    proc = _cli("roboview.pipelines.publish", f"--path={built}", "--repo_id=roboview/tiny", "--dry_run=true")
    assert proc.returncode == 0, proc.stderr
    listed = sorted(
        line.split("roboview/tiny/")[1] for line in proc.stdout.splitlines() if "roboview/tiny/" in line
    )
    on_disk = sorted(
        p.relative_to(built).as_posix()
        for p in built.rglob("*")
        if p.is_file() and not p.relative_to(built).as_posix().startswith("contact_sheet/")
    )
    assert listed == on_disk and "data/color.parquet" in listed
    the_plan = plan(PublishConfig(path=str(built), repo_id="roboview/tiny", dry_run=True))
    assert the_plan.version.startswith("tiny-") and f"tag {the_plan.version}" in proc.stdout


def test_publish_without_token_or_network_fails_cleanly(built, tmp_path):
    before = tree_digest(built)
    no_token = {"HF_HUB_OFFLINE": "0", "HF_HOME": str(tmp_path / "hf"), "HF_TOKEN": ""}
    proc = _cli(
        "roboview.pipelines.publish", f"--path={built}", "--repo_id=roboview/tiny", env_extra=no_token
    )
    assert proc.returncode == 2 and "no Hugging Face token" in proc.stderr
    unreachable = no_token | {"HF_TOKEN": "hf_not_a_real_token", "HF_ENDPOINT": "http://127.0.0.1:9"}
    proc = _cli(
        "roboview.pipelines.publish", f"--path={built}", "--repo_id=roboview/tiny", env_extra=unreachable
    )
    assert proc.returncode == 2 and "cannot reach the hub at http://127.0.0.1:9" in proc.stderr
    offline = no_token | {"HF_HUB_OFFLINE": "1", "HF_TOKEN": "hf_x"}
    proc = _cli("roboview.pipelines.publish", f"--path={built}", "--repo_id=roboview/tiny", env_extra=offline)
    assert proc.returncode == 2 and "offline mode is on" in proc.stderr
    assert tree_digest(built) == before
