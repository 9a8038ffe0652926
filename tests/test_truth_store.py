"""The oracle-prior policies' ground-truth estimate kept on disk (agent.search.truth_store): a
second command reads the first's estimate, bit for bit; another input or a damaged file is a
miss, never a wrong estimate."""

from __future__ import annotations

import json

import pytest

from ctxsearch.agent.search import truth_store
from ctxsearch.agent.search.priors import truth_probabilities
from ctxsearch.envs.styles import load_style


@pytest.fixture
def counted(monkeypatch, tmp_path):
    """The cache in ``tmp_path``; how often the estimate is really made."""
    monkeypatch.setenv("CTXSEARCH_CACHE_DIR", str(tmp_path))
    made = []
    real = truth_store.ground_truth

    def counting(*args, **kwargs):
        made.append(args[1])
        return real(*args, **kwargs)

    monkeypatch.setattr(truth_store, "ground_truth", counting)
    return made


def _ps(table, catalog):
    return [
        table.p(r.name, t.name)
        for ref in catalog.types
        for r in ref.relations
        for t in catalog.types
    ]


def test_a_second_estimate_is_read_back_bit_for_bit(counted, tmp_path, catalog):
    first = truth_probabilities("office", catalog, samples=6)
    again = truth_probabilities("office", catalog, samples=6)
    assert counted == [6]  # made once
    assert _ps(first, catalog) == _ps(again, catalog)
    files = list((tmp_path / "truth").glob("*.json"))
    assert len(files) == 1
    truth_probabilities("office", catalog, samples=7)  # another input: another key
    assert counted == [6, 7]
    style = load_style("office", catalog)
    assert truth_store.truth_key(style, 6, 0, catalog) != truth_store.truth_key(
        style, 6, 1, catalog
    )


@pytest.mark.parametrize("damage", [b"", b"\x00\xff garbage", b'{"style": "office"}', None])
def test_a_damaged_or_foreign_file_is_a_miss_and_is_replaced(counted, tmp_path, catalog, damage):
    fresh = truth_probabilities("office", catalog, samples=5)
    (path,) = (tmp_path / "truth").glob("*.json")
    if damage is None:  # a valid estimate, but of other samples: not the one asked for
        doc = json.loads(path.read_text())
        doc["samples"] = 9
        path.write_text(json.dumps(doc))
    else:
        path.write_bytes(damage)
    again = truth_probabilities("office", catalog, samples=5)
    assert counted == [5, 5]
    assert _ps(fresh, catalog) == _ps(again, catalog)
    assert json.loads(path.read_text())["samples"] == 5  # replaced


def test_an_empty_cache_dir_setting_turns_the_cache_off(monkeypatch, tmp_path):
    monkeypatch.setenv("CTXSEARCH_CACHE_DIR", "")
    assert truth_store.cache_dir() is None
    monkeypatch.delenv("CTXSEARCH_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert truth_store.cache_dir() == tmp_path / "ctxsearch"


@pytest.mark.parametrize("damage", [b"[]", b'[[[0, "NoSuchType", 1]]]', b"not json"])
def test_the_room_truth_is_kept_and_read_back_as_made(monkeypatch, tmp_path, catalog, damage):
    from ctxsearch.envs.houses import resolve_style
    from ctxsearch.envs.truth import room_truth

    monkeypatch.setenv("CTXSEARCH_CACHE_DIR", str(tmp_path))
    style = resolve_style("apartment", catalog)
    fresh = room_truth(style, 3, catalog, 0)
    first = truth_store.cached_room_truth(style, 3, 0, catalog)
    (path,) = (tmp_path / "truth").glob("*.json")
    again = truth_store.cached_room_truth(style, 3, 0, catalog)  # read back
    for got in (first, again):
        assert got.same_room == fresh.same_room and got.room_share == fresh.room_share
    path.write_bytes(damage)  # a miss: made again, the file replaced
    assert truth_store.cached_room_truth(style, 3, 0, catalog).same_room == fresh.same_room
    assert json.loads(path.read_text()) != [] and len(json.loads(path.read_text())) == 3
