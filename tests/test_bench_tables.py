"""``bench intervals`` writes its per-seed rows as CSV beside the JSON (the JSON's cells are
their medians)."""

from __future__ import annotations

import csv
import json
import statistics

import pytest

pytestmark = pytest.mark.render


def _rows(path) -> list[dict]:
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


def test_bench_intervals_writes_per_seed_csv(tmp_path):
    from ctxsearch.scripts.cli import main

    out = tmp_path / "iv"
    args = ["bench", "intervals", "--styles", "office", "--rooms", "1", "--seeds", "2"]
    assert main([*args, "--settings", "perfect", "--truth-samples", "10", "--out", str(out)]) == 0
    doc = json.loads((out / "intervals.json").read_text())
    runs = _rows(out / "intervals.csv")
    assert [(r["style"], r["detector"], r["seed"], r["rooms"]) for r in runs] == [
        ("office", "perfect", "0", "1"),
        ("office", "perfect", "1", "1"),
    ]
    row = doc["rows"][0]
    for key in ("examinations", "clustered_mean_width", "wilson_coverage_informative"):
        assert statistics.median(float(r[key]) for r in runs) == pytest.approx(row[key])
    bias = _rows(out / "intervals_bias.csv")
    assert {r["seed"] for r in bias} == {"0", "1"}
    for ref, median in row["bias_by_type"].items():
        vals = [float(r["bias"]) for r in bias if r["ref_type"] == ref]
        assert statistics.median(vals) == pytest.approx(median)


def test_bench_intervals_default_settings_match_the_cli_copy():
    from ctxsearch.scripts.cmd_learn import INTERVAL_SETTINGS
    from ctxsearch.scripts.experiments.bench_intervals import DEFAULT_SETTINGS, SETTINGS

    assert ",".join(DEFAULT_SETTINGS) == INTERVAL_SETTINGS
    assert set(DEFAULT_SETTINGS) <= {s[0] for s in SETTINGS}
