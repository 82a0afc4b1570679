"""The simulation stack: what, besides the benchmark's own rows, decides the pixels and the physics.

A benchmark's numbers hold only on a stack that draws the same images and integrates the same motion.
`describe(env)` records that stack from a freshly made env (before any instance is applied):

    mujoco        the MuJoCo version
    assets        where the robot came from (gym-hil's version) and a SHA-256 over the compiled model's
                  meshes and textures (the Panda and 2F-85 meshes, the procedural table textures)
    scene         SHA-256 of the scene spec saved as MJCF (`MjSpec.to_xml`): bodies, geoms, cameras, lights
    physics       every physics option of the compiled model (timestep, integrator, solver, friction, ...)
    renderer      the OpenGL vendor / renderer / version strings of the context that renders, and MUJOCO_GL
    image_size    the side of the rendered images

`differences(a, b)` lists what two stacks disagree on, for reports ("mujoco: 3.8.1 vs 3.17.0"). Whether a
difference matters is not decided here: the conformance check (roboview.benchmark.conformance)
re-renders and re-simulates a reference sample and measures it.
"""

from __future__ import annotations

import hashlib
import os
import platform
from importlib import metadata
from typing import Any

import mujoco
import numpy as np

# Compiled-model arrays that carry the robot's and the scene's assets.
ASSET_ARRAYS = (
    "mesh_vert",
    "mesh_face",
    "mesh_normal",
    "tex_data",
    "tex_height",
    "tex_width",
    "mat_rgba",
    "geom_size",
    "geom_rgba",
    "body_mass",
    "geom_friction",
)


def _version(dist: str) -> str:
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return "not installed"


def physics_options(model: mujoco.MjModel) -> dict[str, Any]:
    """Every field of `model.opt` as JSON values (arrays as lists)."""
    out = {}
    for name in sorted(dir(model.opt)):
        if name.startswith("_"):
            continue
        value = getattr(model.opt, name)
        if callable(value):
            continue
        out[name] = np.asarray(value).tolist() if isinstance(value, np.ndarray) else value
    return out


def assets_hash(model: mujoco.MjModel) -> str:
    digest = hashlib.sha256()
    for name in ASSET_ARRAYS:
        array = np.ascontiguousarray(getattr(model, name))
        digest.update(name.encode() + str(array.dtype).encode() + str(array.shape).encode() + array.tobytes())
    return digest.hexdigest()


# What picks the OpenGL implementation a process renders with: read when its first context is made, so fixed for
# the process's life once set.
GL_SELECTORS = (
    "MUJOCO_GL",
    "PYOPENGL_PLATFORM",
    "MUJOCO_EGL_DEVICE_ID",
    "GALLIUM_DRIVER",
    "LIBGL_ALWAYS_SOFTWARE",
)
_GL_STRINGS: dict[tuple[str | None, ...], dict[str, str]] = {}


def gl_strings(env) -> dict[str, str]:
    """The OpenGL vendor / renderer / version of the env's renderer (rendering once makes its context current).

    Read once per process and OpenGL selection (`GL_SELECTORS`): a later env of the same process renders through
    the same implementation, and reading the strings costs a renderer (≈ 0.4 s here) that an env whose
    conformance verdict is cached never needs otherwise. A failure to read them is not remembered."""
    key = tuple(os.environ.get(name) for name in GL_SELECTORS)
    if key in _GL_STRINGS:
        return dict(_GL_STRINGS[key])
    env.render_camera(env.cameras[0])
    try:
        from OpenGL import GL

        strings = {
            field: (GL.glGetString(name) or b"").decode(errors="replace")
            for field, name in (
                ("vendor", GL.GL_VENDOR),
                ("renderer", GL.GL_RENDERER),
                ("version", GL.GL_VERSION),
            )
        }
    except Exception as exc:  # noqa: BLE001 — a renderer that cannot be named is recorded as such
        return {"vendor": "unknown", "renderer": f"unknown ({type(exc).__name__})", "version": "unknown"}
    _GL_STRINGS[key] = strings
    return dict(strings)


def describe(env) -> dict[str, Any]:
    """The stack `env` renders and simulates on. Call it on a freshly made env: instances edit the model."""
    model = env.model
    return {
        "mujoco": mujoco.__version__,
        "assets": {
            **{
                name.replace("-", "_"): _version(name)
                for name in getattr(env, "asset_packages", ("gym-hil",))
            },
            "sha256": assets_hash(model),
        },
        "scene": {"task": env.task, "sha256": hashlib.sha256(env.scene_xml().encode()).hexdigest()},
        "physics": physics_options(model),
        "renderer": {
            **gl_strings(env),
            "mujoco_gl": os.environ.get("MUJOCO_GL", ""),
            "gallium_driver": os.environ.get("GALLIUM_DRIVER", ""),
        },
        "image_size": env.image_size,
        "platform": {
            "python": platform.python_version(),
            "machine": platform.machine(),
            "numpy": np.__version__,
        },
    }


def summary(stack: dict[str, Any] | None) -> str:
    """One line: MuJoCo version, renderer, image size."""
    if not stack:
        return "not recorded"
    renderer = stack.get("renderer", {})
    return (
        f"MuJoCo {stack.get('mujoco', '?')}, {renderer.get('renderer', '?')} ({renderer.get('version', '?')}), "
        f"{stack.get('image_size', '?')} px"
    )


def differences(a: dict[str, Any] | None, b: dict[str, Any] | None) -> list[str]:
    """What stacks `a` and `b` disagree on, one "what: a vs b" line each (platform details left out)."""
    if not a or not b:
        return [] if a == b else ["stack: not recorded on one side"]
    out = []
    for label, get in (
        ("mujoco", lambda s: s.get("mujoco")),
        ("robot assets", lambda s: s.get("assets", {}).get("sha256", "")[:12]),
        ("gym-hil", lambda s: s.get("assets", {}).get("gym_hil")),
        ("scene", lambda s: s.get("scene", {}).get("sha256", "")[:12]),
        ("renderer", lambda s: s.get("renderer", {}).get("renderer")),
        ("OpenGL", lambda s: s.get("renderer", {}).get("version")),
        ("image size", lambda s: s.get("image_size")),
    ):
        if get(a) != get(b):
            out.append(f"{label}: {get(a)} vs {get(b)}")
    pa, pb = a.get("physics", {}), b.get("physics", {})
    changed = sorted(k for k in set(pa) | set(pb) if pa.get(k) != pb.get(k))
    out += [f"physics option {k}: {pa.get(k)} vs {pb.get(k)}" for k in changed]
    return out
