"""A room's furniture and small objects as one composer Entity, built with ``mjcf``.

Each object instance becomes ONE static body (no joints) named ``obj<id>`` at the instance's
bounding-box centre and yaw, holding one geom per solid part from ``envs.parts.solid_parts``
(boxes and upright cylinders), named ``obj<id>_<part>``. Rendering, the room generator and
navigation therefore share one geometry, and segmentation maps geom -> body -> instance id.

All instances live in one Entity rather than one Entity each: a composer Entity costs a fresh
MJCF root and an attachment (milliseconds each), which would dominate the per-room build.
"""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # before dm_control/mujoco are first imported

import numpy as np
from dm_control import composer, mjcf

from ctxsearch.envs.layout import RoomLayout
from ctxsearch.envs.parts import solid_parts
from ctxsearch.knowledge.catalog import Catalog, ObjectType
from ctxsearch.knowledge.geometry import ObjectInstance

OBJECT_GEOM_GROUP = 1


def body_name(instance_id: int) -> str:
    """The (unscoped) MJCF body name of an object instance."""
    return f"obj{instance_id}"


def add_object_body(parent: mjcf.Element, obj: ObjectInstance, otype: ObjectType) -> mjcf.Element:
    """Add ``obj`` as one static body under ``parent``, one geom per solid part of its shape."""
    name = body_name(obj.id)
    body = parent.add("body", name=name, pos=list(obj.position), euler=[0.0, 0.0, float(obj.yaw)])
    base = np.asarray(otype.color, float)
    for part in solid_parts(otype.shape, obj.size):
        rgb = np.asarray(part.color, float) if part.color is not None else base * part.color_scale
        rgba = [*np.clip(rgb, 0.0, 1.0).tolist(), 1.0]
        if part.geom == "cylinder":
            size = [part.half[0], part.half[2]]
        else:
            size = list(part.half)
        body.add(
            "geom",
            name=f"{name}_{part.name}",
            type=part.geom,
            pos=list(part.center),
            size=size,
            rgba=rgba,
            group=OBJECT_GEOM_GROUP,
        )
    return body


class RoomObjects(composer.Entity):
    """Every object instance of a layout: one static body per instance (see the module docstring)."""

    def _build(self, layout: RoomLayout, catalog: Catalog, name: str = "objects") -> None:
        self._mjcf_root = mjcf.RootElement(model=name)
        self._mjcf_root.default.geom.set_attributes(contype=0, conaffinity=0)
        self._bodies: dict[int, mjcf.Element] = {}
        for obj in layout.objects:
            self._bodies[obj.id] = add_object_body(
                self._mjcf_root.worldbody, obj, catalog.type(obj.type)
            )

    @property
    def mjcf_model(self) -> mjcf.RootElement:
        return self._mjcf_root

    @property
    def bodies(self) -> dict[int, mjcf.Element]:
        """Instance id -> its body element."""
        return self._bodies

    def geom_instance_ids(self, physics: mjcf.Physics) -> np.ndarray:
        """(ngeom,) int32: the instance id owning each geom of ``physics``' model, -1 for others."""
        lut = np.full(physics.model.ngeom, -1, np.int32)
        if not self._bodies:
            return lut
        ids = np.fromiter(self._bodies, np.int64, len(self._bodies))
        body_ids = physics.bind(list(self._bodies.values())).element_id
        body_to_inst = np.full(physics.model.nbody, -1, np.int32)
        body_to_inst[body_ids] = ids
        return body_to_inst[physics.model.geom_bodyid]
