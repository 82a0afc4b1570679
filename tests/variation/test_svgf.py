"""SVGF: sampler modules, the variant tree, C_Gen, task subspaces, suites, ids and seeds."""

import hashlib
import itertools
from collections import Counter

import numpy as np
import pytest

from roboview.tasks import PRESETS, load_preset
from roboview.variation.factors import (
    baselines,
    context_factors,
    load_factor,
    visual_factors,
)
from roboview.variation.instances import (
    DEFAULT_FACTORIAL_COLORS,
    SuiteConfig,
    TaskInstance,
    episode_seed,
    generate_suite,
)
from roboview.variation.svgf import (
    ContextSampler,
    FactorSampler,
    FixedSampler,
    Label,
    Product,
    RecursiveVariantTaskManager,
    Union,
    context_space,
)

pytestmark = pytest.mark.fast


@pytest.fixture(scope="module")
def paper_suite():
    return generate_suite(load_preset("paper"))


def test_paper_preset_counts(paper_suite):
    assert len(paper_suite) == 2127 == 11 * (141 + 21 + 9 + 9) + 7 * 21
    assert Counter(i.split for i in paper_suite) == {
        "color": 1551,
        "camera_pose": 231,
        "camera_euler": 99,
        "dist_scale": 99,
        "color_x_camera_pose": 147,
    }
    assert [i.split for i in paper_suite[:1]] == ["color"]
    assert paper_suite[-1].split == "color_x_camera_pose"


def test_dedupe_preset_counts():
    suite = generate_suite(SuiteConfig(union_mode="dedupe"))
    assert len(suite) == 1767 == 9 * 180 + 147
    assert Counter(i.split for i in suite) == {
        "color": 1269,
        "camera_pose": 189,
        "camera_euler": 81,
        "dist_scale": 81,
        "color_x_camera_pose": 147,
    }
    assert len(generate_suite(load_preset("paper_dedupe"))) == 1767


def test_tiny_preset_counts():
    suite = generate_suite(load_preset("tiny"))
    assert len(suite) == 57
    assert len({i.context_id for i in suite}) == 3


def test_context_space_modes():
    per = list(RecursiveVariantTaskManager(context_space("per_subspace")).generate())
    assert len(per) == 11
    baseline = {name: baselines()[name] for name in context_factors()}
    base_rows = [row for row in per if {k: row[k] for k in context_factors()} == baseline]
    assert sorted(row["context_subspace"] for row in base_rows) == sorted(context_factors())

    dedupe = list(RecursiveVariantTaskManager(context_space("dedupe")).generate())
    assert len(dedupe) == 9
    assert dedupe[0] == {"context_subspace": "base", **baseline}
    contexts = {tuple(row[k] for k in context_factors()) for row in dedupe}
    assert len(contexts) == 9
    assert contexts == {tuple(row[k] for k in context_factors()) for row in per}
    with pytest.raises(ValueError, match="unknown union_mode 'set'"):
        context_space("set")


def test_single_factor_splits_hold_other_visual_factors_at_baseline(paper_suite):
    for instance in paper_suite:
        if instance.split in visual_factors():
            assert instance.varied == (instance.split,)
            for name in visual_factors():
                if name != instance.split:
                    assert instance.get(name) == baselines()[name]
    color_split = [i for i in paper_suite if i.split == "color"]
    # Context-major: the first 141 instances sweep every color in the first context.
    assert [i.value for i in color_split[:141]] == list(load_factor("color").values)
    assert len({i.context_id for i in color_split[:141]}) == 1


def test_factorial_split(paper_suite):
    factorial = [i for i in paper_suite if i.split == "color_x_camera_pose"]
    assert {(i.get("color"), i.get("camera_pose")) for i in factorial} == set(
        itertools.product(DEFAULT_FACTORIAL_COLORS, load_factor("camera_pose").values)
    )
    assert {i.context_subspace for i in factorial} == {"base"}
    assert {tuple(i.context.values()) for i in factorial} == {
        tuple(baselines()[name] for name in context_factors())
    }
    first = factorial[0]
    assert (first.factor, first.value) == ("color|camera_pose", "red|orbit_r0_0")
    assert first.to_record()["factor"] == "color|camera_pose"


def test_instance_ids_unique_and_stable(paper_suite):
    ids = [i.instance_id for i in paper_suite]
    assert len(set(ids)) == len(ids)
    assert ids == [i.instance_id for i in generate_suite(load_preset("paper"))]
    assert all(len(i) == 16 and int(i, 16) >= 0 for i in ids)


def test_instance_id_equals_hand_computed_sha256():
    instance = TaskInstance(
        split="color",
        varied=("color",),
        factors={**baselines(), "color": "navy", "shape": "cylinder"},
        context_subspace="shape",
    )
    canonical = (
        '{"context_subspace":"shape","factors":{"camera_euler":"0,0","camera_pose":"original",'
        '"color":"navy","dist_scale":"0","initial_position":"center",'
        '"instruction":"put the small object into the yellow box","shape":"cylinder"},'
        '"split":"color","varied":["color"]}'
    )
    assert instance.instance_id == hashlib.sha256(canonical.encode()).hexdigest()[:16]
    context = (
        '{"context":{"initial_position":"center",'
        '"instruction":"put the small object into the yellow box","shape":"cylinder"},'
        '"context_subspace":"shape"}'
    )
    assert instance.context_id == hashlib.sha256(context.encode()).hexdigest()[:16]
    # Common random numbers: the seed hashes (context_id, repeat 0), never the instance id.
    digest = hashlib.sha256(f"{instance.context_id}:0".encode()).digest()
    assert instance.seed == int.from_bytes(digest[:8], "big") % 2**31


def test_context_ids_shared_within_and_distinct_across_contexts(paper_suite):
    by_context: dict[tuple, set[str]] = {}
    for instance in paper_suite:
        key = (instance.context_subspace, tuple(instance.context.items()))
        by_context.setdefault(key, set()).add(instance.context_id)
    assert all(len(ids) == 1 for ids in by_context.values())
    assert len({next(iter(ids)) for ids in by_context.values()}) == len(by_context) == 12
    color_ctx = {i.context_id for i in paper_suite if i.split == "color"}
    pose_ctx = {i.context_id for i in paper_suite if i.split == "camera_pose"}
    assert color_ctx == pose_ctx and len(color_ctx) == 11


def test_episode_seed_matches_hand_computation():
    expected = int.from_bytes(hashlib.sha256(b"0123456789abcdef:3").digest()[:8], "big") % 2**31
    assert episode_seed("0123456789abcdef", 3) == expected
    assert episode_seed("0123456789abcdef", 3) != episode_seed("0123456789abcdef", 4)
    assert 0 <= episode_seed("x", 0) < 2**31


def test_to_record_columns_and_values():
    instance = TaskInstance("color", ("color",), baselines(), "base")
    record = instance.to_record()
    assert list(record) == [
        "instance_id",
        "task",
        "split",
        "factor",
        "value",
        "context_id",
        "context_subspace",
        "color",
        "camera_pose",
        "camera_euler",
        "dist_scale",
        "lighting",
        "table_texture",
        "distractors",
        "object_size",
        "scene_text",
        "view_azimuth",
        "view_elevation",
        "view_scale",
        "view_rotz",
        "view_roty",
        "noise_motion_blur",
        "noise_gaussian_blur",
        "noise_zoom_blur",
        "noise_fog",
        "noise_glass_blur",
        "noise_wrist",
        "scene_light",
        "scene_background",
        "initial_position",
        "shape",
        "instruction",
        "color_hex",
        "color_rgb",
        "color_lab",
        "seed",
    ]
    assert record["color_hex"] == "#ff0000"
    assert record["color_rgb"] == [1.0, 0.0, 0.0]
    assert record["color_lab"] == pytest.approx([53.24, 80.09, 67.20], abs=0.01)
    assert (record["factor"], record["value"]) == ("color", "red")


def test_task_instance_validation_and_order():
    shuffled = dict(reversed(list(baselines().items())))
    a = TaskInstance("color", ("color",), shuffled, "base")
    b = TaskInstance("color", ("color",), tuple(baselines().items()), "base")
    assert a == b and a.instance_id == b.instance_id
    with pytest.raises(ValueError, match="unknown shape 'sphere'"):
        TaskInstance("color", ("color",), {**baselines(), "shape": "sphere"}, "base")
    with pytest.raises(ValueError, match=r"missing \['shape'\]"):
        no_shape = {k: v for k, v in baselines().items() if k != "shape"}
        TaskInstance("color", ("color",), no_shape, "base")
    with pytest.raises(ValueError, match="unknown context_subspace 'nowhere'"):
        TaskInstance("color", ("color",), baselines(), "nowhere")


def test_sample_context_is_seeded_and_covers_all_values():
    sampler = ContextSampler()
    rng_a, rng_b = np.random.default_rng(11), np.random.default_rng(11)
    seq_a = [sampler.sample_context(rng_a) for _ in range(400)]
    seq_b = [sampler.sample_context(rng_b) for _ in range(400)]
    assert seq_a == seq_b
    rng_c = np.random.default_rng(12)
    assert [sampler.sample_context(rng_c) for _ in range(400)] != seq_a
    for name in context_factors():
        assert {draw[name] for draw in seq_a} == set(load_factor(name).values)
    for name in visual_factors():
        assert {draw[name] for draw in seq_a} == {baselines()[name]}


def test_context_sampler_rejects_visual_restrictions():
    with pytest.raises(ValueError, match="not context factors: \\['color'\\]"):
        ContextSampler({"color": ["red"]})
    restricted = ContextSampler({"shape": ["cylinder"]})
    assert restricted.sample_context(np.random.default_rng(0))["shape"] == "cylinder"


def test_cartesian_product_count_is_product_of_sizes():
    cfg = SuiteConfig(
        splits=(), cartesian=(("color", "shape"), ("camera_euler", "dist_scale", "instruction"))
    )
    suite = generate_suite(cfg)
    counts = Counter(i.split for i in suite)
    assert counts == {
        "cartesian_color_x_shape": 141 * 4,
        "cartesian_camera_euler_x_dist_scale_x_instruction": 9 * 9 * 3,
    }
    first = suite[0]
    assert first.varied == ("color", "shape") and first.context_subspace == "cartesian"
    assert first.get("camera_pose") == "original" and first.get("initial_position") == "center"


def test_recursive_manager_product_union_order_and_checks():
    tree = Union(
        Product(FactorSampler("shape", ["cube", "cuboid"]), FactorSampler("dist_scale", ["0", "1"])),
        Product(FixedSampler("shape", "cylinder"), Label("dist_scale", "8")),
    )
    assert list(RecursiveVariantTaskManager(tree).generate()) == [
        {"shape": "cube", "dist_scale": "0"},
        {"shape": "cube", "dist_scale": "1"},
        {"shape": "cuboid", "dist_scale": "0"},
        {"shape": "cuboid", "dist_scale": "1"},
        {"shape": "cylinder", "dist_scale": "8"},
    ]
    with pytest.raises(ValueError, match=r"assign \['shape'\] twice"):
        Product(FactorSampler("shape"), FixedSampler("shape", "cube"))
    with pytest.raises(ValueError, match="different keys"):
        Union(FactorSampler("shape"), FactorSampler("color"))


def test_sampler_modules():
    assert FactorSampler("dist_scale").values() == tuple(str(k) for k in range(9))
    assert FixedSampler("camera_pose", "original").values() == ("original",)
    module = FactorSampler("color", ["red", "navy"])
    rng = np.random.default_rng(3)
    assert {module.sample(rng) for _ in range(50)} == {"red", "navy"}
    with pytest.raises(ValueError, match="unknown color 'rde'"):
        FactorSampler("color", ["rde"])


def test_suite_config_validation_and_presets():
    assert set(PRESETS) >= {"paper", "tiny"}
    with pytest.raises(ValueError, match="unknown preset 'huge'; valid presets: paper"):
        load_preset("huge")
    with pytest.raises(ValueError, match="unknown union_mode 'set'"):
        SuiteConfig(union_mode="set")
    with pytest.raises(ValueError, match="unknown split 'colour'"):
        SuiteConfig(splits=("colour",))
    with pytest.raises(ValueError, match="unknown color 'grey'"):
        SuiteConfig(factorial_colors=("red", "grey"))
    with pytest.raises(ValueError, match="unknown factor 'size'"):
        SuiteConfig(cartesian=(("color", "size"),))
    with pytest.raises(ValueError, match="not swept values of camera_pose"):
        SuiteConfig(value_subsets=(("camera_pose", ("original",)),))


def test_factorial_colors_are_configurable():
    cfg = SuiteConfig(splits=["color_x_camera_pose"], factorial_colors=["navy", "snow"])
    assert cfg.splits == ("color_x_camera_pose",) and hash(cfg) == hash(cfg)
    suite = generate_suite(cfg)
    assert len(suite) == 2 * 21
    assert {i.get("color") for i in suite} == {"navy", "snow"}
