"""Culling for a house's head-camera images: the object geoms a camera cannot see are left out
of the scene, so a gaze in a house costs about what it costs in one room however large the
house is. Two tests, both conservative (they never hide what could show):

- rooms: the rooms the camera cannot see into through door openings
  (``envs.floorplan.visible_rooms``, 2-D portal visibility);
- frustum: objects whose bounding sphere lies wholly outside one of the four side planes of the
  camera's view pyramid (behind the camera included): ``envs.camera.in_frustum`` with the
  sphere's radius and no near plane.

MuJoCo's ``mjv_updateScene`` skips geoms whose alpha is 0: ``hide`` sets the alpha of the culled
objects' geoms to 0 for one image and ``restore`` puts it back. The images do not change (tested
against unculled renders); only the draw gets cheaper.
"""

from __future__ import annotations

import math

import numpy as np

from ctxsearch.envs.camera import half_fov_tangents, in_frustum
from ctxsearch.envs.floorplan import visible_rooms
from ctxsearch.envs.layout import RoomLayout

MARGIN = 0.05  # m added to every bounding sphere


class RoomCulling:
    """Hides the object geoms a head camera cannot see in a house (see the module docstring)."""

    def __init__(self, layout: RoomLayout, geom_rgba: np.ndarray, geom_instance: np.ndarray):
        """``geom_rgba``: the model's (ngeom, 4) colours (edited in place); ``geom_instance``:
        geom id -> object instance id (-1: not an object)."""
        self.layout = layout
        self._rgba = geom_rgba
        index = {o.id: k for k, o in enumerate(layout.objects)}
        obj = np.array([index.get(int(i), -1) for i in geom_instance], np.int64)
        self._geoms = np.flatnonzero(obj >= 0)
        self._obj = obj[self._geoms]  # object index of each culled-able geom
        self._alpha = geom_rgba[self._geoms, 3].copy()
        self._room = np.array([layout.room_of.get(o.id, -1) for o in layout.objects], np.int64)
        self._center = np.array([o.position for o in layout.objects], float).reshape(-1, 3)
        self._radius = np.array(
            [0.5 * math.dist((0, 0, 0), o.size) + MARGIN for o in layout.objects], float
        )
        self._hidden = False

    def visible_objects(
        self, position: np.ndarray, xmat: np.ndarray, fovy_deg: float, width: int, height: int
    ) -> np.ndarray:
        """(N,) bool over ``layout.objects``: may the camera (world position (3,), rotation
        (3, 3) with MuJoCo's camera axes: x right, y up, looking along -z) see it?"""
        pos = np.asarray(position, float)
        ok = np.ones(len(self._center), bool)
        rooms = visible_rooms(self.layout, float(pos[0]), float(pos[1]))
        if rooms is not None:
            ok &= np.isin(self._room, np.fromiter(rooms, np.int64, len(rooms)))
        tx, ty = half_fov_tangents(fovy_deg, width, height)
        local = (self._center - pos) @ np.asarray(xmat, float).reshape(3, 3)  # right, up, back
        ok &= in_frustum(-local[:, 2], local[:, 0], local[:, 1], tx, ty, -math.inf, self._radius)
        return ok

    def hide(
        self, position: np.ndarray, xmat: np.ndarray, fovy_deg: float, width: int, height: int
    ) -> int:
        """Hide the geoms of every object the camera cannot see; returns how many geoms."""
        show = self.visible_objects(position, xmat, fovy_deg, width, height)[self._obj]
        self._rgba[self._geoms, 3] = np.where(show, self._alpha, 0.0)
        self._hidden = True
        return int(len(show) - show.sum())

    def restore(self) -> None:
        """Show every geom again."""
        if self._hidden:
            self._rgba[self._geoms, 3] = self._alpha
            self._hidden = False
