"""Ground truth: JSON schema, the estimator's arithmetic, and styles that differ as they should."""

from __future__ import annotations

import argparse
import functools
import json
import math

from ctxsearch.envs.rooms import generate_room
from ctxsearch.envs.styles import load_style
from ctxsearch.envs.truth import estimate, ground_truth, lookup, room_counts
from ctxsearch.knowledge.catalog import load_catalog
from ctxsearch.knowledge.geometry import ObjectInstance, related
from ctxsearch.scripts import cmd_truth


@functools.cache
def catalog():
    return load_catalog()


@functools.cache
def truth(style: str, samples: int = 40):
    return ground_truth(style, samples, 0, catalog())


def test_cli_writes_schema(tmp_path, capsys):
    parser = argparse.ArgumentParser()
    cmd_truth.register(parser.add_subparsers())
    out = tmp_path / "t.json"
    args = parser.parse_args(
        ["truth", "--style", "kitchen", "--samples", "5", "--out", str(out), "--seed", "3"]
    )
    assert args.func(args) == 0
    doc = json.loads(out.read_text())
    assert doc["style"] == "kitchen" and doc["samples"] == 5
    assert doc["entries"]
    for e in doc["entries"]:
        assert {"ref", "relation", "type", "p", "se", "n"} <= set(e)
        assert e["n"] > 0 and 0.0 <= e["p"] <= 1.0 and e["se"] >= 0
        assert catalog().relation(e["relation"]).ref == e["ref"]
        assert math.isclose(e["se"], math.sqrt(e["p"] * (1 - e["p"]) / e["n"]))
    assert any(e["p"] == 0 for e in doc["entries"])
    assert "kitchen: 5 rooms" in capsys.readouterr().out


def test_deterministic_and_matches_direct_count():
    a = ground_truth("office", 6, 11, catalog())
    assert a == ground_truth("office", 6, 11, catalog())
    st = load_style("office", catalog())
    layouts = [generate_room(st, s, catalog()) for s in range(11, 17)]
    desks = [(lay, d) for lay in layouts for d in lay.of_type("Desk")]
    y = sum(
        any(
            rel == "ON-TOP-OF-DESK" and o.type == "Monitor"
            for rel, o in related(catalog(), d, lay.objects)
        )
        for lay, d in desks
    )
    e = lookup(a, "Desk", "ON-TOP-OF-DESK", "Monitor")
    assert e["n"] == len(desks) and e["y"] == y


def test_counts_at_least_one_per_instance():
    cat = catalog()
    desk = ObjectInstance("Desk", 1, (0.0, 0.0, 0.37), 0.0, (0.7, 1.4, 0.74))
    pens = [
        ObjectInstance("Pen", i, (0.1 * i - 0.3, 0.0, 0.747), 0.0, (0.14, 0.014, 0.014))
        for i in (2, 3, 4)
    ]

    class Lay:
        objects = (desk, *pens)

    n, y = room_counts(Lay, cat)
    assert n == {"Desk": 1, "Pen": 3}
    assert y[("Desk", "ON-TOP-OF-DESK", "Pen")] == 1  # three pens, one desk: one success
    entries = estimate([(n, y), ({"Desk": 1}, {})], cat)
    e = next(e for e in entries if (e["relation"], e["type"]) == ("ON-TOP-OF-DESK", "Pen"))
    assert e["n"] == 2 and e["p"] == 0.5 and math.isclose(e["se"], 0.5 / math.sqrt(2))
    assert math.isclose(e["se_room"], math.sqrt(2 * (0.5**2 + 0.5**2)) / 2)


def test_office_workstations_likelier_than_in_biology_lab():
    office = lookup(truth("office"), "Desk", "ON-TOP-OF-DESK", "Monitor")
    lab = lookup(truth("biology_lab"), "Desk", "ON-TOP-OF-DESK", "Monitor")
    assert office["p"] > lab["p"] + 2 * math.hypot(office["se"], lab["se"])
    micro = lookup(truth("biology_lab"), "LabBench", "ON-TOP-OF-LABBENCH", "Microscope")
    assert micro["p"] > 0.5
    assert lookup(truth("office"), "Desk", "ON-TOP-OF-DESK", "Microscope")["p"] == 0.0
