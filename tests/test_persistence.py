"""Small objects from one day to the next: stay probabilities in the catalog and the styles, days
made from the day before (stay 0: the days of before; stay 1: everything the day still places
stays put), the truth's persistence and ``envs.persistence.stayed``."""

from __future__ import annotations

import argparse
import copy
import dataclasses
import hashlib
import json
from collections import Counter
from pathlib import Path

import pytest

from ctxsearch.envs.floorplan import generate_layout, layout_dict
from ctxsearch.envs.houses import HouseStyle, resolve_style
from ctxsearch.envs.persistence import same_pose, stayed
from ctxsearch.envs.styles import StyleError, load_style, parse_style
from ctxsearch.envs.truth import persistence, persistence_counts
from ctxsearch.knowledge.catalog import DEFAULT_CATALOG, parse_catalog
from ctxsearch.knowledge.errors import CatalogError
from ctxsearch.knowledge.files import read_toml
from ctxsearch.scripts import cmd_truth
from ctxsearch.scripts.cli import main

# sha256 over the layouts of office, living_room and apartment, seeds 0 and 7, days 1 and 3, as
# the code before small objects could stay generated them (computed with that code): with every
# stay probability 0 the days must stay exactly those.
# The apartment of then is today's apartment_shuffled (tests/test_days.py).
BEFORE_STAYS = "22f299cdb90b0a4cefe1b8b77b4261abf150b336402c739f08ca6fc9c732df58"


def with_stays(style, stays: tuple[tuple[str, float], ...]):
    """A room style with another [stay] table; a house style with it in every room style."""
    if isinstance(style, HouseStyle):
        rooms = tuple((with_stays(s, stays), c) for s, c in style.rooms)
        return dataclasses.replace(style, rooms=rooms)
    return dataclasses.replace(style, stays=stays)


def _small(layout, catalog):
    return [o for o in layout.objects if not catalog.type(o.type).is_furniture]


def _per_room(objects, layout) -> Counter:
    return Counter((layout.room_of.get(o.id, 0), o.type) for o in objects)


# ---- data: the catalog's stay and a style's [stay] ---------------------------------------------
def test_the_catalog_states_a_stay_for_every_small_type(catalog):
    small = {t.name: t.stay for t in catalog.types if not t.is_furniture}
    assert all(0.0 < p <= 1.0 for p in small.values()), small
    assert small["Book"] > small["Laptop"] > small["Cup"] > small["Phone"]
    assert small["Plant"] >= 0.9 and small["Phone"] <= 0.2


@pytest.mark.parametrize("bad", [1.5, -0.1, "often", True, float("nan"), [0.5]])
def test_a_bad_catalog_stay_is_a_one_line_error_naming_file_type_and_field(bad):
    doc = copy.deepcopy(read_toml(DEFAULT_CATALOG))
    cup = next(t for t in doc["type"] if t["name"] == "Cup")
    cup["stay"] = bad
    with pytest.raises(CatalogError) as err:
        parse_catalog(doc, DEFAULT_CATALOG)
    msg = str(err.value)
    assert str(DEFAULT_CATALOG) in msg and "type Cup" in msg and "field 'stay'" in msg
    assert "\n" not in msg and err.value.field == "stay"


def test_catalog_stay_is_optional_and_not_part_of_the_fingerprint(catalog):
    doc = copy.deepcopy(read_toml(DEFAULT_CATALOG))
    for t in doc["type"]:
        t.pop("stay", None)
    bare = parse_catalog(doc, DEFAULT_CATALOG)
    assert all(t.stay == 0.0 for t in bare.types)  # absent: placed anew every day
    assert bare.fingerprint == catalog.fingerprint  # stores stay valid
    desk = next(t for t in doc["type"] if t["name"] == "Desk")
    desk["stay"] = 0.5  # furniture: checked, no effect (it always stays)
    assert parse_catalog(doc, DEFAULT_CATALOG).type("Desk").stay == 0.5


def test_style_stay_reads_the_table_then_star_then_the_catalog(catalog, tmp_path):
    base = read_toml(Path(load_style("office", catalog).path))
    doc = {**base, "stay": {"Book": 0.5, "*": 0.25}}
    st = parse_style(doc, tmp_path / "s.toml", catalog)
    assert st.stays == (("Book", 0.5), ("*", 0.25))
    assert st.stay("Book", catalog) == 0.5 and st.stay("Cup", catalog) == 0.25
    assert st.stay("Desk", catalog) == 1.0  # furniture always stays
    plain = parse_style({**base, "stay": {"Book": 0.5}}, tmp_path / "s.toml", catalog)
    assert plain.stay("Cup", catalog) == catalog.type("Cup").stay
    assert not plain.moves_everything(catalog)
    assert not load_style("office", catalog).moves_everything(catalog)
    assert with_stays(load_style("office", catalog), (("*", 0.0),)).moves_everything(catalog)
    assert st.on_day(5).stays == st.stays  # drift keeps the table
    assert load_style("living_room", catalog).stay("Phone", catalog) == catalog.type("Phone").stay


@pytest.mark.parametrize(
    ("table", "field", "message"),
    [
        ({"Mug": 0.5}, "stay.Mug", "unknown type 'Mug'"),
        ({"Desk": 0.5}, "stay.Desk", "furniture"),
        ({"Book": "often"}, "stay.Book", "probability"),
        ({"Book": True}, "stay.Book", "probability"),
        ({"*": 1.5}, "stay.*", "probability"),
        ({"Cup": -0.2}, "stay.Cup", "probability"),
        ([0.5], "stay", "table"),
    ],
)
def test_a_bad_stay_table_is_a_one_line_style_error(
    catalog, tmp_path, capsys, table, field, message
):
    base = read_toml(Path(load_style("living_room", catalog).path))
    path = tmp_path / "lr.toml"
    with pytest.raises(StyleError, match=message) as err:
        parse_style({**base, "stay": table}, path, catalog)
    assert err.value.field == field and str(path) in str(err.value)
    assert "\n" not in str(err.value)
    text = Path(load_style("living_room", catalog).path).read_text()
    bad = {"stay.Mug": "Mug = 0.5", "stay.Desk": "Desk = 0.5", "stay.*": '"*" = 1.5'}
    if field in bad:  # the same through the CLI
        path.write_text(text + f"\n[stay]\n{bad[field]}\n")
        assert main(["room", "--style", str(path), "--out", str(tmp_path / "r.png")]) == 2
        out = capsys.readouterr().err.strip()
        assert out.startswith("ctxsearch: error: ") and f"field '{field}'" in out
        assert "\n" not in out


# ---- days follow it ---------------------------------------------------------------------------
def test_with_every_stay_0_the_days_are_those_of_before(catalog):
    h = hashlib.sha256()
    for name in ("office", "living_room", "apartment_shuffled"):
        st = with_stays(resolve_style(name, catalog), (("*", 0.0),))
        for seed in (0, 7):
            for day in (1, 3):
                layout = generate_layout(st, seed, catalog, day)
                doc = layout_dict(layout) | {"style": name.removesuffix("_shuffled")}
                blob = json.dumps(doc, sort_keys=True).encode()
                h.update(hashlib.sha256(blob).hexdigest().encode())
    assert h.hexdigest() == BEFORE_STAYS


@pytest.mark.parametrize("name", ["living_room", "kitchen", "apartment"])
def test_with_stay_1_everything_the_day_still_places_stays_put(catalog, name):
    st = with_stays(resolve_style(name, catalog), (("*", 1.0),))
    moved = 0
    for seed in range(4):
        a, b = generate_layout(st, seed, catalog, 1), generate_layout(st, seed, catalog, 2)
        kept = stayed(a, b)
        before, after = _per_room(_small(a, catalog), a), _per_room(_small(b, catalog), b)
        still = _per_room([o for o in _small(b, catalog) if o.id in kept], b)
        for key, n in before.items():  # as many as the day places of that type in that room
            assert still[key] == min(n, after[key]), (seed, key)
        moved += sum(after.values()) - sum(still.values())
        for o in b.objects:  # a stayer rests on what it rested on
            if o.id in kept and b.support.get(o.id) is not None:
                sup = b.by_id(b.support[o.id])
                assert any(same_pose(sup, x) for x in a.objects)
    assert moved > 0  # days that place more than yesterday place new ones


def test_a_realistic_style_keeps_books_far_more_often_than_cups(catalog):
    st = load_style("living_room", catalog)
    kept: dict[tuple[str, str], list[int]] = {}
    for seed in range(40):
        day0, day1 = generate_layout(st, seed, catalog), generate_layout(st, seed, catalog, 1)
        for key, (n, y, _near) in persistence_counts(day0, day1, catalog).items():
            kept.setdefault(key, [0, 0])
            kept[key] = [kept[key][0] + n, kept[key][1] + y]
    share = {t: y / n for (_s, t), (n, y) in kept.items()}
    assert kept[("living_room", "Book")][0] > 200 and kept[("living_room", "Cup")][0] > 30
    # an object stays with its type's probability: configured 0.9 and 0.2 (seeded: no flake)
    assert share["Book"] > share["Cup"] + 0.5
    for t in ("Book", "Cup"):
        n = kept[("living_room", t)][0]
        p = st.stay(t, catalog)
        assert abs(share[t] - p) <= 4 * (p * (1 - p) / n) ** 0.5 + 0.02


def test_days_are_deterministic_and_keep_the_furniture(catalog):
    st = load_style("living_room", catalog)
    a = generate_layout(st, 5, catalog, 3)
    assert a == generate_layout(st, 5, catalog, 3)
    day0 = generate_layout(st, 5, catalog)
    fur = [o for o in day0.objects if catalog.type(o.type).is_furniture]
    assert [o for o in a.objects if catalog.type(o.type).is_furniture] == fur
    ids = [o.id for o in a.objects]
    assert len(set(ids)) == len(ids)
    assert generate_layout(st, 5, catalog) == day0  # day 0 is untouched


def test_houses_on_day_3_have_unique_ids_and_stayers_at_their_exact_earlier_pose(catalog):
    st = resolve_style("apartment", catalog)
    total = 0
    for seed in range(3):
        d2, d3 = generate_layout(st, seed, catalog, 2), generate_layout(st, seed, catalog, 3)
        ids = [o.id for o in d3.objects]
        assert len(set(ids)) == len(ids) and min(ids) == 1
        assert max(ids) <= max(len(d3.objects), len(generate_layout(st, seed, catalog).objects))
        assert set(d3.room_of) == set(ids) and set(d3.support) == set(ids)
        kept = stayed(d2, d3) - {o.id for o in d3.objects if catalog.type(o.type).is_furniture}
        total += len(kept)
        for oid in kept:
            o = d3.by_id(oid)
            (was,) = [x for x in d2.objects if same_pose(o, x)]
            assert d3.room_of[oid] == d2.room_of[was.id]  # in its room
            sup, sup2 = d3.support[oid], d2.support[was.id]
            assert (sup is None) == (sup2 is None)
            if sup is not None:  # on the same thing (house ids may differ across days)
                assert same_pose(d3.by_id(sup), d2.by_id(sup2))
        for oid, (ref, _rel) in d3.placed_by.items():
            assert oid in d3.room_of and ref in d3.room_of
    assert total > 20


def test_stayed_compares_type_and_exact_pose(catalog):
    st = load_style("kitchen", catalog)
    a = generate_layout(st, 2, catalog)
    assert stayed(a, a) == {o.id for o in a.objects}
    o = _small(a, catalog)[0]
    nudged = dataclasses.replace(
        a,
        objects=tuple(
            dataclasses.replace(x, position=(x.position[0] + 1e-3, *x.position[1:]))
            if x.id == o.id
            else x
            for x in a.objects
        ),
    )
    assert stayed(a, nudged) == {x.id for x in a.objects} - {o.id}
    turned = dataclasses.replace(o, yaw=o.yaw + 2 * 3.141592653589793)  # the same yaw
    assert same_pose(o, turned) and not same_pose(o, dataclasses.replace(o, type="Plant"))


# ---- the truth reports it ---------------------------------------------------------------------
def test_the_truth_reports_configured_and_measured_persistence(catalog, tmp_path, capsys):
    parser = argparse.ArgumentParser()
    cmd_truth.register(parser.add_subparsers())
    out = tmp_path / "t.json"
    args = parser.parse_args(["truth", "--style", "living_room", "--samples", "12", "--out",
                              str(out), "--no-progress"])  # fmt: skip
    assert args.func(args) == 0
    doc = json.loads(out.read_text())["persistence"]
    assert (doc["from_day"], doc["to_day"]) == (0, 1)
    st = load_style("living_room", catalog)
    rows = {e["type"]: e for e in doc["types"]}
    assert set(rows) == {t for t in st.types if not catalog.type(t).is_furniture}
    # the same counts by hand
    n, y = Counter(), Counter()
    for seed in range(12):
        day0, day1 = generate_layout(st, seed, catalog), generate_layout(st, seed, catalog, 1)
        kept = stayed(day1, day0)
        for o in _small(day0, catalog):
            n[o.type] += 1
            y[o.type] += o.id in kept
    for t, e in rows.items():
        assert e["stay"] == st.stay(t, catalog)
        assert (e["n"], e["y"]) == (n[t], y[t])
        assert e["p"] == (y[t] / n[t] if n[t] else None)
    printed = capsys.readouterr().out
    assert "persistence, day 0 -> 1" in printed and "Book" in printed.split("persistence")[-1]


def test_objects_that_never_stay_never_do_and_a_house_weights_its_room_styles(catalog):
    office = with_stays(load_style("office", catalog), (("*", 0.0),))
    counts = persistence_counts(
        generate_layout(office, 1, catalog), generate_layout(office, 1, catalog, 1), catalog
    )
    assert counts and all(y == 0 for _n, y, _near in counts.values())
    house = resolve_style("apartment", catalog)
    house = dataclasses.replace(house, rooms=tuple(
        (with_stays(s, (("*", 0.0),)) if s.name == "office" else s, c) for s, c in house.rooms
    ))  # fmt: skip
    d0, d1 = generate_layout(house, 4, catalog), generate_layout(house, 4, catalog, 1)
    counts = persistence_counts(d0, d1, catalog)
    doc = persistence(house, counts, catalog)
    book = next(e for e in doc["types"] if e["type"] == "Book")
    assert book["stay_by_style"]["office"] == 0.0
    assert book["stay_by_style"]["living_room"] == catalog.type("Book").stay
    per = {s: counts.get((s, "Book"), (0, 0, 0))[0] for s in book["stay_by_style"]}
    want = sum(per[s] * p for s, p in book["stay_by_style"].items()) / sum(per.values())
    assert book["stay"] == pytest.approx(want) and book["n"] == sum(per.values())


def test_a_day_is_the_same_from_memory_or_made_from_day_0(catalog):
    from ctxsearch.envs import rooms

    st = load_style("living_room", catalog)
    rooms._DAYS.clear()
    fresh = rooms.generate_room(st, 9, catalog, day=4)
    rooms._DAYS.clear()
    in_turn = [rooms.generate_room(st, 9, catalog, day=d) for d in range(5)]
    assert in_turn[4] == fresh
    assert rooms.generate_room(st, 9, catalog, day=2) == in_turn[2]  # earlier: from day 0 again
    assert rooms.generate_room(st, 9, catalog, day=4) == fresh
