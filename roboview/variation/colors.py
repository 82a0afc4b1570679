"""The 141 named object colors of the color factor, with CIELAB values and basic categories.

The paper perturbs the manipulated object's color over 141 named HTML colors from the W3C color
name specification (CSS Color Level 4). Names and values come from `webcolors` (its CSS3 list plus
`rebeccapurple`, which CSS Color Level 4 added and webcolors' CSS3 list lacks); the seven "grey"
spellings are dropped because they duplicate their "gray" twins and would double-weight those
colors in every per-value statistic.

Each color carries sRGB (0–1), CIELAB (D65) and one of the 11 Berlin–Kay basic color categories,
so reports can group per-color success rates by perceptual family and distance (CIEDE2000).
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass

import numpy as np
import webcolors

# CSS Color Level 4 added rebeccapurple (#663399); webcolors keeps it out of its CSS3 list.
_CSS4_ADDITIONS = {"rebeccapurple": "#663399"}
GREY_SPELLINGS = (
    "darkgrey",
    "darkslategrey",
    "dimgrey",
    "grey",
    "lightgrey",
    "lightslategrey",
    "slategrey",
)
N_COLORS = 141
CATEGORIES = (
    "red",
    "orange",
    "yellow",
    "green",
    "blue",
    "purple",
    "pink",
    "brown",
    "black",
    "white",
    "gray",
)

# sRGB primaries → CIE XYZ (IEC 61966-2-1) and the D65 reference white used to normalize XYZ.
_SRGB_TO_XYZ = np.array(
    [
        [0.4124564, 0.3575761, 0.1804375],
        [0.2126729, 0.7151522, 0.0721750],
        [0.0193339, 0.1191920, 0.9503041],
    ]
)
_D65_WHITE = np.array([0.95047, 1.0, 1.08883])


@dataclass(frozen=True)
class NamedColor:
    """One named color: sRGB in [0, 1], CIELAB (D65) and its basic color category."""

    name: str
    hex: str
    rgb: tuple[float, float, float]
    lab: tuple[float, float, float]
    category: str


def srgb_to_lab(rgb: np.ndarray) -> np.ndarray:
    """Convert sRGB in [0, 1] (shape (..., 3)) to CIELAB under D65.

    Steps: undo the sRGB transfer curve (piecewise: linear segment below 0.04045, else a 2.4
    power), map linear RGB to XYZ, divide by the D65 white, then apply the CIE f(t) (cube root
    above (6/29)^3, linear below) and L = 116 f(Y) − 16, a = 500 (f(X) − f(Y)),
    b = 200 (f(Y) − f(Z)).
    """
    c = np.asarray(rgb, dtype=np.float64)
    linear = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    xyz = linear @ _SRGB_TO_XYZ.T / _D65_WHITE
    delta = 6.0 / 29.0
    f = np.where(xyz > delta**3, np.cbrt(xyz), xyz / (3.0 * delta**2) + 4.0 / 29.0)
    lightness = 116.0 * f[..., 1] - 16.0
    a = 500.0 * (f[..., 0] - f[..., 1])
    b = 200.0 * (f[..., 1] - f[..., 2])
    return np.stack([lightness, a, b], axis=-1)


def delta_e_2000(lab1: np.ndarray, lab2: np.ndarray) -> np.ndarray:
    """CIEDE2000 color difference (Sharma, Wu & Dalal 2005), vectorized over leading axes.

    Used to quantify how far apart two object colors are perceptually, e.g. to relate a policy's
    success-rate gap between two colors to their visual distance. kL = kC = kH = 1.
    """
    lab1 = np.asarray(lab1, dtype=np.float64)
    lab2 = np.asarray(lab2, dtype=np.float64)
    l1, a1, b1 = lab1[..., 0], lab1[..., 1], lab1[..., 2]
    l2, a2, b2 = lab2[..., 0], lab2[..., 1], lab2[..., 2]

    c_bar = (np.hypot(a1, b1) + np.hypot(a2, b2)) / 2.0
    g = 0.5 * (1.0 - np.sqrt(c_bar**7 / (c_bar**7 + 25.0**7)))
    a1p, a2p = (1.0 + g) * a1, (1.0 + g) * a2
    c1p, c2p = np.hypot(a1p, b1), np.hypot(a2p, b2)
    # atan2(0, 0) is 0, which is the convention Sharma prescribes for achromatic colors.
    h1p = np.degrees(np.arctan2(b1, a1p)) % 360.0
    h2p = np.degrees(np.arctan2(b2, a2p)) % 360.0
    chroma_zero = (c1p * c2p) == 0.0

    dlp = l2 - l1
    dcp = c2p - c1p
    dh = h2p - h1p
    dh = np.where(dh > 180.0, dh - 360.0, np.where(dh < -180.0, dh + 360.0, dh))
    dh = np.where(chroma_zero, 0.0, dh)
    dhp = 2.0 * np.sqrt(c1p * c2p) * np.sin(np.radians(dh) / 2.0)

    l_bar = (l1 + l2) / 2.0
    cp_bar = (c1p + c2p) / 2.0
    h_sum = h1p + h2p
    h_bar = np.where(
        np.abs(h1p - h2p) <= 180.0,
        h_sum / 2.0,
        np.where(h_sum < 360.0, (h_sum + 360.0) / 2.0, (h_sum - 360.0) / 2.0),
    )
    h_bar = np.where(chroma_zero, h_sum, h_bar)

    t = (
        1.0
        - 0.17 * np.cos(np.radians(h_bar - 30.0))
        + 0.24 * np.cos(np.radians(2.0 * h_bar))
        + 0.32 * np.cos(np.radians(3.0 * h_bar + 6.0))
        - 0.20 * np.cos(np.radians(4.0 * h_bar - 63.0))
    )
    d_theta = 30.0 * np.exp(-(((h_bar - 275.0) / 25.0) ** 2))
    r_c = 2.0 * np.sqrt(cp_bar**7 / (cp_bar**7 + 25.0**7))
    s_l = 1.0 + 0.015 * (l_bar - 50.0) ** 2 / np.sqrt(20.0 + (l_bar - 50.0) ** 2)
    s_c = 1.0 + 0.045 * cp_bar
    s_h = 1.0 + 0.015 * cp_bar * t
    r_t = -np.sin(np.radians(2.0 * d_theta)) * r_c
    return np.sqrt((dlp / s_l) ** 2 + (dcp / s_c) ** 2 + (dhp / s_h) ** 2 + r_t * (dcp / s_c) * (dhp / s_h))


def basic_category(lab: tuple[float, float, float]) -> str:
    """Assign one of the 11 basic color categories from CIELAB via LCh (chroma C, hue h in deg).

    The rule, checked in this order:

    1. Achromatic, C < 13: black if L < 20, white if L >= 90, else gray. (The threshold keeps
       slate grays and tinted near-whites such as linen or lavender achromatic.)
    2. h in [335, 360) or [0, 15): pink (the magenta-red hues: deeppink, palevioletred, pink).
    3. h in [15, 45) (red hues): pink if L >= 65 (lightcoral, salmon), brown if C < 25
       (rosybrown), else red (CSS "brown", #a52a2a, is a dark red by hue and chroma and lands
       here, as do maroon and firebrick).
    4. h in [45, 100) (orange to yellow hues): brown if dark and not vivid (L < 65 and C < 75:
       sienna, chocolate, saddlebrown, peru, darkgoldenrod) or mid-light and dull (L < 80 and
       C < 35: tan, burlywood); else orange if h < 80, yellow otherwise.
    5. h in [100, 115): yellow. h in [115, 190): green (turquoise lands here, teal and cyan in
       blue).
    6. h in [190, 335): purple if h >= 310, or h >= 304 with L >= 45; else blue. The lightness
       clause corrects CIELAB's known purple shift of constant-hue lines in the blue region:
       sRGB blue and mediumpurple share h ≈ 306°, but only the dark one looks blue.
    """
    lightness, a, b = lab
    chroma = float(np.hypot(a, b))
    hue = float(np.degrees(np.arctan2(b, a)) % 360.0)
    if chroma < 13.0:
        if lightness < 20.0:
            return "black"
        return "white" if lightness >= 90.0 else "gray"
    if hue >= 335.0 or hue < 15.0:
        return "pink"
    if hue < 45.0:
        if lightness >= 65.0:
            return "pink"
        return "brown" if chroma < 25.0 else "red"
    if hue < 100.0:
        if (lightness < 65.0 and chroma < 75.0) or (lightness < 80.0 and chroma < 35.0):
            return "brown"
        return "orange" if hue < 80.0 else "yellow"
    if hue < 115.0:
        return "yellow"
    if hue < 190.0:
        return "green"
    if hue >= 310.0 or (hue >= 304.0 and lightness >= 45.0):
        return "purple"
    return "blue"


def _build_colors() -> dict[str, NamedColor]:
    """Build the color table from webcolors; raise if the library's list is not what we expect."""
    hex_by_name = {
        name: webcolors.name_to_hex(name, spec="css3")
        for name in webcolors.names("css3")
        if name not in GREY_SPELLINGS
    }
    hex_by_name.update(_CSS4_ADDITIONS)
    if len(hex_by_name) != N_COLORS:
        raise RuntimeError(
            f"expected {N_COLORS} named colors from webcolors' css3 list + rebeccapurple minus "
            f"{len(GREY_SPELLINGS)} grey spellings, got {len(hex_by_name)}; check the webcolors "
            "version"
        )
    names = sorted(hex_by_name)
    hexes = [webcolors.normalize_hex(hex_by_name[name]) for name in names]
    rgb = np.array([[int(h[i : i + 2], 16) / 255.0 for i in (1, 3, 5)] for h in hexes])
    lab = srgb_to_lab(rgb)
    table = {}
    for name, hex_value, rgb_row, lab_row in zip(names, hexes, rgb, lab):
        lab_tuple = tuple(float(v) for v in lab_row)
        table[name] = NamedColor(
            name=name,
            hex=hex_value,
            rgb=tuple(float(v) for v in rgb_row),
            lab=lab_tuple,
            category=basic_category(lab_tuple),
        )
    return table


COLORS: dict[str, NamedColor] = _build_colors()


def get_color(name: str) -> NamedColor:
    """Look a color up by its CSS name; unknown names raise with close matches as a way out."""
    try:
        return COLORS[name]
    except KeyError:
        close = difflib.get_close_matches(str(name), COLORS, n=3)
        hint = f" did you mean {', '.join(close)}?" if close else ""
        grey = ""
        if name in GREY_SPELLINGS:
            grey = " (the grey spellings are excluded; use the 'gray' spelling)"
        raise ValueError(
            f"unknown color {name!r}{grey};{hint} valid names are the {N_COLORS} keys of "
            "roboview.variation.colors.COLORS (CSS named colors, e.g. red, navy, rosybrown)"
        ) from None
