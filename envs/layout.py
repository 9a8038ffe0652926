"""RoomLayout: a generated room or house as pure data (no MuJoCo).

Room frame: the floor is z = 0, the room spans x in [-width/2, width/2] and y in
[-depth/2, depth/2] (origin at the room's centre). Walls stand on the boundary.

A house (``envs.floorplan.generate_house``) is the same type: ``width`` x ``depth`` is its whole
footprint (origin at its centre), ``door`` its entrance in the outer wall, and ``rooms``,
``doors`` and ``room_of`` say which furnished room holds what. A single room has none of them.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from ctxsearch.knowledge.geometry import ObjectInstance


@dataclass(frozen=True)
class Door:
    """A gap in one wall: which wall ('north' y+, 'south' y-, 'east' x+, 'west' x-), the gap's
    centre along the wall (m, in room coordinates) and its width (m)."""

    wall: str
    center: float
    width: float


@dataclass(frozen=True)
class Room:
    """One room of a house: its index, its room style's name (``corridor``: a hall with no
    furniture) and its interior outline, an axis-aligned rectangle (x0, y0, x1, y1) in house
    coordinates (interior walls stand around it)."""

    index: int
    style: str
    outline: tuple[float, float, float, float]

    @property
    def center(self) -> tuple[float, float]:
        """The outline's centre (x, y)."""
        x0, y0, x1, y1 = self.outline
        return (x0 + x1) / 2, (y0 + y1) / 2

    @property
    def area(self) -> float:
        """Interior floor area (m^2)."""
        x0, y0, x1, y1 = self.outline
        return (x1 - x0) * (y1 - y0)


@dataclass(frozen=True)
class Passage:
    """A door of a house: the two rooms it joins (``rooms[1] == -1``: the entrance, to the
    outside), the opening's centre (x, y) on its wall's centre line, the direction the wall runs
    (``axis`` 'x' or 'y') and the opening's width (m)."""

    rooms: tuple[int, int]
    center: tuple[float, float]
    axis: str
    width: float


@dataclass(frozen=True)
class RoomLayout:
    """A furnished room: its size, door and every object instance (furniture and small objects).

    ``support`` maps an object's id to the id of the object it rests on (None: the floor);
    ``placed_by`` maps an object's id to the (reference id, relation) of the placement rule that
    put it there, where one did (clutter has none). Both are ground truth: the robot never reads
    them.

    For a house, ``rooms`` are its rooms, ``doors`` every opening between them (and the entrance)
    and ``room_of`` maps every object's id to the index of the room it stands in.
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
    rooms: tuple[Room, ...] = ()
    doors: tuple[Passage, ...] = ()
    room_of: dict[int, int] = field(default_factory=dict)

    @property
    def is_house(self) -> bool:
        """True for a multi-room house (``rooms`` given), False for a single room."""
        return bool(self.rooms)

    def without(self, ids: set[int] | frozenset[int]) -> RoomLayout:
        """This layout less the objects of ``ids`` and whatever rests on them (as if they had
        never been placed: the support and placement maps lose them too)."""
        gone = set(ids)
        while True:
            more = {o for o, s in self.support.items() if s in gone and o not in gone}
            if not more:
                break
            gone |= more
        return replace(
            self,
            objects=tuple(o for o in self.objects if o.id not in gone),
            support={k: v for k, v in self.support.items() if k not in gone},
            placed_by={k: v for k, v in self.placed_by.items() if k not in gone},
            room_of={k: v for k, v in self.room_of.items() if k not in gone},
        )

    def by_id(self, obj_id: int) -> ObjectInstance:
        """The object with instance id ``obj_id``."""
        for o in self.objects:
            if o.id == obj_id:
                return o
        raise KeyError(obj_id)

    def of_type(self, type_name: str) -> list[ObjectInstance]:
        """All instances of one type."""
        return [o for o in self.objects if o.type == type_name]
