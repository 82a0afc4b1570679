"""LIBERO's suite presets: `libero_object` is the `libero` preset's look restricted to one suite, so its instances
are the `libero` preset's own (the same ids: a run on either build compares), and its repeats run init states the
suite's demos (init states 10–49) never saw."""

from collections import Counter

import pytest

from roboview.tasks import load_preset
from roboview.tasks.repetition import Repetition, repetition_of
from roboview.variation.instances import DEFAULT_FACTORIAL_COLORS, generate_suite

pytestmark = pytest.mark.fast


def test_libero_object_is_the_libero_presets_look_of_one_suite():
    suite = generate_suite(load_preset("libero_object"))
    full = {i.instance_id: i for i in generate_suite(load_preset("libero"))}
    assert len(suite) == 250
    assert Counter(i.split for i in suite) == {
        "libero_color": 80,
        "libero_lighting": 90,
        "libero_table_texture": 80,
    }
    assert all(i.instance_id in full and full[i.instance_id].factors == i.factors for i in suite)
    assert {i.get("libero_task") for i in suite} == {f"libero_object/{k}" for k in range(10)}
    assert {i.get("init_state") for i in suite} == {"0"}
    colors = {i.get("color") for i in suite if i.split == "libero_color"}
    assert colors == {"original", *DEFAULT_FACTORIAL_COLORS}
    subsets = {k: list(v) for k, v in load_preset("libero_object").value_subsets}
    assert repetition_of("libero", {"value_subsets": subsets}) == Repetition("init_state", 1)
