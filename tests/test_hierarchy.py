"""The type hierarchy: classes validated in the catalog, evidence pooled with 'at least one'
semantics, and backoff that lets a rare type borrow from its class."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest

from ctxsearch.knowledge import intervals
from ctxsearch.knowledge.catalog import DEFAULT_CATALOG, load_catalog, parse_catalog
from ctxsearch.knowledge.errors import CatalogError
from ctxsearch.knowledge.pooling import Backoff, PooledCounts


@pytest.fixture(scope="module")
def doc():
    return tomllib.loads(DEFAULT_CATALOG.read_text())


def test_shipped_classes(catalog):
    h = catalog.hierarchy
    assert h.ancestors("Desk") == ("WorkSurface", "HorizontalSurface")
    assert set(h.members("WorkSurface")) == {"Desk", "Table", "Counter", "LabBench"}
    assert h.lift("ON-TOP-OF-DESK") == "ON-TOP-OF-WORKSURFACE"
    assert h.lift("ON-TOP-OF-WORKSURFACE") == "ON-TOP-OF-HORIZONTALSURFACE"
    assert h.lift("UNDER-WORKSURFACE") is None  # a shelf has no underside worth pooling
    assert h.members("Container") == ("Cup", "Bottle", "Beaker")


def test_classes_are_not_in_the_fingerprint(doc):
    flat = parse_catalog({k: v for k, v in doc.items() if k != "class"})
    assert flat.fingerprint == load_catalog().fingerprint
    assert not flat.hierarchy


def _with(doc, edit):
    d = {**doc, "class": [dict(c, maps=dict(c.get("maps", {}))) for c in doc["class"]]}
    edit(d["class"])
    return d


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda cs: cs[0].update(parent="Seat"), "cycle"),
        (lambda cs: cs[1].update(parent="Furniture"), "unknown class 'Furniture'"),
        (lambda cs: cs[1].update(types=["Desk", "Walkman"]), "unknown type 'Walkman'"),
        (lambda cs: cs[2].update(types=["Shelf", "Desk"]), "already in class WorkSurface"),
        (lambda cs: cs[1].update(relations=["ON-TOP-OF-DESKS"]), "must end in '-WORKSURFACE'"),
        (
            lambda cs: cs[1]["maps"].update({"ON-SOFA": "ON-TOP-OF-WORKSURFACE"}),
            "not a relation of a member",
        ),
        (
            lambda cs: cs[1]["maps"].update({"ON-TOP-OF-DESK": "BESIDE-WORKSURFACE"}),
            "not one of its relations",
        ),
        (lambda cs: cs[1].update(name="Desk"), "a type's name"),
        (lambda cs: cs[1].update(colour=1), "unknown field"),
        (lambda cs: cs.append(dict(cs[1])), "duplicate class name"),
    ],
)
def test_bad_classes_get_one_line_errors(doc, edit, message):
    with pytest.raises(CatalogError, match=message) as exc:
        parse_catalog(_with(doc, edit), "types.toml")
    assert "\n" not in str(exc.value) and str(exc.value).startswith("types.toml")


def test_pooling_counts_at_least_one_per_examination(catalog):
    pc = PooledCounts.from_examinations(
        catalog.hierarchy,
        [
            # A desk with two cups and a bottle on top, and a cup near it: one examination.
            (
                "Desk",
                [
                    ("ON-TOP-OF-DESK", "Cup"),
                    ("ON-TOP-OF-DESK", "Cup"),
                    ("ON-TOP-OF-DESK", "Bottle"),
                    ("NEAR-DESK", "Cup"),
                ],
            ),
            ("Desk", []),
            ("Table", [("ON-TOP-OF-TABLE", "Beaker")]),
            ("Sofa", [("ON-SOFA", "Remote")]),
        ],
    )
    assert pc.n["Desk"] == 2 and pc.n["WorkSurface"] == 3 and pc.n["HorizontalSurface"] == 4
    assert pc.y[("Desk", "ON-TOP-OF-DESK", "Cup")] == 1  # two cups: still one examination
    assert pc.y[("Desk", "ON-TOP-OF-DESK", "Container")] == 1  # cups and a bottle: one
    assert pc.y[("WorkSurface", "ON-TOP-OF-WORKSURFACE", "Container")] == 2
    assert pc.y[("HorizontalSurface", "ON-TOP-OF-HORIZONTALSURFACE", "Electronics")] == 1
    assert pc.via[("WorkSurface", "Table", "ON-TOP-OF-WORKSURFACE", "Beaker")] == 1
    lo, hi = pc.interval("WorkSurface", "ON-TOP-OF-WORKSURFACE", "Container", 0.1)
    assert (lo, hi) == pytest.approx(tuple(intervals.interval(2, 3, 0.1)))


def _simulate(catalog, p_by_type, n_by_type, seed=0):
    rng = np.random.default_rng(seed)
    exams = []
    for t, n in n_by_type.items():
        rel = f"ON-TOP-OF-{t.upper()}"
        for _ in range(n):
            exams.append((t, [(rel, "Cup")] if rng.random() < p_by_type[t] else []))
    return PooledCounts.from_examinations(catalog.hierarchy, exams)


def test_a_type_never_seen_borrows_its_class(catalog):
    pc = _simulate(
        catalog,
        {"Desk": 0.6, "Table": 0.5, "Counter": 0.55},
        {"Desk": 40, "Table": 30, "Counter": 30},
    )
    est = Backoff(pc).estimate("LabBench", "ON-TOP-OF-LABBENCH", "Cup")
    assert est.kappa > 0 and 0.45 < est.p_class < 0.65
    assert est.low > 0.2 and est.high < 0.9  # not [0, 1]
    # A type with plenty of evidence keeps (nearly) its own interval.
    own = Backoff(pc).estimate("Desk", "ON-TOP-OF-DESK", "Cup")
    flat = intervals.interval(pc.y[("Desk", "ON-TOP-OF-DESK", "Cup")], 40)
    assert abs(own.p - pc.y[("Desk", "ON-TOP-OF-DESK", "Cup")] / 40) < 0.05
    assert own.high - own.low <= flat[1] - flat[0] + 1e-12


def test_members_that_differ_borrow_less(catalog):
    n = {"Desk": 40, "Table": 40, "Counter": 40, "LabBench": 2}
    alike = Backoff(
        _simulate(catalog, {"Desk": 0.5, "Table": 0.5, "Counter": 0.5, "LabBench": 0.5}, n)
    )
    unlike = Backoff(
        _simulate(catalog, {"Desk": 0.05, "Table": 0.5, "Counter": 0.95, "LabBench": 0.5}, n)
    )
    assert unlike.rho("WorkSurface") > alike.rho("WorkSurface")
    k_alike = alike.estimate("LabBench", "ON-TOP-OF-LABBENCH", "Cup").kappa
    k_unlike = unlike.estimate("LabBench", "ON-TOP-OF-LABBENCH", "Cup").kappa
    assert k_unlike < k_alike


def test_an_entry_whose_members_differ_borrows_less_than_its_class_average(catalog):
    """Cups on work surfaces differ by member, pens do not: the pen entry borrows the class's
    average amount, the cup entry less (rho = max(rho_C, rho_e))."""
    rng = np.random.default_rng(3)
    rates = {
        "Desk": (0.05, 0.5),
        "Table": (0.5, 0.5),
        "Counter": (0.95, 0.5),
        "LabBench": (0.5, 0.5),
    }
    exams = []
    for t, n in {"Desk": 40, "Table": 40, "Counter": 40, "LabBench": 2}.items():
        rel = f"ON-TOP-OF-{t.upper()}"
        for _ in range(n):
            exams.append((t, [(rel, b) for b, p in zip(("Cup", "Pen"), rates[t], strict=True)
                              if rng.random() < p]))  # fmt: skip
    bo = Backoff(PooledCounts.from_examinations(catalog.hierarchy, exams))
    cup = bo.entry_rho("WorkSurface", "ON-TOP-OF-WORKSURFACE", "Cup")
    pen = bo.entry_rho("WorkSurface", "ON-TOP-OF-WORKSURFACE", "Pen")
    assert pen < bo.rho("WorkSurface") < cup  # the class's rho is their mean
    k_cup = bo.estimate("LabBench", "ON-TOP-OF-LABBENCH", "Cup").kappa
    k_pen = bo.estimate("LabBench", "ON-TOP-OF-LABBENCH", "Pen").kappa
    assert k_cup == pytest.approx(1 / cup - 1) and k_pen == pytest.approx(
        1 / bo.rho("WorkSurface") - 1
    )
    assert k_cup < k_pen


def test_backoff_beats_flat_for_rare_types(catalog):
    """Members' p drawn around a class mean (0.2 +- 0.05): with k <= 3 examinations of the rare
    member, backoff's estimate is closer to its truth than the flat Wilson centre p0."""
    rng = np.random.default_rng(5)
    err_flat, err_back = [], []
    for rep in range(150):
        ps = {
            t: float(np.clip(rng.normal(0.2, 0.05), 0, 1))
            for t in ("Desk", "Table", "Counter", "LabBench")
        }
        k = int(rng.integers(0, 4))
        pc = _simulate(
            catalog, ps, {"Desk": 30, "Table": 30, "Counter": 30, "LabBench": k}, seed=rep
        )
        y = pc.y.get(("LabBench", "ON-TOP-OF-LABBENCH", "Cup"), 0)
        err_flat.append(abs(float(intervals.p0(y, k)) - ps["LabBench"]))
        err_back.append(
            abs(Backoff(pc).estimate("LabBench", "ON-TOP-OF-LABBENCH", "Cup").p - ps["LabBench"])
        )
    assert np.mean(err_back) < 0.5 * np.mean(err_flat)


def _store_with_desks(path, catalog):
    from ctxsearch.knowledge.store import EvidenceStore

    with EvidenceStore.open(path, catalog) as s:
        for i, pairs in enumerate(
            [[("ON-TOP-OF-DESK", "Cup")], [("ON-TOP-OF-DESK", "Bottle")], []]
        ):
            s.record(
                run="r",
                style="office",
                room_seed=1,
                object_id=i,
                ref_type="Desk",
                sim_time=float(i),
                strategy="hif",
                related=[(r, t, 100 + i) for r, t in pairs],
            )


def test_kb_show_prints_classes_and_backoff(tmp_path, catalog, capsys):
    from ctxsearch.scripts.cli import main

    store = tmp_path / "kb.sqlite"
    _store_with_desks(store, catalog)
    assert main(["kb", "show", str(store), "--type", "WorkSurface"]) == 0
    out = capsys.readouterr().out
    line = next(
        ln
        for ln in out.splitlines()
        if ln.startswith("ON-TOP-OF-WORKSURFACE") and "Container" in ln
    )
    assert "2/3" in line
    assert main(["kb", "show", str(store), "--related", "Container", "--json"]) == 0
    rows = __import__("json").loads(capsys.readouterr().out)
    assert {(r["ref"], r["relation"], r["y"], r["n"]) for r in rows} >= {
        ("Desk", "ON-TOP-OF-DESK", 2, 3),
        ("WorkSurface", "ON-TOP-OF-WORKSURFACE", 2, 3),
    }
    # A table was never examined: flat it is [0, 1] (not shown), backed off it borrows.
    assert main(["kb", "show", str(store), "--type", "Table", "--backoff", "--json"]) == 0
    rows = __import__("json").loads(capsys.readouterr().out)
    cup = next(r for r in rows if r["relation"] == "ON-TOP-OF-TABLE" and r["type"] == "Container")
    assert cup["n"] == 0 and 0 < cup["low"] < cup["high"] < 1
    assert main(["kb", "show", str(store), "--type", "Furniture"]) == 2
    err = capsys.readouterr().err
    assert "unknown type or class 'Furniture'" in err and "WorkSurface" in err
