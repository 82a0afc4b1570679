"""LIBERO-plus's sensor-noise dimension in the `liberoplus` task (roboview.libero.noise): its 1,601 variants read from
its package; the presets with each type's severity ladder and every value on both cameras; the env's frames, each
LIBERO-plus's corruption of the clean render drawn from the episode's generator, the wrist camera clean or not; a
certificate that names the cameras a split changes; a missing ImageMagick refused in one line; and the whole path
(build, evaluate, report, eval_info.json) on the tiny preset."""

import json
import sys
from collections import Counter

import numpy as np
import pandas as pd
import pytest

pytestmark = pytest.mark.slow

pytest.importorskip("libero", reason="LIBERO not installed (make install-libero)")
pytest.importorskip("liberoplus", reason="LIBERO-plus not installed (make install-libero)")
pytest.importorskip("wand.api", reason="Wand / ImageMagick missing (make install-liberoplus-noise)")

from roboview.eval.running import isolation  # noqa: E402
from roboview.libero import corruptions, noise  # noqa: E402
from roboview.tasks import load_preset  # noqa: E402
from roboview.variation.instances import generate_suite  # noqa: E402


def test_counts_and_every_variant_beside_its_ladder_and_its_twin():
    counts = noise.counts()
    assert counts["total"] == 1601
    assert counts["per_suite"] == {
        "libero_spatial": 351,
        "libero_object": 422,
        "libero_goal": 379,
        "libero_10": 449,
    }
    assert sum(counts["per_type"].values()) == 1601 and counts["per_type"]["noise_fog"] == 272
    suite = generate_suite(load_preset("liberoplus_noise_object"))
    assert len(suite) == 10 * (1 + 50 + 50) and len({i.instance_id for i in suite}) == len(suite)
    by_split = Counter(i.split.removeprefix("liberoplus_") for i in suite)
    own = [v for v in noise.noise_variants() if v.suite == "libero_object"]
    assert sum(by_split[s] for s in noise.LIBERO_PLUS_SPLITS) == 422 + 10  # and the no-change views
    assert sum(by_split[s] for s in noise.LADDER_SPLITS) == 500 - 422
    assert all(by_split[s] == 100 for s in noise.WRIST_SPLITS)
    where = {
        (i.get("liberoplus_task"), noise.noise_code(i.factor_values), i.get("noise_wrist")): i for i in suite
    }
    for v in own:
        assert where[(v.libero_task, v.code, "0")].split == f"liberoplus_{v.factor}", v.name
        assert where[(v.libero_task, v.code, "1")].varied == (v.factor, "noise_wrist")
    for task in {v.libero_task for v in own}:
        assert {c for t, c, w in where if t == task and w == "0"} == set(range(0, 51))  # every ladder whole
    assert load_preset("liberoplus_noise").ungated_splits == noise.LIBERO_PLUS_SPLITS
    assert {
        i.get("liberoplus_instruction") for i in generate_suite(load_preset("liberoplus_noise_tiny"))
    } == {"libero"}
    assert len(generate_suite(load_preset("liberoplus_noise"))) == 4040


def test_bad_input_and_a_missing_imagemagick_are_refused_in_one_line(monkeypatch):
    with pytest.raises(
        ValueError, match=r"LIBERO-plus's noise is one type at a time; set one noise_\* factor"
    ):
        noise.noise_code({"noise_fog": "3", "noise_zoom_blur": "2"})
    with pytest.raises(ValueError, match=r"noise_wrist=1 corrupts the wrist camera with the agentview noise"):
        noise.SensorNoise.of({"noise_wrist": "1"})
    assert noise.noise_code({"noise_fog": "3"}) == 33 and noise.noise_code({}) == 0
    # Wand installed, ImageMagick's library not: `import wand.api` fails as it then does.
    monkeypatch.delitem(sys.modules, "wand.api")
    monkeypatch.setattr("builtins.__import__", _failing_import(__import__, "wand.api"))
    with pytest.raises(
        corruptions.NoiseMissing,
        match=r"\(missing: ImageMagick's library, libmagickwand-6.q16-6\); install it with: "
        r"make install-liberoplus-noise$",
    ):
        generate_suite(load_preset("liberoplus_noise_tiny"))
    from roboview.pipelines.build_benchmark import presets_help

    assert "liberoplus_noise_tiny (needs make install-liberoplus-noise)" in presets_help()
    assert "liberoplus_camera_tiny (8)" in presets_help()


def _failing_import(real, module: str):
    def fake(name, *args, **kwargs):
        if name == module:
            raise ImportError("MagickWand shared library not found.")
        return real(name, *args, **kwargs)

    return fake


@pytest.fixture(scope="module")
def env():
    from roboview.libero.plus_task import LiberoPlusTaskEnv

    env = LiberoPlusTaskEnv(image_size=64)
    yield env
    env.close()


def _tiny() -> dict:
    """The tiny preset's instances by "<split>:<value>"."""
    return {
        i.split.removeprefix("liberoplus_") + ":" + i.value: i
        for i in generate_suite(load_preset("liberoplus_noise_tiny"))
    }


def _frames(env, instance, steps: int = 0) -> list[dict[str, np.ndarray]]:
    obs, _ = env.reset(seed=instance.seed, options={"instance": instance})
    out = [{c: obs[f"observation.images.{c}"] for c in ("agentview", "wrist")}]
    for _ in range(steps):
        obs, *_ = env.step(np.zeros(7))
        out.append({c: obs[f"observation.images.{c}"] for c in ("agentview", "wrist")})
    return out


def test_the_env_frames_are_liberoplus_corruption_of_the_clean_render(env):
    tiny = _tiny()
    clean = _frames(env, tiny["noise_motion_blur:0"], steps=1)
    for key in ("noise_fog:3", "noise_glass_blur:5", "noise_fog_x_noise_wrist:3|1"):
        instance = tiny[key]
        code, both = noise.noise_code(instance.factor_values), instance.get("noise_wrist") == "1"
        frames = _frames(env, instance, steps=1)
        for step, (noisy, plain) in enumerate(zip(frames, clean)):
            rng = corruptions.frame_rng(instance.seed, step)
            # Corrupted on robosuite's raw frame (upside down), where LIBERO-plus corrupts it.
            expected = corruptions.corrupt(plain["agentview"][::-1, ::-1], code, rng)[::-1, ::-1]
            assert np.array_equal(noisy["agentview"], expected), (key, step)
            if both:  # the same draws as agentview's
                rng = corruptions.frame_rng(instance.seed, step)
                wrist = corruptions.corrupt(plain["wrist"][::-1, ::-1], code, rng)[::-1, ::-1]
                assert np.array_equal(noisy["wrist"], wrist) and not np.array_equal(wrist, plain["wrist"])
            else:
                assert np.array_equal(noisy["wrist"], plain["wrist"]), key  # LIBERO-plus's clean wrist view
        assert not np.array_equal(frames[0]["agentview"], frames[1]["agentview"])
    # Each value of a block, and a rerun, sees the same noise: the episode seed and the step fix it.
    again = _frames(env, tiny["noise_fog:3"], steps=1)
    assert all(
        np.array_equal(a["agentview"], b["agentview"])
        for a, b in zip(again, _frames(env, tiny["noise_fog:3"], 1))
    )
    assert env.image_filters() == {"agentview": "liberoplus noise 33"}


def test_the_certificate_names_the_cameras_and_the_suffixed_instruction_names_the_code(env):
    rows = []
    for instance in generate_suite(load_preset("liberoplus_noise_tiny")):
        env.reset(seed=instance.seed, options={"instance": instance})
        rows.append(
            instance.to_record()
            | {
                "repeat": 0,
                isolation.COLUMN: isolation.record(env, instance.seed),
                "instruction": env.instruction,
            }
        )
    cert = isolation.verify(pd.DataFrame(rows))
    motion = cert["liberoplus_noise_motion_blur"]  # the no-change view and motion blur 3
    assert motion["isolated"] and not motion["violations"] and motion["blocks"] == 1
    assert isolation.label(motion) == "isolated (noise_motion_blur) on agentview"
    twin = cert["liberoplus_noise_fog_x_noise_wrist"]
    assert isolation.label(twin) == "2 changes: noise_fog + noise_wrist on agentview + wrist"
    components = [json.loads(r[isolation.COLUMN]) for r in rows[:2]]
    assert "image:agentview" not in components[0] and components[1]["image:agentview"]
    # Without the noise factors' declaration, the changed frames are a violation.
    frame = pd.DataFrame(rows[:2]).assign(factor="view_azimuth")
    assert isolation.verify(frame)["liberoplus_noise_motion_blur"]["violations"][0]["components"] == [
        "image:agentview"
    ]
    from dataclasses import replace

    cfg = load_preset("liberoplus_noise_tiny")
    cfg = replace(cfg, value_subsets=(*cfg.value_subsets, ("liberoplus_instruction", ("liberoplus",))))
    fog = next(i for i in generate_suite(cfg) if i.split == "liberoplus_noise_fog")
    env.reset(seed=fog.seed, options={"instance": fog})
    assert (
        env.instruction
        == "pick up the salad dressing and place it in the basket view 0 0 100 0 0 initstate 0 noise 33"
    )


def test_build_evaluate_report_the_tiny_preset(tmp_path):
    from roboview.eval.campaign.config import BenchmarkConfig, EvalConfig, EvaluateConfig
    from roboview.eval.reporting.report import write_report
    from roboview.eval.verification.results import verify_results
    from roboview.pipelines.build_benchmark import BuildConfig
    from roboview.pipelines.build_benchmark import run as build
    from roboview.pipelines.evaluate import run
    from roboview.policies.types import policy_config

    bench, out = tmp_path / "bench", tmp_path / "eval"
    build(BuildConfig(output_dir=str(bench), preset="liberoplus_noise_tiny", image_size=64, num_workers=1))
    manifest = json.loads((bench / "benchmark.json").read_text())
    assert (manifest["candidates"], manifest["rejected"]) == (13, 0)
    run(
        EvaluateConfig(
            BenchmarkConfig(str(bench)),
            policy_config("expert"),
            EvalConfig(n_repeats=2, num_workers=1, max_steps=30),  # the counts are checked, not the successes
            str(out),
        )
    )
    report = verify_results(out, bench)
    assert report.passed, [c for c in report.checks if not c.passed]
    episodes = pd.read_parquet(out / "episodes.parquet")
    assert len(episodes) == 26
    write_report(episodes, tmp_path / "report", plots=False)
    metrics = json.loads((tmp_path / "report" / "metrics.json").read_text())
    assert (
        "liberoplus_camera" not in metrics["analyses"]
    )  # no camera split ran: nothing taken for its no-change view
    result = metrics["analyses"]["liberoplus_noise"]
    assert result["noise"]["liberoplus"]["n"] == 10 and result["noise"]["n_variants"] == 5
    assert result["noise"]["no_change"]["n"] == 2
    assert (
        result["twin"]["n_variants"] == 5 and result["twin"]["liberoplus"]["n"] == 10
    )  # fog 1's twin: not in it
    assert set(result["twin"]["kinds"]) == {"motion blur", "Gaussian blur", "zoom blur", "fog", "glass blur"}
    assert result["twin"]["kinds"]["fog"]["n_variants"] == 2 and result["interactions"] == {}
    assert [c["magnitude"] for c in result["dose_response"]["fog"]["curve"]] == [0.0, 1.0, 3.0]
    text = (tmp_path / "report" / "report.md").read_text()
    assert "## LIBERO-plus's sensor-noise dimension, taken apart" in text
    assert "Noise success rate on both cameras" in text
    assert "2 changes: noise_fog + noise_wrist on agentview + wrist" in text
