"""The 141 named colors: membership, CIELAB values, CIEDE2000 and basic categories."""

import numpy as np
import pytest

from roboview.variation.colors import (
    CATEGORIES,
    COLORS,
    GREY_SPELLINGS,
    basic_category,
    delta_e_2000,
    get_color,
    srgb_to_lab,
)

pytestmark = pytest.mark.fast


def test_141_colors_sorted_without_grey_spellings():
    assert len(COLORS) == 141
    assert list(COLORS) == sorted(COLORS)
    assert not set(GREY_SPELLINGS) & set(COLORS)
    assert {"gray", "darkgray", "darkslategray", "dimgray", "lightgray", "slategray"} <= set(COLORS)
    assert not any("grey" in name for name in COLORS)


def test_rebeccapurple_and_a_few_hex_values():
    assert COLORS["rebeccapurple"].hex == "#663399"
    assert COLORS["red"].hex == "#ff0000"
    assert COLORS["navy"].hex == "#000080"
    assert COLORS["rosybrown"].hex == "#bc8f8f"
    assert COLORS["navy"].rgb == (0.0, 0.0, 128 / 255)


@pytest.mark.parametrize(
    "name, lab",
    [
        ("red", (53.24, 80.09, 67.20)),
        ("lime", (87.73, -86.18, 83.18)),
        ("blue", (32.30, 79.19, -107.86)),
        ("gray", (53.59, 0.0, 0.0)),
        ("white", (100.0, 0.0, 0.0)),
        ("black", (0.0, 0.0, 0.0)),
    ],
)
def test_lab_of_known_colors(name, lab):
    np.testing.assert_allclose(COLORS[name].lab, lab, atol=0.01)


def test_srgb_to_lab_is_vectorized():
    rgb = np.array([[[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]])
    lab = srgb_to_lab(rgb)
    assert lab.shape == (1, 2, 3)
    np.testing.assert_allclose(lab[0, 1], COLORS["blue"].lab)


# Rows of Sharma, Wu & Dalal (2005), Table 1: (L1, a1, b1), (L2, a2, b2), ΔE00.
SHARMA_ROWS = [
    ((50.0, 2.6772, -79.7751), (50.0, 0.0, -82.7485), 2.0425),
    ((50.0, 0.0, 0.0), (50.0, -1.0, 2.0), 2.3669),
    ((50.0, 2.49, -0.001), (50.0, -2.49, 0.0009), 7.1792),
    ((50.0, 2.49, -0.001), (50.0, -2.49, 0.0011), 7.2195),
    ((50.0, -0.001, 2.49), (50.0, 0.0011, -2.49), 4.7461),
    ((50.0, 2.5, 0.0), (73.0, 25.0, -18.0), 27.1492),
    ((50.0, 2.5, 0.0), (61.0, -5.0, 29.0), 22.8977),
    ((60.2574, -34.0099, 36.2677), (60.4626, -34.1751, 39.4387), 1.2644),
]


@pytest.mark.parametrize("lab1, lab2, expected", SHARMA_ROWS)
def test_delta_e_2000_matches_sharma(lab1, lab2, expected):
    assert delta_e_2000(lab1, lab2) == pytest.approx(expected, abs=1e-4)
    assert delta_e_2000(lab2, lab1) == pytest.approx(expected, abs=1e-4)


def test_delta_e_2000_vectorized_and_zero_on_identity():
    lab1 = np.array([row[0] for row in SHARMA_ROWS])
    lab2 = np.array([row[1] for row in SHARMA_ROWS])
    np.testing.assert_allclose(delta_e_2000(lab1, lab2), [row[2] for row in SHARMA_ROWS], atol=1e-4)
    assert delta_e_2000(COLORS["teal"].lab, COLORS["teal"].lab) == 0.0


@pytest.mark.parametrize(
    "name, category",
    [
        ("red", "red"),
        ("crimson", "red"),
        ("navy", "blue"),
        ("blue", "blue"),
        ("pink", "pink"),
        ("hotpink", "pink"),
        ("saddlebrown", "brown"),
        ("chocolate", "brown"),
        ("gold", "yellow"),
        ("yellow", "yellow"),
        ("orange", "orange"),
        ("darkorange", "orange"),
        ("gray", "gray"),
        ("silver", "gray"),
        ("white", "white"),
        ("snow", "white"),
        ("black", "black"),
        ("purple", "purple"),
        ("indigo", "purple"),
        ("mediumpurple", "purple"),
        ("lime", "green"),
        ("green", "green"),
        ("rosybrown", "brown"),
    ],
)
def test_category_spot_checks(name, category):
    assert COLORS[name].category == category


def test_teal_is_blue_or_green():
    assert COLORS["teal"].category in ("blue", "green")


def test_every_color_has_a_basic_category_and_every_category_is_used():
    used = {color.category for color in COLORS.values()}
    assert used == set(CATEGORIES)
    assert len(CATEGORIES) == 11
    for color in COLORS.values():
        assert basic_category(color.lab) == color.category


def test_get_color_names_bad_value_and_suggests():
    assert get_color("navy") is COLORS["navy"]
    with pytest.raises(ValueError, match=r"'rde'.*did you mean red"):
        get_color("rde")
    with pytest.raises(ValueError, match="'grey'.*gray"):
        get_color("grey")
