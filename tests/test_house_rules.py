"""House layout rules ([layout]): parsed and refused in one line, met by the generated plans of
the styles that have them, and nothing changes for the styles without them (the control style
apartment_shuffled draws the apartment's worlds of before the rules, seed for seed)."""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json

import pytest

from ctxsearch.envs.floorplan import generate_house, layout_dict
from ctxsearch.envs.house_rules import LayoutRules, layout_violations
from ctxsearch.envs.houses import HouseError, load_house, resolve_style
from ctxsearch.knowledge.catalog import load_catalog

# sha256 over layout_dict of seeds 0, 1 and 7 of each style, computed with the code before house
# styles had layout rules: the worlds of a style without rules must stay exactly these.
BEFORE_RULES = {
    "apartment": "b1f2783e630340fc226794453614bc944ca1ddfba085390d5af9d41e57658ab3",
    "family_house": "46e76ffbdbb03afa523311fe34c910387f2c85184d6c16dc7d41576b6db670c3",
    "office_floor": "93ab7b9dd3328ddb6779d97510539ac3311ac9843923389a429448a9f911b4ec",
}
RULED = ["apartment", "family_house"]


@functools.cache
def cat():
    return load_catalog()


def _digest(style, name: str) -> str:
    """The layouts of seeds 0, 1, 7 hashed under the style name ``name``."""
    h = hashlib.sha256()
    for s in (0, 1, 7):
        doc = layout_dict(generate_house(style, s, cat())) | {"style": name}
        h.update(json.dumps(doc, sort_keys=True).encode())
    return h.hexdigest()


def test_styles_without_rules_draw_the_worlds_of_before():
    assert load_house("office_floor", cat()).layout_rules is None
    assert (
        _digest(load_house("office_floor", cat()), "office_floor") == BEFORE_RULES["office_floor"]
    )
    control = load_house("apartment_shuffled", cat())
    assert control.layout_rules is None and control.seed_name == "apartment"
    assert _digest(control, "apartment") == BEFORE_RULES["apartment"]
    # A ruled style less its rules is the style of before (the generator's branch, not the data).
    family = dataclasses.replace(load_house("family_house", cat()), layout_rules=None)
    assert _digest(family, "family_house") == BEFORE_RULES["family_house"]


def test_the_control_is_the_apartment_less_its_rules():
    ruled, control = load_house("apartment", cat()), load_house("apartment_shuffled", cat())
    assert ruled.layout_rules is not None
    same = ("rooms", "total", "footprint", "height", "plan", "corridor_width", "door_width")
    assert all(getattr(ruled, f) == getattr(control, f) for f in same + ("entrance",))


def test_stock_rules():
    apt = load_house("apartment", cat()).layout_rules
    assert apt == LayoutRules(
        next_to=(("kitchen", ("living_room",)), ("office", ("living_room",))),
        only_to=(("bedroom", ("living_room",)),),
    )
    fam = load_house("family_house", cat()).layout_rules
    assert fam.must("kitchen") == ("living_room",) and fam.by_entrance == "office"
    assert fam.allowed("bedroom", "corridor") and not fam.allowed("bedroom", "living_room")


@functools.cache
def ruled_houses(name: str):
    st = load_house(name, cat())
    return st, tuple(generate_house(st, s, cat()) for s in range(30))


@pytest.mark.parametrize("name", RULED)
def test_generated_plans_meet_every_rule(name):
    st, houses = ruled_houses(name)
    for lay in houses:
        assert layout_violations(st.layout_rules, lay) == [], lay.seed
    kinds = [{r.style for r in lay.rooms} for lay in houses]
    assert sum("office" in k for k in kinds) >= 5  # the office's rule was put to the test


def test_the_control_breaks_the_rules_that_the_ruled_style_meets():
    rules = load_house("apartment", cat()).layout_rules
    control = load_house("apartment_shuffled", cat())
    broken = [bool(layout_violations(rules, generate_house(control, s, cat()))) for s in range(30)]
    assert sum(broken) >= 10  # measured: most of 200 control apartments break one


def test_a_broken_rule_is_seen():
    st, houses = ruled_houses("family_house")
    lay = houses[0]
    kitchen = next(r.index for r in lay.rooms if r.style == "kitchen")
    living = next(r.index for r in lay.rooms if r.style == "living_room")
    shut = dataclasses.replace(
        lay, doors=tuple(p for p in lay.doors if set(p.rooms) != {kitchen, living})
    )
    assert [v.split(":")[0] for v in layout_violations(st.layout_rules, shut)] == [
        "kitchen.next_to"
    ]
    # A door between a bedroom and the living room breaks the bedroom's only_to.
    bedroom = next(r.index for r in lay.rooms if r.style == "bedroom")
    extra = dataclasses.replace(lay.doors[0], rooms=(bedroom, living))
    more = dataclasses.replace(lay, doors=(extra, *lay.doors))
    assert any(v.startswith("bedroom.only_to") for v in layout_violations(st.layout_rules, more))


HEAD = '[house]\nrooms = [3, 4]\nfootprint = [60, 110]\nplan = "open"\nentrance = "living_room"\n'
ROOMS = "[rooms]\nliving_room = 1\nkitchen = 1\nbedroom = [1, 2]\noffice = [0, 1]\n"
CORRIDOR_HEAD = "[house]\nrooms = [3, 4]\nfootprint = [90, 140]\n"
BAD_RULES = [
    ("layout = 3\n" + HEAD, "", "field 'layout'"),
    (HEAD, "[layout]\n", "field 'layout'"),
    (HEAD, "[layout]\nsauna = { next_to = ['kitchen'] }\n", "layout.sauna"),
    (HEAD, "[layout]\ncorridor = { only_to = ['kitchen'] }\n", "layout.corridor"),
    (HEAD, "[layout]\nkitchen = 1\n", "layout.kitchen"),
    (HEAD, "[layout]\nkitchen = {}\n", "layout.kitchen"),
    (HEAD, "[layout]\nkitchen = { beside = ['bedroom'] }\n", "layout.kitchen.beside"),
    (HEAD, "[layout]\nkitchen = { next_to = 'living_room' }\n", "layout.kitchen.next_to"),
    (HEAD, "[layout]\nkitchen = { next_to = [] }\n", "layout.kitchen.next_to"),
    (HEAD, "[layout]\nkitchen = { next_to = [3] }\n", "layout.kitchen.next_to"),
    (HEAD, "[layout]\nkitchen = { next_to = ['sauna'] }\n", "layout.kitchen.next_to"),
    (HEAD, "[layout]\nkitchen = { next_to = ['corridor'] }\n", "layout.kitchen.next_to"),
    (HEAD, "[layout]\nkitchen = { only_to = ['bedroom', 'bedroom'] }\n", "layout.kitchen.only_to"),
    (HEAD, "[layout]\noffice = { by_entrance = 'yes' }\n", "layout.office.by_entrance"),
    # contradictions
    (HEAD, "[layout]\nkitchen = { next_to = ['office'] }\n", "layout.kitchen.next_to"),
    (HEAD, "[layout]\nkitchen = { next_to = ['kitchen'] }\n", "layout.kitchen.next_to"),
    (
        HEAD,
        "[layout]\nkitchen = { next_to = ['living_room'] }\nliving_room = { only_to = ['office'] }\n",
        "layout.kitchen.next_to",
    ),
    (
        HEAD,
        "[layout]\nkitchen = { next_to = ['living_room'], only_to = ['bedroom'] }\n",
        "layout.kitchen.next_to",
    ),
    (
        HEAD,
        "[layout]\nbedroom = { only_to = ['kitchen'] }\nkitchen = { only_to = ['living_room'] }\n",
        "layout.bedroom.only_to",
    ),
    (
        HEAD,
        "[layout]\noffice = { by_entrance = true }\nkitchen = { by_entrance = true }\n",
        "layout.kitchen.by_entrance",
    ),
    (HEAD, "[layout]\nliving_room = { by_entrance = true }\n", "layout.living_room.by_entrance"),
    (
        HEAD,
        "[layout]\noffice = { by_entrance = true, only_to = ['kitchen'] }\n",
        "layout.office.by_entrance",
    ),
    (
        CORRIDOR_HEAD,
        "[layout]\nbedroom = { only_to = ['living_room'] }\n",
        "layout.bedroom.only_to",
    ),
    (HEAD.replace('entrance = "living_room"\n', "seed_name = 3\n"), "", "house.seed_name"),
]


@pytest.mark.parametrize("head,layout,where", BAD_RULES)
def test_bad_layout_rules_give_one_line_errors(tmp_path, head, layout, where):
    p = tmp_path / "bad_rules.toml"
    p.write_text(head + ROOMS + layout)
    with pytest.raises(HouseError) as exc:
        load_house(p, cat())
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith(str(p)) and where in msg, msg
    with pytest.raises(HouseError) as exc2:
        resolve_style(p, cat())
    assert str(exc2.value) == msg


@pytest.mark.parametrize("head", [HEAD, CORRIDOR_HEAD])
def test_good_layout_rules_parse_and_generate(tmp_path, head):
    rules = "[layout]\nkitchen = { next_to = ['living_room'] }\n"
    if head == CORRIDOR_HEAD:
        rules += (
            "bedroom = { only_to = ['corridor', 'bedroom'] }\noffice = { by_entrance = true }\n"
        )
    else:
        rules += "bedroom = { only_to = ['living_room', 'bedroom'] }\n"
    p = tmp_path / "good_rules.toml"
    p.write_text(head + ROOMS + rules)
    st = load_house(p, cat())
    assert st.layout_rules is not None and st.layout_rules.must("kitchen") == ("living_room",)
    for s in range(5):
        lay = generate_house(st, s, cat())
        assert layout_violations(st.layout_rules, lay) == []
        assert layout_dict(lay) == layout_dict(generate_house(st, s, cat()))  # by seed
