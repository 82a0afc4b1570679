"""The LIBERO-plus noise decomposition (its design roboview.libero.decomposition.NOISE, the statistics
roboview.eval.statistics.decompose): the noise number and its twins on both cameras on a constructed table, each
design reading only its own splits, and by simulation the twins' difference interval covering the truth."""

import json

import numpy as np
import pandas as pd
import pytest

from roboview.eval.reporting.decomposition import markdown
from roboview.eval.statistics import decompose as dec
from roboview.libero.decomposition import CAMERA, NOISE
from roboview.libero.noise import NOISE_FACTORS, WRIST_FACTOR

pytestmark = pytest.mark.fast

COLUMNS = (*NOISE_FACTORS, WRIST_FACTOR)


@pytest.fixture(autouse=True)
def fewer_resamples(monkeypatch):
    monkeypatch.setattr(dec, "N_BOOT", 400)
    monkeypatch.setattr(dec, "N_FLIPS", 2000)


def row(
    block: int, noise: dict, success: bool, split: str, task: str = "libero_object/0", repeat: int = 0
) -> dict:
    values = {c: str(noise.get(c, 0)) for c in COLUMNS}
    varied = [c for c in COLUMNS if values[c] != "0"] or [NOISE_FACTORS[0]]
    return {
        "task": "liberoplus",
        "split": f"liberoplus_{split}",
        "factor": "|".join(varied),
        "success": bool(success),
        "liberoplus_task": task,
        "liberoplus_instruction": "libero",
        "context_id": f"c{block}",
        "repeat": repeat,
        "instance_id": f"{task}:{sorted(values.items())}",
        "value": "|".join(values[c] for c in varied),
        **values,
        **{f: "0" for f in ("view_azimuth", "view_elevation", "view_rotz", "view_roty")},
        "view_scale": "100",
    }


def table() -> pd.DataFrame:
    """Two tasks. libero_object/0: fog 3 and 5 LIBERO-plus's (both succeed), fog 4 the ladder (fails); on both
    cameras fog 3 fails, 4 fails, 5 succeeds. libero_10/1: motion blur 2 LIBERO-plus's (fails), on both cameras fails."""
    fog, mb = "noise_fog", "noise_motion_blur"
    rows = [row(0, {}, True, mb), row(1, {}, True, mb, "libero_10/1")]
    rows += [
        row(0, {fog: 3}, True, fog),
        row(0, {fog: 5}, True, fog),
        row(0, {fog: 4}, False, f"{fog}_ladder"),
    ]
    rows += [row(0, {fog: s, WRIST_FACTOR: 1}, s == 5, f"{fog}_x_{WRIST_FACTOR}") for s in (3, 4, 5)]
    rows += [
        row(1, {mb: 2}, False, mb, "libero_10/1"),
        row(1, {mb: 2, WRIST_FACTOR: 1}, False, f"{mb}_x_noise_wrist", "libero_10/1"),
    ]
    return pd.DataFrame(rows)


def test_the_noise_number_and_its_twins_on_both_cameras():
    result = dec.compute(table(), NOISE)
    total = result["noise"]
    assert total["n_variants"] == 3 and total["liberoplus"]["sr"] == pytest.approx(2 / 3)
    assert total["vla_eval"] == pytest.approx((1.0 + 0.0) / 2) and total["no_change"]["n"] == 2
    twin = result["twin"]
    # Over the twins of LIBERO-plus's three variants (fog 4's twin is a ladder one's): 1 of 3.
    assert twin["n_variants"] == 3 and twin["liberoplus"]["sr"] == pytest.approx(1 / 3)
    against = twin["against_original"]
    # Per block: libero_object/0 (0 − 1 + 1 − 1) / 2 = −0.5, libero_10/1 0; the mean −0.25.
    assert against["difference"] == pytest.approx(-0.25) and against["n_blocks"] == 2
    assert twin["kinds"]["fog"]["n_variants"] == 3 and twin["kinds"]["fog"]["difference"] == pytest.approx(
        -1 / 3
    )
    assert twin["kinds"]["motion blur"]["difference"] == 0
    assert set(result["kinds"]) == {
        "fog",
        "motion blur",
        "fog + wrist camera too",
        "motion blur + wrist camera too",
    }
    assert result["interactions"] == {}  # the wrist alone is no kind: no interaction to take
    fog = result["dose_response"]["fog"]
    assert [(c["magnitude"], c["sr"]) for c in fog["curve"]] == [(0, 1.0), (3, 1.0), (4, 0.0), (5, 1.0)]
    text = "\n".join(markdown(result, "policy", NOISE))
    assert "Noise success rate on both cameras, the same noise on the wrist camera too" in text
    assert (
        "over the twins of LIBERO-plus's 3 variants: **33.33** [0.84, 90.57] as LIBERO-plus totals it" in text
    )
    assert "against the same variants as LIBERO-plus runs them (66.67): -25.00 points" in text
    assert "| fog | 3 | 66.67 | 33.33 | -33.33 | N/A | N/A | 1 |" in text
    # The camera design reads none of these splits, and the noise design none of the camera's.
    assert dec.compute(table(), CAMERA) is None
    camera_rows = table().assign(split="liberoplus_view_azimuth")
    assert dec.compute(camera_rows, NOISE) is None


def test_the_twins_difference_interval_covers_the_truth():
    rng = np.random.default_rng(4)
    covered, sims = 0, 120
    for _ in range(sims):
        rows = []
        for block in range(30):
            task = f"libero_goal/{block % 10}"
            rows.append(row(block, {}, rng.random() < 0.9, NOISE_FACTORS[0], task))
            for severity in (2, 6):
                rows.append(row(block, {"noise_fog": severity}, rng.random() < 0.8, "noise_fog", task))
                both = {"noise_fog": severity, WRIST_FACTOR: 1}
                rows.append(row(block, both, rng.random() < 0.5, "noise_fog_x_noise_wrist", task))
        against = dec.twins(dec.views(pd.DataFrame(rows), NOISE), NOISE)["against_original"]
        covered += against["ci95"][0] <= -0.3 <= against["ci95"][1]
    assert 0.88 <= covered / sims <= 0.99


def test_eval_info_json_carries_both_numbers(tmp_path):
    from roboview.integrations.lerobot.convert import add_control_arm

    path = tmp_path / "eval_info.json"
    info = {"per_group": {"liberoplus_noise_fog": {"pc_success": 66.7}}}
    add_control_arm(path, info, table().to_dict("records"))
    written = json.loads(path.read_text())
    noise = written["analyses"]["liberoplus_noise"]
    assert noise["noise"]["liberoplus"]["sr"] == pytest.approx(2 / 3)
    assert noise["twin"]["liberoplus"]["sr"] == pytest.approx(1 / 3)
    assert "liberoplus_camera" not in written["analyses"]
    assert written["per_group"]["liberoplus_noise_fog"]["pc_success"] == 66.7
