"""Where did I see it last: persistence as intervals (knowledge.persistence), the checks a visit
makes of remembered places (agent.home.PlaceChecks), the remembered sightings in the search's
prior (agent.search.memory), and ``bench home``'s command line."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from ctxsearch.agent.home import PlaceChecks
from ctxsearch.agent.search import space as ss
from ctxsearch.agent.search.memory import ELSEWHERE, LAST_SEEN, MemoryPrior, memory_prior
from ctxsearch.envs.camera import Frame, camera_at
from ctxsearch.envs.detector import Detection, load_detector
from ctxsearch.envs.floorplan import generate_layout
from ctxsearch.envs.houses import resolve_style
from ctxsearch.envs.robot_spec import RobotPose, RobotSpec
from ctxsearch.knowledge import intervals
from ctxsearch.knowledge.catalog import load_catalog
from ctxsearch.knowledge.geometry import ObjectInstance
from ctxsearch.knowledge.home_map import PersistenceCheck, RememberedObject
from ctxsearch.knowledge.persistence import (
    RADIUS_M,
    LearnedPersistence,
    TruePersistence,
    estimates,
    near_place,
    still_where_seen,
    store_persistence,
)
from ctxsearch.knowledge.store import EvidenceStore
from ctxsearch.scripts.cli import main
from tests.test_home_map import _visit, make_map


def _checks(type_name: str, still: int, gone: int, recall: float = 1.0, age: int = 1):
    return [PersistenceCheck(type_name, age, recall, 0.0, True)] * still + [
        PersistenceCheck(type_name, age, recall, 0.0, False)
    ] * gone


# ---- the intervals ------------------------------------------------------------------------------
def test_with_full_recall_the_interval_is_wilsons():
    e = estimates(_checks("Book", 17, 3), alpha=0.1)[("Book", 1)]
    lo, hi = intervals.interval(17, 20, alpha=0.1)
    assert (e.low, e.high) == pytest.approx((lo, hi), abs=1e-6)
    assert (e.checks, e.still, e.information) == (20, 17, pytest.approx(20.0))
    assert e.p == pytest.approx((lo + hi) / 2) and "STILL-WHERE-SEEN(Book) after 1 day" in e.line()


def test_missed_detections_are_not_counted_as_moves():
    """Half the checks could not have seen the object: 10 of 20 'still' at recall 0.5 says
    the object nearly always stays, where the plain count would say half."""
    low_recall = estimates(_checks("Cup", 10, 10, recall=0.5))[("Cup", 1)]
    plain = estimates(_checks("Cup", 10, 10))[("Cup", 1)]
    assert plain.low < 0.5 < plain.high
    assert low_recall.p > 0.8 and low_recall.low > plain.high - 0.05


def test_the_learned_persistence_reads_its_age_then_the_one_day_estimate_then_nothing():
    learned = LearnedPersistence(_checks("Book", 45, 5) + _checks("Book", 3, 7, age=3))
    one = learned.estimate("Book", 1).p
    assert learned.p("Book", 1) == one and learned.p("Book", 0) == 1.0
    assert learned.p("Book", 3) == learned.estimate("Book", 3).p < 0.5
    assert learned.p("Book", 2) == pytest.approx(one**2)  # no check of age 2: a Markov chain
    assert learned.p("Phone", 1) == 0.5  # never checked: nothing known
    assert learned.types() == ["Book"] and [e.age for e in learned.of_type("Book")] == [1, 3]


def test_the_worlds_persistence_is_its_rule_to_the_power_of_the_days():
    true = TruePersistence({"Book": 0.9, "Cup": 0.2}.__getitem__)
    assert true.p("Book", 2) == pytest.approx(0.81) and true.p("Cup", 0) == 1.0


def test_still_where_seen_is_an_instance_of_the_type_within_the_radius():
    cup = ObjectInstance("Cup", 1, (1.0, 1.0, 0.8), 0.0, (0.1, 0.1, 0.1))
    moved = replace(cup, position=(1.0 + RADIUS_M + 0.01, 1.0, 0.8))
    nudged = replace(cup, id=9, position=(1.0 + RADIUS_M - 0.01, 1.0, 0.8))
    assert near_place(cup.position, [nudged], "Cup") and not near_place(
        cup.position, [moved], "Cup"
    )
    assert not near_place(cup.position, [replace(nudged, type="Book")], "Cup")
    assert still_where_seen([cup], [moved, nudged], "Cup")
    assert not still_where_seen([cup], [moved], "Cup")


def test_the_store_reads_the_checks_of_its_maps_and_kb_show_lists_them(tmp_path, catalog, capsys):
    path = tmp_path / "kb.sqlite"
    with EvidenceStore.open(path, catalog) as store:
        _visit(store, replace(make_map(seed=1, day=1), checks=tuple(_checks("Cup", 2, 8))))
        _visit(store, replace(make_map(seed=2, day=1), checks=tuple(_checks("Cup", 1, 9))))
        _visit(store, make_map(seed=3, day=0))
        learned = store_persistence(store)
    e = learned.estimate("Cup", 1)
    assert (e.checks, e.still) == (20, 3)
    assert main(["kb", "show", str(path), "--type", "Cup"]) == 0
    out = capsys.readouterr().out
    assert "STILL-WHERE-SEEN(Cup) after 1 day" in out and "(3 of 20 checks still" in out
    assert main(["kb", "show", str(path), "--type", "Book"]) == 0
    assert "STILL-WHERE-SEEN" not in capsys.readouterr().out


# ---- the checks a visit makes ------------------------------------------------------------------
def test_a_visit_checks_the_places_its_images_show_and_carries_the_others(catalog):
    spec = RobotSpec()
    pose = RobotPose(0.0, 0.0, 0.0, 0.0, -0.3)
    cam = camera_at(pose, spec)
    frame = Frame(None, np.full((cam.height, cam.width), 10.0), None, cam, pose)
    ahead = RememberedObject("Cup", 3, (2.0, 0.0, 0.4), 0.0, (0.1, 0.1, 0.1), 0.8, 2)
    behind = RememberedObject("Book", 4, (-3.0, 0.0, 0.4), 0.0, (0.2, 0.1, 0.3), 0.9, 1)
    prev = replace(make_map(day=2), small=(ahead, replace(behind, day=1)))
    det = load_detector("realistic", catalog)
    places = PlaceChecks(prev, 4, catalog, det, spec, cam.width, cam.height)
    places.observe(frame, [])
    (miss,) = places.checks()
    assert miss.type == "Cup" and miss.age == 2 and not miss.still and 0 < miss.recall < 1
    cup = ObjectInstance("Cup", 77, (2.1, 0.1, 0.4), 0.0, (0.1, 0.1, 0.1))
    places.observe(frame, [Detection(77, "Cup", cup, 400, 2.0, (0, 0, 1, 1), 0.9)])
    (hit,) = places.checks()
    assert hit.still and hit.recall > miss.recall
    assert places.carried() == [replace(behind, day=1)]  # never shown: kept with its day
    assert PlaceChecks(None, 4, catalog, det, spec, 64, 48).checks() == []


# ---- the prior --------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def office_seen(catalog):
    layout = generate_layout(resolve_style("office", catalog), 3, catalog)
    return layout, ss.SeenMap.for_footprint(layout)


def test_a_sighting_adds_its_persistence_at_its_place(office_seen):
    layout, seen = office_seen
    spot = seen.points[len(seen.points) // 2]
    book = RememberedObject("Book", 5, tuple(float(v) for v in spot), 0.0, (0.2, 0.1, 0.3), 0.9, 1)
    home = replace(make_map(style=layout.style, day=1), small=(book,))
    mem = MemoryPrior(home, "Book", 3, TruePersistence(lambda t: 0.5), seen)
    (s,) = mem.sightings
    assert s.age == 2 and s.p == pytest.approx(0.25)
    near = np.linalg.norm(seen.points[s.points, :2] - spot[:2], axis=1)
    assert len(s.points) and near.max() <= RADIUS_M + 1e-9
    stand = np.ones(len(seen.points))
    rel = np.ones(len(seen.points))
    prior = mem.prior(rel, stand)  # one book remembered: 0.25 there, 0.75 + ELSEWHERE elsewhere
    assert prior.sum() == pytest.approx(1.0 + ELSEWHERE)
    assert prior[s.points].sum() >= 0.25
    assert prior[s.points].min() > prior.min()
    (region,) = mem.regions()
    assert region.members == [(LAST_SEEN, -6)] and region.p == pytest.approx(0.25)
    assert mem.regions({region.key}) == []
    # another type, no persistence, no map: no memory
    assert memory_prior(home, "Cup", 3, TruePersistence(lambda t: 0.5), seen) is None
    assert memory_prior(home, "Book", 3, None, seen) is None
    assert memory_prior(None, "Book", 3, TruePersistence(lambda t: 0.5), seen) is None
    assert memory_prior(home, "Book", 3, TruePersistence(lambda t: 0.0), seen) is None


# ---- bench home's command line ------------------------------------------------------------------
@pytest.mark.parametrize(
    "argv, message",
    [
        (["--out", "OUT"], "--kb is required"),
        (["--kb", "KB"], "--out DIR is required"),
        (["--kb", "KB", "--out", "OUT", "--map", "given"], "the home is the remembered map"),
    ],
)
def test_bench_home_refuses_what_it_cannot_run_in_one_line(tmp_path, capsys, argv, message):
    argv = [str(tmp_path / a) if a in ("OUT", "KB") else a for a in argv]
    assert main(["bench", "home", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err and "Traceback" not in err


@pytest.mark.parametrize("days", ["2,1", "0", "1,,2", "x"])
def test_bench_home_refuses_bad_gaps(capsys, days):
    with pytest.raises(SystemExit) as exc:
        main(["bench", "home", "--days-after", days, "--out", "x"])
    assert exc.value.code == 2 and "--days-after" in capsys.readouterr().err


# ---- a few days in a home, then the changing home's benchmark ------------------------------------
def test_living_in_a_room_for_days_learns_persistence_and_bench_home_runs_the_arms(
    tmp_path, capsys
):
    kb, out = tmp_path / "home.sqlite", tmp_path / "home"
    argv = ["learn", "--style", "living_room", "--rooms", "1", "--days", "2", "--map", "built",
            "--detector", "realistic", "--kb", str(kb), "--no-progress"]  # fmt: skip
    assert main(argv) == 0
    catalog = load_catalog()
    with EvidenceStore.open(kb, catalog, read_only=True) as store:
        (run, style, seed, _), (_, _, _, day) = store.home_maps()
        day0 = store.home_map(style, seed, run, upto_day=0)
        day1 = store.home_map(style, seed, run, upto_day=1)
        learned = store_persistence(store)
    assert day == 1 and day0.small and not day0.checks
    assert day1.checks and all(c.age == 1 and 0 < c.recall <= 1 for c in day1.checks)
    assert {c.type for c in day1.checks} <= {o.type for o in day0.small}
    assert learned.types()
    capsys.readouterr()
    argv = ["bench", "home", "--kb", str(kb), "--style", "living_room", "--episodes", "1",
            "--days-after", "1", "--policies", "uniform,memory,memory-location", "--quiet",
            "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    printed = capsys.readouterr().out
    assert "1 day(s) after the robot's map: 1 queries (1 stayed, 0 moved)" in printed
    doc = json.loads((out / "home.json").read_text())
    gap = doc["gaps"]["1"]
    assert set(gap["vs_uniform"]) == {"memory", "memory-location"}
    assert gap["context_vs"]["memory"]["n"] == 1
    assert (out / "d=1" / "search.json").exists() and (out / "home.md").exists()


def test_a_drawn_episode_keeps_whether_its_target_stayed_through_the_draw_cache():
    from ctxsearch.agent.search import draw_store
    from ctxsearch.agent.search.episode import Episode, EpisodeDraw

    eps = [Episode(i, "apartment", 5, "Cup", RobotPose(1.0, 2.0, 0.5), day=2, stayed=s)
           for i, s in enumerate((True, False, None))]  # fmt: skip
    back = draw_store.from_json(json.loads(json.dumps(draw_store.to_json(EpisodeDraw(eps)))))
    assert [e.stayed for e in back.episodes] == [True, False, None] and back.episodes == eps
    doc = draw_store.to_json(EpisodeDraw(eps[:1]))
    doc["episodes"][0]["stayed"] = "yes"
    with pytest.raises(TypeError):
        draw_store.from_json(doc)
