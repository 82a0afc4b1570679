"""The fairness gate in a world whose look is another benchmark's design (roboview.tasks.fairness.violations with the
context's no-change view): each floor is the threshold or 85 % of the no-change view's own figure, whichever is lower;
an object the no-change view does not hold wholly in frame is judged by its share in frame; RoboView's own scene keeps
its thresholds."""

import math

import pytest

from roboview.tasks.fairness import CameraFairness, FairnessThresholds, violations
from roboview.tasks.world import WORLDS, World, register_world

pytestmark = pytest.mark.fast

T = FairnessThresholds()


def measures(**changes) -> CameraFairness:
    base = dict(
        camera="agentview",
        object_visible=0.9,
        object_pixels=400,
        object_in_frame=True,
        box_visible=1.0,
        box_pixels=0,
        box_in_frame=True,
        delta_e_nominal=10.0,
        delta_e_table=20.0,
        object_frame_share=1.0,
    )
    return CameraFairness(**{**base, **changes})


def test_a_value_is_held_to_the_lower_of_the_threshold_and_its_no_change_view():
    cluttered = measures(
        object_visible=0.58
    )  # libero_object/8's pudding among the clutter, as LIBERO shows it
    # Without the view, RoboView's thresholds: 0.55 visible fails.
    assert violations(measures(object_visible=0.55), T, 33, False) == ["agentview: object visible 0.55 < 0.6"]
    # Against a view that itself shows 0.58: 0.55 keeps 95 % of it and passes; 0.45 (78 %) fails, naming the view.
    assert violations(measures(object_visible=0.55), T, 33, False, view=cluttered) == []
    assert violations(measures(object_visible=0.45), T, 33, False, view=cluttered) == [
        "agentview: object visible 0.45 < 0.49 (85% of its no-change view's 0.58)"
    ]
    # A view above the threshold changes nothing: the threshold is the lower floor.
    assert violations(measures(object_visible=0.55), T, 33, False, view=measures()) == [
        "agentview: object visible 0.55 < 0.6"
    ]


def test_a_fixture_larger_than_the_frame_is_judged_by_its_share_in_frame():
    cabinet = measures(
        object_in_frame=False, object_frame_share=0.88
    )  # libero_goal/0's cabinet from agentview
    shifted = measures(object_in_frame=False, object_frame_share=0.8)
    swung_out = measures(object_in_frame=False, object_frame_share=0.47)
    assert violations(shifted, T, 33, False) == ["agentview: object not wholly in frame"]
    assert violations(shifted, T, 33, False, view=cabinet) == []
    assert violations(swung_out, T, 33, False, view=cabinet) == ["agentview: object 0.47 in frame < 0.6"]
    # An object the no-change view holds whole must stay whole.
    assert violations(shifted, T, 33, False, view=measures()) == ["agentview: object not wholly in frame"]


def test_a_reskin_may_stand_out_as_little_as_the_world_own_object_does():
    dark_bowl = measures(delta_e_table=2.2)  # a black bowl on a dark table, LIBERO's own texture
    assert violations(measures(delta_e_table=2.0), T, 33, False) == [
        "agentview: object-table ΔE2000 2.0 < 3.0"
    ]
    assert violations(measures(delta_e_table=2.0), T, 33, False, view=dark_bowl) == []
    assert violations(measures(delta_e_table=1.0), T, 33, False, view=dark_bowl) == [
        "agentview: object-table ΔE2000 1.0 < 1.9 (85% of its no-change view's 2.20)"
    ]
    # A view whose contrast was not measured (NaN) leaves the threshold.
    assert violations(measures(delta_e_table=2.0), T, 33, False, view=measures(delta_e_table=math.nan)) == [
        "agentview: object-table ΔE2000 2.0 < 3.0"
    ]


def test_the_worlds_declare_what_the_gate_judges_against():
    assert WORLDS["roboview"].gate_reference == "thresholds"
    for name in ("libero", "metaworld"):
        if name in WORLDS:
            assert WORLDS[name].gate_reference == "no_change_view"
    with pytest.raises(ValueError, match=r"gate_reference 'own'; allowed: thresholds, no_change_view"):
        register_world(
            World("x", "x", {"a": "a"}, ("a",), ("a",), ("a",), (), ("c",), "m:P", gate_reference="own")
        )
    with pytest.raises(ValueError, match=r"min_share_of_view=0 must lie in \(0, 1\]"):
        FairnessThresholds(min_share_of_view=0)


def test_an_external_benchmark_own_variants_are_kept_whatever_the_gate_says():
    from roboview.benchmark.build import Judged, ungated_split_names
    from roboview.benchmark.review import adjudicate
    from roboview.tasks import load_preset

    suite = load_preset("liberoplus_camera")
    ungated = ungated_split_names(suite)
    assert "liberoplus_view_azimuth" in ungated and "liberoplus_view_elevation" not in ungated

    def record(split: str, passed: bool) -> dict:
        return {
            "split": split,
            "fairness": {"passed": passed, "reject_reason": "" if passed else "out of frame"},
        }

    records = [record("liberoplus_view_azimuth", False), record("liberoplus_view_azimuth", True)]
    records += [record("liberoplus_view_elevation", False), *[record("liberoplus_view_elevation", True)] * 3]
    verdicts = [adjudicate(r, None, r["split"] in ungated) for r in records]
    assert verdicts[:3] == [(True, ""), (True, ""), (False, "gate")]
    judged = Judged(records, [v for v, _ in verdicts], [w for _, w in verdicts], {}, ungated)
    # The floor judges the gated parts alone (3 of 4 pass); the kept variant's verdict stays in its record.
    assert judged.gated_pass_rate == 0.75 and judged.gate_pass_rate == pytest.approx(4 / 6)
    assert judged.kept_over_gate() == {"liberoplus_view_azimuth": 1}
    assert records[0]["fairness"]["passed"] is False
    with pytest.raises(ValueError, match=r"ungated_splits \['colour'\] are not splits of the suite"):
        from dataclasses import replace

        replace(suite, ungated_splits=("colour",))


def test_a_build_counts_each_split_gate_failures_by_kind():
    from roboview.benchmark.build import rejection_kinds

    def record(split: str, reason: str) -> dict:
        return {"split": split, "fairness": {"passed": not reason, "reject_reason": reason}}

    records = [
        record("libero_camera_euler", "agentview: object 0.47 in frame < 0.6"),
        record(
            "libero_camera_euler", "agentview: object visible 0.00 < 0.6; agentview: object area 0 px < 33"
        ),
        record(
            "libero_camera_euler", "agentview: object visible 0.45 < 0.49 (85% of its no-change view's 0.58)"
        ),
        record("libero_color", ""),
    ]
    assert rejection_kinds(records) == {
        "libero_camera_euler": {
            "agentview: object visible": 2,
            "agentview: object in frame": 1,
            "agentview: object area": 1,
        }
    }
