"""What the robot keeps of a house it visited: its built map made into a remembered map
(knowledge.home_map.HomeMap), by a learning visit (agent.acquisition.RoomLearner.home_map) or a
search's tour (agent.search.tour).

Kept: the built map's occupancy (agent.mapping.BuiltMap), its own room segmentation of it
(agent.room_segmentation.RoomLabels.of_built), the furniture it recognised and, where the visit
kept a search lattice, which of its points rest on a surface.

A visit on a later day also checks what it remembers (``PlaceChecks``): every small object the
run's previous map of the world holds is a place; each image whose depth shows the place (its
centre in view and not hidden) multiplies the place's miss by one minus the detector's recall of
the type at that distance (agent.sight.DetectionCurve), and an instance of the type reported
within ``knowledge.persistence.RADIUS_M`` of it by such an image makes it "still there". At the
end, each place an image showed is a ``PersistenceCheck`` (recall: one minus its miss), and the
visit's map keeps today's small objects and carries over the remembered ones no image showed
(with the day they were last seen).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from ctxsearch.agent.mapping import BuiltMap
from ctxsearch.agent.room_segmentation import RoomLabels
from ctxsearch.agent.sight import detection_curve
from ctxsearch.envs.camera import Frame
from ctxsearch.envs.detector import Detection, DetectorModel
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.envs.robot_spec import RobotSpec
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.knowledge.home_map import HomeMap, PersistenceCheck, RememberedObject
from ctxsearch.knowledge.persistence import RADIUS_M

SHOWN_TOL_M = 0.25  # a place is shown when it is at most this behind the depth image's surface


def home_map(
    built: BuiltMap,
    layout: RoomLayout,
    day: int,
    furniture: list[RememberedObject],
    support: np.ndarray | None = None,
) -> HomeMap:
    """The remembered map of ``layout``'s world on ``day`` from the visit's ``built`` map
    (over the layout's footprint, up to its height), with the ``furniture`` it recognised and
    the lattice's ``support`` (None: the visit kept none). The layout gives only the world's
    name and extent, what the robot knew before it looked."""
    sup = np.zeros(0, bool) if support is None else np.asarray(support, bool)
    hw, hd = layout.width / 2, layout.depth / 2
    return HomeMap(
        layout.style, int(layout.seed), int(day), (-hw, -hd, hw, hd), float(layout.height),
        built.x0,
        built.y0, built.resolution, built.floor.copy(), built.occupied.copy(),
        built.top_z.copy(), RoomLabels.of_built(built).labels.astype(np.int16),
        tuple(sorted(furniture, key=lambda o: o.id)), sup, built.images,
    )  # fmt: skip


class PlaceChecks:
    """The places of ``previous``'s small objects checked by a visit on ``day`` (module
    docstring), with the run's ``detector`` (None: perfect) on ``spec``'s camera."""

    def __init__(
        self,
        previous: HomeMap | None,
        day: int,
        catalog: Catalog,
        detector: DetectorModel | None,
        spec: RobotSpec,
        width: int,
        height: int,
    ):
        self.day = int(day)
        self.places = [] if previous is None else list(previous.small)
        self.seen_day = {id(o): previous.seen_day(o) for o in self.places} if previous else {}
        curves = {}
        for o in self.places:
            if o.type not in curves:
                curves[o.type] = detection_curve(
                    catalog.type(o.type), detector, spec, width, height
                )
        self.curves = curves
        self.miss = np.ones(len(self.places))
        self.still = np.zeros(len(self.places), bool)
        self.xyz = np.array([o.position for o in self.places], float).reshape(-1, 3)

    def observe(self, frame: Frame | None, detections: Sequence[Detection]) -> None:
        """One image and what the detector reported in it."""
        if frame is None or frame.depth is None or not self.places:
            return
        cam = frame.camera
        shown = np.flatnonzero(cam.visible(self.xyz, frame.depth, tol=SHOWN_TOL_M))
        if not len(shown):
            return
        d = np.linalg.norm(self.xyz[shown] - np.asarray(cam.position, float), axis=1)
        for k, dist in zip(shown, d, strict=True):
            o = self.places[k]
            self.miss[k] *= 1.0 - float(self.curves[o.type].p(dist))
            for det in detections:
                near = np.linalg.norm(np.asarray(det.pose.position, float) - self.xyz[k])
                if det.type == o.type and near <= RADIUS_M:
                    self.still[k] = True

    def checks(self) -> list[PersistenceCheck]:
        """One check per place an image showed."""
        return [
            PersistenceCheck(o.type, self.day - self.seen_day[id(o)], 1.0 - float(m), 0.0, bool(y))
            for o, m, y in zip(self.places, self.miss, self.still, strict=True)
            if m < 1.0 and self.day > self.seen_day[id(o)]
        ]

    def carried(self) -> list[RememberedObject]:
        """The remembered small objects no image showed, with the day they were last seen."""
        return [
            replace(o, day=self.seen_day[id(o)])
            for o, m in zip(self.places, self.miss, strict=True)
            if m >= 1.0
        ]
