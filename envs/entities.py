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


def object_geoms(obj: ObjectInstance, otype: ObjectType) -> list[tuple[str, str, list, list, list]]:
    """The geoms of ``obj``'s body: (name, geom type, size, pos, rgba) per solid part of its
    shape, in the order the body holds them (names unscoped)."""
    name = body_name(obj.id)
    base = [float(c) for c in otype.color]
    out = []
    for part in solid_parts(otype.shape, obj.size):
        if part.color is not None:
            rgb = [float(c) for c in part.color]
        else:
            rgb = [c * part.color_scale for c in base]
        rgba = [min(max(c, 0.0), 1.0) for c in rgb] + [1.0]  # the same floats as np.clip
        if part.geom == "cylinder":
            size = [part.half[0], part.half[2]]
        else:
            size = list(part.half)
        out.append((f"{name}_{part.name}", part.geom, size, list(part.center), rgba))
    return out


def add_object_body(parent: mjcf.Element, obj: ObjectInstance, otype: ObjectType) -> mjcf.Element:
    """Add ``obj`` as one static body under ``parent``, one geom per solid part of its shape."""
    body = parent.add(
        "body", name=body_name(obj.id), pos=list(obj.position), euler=[0.0, 0.0, float(obj.yaw)]
    )
    for name, geom, size, pos, rgba in object_geoms(obj, otype):
        body.add(
            "geom", name=name, type=geom, pos=pos, size=size, rgba=rgba, group=OBJECT_GEOM_GROUP
        )
    return body


def _xml_floats(values) -> str:
    """Numbers as dm_control's MJCF writes them (``%.17g`` each, space-separated): they read
    back to the same bits."""
    return " ".join(f"{float(v):.17g}" for v in values)


def objects_xml(layout: RoomLayout, catalog: Catalog, scope: str = "objects/") -> str:
    """The ``<body>`` element that ``RoomObjects(layout, catalog)`` attached under the name scope
    ``scope`` adds to the world's XML, byte for byte as dm_control's ``to_xml_string`` writes it
    (indented for the world's ``<worldbody>``), written without building its MJCF elements: a
    house's hundreds of elements cost dm_control tens of milliseconds, this string a few."""
    if not layout.objects:
        return f'    <body name="{scope}"/>\n'
    lines = [f'    <body name="{scope}">']
    for obj in layout.objects:
        head = (
            f'      <body name="{scope}{body_name(obj.id)}" pos="{_xml_floats(obj.position)}" '
            f'euler="{_xml_floats((0.0, 0.0, obj.yaw))}"'
        )
        geoms = object_geoms(obj, catalog.type(obj.type))
        if not geoms:
            lines.append(head + "/>")
            continue
        lines.append(head + ">")
        for name, geom, size, pos, rgba in geoms:
            lines.append(
                f'        <geom name="{scope}{name}" class="{scope}" type="{geom}" '
                f'group="{OBJECT_GEOM_GROUP}" size="{_xml_floats(size)}" pos="{_xml_floats(pos)}" '
                f'rgba="{_xml_floats(rgba)}"/>'
            )
        lines.append("      </body>")
    lines.append("    </body>")
    return "\n".join(lines) + "\n"


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
