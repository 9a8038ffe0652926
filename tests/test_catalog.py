"""The object-type catalog: the default loads; every bad input is a one-line CatalogError that
names the file, the type and the field."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ctxsearch.knowledge.catalog import (
    DEFAULT_CATALOG,
    load_catalog,
    parse_catalog,
    relation_suffix,
)
from ctxsearch.knowledge.errors import CatalogError, CtxsearchError

GOOD = """\
schema = 1

[[type]]
name = "Desk"
kind = "furniture"
shape = "desk"
size = [[0.6, 0.8], [1.2, 1.6], [0.72, 0.76]]
color = [0.5, 0.4, 0.2]
min_pixels = 300
max_range = 12.0
  [[type.relation]]
  name = "ON-TOP-OF-DESK"
  lo = [-0.5, -0.5, 0.5]
  hi = [0.5, 0.5, 0.5]
  margin_hi = [0.0, 0.0, 0.45]

[[type]]
name = "Cup"
kind = "object"
shape = "mug"
size = [0.08, 0.08, 0.1]
color = [0.9, 0.9, 0.9]
min_pixels = 20
max_range = 4.0
  [[type.relation]]
  name = "NEAR-CUP"
  lo = [-0.5, -0.5, -0.5]
  hi = [0.5, 0.5, 0.5]
  margin_lo = [-0.3, -0.3, 0.0]
  margin_hi = [0.3, 0.3, 0.0]
"""


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "types.toml"
    p.write_text(text)
    return p


def test_default_catalog_loads(catalog):
    assert len(catalog) >= 6
    assert {"Desk", "Table", "Chair", "Cup", "Book", "Monitor"} <= set(catalog.type_names)
    for t in catalog.types:
        assert t.name[0].isupper()
        assert all(r.name.endswith(relation_suffix(t.name)) for r in t.relations)
        assert all(r.ref == t.name for r in t.relations)
        assert min(t.size_min) > 0 and all(
            a <= b for a, b in zip(t.size_min, t.size_max, strict=True)
        )
    assert catalog.relation("ON-TOP-OF-DESK").ref == "Desk"
    assert str(DEFAULT_CATALOG).endswith("types.toml")


def test_good_catalog(tmp_path):
    cat = load_catalog(_write(tmp_path, GOOD))
    assert cat.type_names == ("Desk", "Cup")
    assert cat.type("Cup").relation_names == ("NEAR-CUP",)
    assert cat.type("Desk").is_furniture and not cat.type("Cup").is_furniture
    assert cat.type("Cup").size_min == cat.type("Cup").size_max == (0.08, 0.08, 0.1)
    lo, hi = cat.relation("ON-TOP-OF-DESK").local_bounds(np.array([0.8, 1.4, 0.74]))
    np.testing.assert_allclose(lo, [-0.4, -0.7, 0.37])
    np.testing.assert_allclose(hi, [0.4, 0.7, 0.82])
    s = cat.type("Desk").sample_size(np.random.default_rng(0))
    assert all(a <= v <= b for v, a, b in zip(s, (0.6, 1.2, 0.72), (0.8, 1.6, 0.76), strict=True))
    assert "Cup" in cat and "Mug" not in cat and cat.has_relation("NEAR-CUP")


def test_fingerprint_is_stable_and_content_sensitive(tmp_path):
    a = load_catalog(_write(tmp_path, GOOD))
    b = parse_catalog(__import__("tomllib").loads(GOOD), "elsewhere.toml")
    assert a.fingerprint == b.fingerprint  # the path is not content
    c = load_catalog(
        _write(
            tmp_path, GOOD.replace("margin_hi = [0.0, 0.0, 0.45]", "margin_hi = [0.0, 0.0, 0.5]")
        )
    )
    assert c.fingerprint != a.fingerprint


def test_unknown_names_raise(tmp_path):
    cat = load_catalog(_write(tmp_path, GOOD))
    with pytest.raises(CatalogError, match="unknown type 'Mug'.*known: Desk, Cup"):
        cat.type("Mug")
    with pytest.raises(CatalogError, match="unknown relation 'UNDER-DESK'"):
        cat.relation("UNDER-DESK")


# (case id, edit of GOOD, type named in the message or None, field named in the message or None)
BAD = [
    ("toml-syntax", lambda s: s.replace('kind = "object"', 'kind = "object'), None, None),
    (
        "unknown-field",
        lambda s: s.replace('shape = "mug"', 'shape = "mug"\nweight = 0.3'),
        "Cup",
        "weight",
    ),
    (
        "duplicate-name",
        lambda s: s.replace('name = "Cup"', 'name = "Desk"').replace("NEAR-CUP", "NEAR-DESK"),
        "Desk",
        "name",
    ),
    (
        "zero-size",
        lambda s: s.replace("size = [0.08, 0.08, 0.1]", "size = [0.08, 0.0, 0.1]"),
        "Cup",
        "size",
    ),
    ("negative-size-range", lambda s: s.replace("[0.72, 0.76]", "[-0.1, 0.76]"), "Desk", "size"),
    ("relation-suffix", lambda s: s.replace('"NEAR-CUP"', '"NEAR-MUG"'), "Cup", "relation.name"),
    (
        "relation-is-only-the-suffix",
        lambda s: s.replace('"NEAR-CUP"', '"CUP"'),
        "Cup",
        "relation.name",
    ),
    ("boolean-size", lambda s: s.replace("[0.72, 0.76]", "[true, 0.76]"), "Desk", "size"),
    ("bad-kind", lambda s: s.replace('kind = "object"', 'kind = "gadget"'), "Cup", "kind"),
    ("bad-shape", lambda s: s.replace('shape = "mug"', 'shape = "teapot"'), "Cup", "shape"),
    ("missing-field", lambda s: s.replace("min_pixels = 20\n", ""), "Cup", "min_pixels"),
    ("bad-colour", lambda s: s.replace("[0.9, 0.9, 0.9]", "[0.9, 1.9, 0.9]"), "Cup", "color"),
    (
        "bad-max-range",
        lambda s: s.replace("max_range = 4.0", "max_range = -4.0"),
        "Cup",
        "max_range",
    ),
    (
        "bad-min-pixels",
        lambda s: s.replace("min_pixels = 20", "min_pixels = 2.5"),
        "Cup",
        "min_pixels",
    ),
    ("lowercase-type", lambda s: s.replace('name = "Cup"', 'name = "cup"'), None, "name"),
    (
        "empty-volume",
        lambda s: s.replace(
            "margin_lo = [-0.3, -0.3, 0.0]", "margin_lo = [0.3, -0.3, 0.0]"
        ).replace("margin_hi = [0.3, 0.3, 0.0]", "margin_hi = [-0.3, 0.3, 0.0]"),
        "Cup",
        "relation.NEAR-CUP",
    ),
    (
        "unknown-relation-field",
        lambda s: s.replace('name = "NEAR-CUP"', 'name = "NEAR-CUP"\nshape = "x"'),
        "Cup",
        "relation",
    ),
    (
        "duplicate-relation",
        lambda s: s + '  [[type.relation]]\n  name = "NEAR-CUP"\n  lo = [0,0,0]\n  hi = [1,1,1]\n',
        "Cup",
        "relation.name",
    ),
    (
        "vector-not-3",
        lambda s: s.replace("lo = [-0.5, -0.5, 0.5]", "lo = [-0.5, 0.5]"),
        "Desk",
        "ON-TOP-OF-DESK.lo",
    ),
    ("unknown-top-level", lambda s: "colour_space = 'srgb'\n" + s, None, None),
    ("no-types", lambda s: "schema = 1\n", None, "type"),
]


@pytest.mark.parametrize("case,edit,tname,field", BAD, ids=[b[0] for b in BAD])
def test_bad_catalog_gives_one_line_error_naming_file_type_field(
    tmp_path, case, edit, tname, field
):
    text = edit(GOOD)
    assert text != GOOD, case
    path = _write(tmp_path, text)
    with pytest.raises(CatalogError) as info:
        load_catalog(path)
    msg = str(info.value)
    assert "\n" not in msg
    assert msg.startswith(str(path)), msg
    assert isinstance(info.value, CtxsearchError)
    if tname:
        assert f"type {tname}" in msg, msg
        assert info.value.type_name == tname
    if field:
        assert f"field '{field}'" in msg, msg
        assert info.value.field == field


def test_toml_syntax_error_says_where(tmp_path):
    path = _write(tmp_path, GOOD.replace('kind = "object"', 'kind = "object'))
    with pytest.raises(CatalogError, match=r"TOML syntax error.*line \d+"):
        load_catalog(path)


def test_missing_catalog_file(tmp_path):
    with pytest.raises(CatalogError, match="no such file"):
        load_catalog(tmp_path / "nope.toml")
