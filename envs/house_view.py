"""Room culling for a house's head-camera images: geoms of rooms the camera cannot see into are
left out of the scene (``envs.floorplan.visible_rooms``), so a gaze in a house costs about what
it costs in one room however many rooms the house has.

MuJoCo's ``mjv_updateScene`` skips geoms whose alpha is 0: ``hide`` sets the alpha of every
object geom in a culled room to 0 for one image and ``restore`` puts it back. The images do not
change (a culled room is behind walls); only the draw gets cheaper.
"""

from __future__ import annotations

import numpy as np

from envs.floorplan import visible_rooms
from envs.layout import RoomLayout


class RoomCulling:
    """Hides the object geoms of the rooms a camera position cannot see (a house only)."""

    def __init__(self, layout: RoomLayout, geom_rgba: np.ndarray, geom_instance: np.ndarray):
        """``geom_rgba``: the model's (ngeom, 4) colours (edited in place); ``geom_instance``:
        geom id -> object instance id (-1: not an object)."""
        self.layout = layout
        self._rgba = geom_rgba
        room = np.full(len(geom_instance), -1, np.int64)
        for g, inst in enumerate(geom_instance):
            if inst >= 0 and int(inst) in layout.room_of:
                room[g] = layout.room_of[int(inst)]
        self._geoms = np.flatnonzero(room >= 0)
        self._room = room[self._geoms]
        self._alpha = geom_rgba[self._geoms, 3].copy()
        self._hidden = False

    def hide(self, x: float, y: float) -> int:
        """Hide the object geoms of every room not visible from (x, y); returns how many."""
        rooms = visible_rooms(self.layout, x, y)
        if rooms is None:
            return 0
        show = np.isin(self._room, np.fromiter(rooms, np.int64, len(rooms)))
        self._rgba[self._geoms, 3] = np.where(show, self._alpha, 0.0)
        self._hidden = True
        return int(len(show) - show.sum())

    def restore(self) -> None:
        """Show every geom again."""
        if self._hidden:
            self._rgba[self._geoms, 3] = self._alpha
            self._hidden = False
