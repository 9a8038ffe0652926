"""RoomLayout: a generated room as pure data (no MuJoCo).

Room frame: the floor is z = 0, the room spans x in [-width/2, width/2] and y in
[-depth/2, depth/2] (origin at the room's centre). Walls stand on the boundary.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from knowledge.geometry import ObjectInstance


@dataclass(frozen=True)
class Door:
    """A gap in one wall: which wall ('north' y+, 'south' y-, 'east' x+, 'west' x-), the gap's
    centre along the wall (m, in room coordinates) and its width (m)."""

    wall: str
    center: float
    width: float


@dataclass(frozen=True)
class RoomLayout:
    """A furnished room: its size, door and every object instance (furniture and small objects).

    ``support`` maps an object's id to the id of the object it rests on (None: the floor);
    ``placed_by`` maps an object's id to the (reference id, relation) of the placement rule that
    put it there, where one did (clutter has none). Both are ground truth: the robot never reads
    them.
    """

    style: str
    seed: int
    width: float
    depth: float
    height: float
    door: Door
    objects: tuple[ObjectInstance, ...]
    support: dict[int, int | None] = field(default_factory=dict)
    placed_by: dict[int, tuple[int, str]] = field(default_factory=dict)

    def by_id(self, obj_id: int) -> ObjectInstance:
        """The object with instance id ``obj_id``."""
        for o in self.objects:
            if o.id == obj_id:
                return o
        raise KeyError(obj_id)

    def of_type(self, type_name: str) -> list[ObjectInstance]:
        """All instances of one type."""
        return [o for o in self.objects if o.type == type_name]
