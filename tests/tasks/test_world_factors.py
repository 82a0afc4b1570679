"""Every registered world against every registered visual factor: whether the world takes it (a value away from its
baseline is applied), refuses it (its applier table, `World.appliers`, declares the factor does not apply to its
scenes) or lacks it (its table does not name the factor: neither an applier nor a refusal is written for it, refused all
the same; in RoboView's scene, which has no table, a factor that brings no applier for it: LIBERO-plus's `view_*`,
`noise_*`, `scene_light` and `scene_background`, declared in the LIBERO wing). A new factor shows its row here, in every
world at once."""

import numpy as np
import pytest

from roboview.tasks import TASKS
from roboview.tasks.pick_place import PickPlaceEnv
from roboview.tasks.world import WORLDS, World
from roboview.variation.factors import FACTORS, baseline_of, baselines, visual_factors
from roboview.variation.instances import TaskInstance

pytestmark = pytest.mark.fast

EXPECTED = """
factor          roboview  libero   metaworld
color           takes     takes    takes
camera_pose     takes     takes    takes
camera_euler    takes     takes    takes
dist_scale      takes     takes    takes
lighting        takes     takes    takes
table_texture   takes     takes    takes
distractors     takes     refuses  refuses
object_size     takes     refuses  refuses
scene_text      takes     takes    lacks
view_azimuth    lacks     takes    lacks
view_elevation  lacks     takes    lacks
view_scale      lacks     takes    lacks
view_rotz       lacks     takes    lacks
view_roty       lacks     takes    lacks
noise_motion_blur   lacks     takes    lacks
noise_gaussian_blur lacks     takes    lacks
noise_zoom_blur     lacks     takes    lacks
noise_fog           lacks     takes    lacks
noise_glass_blur    lacks     takes    lacks
noise_wrist         lacks     takes    lacks
scene_light         lacks     takes    lacks
scene_background    lacks     takes    lacks
"""


def expected() -> dict[tuple[str, str], str]:
    header, *rows = (line.split() for line in EXPECTED.strip().splitlines())
    return {(row[0], world): status for row in rows for world, status in zip(header[1:], row[1:])}


def task_of(world: World) -> str:
    """The first registered task whose env runs in `world`."""
    return next(name for name, task in TASKS.items() if task.env_class().world is world)


def changed(factor: str, task: str) -> str:
    """`factor`'s first registered value away from its baseline in `task`'s world."""
    return next(v for v in FACTORS[factor].values if v != baseline_of(factor, task))


# A factor that qualifies another is applied with it: `noise_wrist` puts a noise type's corruption on the wrist camera
# too, and alone is refused (a test of the LIBERO wing says so).
COMPANIONS = {"noise_wrist": {"noise_fog": "3"}}


def in_scene_of(scene: PickPlaceEnv, values: dict[str, str]) -> None:
    """Reset `scene` to the instance with `values` over the baselines: a factor whose additions only the scene of an
    instance that sets it holds (`Factor.extend_spec_when_set`: scene_text's card) is applied in that scene."""
    scene.reset(options={"instance": TaskInstance("color", ("color",), baselines() | values, "base")})


def observed(world: World, factor: str, scene: PickPlaceEnv) -> str:
    """What `world` does with a value of `factor` away from its baseline."""
    task = task_of(world)
    value = changed(factor, task)
    try:
        if world.appliers is None:  # RoboView's scene: every factor's own applier, bound to the scene
            if FACTORS[factor].extend_spec_when_set is not None:
                in_scene_of(scene, {factor: value})
            scene.applier(factor).apply(value, np.random.default_rng(0))
            in_scene_of(scene, {})
        else:
            values = {factor: value} | COMPANIONS.get(factor, {})
            assert len(world.make_appliers(values, task)) == 1, (world.name, factor)
    except ValueError as refused:
        assert factor in str(refused), (world.name, factor, str(refused))
        return "lacks" if world.status(factor) == "lacks" else "refuses"
    return "takes"


@pytest.fixture(scope="module")
def scene():
    env = PickPlaceEnv(cameras=("front",), image_size=64)  # compiled, never rendered
    yield env
    env.close()


def test_every_world_takes_refuses_or_lacks_every_visual_factor(scene):
    want = expected()
    assert sorted({w for _, w in want}) == sorted(WORLDS), "a column per registered world"
    assert [f for f, w in want if w == "roboview"] == list(visual_factors()), (
        "a row per registered visual factor"
    )
    got = {(f, w): observed(world, f, scene) for f in visual_factors() for w, world in WORLDS.items()}
    wrong = {pair: f"{got[pair]} (expected {want[pair]})" for pair in want if got[pair] != want[pair]}
    assert not wrong, wrong


def test_what_a_world_does_not_take_is_derived_from_its_table():
    table = expected()
    for name, world in WORLDS.items():
        assert world.not_applicable == tuple(f for f in visual_factors() if table[f, name] != "takes"), name
    # RoboView's scene takes every factor that brings its applier for it, and lacks the LIBERO wing's view, noise and
    # scene factors.
    assert WORLDS["roboview"].appliers is None and WORLDS["roboview"].not_applicable == tuple(
        f
        for f in visual_factors()
        if f.startswith(("view_", "noise_")) or f in ("scene_light", "scene_background")
    )
    assert WORLDS["metaworld"].status("view_azimuth") == "lacks"
    assert (
        WORLDS["libero"].status("view_azimuth") == "takes"
        and WORLDS["libero"].status("distractors") == "refuses"
    )
    # The message names what the world takes, in registration order.
    with pytest.raises(
        ValueError, match=r"the metaworld world cannot apply view_azimuth, distractors; its factors: "
    ):
        WORLDS["metaworld"].make_appliers(
            {"view_azimuth": "31", "color": "red", "distractors": "2"}, "metaworld"
        )


def test_a_world_table_naming_no_registered_visual_factor_is_refused():
    from roboview.tasks.world import register_world

    world = World("x", "x", {"a": "a"}, ("a",), ("a",), ("a",), (), ("c",), "m:P", appliers={"colour": "m:C"})
    with pytest.raises(ValueError, match=r"world 'x': its appliers name colour, no registered visual factor"):
        register_world(world)
    assert "x" not in WORLDS
