"""LIBERO-plus's sensor noise, reproduced exactly (roboview.libero.corruptions): for every type and severity, RoboView's
frame equals LIBERO-plus's own function applied to the same frame, its draws from numpy's global generator in the
state a generator of RoboView's starts in; the codes, and bad input refused in one line."""

import numpy as np
import pytest

# Slow: LIBERO-plus's own glass blur shuffles its pixels one Python call at a time (seconds a frame).
pytestmark = [
    pytest.mark.slow,
    pytest.mark.filterwarnings("ignore:The binary mode of fromstring:DeprecationWarning"),  # its motion blur
]

pytest.importorskip("liberoplus", reason="LIBERO-plus not installed (make install-libero)")
pytest.importorskip("wand.api", reason="Wand / ImageMagick missing (make install-liberoplus-noise)")
pytest.importorskip("skimage", reason="scikit-image missing (make install-liberoplus-noise)")

from roboview.libero import corruptions  # noqa: E402


@pytest.fixture(scope="module")
def theirs() -> dict:
    return corruptions.liberoplus_functions()


@pytest.fixture(scope="module")
def frame() -> np.ndarray:
    """A 256² frame with edges, gradients and flat regions (LIBERO-plus renders at 256²)."""
    rng = np.random.default_rng(7)
    y, x = np.mgrid[0:256, 0:256]
    image = np.stack([x, y, (x + y) // 2], axis=-1).astype(np.uint8)
    image[60:140, 90:200] = (200, 40, 30)
    image[150:230, 20:80] = rng.integers(0, 256, (80, 60, 3))
    return image


def liberoplus_frame(theirs: dict, image: np.ndarray, code: int, seed: int) -> np.ndarray:
    """What LIBERO-plus's `ControlEnv.step` hands on for `code`, numpy's global generator seeded `seed` first."""
    from PIL import Image

    kind, severity = corruptions.type_of(code)
    np.random.seed(seed)
    out = theirs[kind](Image.fromarray(image), severity=severity)
    return out if kind == "motion_blur" else out.astype(np.uint8)


@pytest.mark.parametrize("kind", corruptions.TYPES)
def test_every_severity_equals_liberoplus_own_function(theirs, frame, kind):
    previous = None
    for severity in range(1, corruptions.SEVERITIES + 1):
        code = corruptions.code_of(kind, severity)
        ours = corruptions.corrupt(frame, code, np.random.RandomState(11))
        expected = liberoplus_frame(theirs, frame, code, 11)
        assert ours.dtype == np.uint8 and ours.shape == frame.shape, code
        assert np.array_equal(ours, expected), f"{kind} severity {severity}: {np.abs(ours - expected).max()}"
        assert not np.array_equal(ours, frame) and (previous is None or not np.array_equal(ours, previous))
        previous = ours


def test_the_random_types_draw_from_the_generator_and_the_others_do_not(frame):
    for kind, draws in (("motion_blur", True), ("fog", True), ("glass_blur", True), ("zoom_blur", False)):
        code = corruptions.code_of(kind, 3)
        a = corruptions.corrupt(frame, code, np.random.RandomState(1))
        b = corruptions.corrupt(frame, code, np.random.RandomState(2))
        assert np.array_equal(a, corruptions.corrupt(frame, code, np.random.RandomState(1)))
        assert (not np.array_equal(a, b)) == draws, kind
    # The generator of a frame: the episode seed and the step, nothing else.
    first = corruptions.frame_rng(5, 3).uniform()
    assert first == corruptions.frame_rng(5, 3).uniform() != corruptions.frame_rng(5, 4).uniform()
    assert first != corruptions.frame_rng(6, 3).uniform()


def test_another_size_runs_and_keeps_its_shape(frame):
    small = frame[::4, ::4].copy()
    for code in corruptions.CODES:
        out = corruptions.corrupt(small, code, np.random.RandomState(0))
        assert out.shape == (64, 64, 3) and out.dtype == np.uint8, code
    # The fog of a 64² frame is the 256² fractal's corner, as at 256² (the same draws).
    fog = corruptions.code_of("fog", 10)
    big = corruptions.corrupt(np.full((256, 256, 3), 100, np.uint8), fog, np.random.RandomState(3))
    corner = corruptions.corrupt(np.full((64, 64, 3), 100, np.uint8), fog, np.random.RandomState(3))
    assert np.array_equal(big[:64, :64], corner)


def test_codes_and_bad_input():
    assert corruptions.type_of(1) == ("motion_blur", 1) and corruptions.type_of(50) == ("glass_blur", 10)
    assert corruptions.type_of(33) == ("fog", 3) and corruptions.code_of("fog", 3) == 33
    assert [corruptions.code_of(*corruptions.type_of(c)) for c in corruptions.CODES] == list(range(1, 51))
    with pytest.raises(ValueError, match=r"noise code 51 is not one of LIBERO-plus's; allowed: 1–50$"):
        corruptions.type_of(51)
    with pytest.raises(ValueError, match=r"noise 'rain' severity 3; allowed: motion_blur, gaussian_blur"):
        corruptions.code_of("rain", 3)
