"""Room styles: the shipped ones load; bad files give one-line errors naming file and field."""

from __future__ import annotations

import pytest

from ctxsearch.envs.styles import StyleError, available_styles, load_style
from ctxsearch.knowledge.catalog import load_catalog
from ctxsearch.knowledge.errors import CtxsearchError

GOOD = """
name = "tiny"
[room]
width = [5.0, 6.0]
depth = [4.5, 5.0]
height = 2.7
door_width = 0.9
[furniture]
Desk = [1, 2]
Shelf = 1
[[rule]]
ref = "Desk"
relation = "ON-TOP-OF-DESK"
type = "Monitor"
p = 0.5
count = [1, 2]
[clutter]
Pen = [0, 2]
"""


def write(tmp_path, text, name="style.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_shipped_styles_load():
    names = available_styles()
    assert {"office", "biology_lab", "living_room", "kitchen"} <= set(names)
    cat = load_catalog()
    for n in names:
        st = load_style(n, cat)
        assert st.name == n and st.furniture and st.rules
        assert all(cat.relation(r.relation).ref == r.ref for r in st.rules)


def test_bare_name_and_path_agree(tmp_path):
    path = write(tmp_path, GOOD)
    st = load_style(path)
    assert st.name == "tiny" and st.width == (5.0, 6.0) and st.height == (2.7, 2.7)
    assert st.furniture == (("Desk", (1, 2)), ("Shelf", (1, 1)))
    assert st.rules[0].count == (1, 2) and st.rules[0].on == "auto"
    assert load_style("office") == load_style(load_style("office").path)


@pytest.mark.parametrize(
    "old,new,field",
    [
        ("Desk = [1, 2]", "Dsek = [1, 2]", "furniture.Dsek"),
        ("Desk = [1, 2]", "Desk = [2, 1]", "furniture.Desk"),
        ("Desk = [1, 2]", "Desk = [1, 2]\nPen = 1", "furniture.Pen"),
        ('relation = "ON-TOP-OF-DESK"', 'relation = "ON-TOP-OF-DESKK"', "rule[0].relation"),
        ('relation = "ON-TOP-OF-DESK"', 'relation = "ON-SHELF"', "rule[0].relation"),
        ('type = "Monitor"', 'type = "Monitr"', "rule[0].type"),
        (
            'ref = "Desk"\nrelation = "ON-TOP-OF-DESK"',
            'ref = "Sofa"\nrelation = "ON-SOFA"',
            "rule[0].ref",
        ),
        ("p = 0.5", "p = 1.5", "rule[0].p"),
        ("p = 0.5", "p = -0.1", "rule[0].p"),
        ("p = 0.5", 'p = "high"', "rule[0].p"),
        ("count = [1, 2]", "count = [2, 1]", "rule[0].count"),
        ("count = [1, 2]", "count = [-1, 2]", "rule[0].count"),
        ("count = [1, 2]", "count = 1.5", "rule[0].count"),
        ("count = [1, 2]", 'on = "ceiling"', "rule[0].on"),
        ("count = [1, 2]", "cnt = 2", "rule[0].cnt"),
        ("height = 2.7", "height = 2.7\ncolour = 1", "room.colour"),
        ('name = "tiny"', 'name = "tiny"\nlights = 3', "lights"),
        ("Pen = [0, 2]", "Pen = [0, 2]\nDesk = 1", "clutter.Desk"),
        ("Pen = [0, 2]", "Pan = [0, 2]", "clutter.Pan"),
        ("width = [5.0, 6.0]", "width = [1.0, 6.0]", "room.width"),
        ("door_width = 0.9", "door_width = 4.4", "room.door_width"),
        ("Desk = [1, 2]", "Desk = [12, 14]", "furniture"),
    ],
)
def test_bad_style_one_line_error(tmp_path, old, new, field):
    assert old in GOOD
    path = write(tmp_path, GOOD.replace(old, new, 1))
    with pytest.raises(StyleError) as exc:
        load_style(path)
    msg = str(exc.value)
    assert isinstance(exc.value, CtxsearchError)
    assert "\n" not in msg
    assert str(path) in msg
    assert f"field '{field}'" in msg, msg


def test_room_too_small(tmp_path):
    text = GOOD.replace("width = [5.0, 6.0]", "width = [2.5, 3.0]").replace(
        "depth = [4.5, 5.0]", "depth = 2.5"
    )
    with pytest.raises(StyleError, match="room too small|does not fit"):
        load_style(write(tmp_path, text))


def test_missing_and_broken_files(tmp_path):
    with pytest.raises(StyleError, match="no such style file.*available: .*office"):
        load_style("no_such_style")
    with pytest.raises(StyleError, match="TOML syntax error"):
        load_style(write(tmp_path, "name = \n"))
