"""The LIBERO-plus camera decomposition (its design roboview.libero.decomposition, its statistics
roboview.eval.statistics.decompose), checked against known truth:
the camera number both ways on a constructed table, and by simulation the kind effects' intervals and tests, the
interaction's behaviour when costs add and when they compound, and the dose–response's half-magnitude interval."""

import numpy as np
import pandas as pd
import pytest

from roboview.eval.statistics import decompose as dec
from roboview.libero.decomposition import CAMERA
from roboview.libero.plus import NO_CHANGE, SUB_FACTORS

pytestmark = pytest.mark.fast

SIMS = 200


@pytest.fixture(autouse=True)
def fewer_resamples(monkeypatch):
    # The simulations call the tests hundreds of times: fewer bootstrap draws and sign flips (the Monte Carlo error
    # this adds is far below the tolerances checked).
    monkeypatch.setattr(dec, "N_BOOT", 400)
    monkeypatch.setattr(dec, "N_FLIPS", 2000)


def row(
    block: int, params: tuple, success: bool, split: str, task: str = "libero_spatial/0", repeat: int = 0
) -> dict:
    values = dict(zip(SUB_FACTORS, map(str, params)))
    changed = [f for f, v, b in zip(SUB_FACTORS, params, NO_CHANGE) if v != b]
    return {
        "task": "liberoplus",
        "split": f"liberoplus_{split}",
        "success": bool(success),
        "liberoplus_task": task,
        "liberoplus_instruction": "libero",
        "context_id": f"c{block}",
        "repeat": repeat,
        "instance_id": f"{task}:{params}",
        "value": "|".join(values[f] for f in changed) or "0",
        **values,
    }


def analyse(rows: list[dict]) -> dict:
    return dec.compute(pd.DataFrame(rows), CAMERA)


def views(rows: list[dict]) -> pd.DataFrame:
    return dec.views(pd.DataFrame(rows), CAMERA)


def test_the_camera_number_as_liberoplus_totals_it_and_as_vla_eval_averages_it():
    rows = []
    # libero_spatial: 10 azimuth variants, 9 succeed; libero_object: 30 scale variants, 15 succeed.
    rows += [row(0, (i + 1, 0, 100, 0, 0), i < 9, "view_azimuth") for i in range(10)]
    rows += [row(1, (0, 0, 101 + i, 0, 0), i < 15, "view_scale", "libero_object/0") for i in range(30)]
    # Parts LIBERO-plus does not run, and the no-change views, stay out of its number.
    rows += [row(0, (0, 15, 100, 0, 0), False, "view_elevation"), row(0, NO_CHANGE, True, "view_azimuth")]
    rows += [row(1, NO_CHANGE, False, "view_azimuth", "libero_object/0")]
    camera = analyse(rows)["camera"]
    assert camera["liberoplus"]["n"] == 40 and camera["liberoplus"]["sr"] == pytest.approx(24 / 40)
    assert camera["vla_eval"] == pytest.approx((0.9 + 0.5) / 2)
    assert camera["n_variants"] == 40 and camera["no_change"]["n"] == 2 and camera["no_change"]["sr"] == 0.5
    lo, hi = camera["liberoplus"]["ci95"]
    assert lo < 0.6 < hi


def test_the_camera_number_over_all_variants_and_over_the_fair_ones():
    # libero_spatial: 10 azimuth variants, 9 succeed, the 3 last unfair (their target leaves the frame: 2 of them
    # failed); libero_object: 4 scale variants, 2 succeed, all fair.
    rows = [row(0, (i + 1, 0, 100, 0, 0), i < 9, "view_azimuth") | {"gate_passed": i < 7} for i in range(10)]
    rows += [
        row(1, (0, 0, 101 + i, 0, 0), i < 2, "view_scale", "libero_object/0") | {"gate_passed": True}
        for i in range(4)
    ]
    rows += [row(0, NO_CHANGE, True, "view_azimuth") | {"gate_passed": False}]  # kept: the control arm
    camera = analyse(rows)["camera"]
    assert camera["liberoplus"]["sr"] == pytest.approx(11 / 14) and camera["n_variants"] == 14
    assert camera["vla_eval"] == pytest.approx((0.9 + 0.5) / 2)
    fair = camera["fair"]
    assert fair["n_variants"] == 11 and camera["n_variants_unfair"] == 3
    assert fair["liberoplus"]["sr"] == pytest.approx(9 / 11) and fair["vla_eval"] == pytest.approx(
        (1.0 + 0.5) / 2
    )
    assert camera["no_change"]["n"] == 1  # the no-change view counts whatever its verdict
    from roboview.eval.reporting.decomposition import totals_line

    text = totals_line(analyse(rows), CAMERA)
    assert "Over the 11 variants the fairness gate passes (3 of LIBERO-plus's set it does not" in text
    # A benchmark that gated its variants (no verdict column) reports the one number.
    assert "fair" not in analyse([{k: v for k, v in r.items() if k != "gate_passed"} for r in rows])["camera"]


def _blocks(rng, n_blocks: int, p_none: float, kinds: dict[tuple, float]) -> list[dict]:
    """Each block: its no-change episode and one episode of each view in `kinds` (view → success probability)."""
    rows = []
    for b in range(n_blocks):
        task = f"libero_goal/{b % 10}"
        rows.append(row(b, NO_CHANGE, rng.random() < p_none, "view_azimuth", task))
        for params, p in kinds.items():
            changed = [f for f, v, d in zip(SUB_FACTORS, params, NO_CHANGE) if v != d]
            split = "_x_".join(changed) if len(changed) > 1 else changed[0]
            rows.append(row(b, params, rng.random() < p, split, task))
    return rows


def test_a_kind_effect_interval_covers_the_truth_and_its_test_holds_alpha():
    rng = np.random.default_rng(1)
    azimuths = {(a, 0, 100, 0, 0): 0.5 for a in (10, 20, 340)}
    covered = rejected_null = 0
    for _ in range(SIMS):
        k = dec.kind_effects(views(_blocks(rng, 30, 0.8, azimuths)), CAMERA)["azimuth"]
        covered += k["ci95_effect"][0] <= -0.3 <= k["ci95_effect"][1]
        null = dec.kind_effects(views(_blocks(rng, 30, 0.7, {v: 0.7 for v in azimuths})), CAMERA)["azimuth"]
        rejected_null += null["p"] < 0.05
    assert 0.88 <= covered / SIMS <= 0.99
    assert rejected_null / SIMS <= 0.09


def test_the_interaction_is_zero_when_costs_add_and_negative_when_they_compound():
    rng = np.random.default_rng(2)
    parts = {(30, 0, 100, 0, 0): 0.7, (0, 15, 100, 0, 0): 0.8}
    additive = {**parts, (30, 15, 100, 0, 0): 0.6}  # 0.6 − 0.7 − 0.8 + 0.9 = 0
    compound = {**parts, (30, 15, 100, 0, 0): 0.2}  # −0.4
    false_alarms = detected = covered = 0
    for _ in range(SIMS):
        null = dec.interactions(views(_blocks(rng, 40, 0.9, additive)), CAMERA)["azimuth + elevation"]
        false_alarms += null["p"] < 0.05
        covered += null["ci95"][0] <= 0 <= null["ci95"][1]
        bad = dec.interactions(views(_blocks(rng, 60, 0.9, compound)), CAMERA)["azimuth + elevation"]
        detected += bad["p"] < 0.05 and bad["interaction"] < 0
        assert null["n_variants"] == 10  # one two-change variant per task (10 tasks), its parts beside it
    assert false_alarms / SIMS <= 0.09 and covered / SIMS >= 0.88
    assert detected / SIMS >= 0.9


def test_the_dose_response_recovers_the_half_magnitude():
    rng = np.random.default_rng(3)
    a = np.log(0.9 / 0.1)
    truth = 40.0  # degrees where success falls to 0.45
    b = (np.log(0.45 / 0.55) - a) / truth
    azimuths = [*range(5, 76, 10), *range(290, 360, 10)]  # both sides: |azimuth| is the magnitude
    estimates, covered = [], 0
    for _ in range(SIMS):
        rows = []
        for block in range(20):
            task = f"libero_10/{block % 10}"
            rows.append(row(block, NO_CHANGE, rng.random() < 0.9, "view_azimuth", task))
            for az in azimuths:
                m = min(az, 360 - az)
                p = 1 / (1 + np.exp(-(a + b * m)))
                rows.append(row(block, (az, 0, 100, 0, 0), rng.random() < p, "view_azimuth", task))
        d = dec.dose_response(views(rows), CAMERA.sub_factor("view_azimuth"))
        estimates.append(d["half_magnitude"])
        lo, hi = d["half_magnitude_ci95"]
        covered += lo <= truth <= hi
    assert abs(np.median(estimates) - truth) < 2.0
    assert 0.88 <= covered / SIMS <= 0.99


def test_no_decline_gives_no_half_magnitude_and_repeats_give_per_variant_rates():
    rows = [row(b, NO_CHANGE, True, "view_scale", repeat=r) for b in range(3) for r in range(2)]
    rows += [row(b, (0, 0, 150, 0, 0), b > 0, "view_scale", repeat=r) for b in range(3) for r in range(2)]
    result = analyse(rows)
    d = result["dose_response"]["scale"]
    assert d["curve"][0]["magnitude"] == 0 and d["curve"][1] == {
        "magnitude": 50.0,
        "sr": 4 / 6,
        "ci95": d["curve"][1]["ci95"],
        "n": 6,
    }
    # 4/6 with its Clopper–Pearson interval, as every other success rate of the report has it.
    assert d["curve"][1]["ci95"] == pytest.approx([0.2228, 0.9567], abs=1e-4)
    [variant] = result["per_variant"]
    assert (
        variant["n"] == 6
        and variant["delta_control"] == pytest.approx(4 / 6 - 1)
        and variant["kind"] == "scale"
    )
    flat = analyse(
        [
            row(b, p, True, "view_scale", f"libero_goal/{b}")
            for b in range(3)
            for p in (NO_CHANGE, (0, 0, 150, 0, 0))
        ]
    )
    assert flat["dose_response"]["scale"]["half_magnitude"] is None and flat["per_variant"] == []
