"""`object_size`: the object scaled 0.7–1.3 (its mass held at 60 g).

Applied in place to whichever shape the task placed: box and cylinder geoms scale their `geom_size`;
the hexagonal prism switches its mesh (`geom_dataid`) to one of seven scaled copies compiled into the
scene once (a mesh cannot be rescaled in place). Bounding radii, boxes, the body's bounding-volume
hierarchy and its inertia follow;
the object is set down so it rests on the table at its new height. Every other shape is restored to
scale 1, so a switch back restores the scene exactly.
"""

from __future__ import annotations

import mujoco
import numpy as np

from roboview.sim.scene import HEX_CIRCUMRADIUS, SHAPES, hex_prism_vertices
from roboview.variation.factors.base import Factor, register_factor

SCALES = (0.7, 0.8, 0.9, 1.0, 1.1, 1.2, 1.3)
VALUES = tuple(f"{s:.1f}" for s in SCALES)


def add_meshes(spec: mujoco.MjSpec) -> None:
    half = SHAPES["hex_prism"].half_height
    for value, s in zip(VALUES, SCALES):
        spec.add_mesh(name=f"hex_prism_x{value}", uservert=hex_prism_vertices(HEX_CIRCUMRADIUS * s, half * s))


class ObjectScale:
    def __init__(self, scene) -> None:
        self.scene = scene
        model = scene.model
        ids = scene.ids
        self.geoms = dict(ids.shape_geom)
        self.bodies = dict(ids.shape_body)
        self.base = {
            s: (
                model.geom_size[g].copy(),
                float(model.geom_rbound[g]),
                model.geom_aabb[g].copy(),
                model.body_inertia[self.bodies[s]].copy(),
                int(model.geom_dataid[g]),
            )
            for s, g in self.geoms.items()
        }
        # The body's bounding-volume hierarchy (collision midphase) was built around the compiled size:
        # it must grow with the geom, or a larger object falls through the table.
        self.bvh = {
            s: slice(int(model.body_bvhadr[b]), int(model.body_bvhadr[b] + model.body_bvhnum[b]))
            for s, b in self.bodies.items()
        }
        self.base_bvh = {s: model.bvh_aabb[sl].copy() for s, sl in self.bvh.items()}
        self.meshes = {v: model.mesh(f"hex_prism_x{v}").id for v in VALUES}

    def _scale(self, shape: str, value: str) -> None:
        model, g, s = self.scene.model, self.geoms[shape], float(value)
        size, rbound, aabb, inertia, dataid = self.base[shape]
        model.geom_size[g] = size * s
        model.geom_rbound[g] = rbound * s
        model.geom_aabb[g] = aabb * s
        model.body_inertia[self.bodies[shape]] = inertia * s * s
        model.bvh_aabb[self.bvh[shape]] = self.base_bvh[shape] * s
        if SHAPES[shape].geom_type == mujoco.mjtGeom.mjGEOM_MESH:
            model.geom_dataid[g] = dataid if value == "1.0" else self.meshes[value]

    def apply(self, value: str, rng: np.random.Generator) -> None:
        OBJECT_SIZE.validate(value)
        for shape in self.geoms:
            self._scale(shape, "1.0")
        active = self.scene.active_shape
        self._scale(active, value)
        adr = self.scene.ids.shape_qpos[active]
        self.scene.data.qpos[adr + 2] = SHAPES[active].half_height * float(value)  # resting on the table


OBJECT_SIZE = register_factor(
    Factor(
        name="object_size",
        kind="visual",
        values=VALUES,
        baseline="1.0",
        title="Object size",
        doc="Uniform scale of the object (0.7–1.3); its mass stays 60 g.",
        bind=ObjectScale,
        extend_spec=add_meshes,
        alters=("object_height",),
    )
)
