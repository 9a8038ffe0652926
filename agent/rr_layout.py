"""The rerun viewer's layout (blueprint) of each kind of recording, stored in the file with it.

``learn_blueprint``: a large 3-D view of the room, the head camera (RGB, segmentation,
detections) and its depth image in views of their own, one plot of n per type present and one
of the mean interval width, a wide log of the choices. ``search_blueprint``: one column per
search (3-D view above its camera and depth views), side by side on the same simulated
seconds, the share of the room seen and the log below. ``room_blueprint``: 3-D view, camera,
depth, log. Every layout shows the ``sim_time`` timeline and starts with the side panels
collapsed; the 3-D eye looks into the room from above a corner (``room_eye``), where the
wireframe walls hide nothing.

rerun is imported inside the functions (see agent.recording).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from ctxsearch.envs.layout import RoomLayout

# Application ids: the viewer remembers a layout per application, so each kind has its own.
LEARN_APP = "ctxsearch-learn"
SEARCH_APP = "ctxsearch-search"
ROOM_APP = "ctxsearch-room"


def room_eye(width: float, depth: float, height: float) -> Any:
    """A 3-D eye above the room's south-west corner, looking at its centre."""
    import rerun.blueprint as rrb

    span = max(width, depth)
    return rrb.EyeControls3D(
        kind=rrb.Eye3DKind.Orbital,
        position=[-0.45 * width - 0.2 * span, -0.55 * depth - 0.45 * span, height + 0.7 * span],
        look_target=[0.0, 0.0, 0.3],
        eye_up=[0.0, 0.0, 1.0],
    )


def _p(root: str, path: str) -> str:
    return f"{root}/{path}" if root else path


def _camera_views(root: str, title: str = "") -> list[Any]:
    """The head camera (images, segmentation, detections) and its depth, each in its own view."""
    import rerun.blueprint as rrb

    pre = f"{title}: " if title else ""
    return [
        rrb.Spatial2DView(
            name=f"{pre}head camera, detections", origin=_p(root, "world/camera/image")
        ),
        rrb.Spatial2DView(name=f"{pre}depth", origin=_p(root, "world/camera/depth")),
    ]


def _room_view(root: str, eye: Any, name: str) -> Any:
    import rerun.blueprint as rrb

    return rrb.Spatial3DView(
        name=name,
        origin=_p(root, "world"),
        contents=["+ $origin/**", "- $origin/camera/depth/**"],
        eye_controls=eye,
    )


def _panels() -> list[Any]:
    import rerun.blueprint as rrb

    return [
        rrb.TimePanel(timeline="sim_time"),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
    ]


def learn_blueprint(layout: RoomLayout) -> Any:
    """The layout of a learning run's recording (``layout``: the first room, for the eye)."""
    import rerun.blueprint as rrb

    eye = room_eye(layout.width, layout.depth, layout.height)
    top = rrb.Horizontal(
        _room_view("", eye, "room (3-D)"),
        rrb.Vertical(*_camera_views("")),
        column_shares=[3, 2],
    )
    bottom = rrb.Horizontal(
        rrb.TextLogView(name="choices and examinations", origin="log"),
        rrb.Vertical(
            rrb.TimeSeriesView(name="n per type (examinations)", origin="knowledge/n"),
            rrb.TimeSeriesView(name="mean interval width", origin="knowledge/mean_width"),
        ),
        column_shares=[3, 2],
    )
    return rrb.Blueprint(rrb.Vertical(top, bottom, row_shares=[3, 2]), *_panels())


def search_blueprint(layout: RoomLayout, runs: Sequence[tuple[str, str]]) -> Any:
    """The layout of a search recording: ``runs`` (root entity, title) side by side."""
    import rerun.blueprint as rrb

    eye = room_eye(layout.width, layout.depth, layout.height)
    columns = [
        rrb.Vertical(
            _room_view(root, eye, f"{title}: room (3-D)"),
            rrb.Horizontal(*_camera_views(root, title)),
            row_shares=[3, 2],
        )
        for root, title in runs
    ]
    bottom = rrb.Horizontal(
        rrb.TextLogView(
            name="search log", origin="/", contents=[f"+ /{_p(r, 'log')}" for r, _ in runs]
        ),
        rrb.TimeSeriesView(
            name="share of the room seen",
            origin="/",
            contents=[f"+ /{_p(r, 'search')}/**" for r, _ in runs],
        ),
        column_shares=[3, 2],
    )
    return rrb.Blueprint(
        rrb.Vertical(rrb.Horizontal(*columns), bottom, row_shares=[3, 1]), *_panels()
    )


def room_blueprint(layout: RoomLayout) -> Any:
    """The layout of ``ctxsearch room --record``."""
    import rerun.blueprint as rrb

    eye = room_eye(layout.width, layout.depth, layout.height)
    return rrb.Blueprint(
        rrb.Vertical(
            rrb.Horizontal(
                _room_view("", eye, "room (3-D)"),
                rrb.Vertical(*_camera_views("")),
                column_shares=[3, 2],
            ),
            rrb.TextLogView(name="views", origin="log"),
            row_shares=[4, 1],
        ),
        *_panels(),
    )
