"""scripts.experiments.belief_shares: where the online search's belief holds its mass when it
decides, without changing what the search does."""

from __future__ import annotations

import math

import pytest

from ctxsearch.agent.search.config import SearchConfig
from ctxsearch.scripts.experiments.belief_shares import main, measure
from ctxsearch.scripts.experiments.bench_search import bench_search


@pytest.mark.render
def test_the_shares_are_read_at_every_decision_and_the_times_are_the_benchmarks(
    tmp_path, desk_cup_store, capsys
):
    kb = desk_cup_store(tmp_path / "kb.sqlite")
    pols = ("uniform", "location")
    config = SearchConfig(style="office", policies=pols, seed=3, budget_s=20.0, episodes=1)
    config = config.updated({"map.scenario": "given", "knowledge.kb": kb})
    rows, times = measure(config)
    bench = bench_search(config, tmp_path / "b", progress=None, bar=False)
    for p in pols:  # wrapped for reading only: the benchmark's times
        assert times[p] == [r.time_to_find for r in bench.results[p]]
    assert {r["policy"] for r in rows} == set(pols)
    for r in rows:
        assert 0.0 <= r["unexplored"] <= 1.0 + 1e-9
        assert math.isnan(r["rooms"]) and math.isnan(r["rooms_unexplored"])  # no room context
        if r["policy"] == "uniform":
            assert math.isnan(r["volumes"])  # no knowledge, no volumes
        else:
            assert 0.0 <= r["volumes"] <= 1.0 + 1e-9
    argv = ["--kb", str(kb), "--style", "office", "--map", "given", "--episodes", "0"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--episodes" in err


def test_the_room_shares_are_the_belief_in_rooms_with_a_factor_and_their_unsurveyed_part():
    from types import SimpleNamespace

    import numpy as np

    from ctxsearch.scripts.experiments.belief_shares import _shares

    w = np.array([0.1, 0.2, 0.3, 0.4])
    unseen = np.array([True, False, True, False])
    factor = np.array([2.0, 2.0, 1.0, 0.5])  # points 0, 1 and 3 in rooms with known furniture
    rooms = SimpleNamespace(factor=lambda known, built: factor)
    seen = SimpleNamespace(unseen=lambda rng: unseen)
    search = SimpleNamespace(
        builder=None,
        rooms=rooms,
        known_objects=list,
        ctx=SimpleNamespace(seen=seen, built=None, sight_cap=5.0),
    )
    vols, away, in_rooms, rooms_away = _shares(search, SimpleNamespace(weights=w))
    assert math.isnan(vols) and away == pytest.approx(0.4)
    assert in_rooms == pytest.approx(0.7) and rooms_away == pytest.approx(0.1)
    rooms.factor = lambda known, built: None  # no room with known furniture yet
    assert _shares(search, SimpleNamespace(weights=w))[2:] == (0.0, 0.0)
