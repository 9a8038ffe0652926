"""What a search is and how it went: the episode (a world, a start pose, a target, a budget), one
image's record, and the result of one policy on one episode. Pure data; the measures read from
results (success, time to find, spl, paired ratios) are ``agent.search.measures``'.

Held-out worlds. Search worlds are never worlds the robot learned in: ``ctxsearch learn`` derives
its room seeds from (seed, index) with ``agent.learning.room_seed``; search episodes use
``held_out_seed(seed, i)``, the same hash of (seed, i) with a distinct tag, and the episode draw
skips any seed the store lists among its learned rooms.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ctxsearch.agent.navigation import OccupancyGrid, nearest_free
from ctxsearch.agent.search import measures
from ctxsearch.agent.search.config import DEFAULT_BUDGET_S
from ctxsearch.agent.viewplan import Gaze
from ctxsearch.envs.houses import WorldStyle
from ctxsearch.envs.layout import RoomLayout
from ctxsearch.envs.robot_spec import RobotPose, TimeModel
from ctxsearch.knowledge.catalog import Catalog
from ctxsearch.knowledge.errors import CtxsearchError

HELD_OUT_TAG = 0x5EA4C4  # distinguishes search rooms from learning rooms in the seed hash


def held_out_seed(seed: int, index: int) -> int:
    """The room seed of search episode ``index`` for benchmark seed ``seed`` (31-bit, spread out,
    never produced for the same (seed, index) by ``agent.learning.room_seed``)."""
    return int(
        np.random.SeedSequence([int(seed), int(index), HELD_OUT_TAG]).generate_state(1)[0]
        & 0x7FFFFFFF
    )


@dataclass(frozen=True)
class OracleView:
    """The oracle's choice: the gaze, the seconds it costs from the pose it was planned from, the
    instance it detects, and how many views were rendered to find it."""

    seconds: float
    gaze: Gaze
    instance_id: int
    renders: int
    key: tuple  # (base x, base y, instance id, view): for not trying it twice


@dataclass(frozen=True)
class Episode:
    """One search task: the room, where the robot starts, what it looks for, how long it may."""

    index: int
    style: str
    room_seed: int
    target: str
    start: RobotPose
    budget_s: float = DEFAULT_BUDGET_S
    # ``--targets instance``: the one instance of the target the world keeps (the others are
    # taken out of it: ``episode_layout``); None: every instance of the type counts.
    instance: int | None = None
    # the day of the world (envs.floorplan: furniture stays, small objects stay or move by
    # their type's stay probability): the remembered map's searches happen on a day after its
    # map was made
    day: int = 0
    # The oracle's first plan (``oracle_view`` from ``start`` at second 0), as the episode draw
    # computed it to check the episode is feasible: the Oracle policy starts from it instead of
    # planning the same view again. Not part of the episode's identity.
    first_view: OracleView | None = field(default=None, compare=False, repr=False)
    # on the remembered map: whether an instance of the target stands where one stood on the
    # day of the robot's map (agent.search.draw's ``since``); None: not asked
    stayed: bool | None = None

    def to_json(self) -> dict:
        """A JSON-serialisable dict."""
        s = self.start
        return {
            "index": self.index,
            "style": self.style,
            "room_seed": self.room_seed,
            "target": self.target,
            "start": [s.x, s.y, s.yaw],
            "budget_s": self.budget_s,
            **({} if self.instance is None else {"instance": self.instance}),
            **({"day": self.day} if self.day else {}),
            **({} if self.stayed is None else {"stayed": self.stayed}),
        }


@dataclass(frozen=True)
class GazeRecord:
    """One image of a search: when (seconds since the start, after the image), from where, why,
    and what the detector reported (type, instance id)."""

    t: float
    pose: RobotPose
    purpose: str
    detections: tuple[tuple[str, int], ...]


@dataclass
class SearchResult:
    """How an episode went for one policy. ``sim_time`` is the simulated seconds until the
    search ended on a confirmed detection of the target (``found_id``; or until the policy
    stopped); ``found`` is the judgement of whoever knows the truth (``measures.judge``: the
    episode runner), False until judged; ``success`` requires it within the budget."""

    policy: str
    episode: int
    target: str
    found: bool
    found_id: int | None
    sim_time: float
    gazes: int
    path_m: float
    budget_s: float
    trace: list[GazeRecord] = field(default_factory=list)
    log: list[str] = field(default_factory=list)
    # indirect search on the built map: the intermediate type it used first (searched for, or
    # whose relation volume it looked into; None: none), and Wixson & Ballard's predicted gain
    # C_direct / C_via for it (else for the best candidate type)
    intermediate: str | None = None
    predicted_gain: float | None = None
    unconfirmed: int = 0  # detections of the target a second image did not confirm
    # the belief's detectable mass left when the policy stopped before its budget without a
    # find (agent.search.belief.mass_left); None: found, out of time, or a policy without one
    mass_left: float | None = None

    @property
    def stop(self) -> str:
        """How the episode ended: ``found`` (success), ``false-find`` (a confirmed detection
        the judge found to be no target), ``budget`` (out of time) or ``gave-up`` (the policy
        stopped before its budget with nothing found)."""
        if self.success:
            return "found"
        if self.found_id is not None and self.sim_time < self.budget_s:
            return "false-find"
        return "budget" if self.sim_time >= self.budget_s else "gave-up"

    @property
    def success(self) -> bool:
        """Found within the budget (``measures.success``)."""
        return measures.success(self.found, self.sim_time, self.budget_s)

    @property
    def time_to_find(self) -> float:
        """Seconds to find; a failure counts as the budget (``measures.time_to_find``)."""
        return measures.time_to_find(self.found, self.sim_time, self.budget_s)

    def summary(self) -> str:
        """One line for the terminal."""
        what = (
            f"found {self.target} #{self.found_id}"
            if self.success
            else f"did not find {self.target}"
        )
        return (
            f"{self.policy}: {what} in {self.sim_time:.1f} simulated s "
            f"({self.gazes} gazes, {self.path_m:.1f} m driven; budget {self.budget_s:.0f} s)"
        )


@dataclass
class EpisodeDraw:
    """The episodes drawn and what was left out: worlds dropped because the target was visible
    from every start tried (``visible_at_start``) or no pose detects it within the budget
    (``infeasible``), and starts redrawn because the target was visible from them."""

    episodes: list[Episode]
    visible_at_start: int = 0
    infeasible: int = 0
    start_redraws: int = 0

    def excluded(self) -> dict[str, int]:
        """search.json's ``excluded``: worlds dropped, by reason."""
        return {"visible_at_start": self.visible_at_start, "infeasible": self.infeasible}


def episode_layout(layout: RoomLayout, ep: Episode) -> RoomLayout:
    """The world of episode ``ep`` from its generated ``layout``: as generated, or with
    ``--targets instance`` every instance of the target but ``ep.instance`` taken out."""
    if ep.instance is None:
        return layout
    others = {o.id for o in layout.of_type(ep.target) if o.id != ep.instance}
    return layout.without(others)


def random_start(layout: RoomLayout, grid: OccupancyGrid, rng: np.random.Generator) -> RobotPose:
    """A start pose: a uniformly drawn free cell of the largest free region, random heading."""
    region = grid.largest_region()
    if region is None:
        raise CtxsearchError(f"room {layout.style}/{layout.seed} has no free space for the robot")
    rows, cols = np.nonzero(region)
    k = int(rng.integers(len(rows)))
    xy = grid.to_xy(int(rows[k]), int(cols[k]))
    return RobotPose(float(xy[0]), float(xy[1]), float(rng.uniform(-math.pi, math.pi)))


def small_types_present(layout: RoomLayout, catalog: Catalog) -> list[str]:
    """The small-object (kind=object) types with an instance in the room, in catalog order."""
    present = {o.type for o in layout.objects}
    return [t.name for t in catalog.types if t.name in present and not t.is_furniture]


def nearest_free_start(grid: OccupancyGrid, pose: RobotPose) -> RobotPose:
    """``pose`` moved to the nearest free cell (a start pose must be drivable)."""
    p = nearest_free(grid, pose.xy)
    if p is None:
        raise CtxsearchError("the room has no free space for the robot")
    return RobotPose(float(p[0]), float(p[1]), pose.yaw, pose.pan, pose.tilt)


def check_target(catalog: Catalog, target: str, style: WorldStyle | None = None) -> None:
    """A one-line error unless ``target`` is a small-object type of the catalog that worlds of
    ``style`` (when given) can hold: checked on the style's definition (``style.types``: its
    furniture, rules and clutter), so an impossible request is refused before any episode is
    drawn, instead of after a draw that tries every room it may."""
    small = [t.name for t in catalog.types if not t.is_furniture]
    if target not in catalog:
        raise CtxsearchError(
            f"unknown target type '{target}' (small-object types: {', '.join(small)})"
        )
    if catalog.type(target).is_furniture:
        raise CtxsearchError(
            f"target '{target}' is a furniture type: a search looks for small objects "
            f"({', '.join(small)})"
        )
    if style is not None and target not in style.types:
        held = [t for t in small if t in style.types]
        raise CtxsearchError(
            f"no world of style '{style.name}' can hold a {target} (its small objects: "
            f"{', '.join(held) or 'none'})"
        )


def check_budget(budget_s: float, time_model: TimeModel | None = None) -> None:
    """A one-line error unless ``budget_s`` leaves time for the two images a find takes (a
    detection and the image that confirms it, ``TimeModel.image_cost`` each): a smaller budget
    is refused before any episode is drawn (no world could be feasible)."""
    tm = time_model or TimeModel()
    need = 2 * tm.image_cost
    if not budget_s >= need:
        raise CtxsearchError(
            f"a budget of {budget_s:g} simulated s is too small to find anything: a find takes "
            f"two images (a detection and its confirmation, {tm.image_cost:g} s each: {need:g} s)"
        )
