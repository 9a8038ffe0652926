"""``ctxsearch kb show|stats|merge`` and ``ctxsearch bench kb`` through the CLI entry point."""

from __future__ import annotations

import csv
import hashlib
import json
import sqlite3
from pathlib import Path

import numpy as np
import pytest

from ctxsearch.knowledge import intervals
from ctxsearch.knowledge.store import EvidenceStore
from ctxsearch.scripts.cli import main


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def rel(catalog, ref: str, prefix: str) -> str:
    return next(r for r in catalog.type(ref).relation_names if r.startswith(prefix))


def make_store(path: Path, catalog, run: str = "r1") -> Path:
    """Desk examined 4 times (Cup on top in 3, Chair near in 1); Cup examined once."""
    on, near = rel(catalog, "Desk", "ON-TOP-OF"), rel(catalog, "Desk", "NEAR")
    exams = [
        ("Desk", [(on, "Cup", 10), (on, "Cup", 11)]),
        ("Desk", [(on, "Cup", 12), (near, "Chair", 13)]),
        ("Desk", [(on, "Cup", 14)]),
        ("Desk", []),
        ("Cup", []),
    ]
    with EvidenceStore.open(path, catalog) as s:
        s.mark_room(run, "office", 1, "started")
        for i, (ref, related) in enumerate(exams):
            s.record(
                run=run,
                style="office",
                room_seed=1,
                object_id=i,
                ref_type=ref,
                sim_time=i,
                strategy="hif",
                related=related,
            )
        s.mark_room(run, "office", 1, "done")
    return path


@pytest.fixture
def store(tmp_path, catalog) -> Path:
    return make_store(tmp_path / "kb.sqlite", catalog)


def run_cli(capsys, *argv) -> tuple[int, str, str]:
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def n_pairs(catalog, refs=None) -> int:
    refs = refs or catalog.type_names
    return sum(len(catalog.type(a).relations) for a in refs) * len(catalog)


def test_show_prints_nonzero_rows_sorted(capsys, store, catalog):
    rc, out, err = run_cli(capsys, "kb", "show", store)
    assert rc == 0 and err == ""
    lines = out.splitlines()
    assert lines[0].startswith(f"{store}: 5 examinations, alpha 0.1, catalog {catalog.fingerprint}")
    assert lines[1].split() == ["relation", "type", "y/n", "low", "high"]
    on, near = rel(catalog, "Desk", "ON-TOP-OF"), rel(catalog, "Desk", "NEAR")
    body = [ln.split() for ln in lines[2:-1]]
    assert [b[:3] for b in body] == [[on, "Cup", "3/4"], [near, "Chair", "1/4"]]
    lo, hi = intervals.interval(3, 4)
    assert body[0][3:] == [f"{lo:.3f}", f"{hi:.3f}"]
    assert lines[-1] == f"({n_pairs(catalog) - 2} rows with y = 0 hidden; --all shows them)"


def test_show_all_type_related_alpha(capsys, store, catalog):
    rc, out, _ = run_cli(capsys, "kb", "show", store, "--all")
    assert rc == 0
    assert len(out.splitlines()) == 2 + n_pairs(catalog)
    assert "hidden" not in out
    rc, out, _ = run_cli(capsys, "kb", "show", store, "--type", "Desk", "--all")
    rows = out.splitlines()[2:]
    assert len(rows) == n_pairs(catalog, ["Desk"])
    assert all(r.split()[0].endswith("-DESK") for r in rows)
    lows = [float(r.split()[3]) for r in rows]
    assert lows == sorted(lows, reverse=True)
    rc, out, _ = run_cli(capsys, "kb", "show", store, "--related", "Chair")
    assert [ln.split()[:2] for ln in out.splitlines()[2:-1]] == [
        [rel(catalog, "Desk", "NEAR"), "Chair"]
    ]
    rc, out, _ = run_cli(capsys, "kb", "show", store, "--alpha", "0.05")
    lo, _ = intervals.interval(3, 4, 0.05)
    assert out.splitlines()[2].split()[3] == f"{lo:.3f}" and "alpha 0.05" in out
    rc, out, _ = run_cli(capsys, "kb", "show", store, "--type", "Cup")
    assert "no observed pairs for type Cup" in out


def test_show_json(capsys, store, catalog):
    rc, out, _ = run_cli(capsys, "kb", "show", store, "--json")
    rows = json.loads(out)
    assert rc == 0 and len(rows) == 2
    assert set(rows[0]) == {"ref", "relation", "type", "y", "n", "p0", "low", "high"}
    assert rows[0]["ref"] == "Desk" and rows[0]["y"] == 3 and rows[0]["n"] == 4
    assert rows[0]["low"] >= rows[1]["low"]
    rc, out, _ = run_cli(capsys, "kb", "show", store, "--json", "--all", "--type", "Cup")
    rows = json.loads(out)
    assert len(rows) == n_pairs(catalog, ["Cup"]) and all(r["n"] == 1 and r["y"] == 0 for r in rows)


def test_show_empty_store(capsys, tmp_path, catalog):
    path = tmp_path / "empty.sqlite"
    EvidenceStore.open(path, catalog).close()
    rc, out, _ = run_cli(capsys, "kb", "show", path)
    assert rc == 0 and "no examinations yet" in out


def test_stats(capsys, store, catalog):
    rc, out, _ = run_cli(capsys, "kb", "stats", store)
    assert rc == 0
    assert "examinations      5 (runs: r1 (5))" in out
    assert f"types examined    2 of {len(catalog)}: Desk 4, Cup 1" in out
    assert "1 done, 0 started" in out
    rc, out, _ = run_cli(capsys, "kb", "stats", store, "--json")
    st = json.loads(out)
    assert st["examinations"] == 5 and st["pairs_observed"] == 2 and st["types_examined"] == 2
    assert 0 < st["mean_width"] < 1


def test_merge(capsys, tmp_path, catalog, store):
    other = make_store(tmp_path / "b.sqlite", catalog, run="r2")
    out_path = tmp_path / "all.sqlite"
    rc, out, err = run_cli(capsys, "kb", "merge", out_path, store, other)
    assert rc == 0 and err == ""
    assert (
        out.strip()
        == f"merged 10 examinations from 2 store(s) into {out_path} (now 10 examinations)"
    )
    rc, out, _ = run_cli(capsys, "kb", "show", out_path, "--json")
    assert json.loads(out)[0]["y"] == 6 and json.loads(out)[0]["n"] == 8


@pytest.mark.parametrize(
    "argv",
    [
        ["kb", "show", "--type", "Mug"],
        ["kb", "show", "--related", "Mug"],
        ["kb", "show", "--catalog", "/no/such/types.toml"],
    ],
)
def test_bad_arguments_one_line(capsys, store, argv):
    rc, out, err = run_cli(capsys, *argv[:2], store, *argv[2:])
    assert rc == 2 and out == ""
    assert err.count("\n") == 1 and err.startswith("ctxsearch: error: "), err


def _random_bytes(path: Path, catalog, other_catalog) -> None:
    path.write_bytes(np.random.default_rng(3).bytes(4096))


def _foreign_db(path: Path, catalog, other_catalog) -> None:
    conn = sqlite3.connect(path)
    conn.execute("CREATE TABLE examinations (id INTEGER PRIMARY KEY, what TEXT)")
    conn.execute("INSERT INTO examinations (what) VALUES ('dentist')")
    conn.commit()
    conn.close()


def _other_catalog_store(path: Path, catalog, other_catalog) -> None:
    with EvidenceStore.open(path, other_catalog) as s:
        s.record(
            run="r",
            style="office",
            room_seed=1,
            object_id=1,
            ref_type="Crate",
            sim_time=0,
            strategy="hif",
            related=[("ON-TOP-OF-CRATE", "Cup", 2)],
        )


@pytest.mark.parametrize(
    "maker",
    [_random_bytes, _foreign_db, _other_catalog_store],
    ids=["random-bytes", "foreign-sqlite", "other-catalog"],
)
@pytest.mark.parametrize("command", ["show", "stats", "merge-in", "merge-out"])
def test_bad_store_exits_2_with_one_line_and_leaves_file_untouched(
    capsys, tmp_path, catalog, other_catalog, store, maker, command
):
    bad = tmp_path / "bad.sqlite"
    maker(bad, catalog, other_catalog)
    before = digest(bad)
    files_before = sorted(p.name for p in tmp_path.iterdir())
    argv = {
        "show": ["kb", "show", bad],
        "stats": ["kb", "stats", bad],
        "merge-in": ["kb", "merge", tmp_path / "out.sqlite", store, bad],
        "merge-out": ["kb", "merge", bad, store],
    }[command]
    rc, out, err = run_cli(capsys, *argv)
    assert rc == 2, (out, err)
    assert out == ""
    assert err.count("\n") == 1 and err.startswith(f"ctxsearch: error: {bad}: "), err
    if maker is _other_catalog_store:
        assert other_catalog.fingerprint in err and catalog.fingerprint in err
    else:
        assert "not a ctxsearch knowledge store" in err
    assert digest(bad) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == files_before  # no out.sqlite, no -wal/-shm


def test_missing_store(capsys, tmp_path):
    rc, out, err = run_cli(capsys, "kb", "show", tmp_path / "nope.sqlite")
    assert (
        rc == 2
        and err.strip() == f"ctxsearch: error: {tmp_path / 'nope.sqlite'}: no such knowledge store"
    )
    assert not (tmp_path / "nope.sqlite").exists()


def test_bench_kb_bounds_the_related_types_per_relation(capsys, tmp_path):
    """--related K: at most K related types per type and relation (1% of T below it)."""
    rc, _, err = run_cli(
        capsys, "bench", "kb", "--sizes", "500", "--reps", "1", "--related", "2", "--out", tmp_path
    )
    assert rc == 0, err
    (row,) = json.loads((tmp_path / "bench_kb.json").read_text())
    assert row["nonzero"] == 500 * 6 * 2 and row["max_related"] == 2  # 1% of 500 would be 5


def test_bench_kb_tiny(capsys, tmp_path):
    rc, out, err = run_cli(
        capsys, "bench", "kb", "--sizes", "50,100", "--reps", "3", "--out", tmp_path
    )
    assert rc == 0, err
    rows = json.loads((tmp_path / "bench_kb.json").read_text())
    assert [r["types"] for r in rows] == [50, 100]
    for r in rows:
        assert {"types", "choose_ms", "record_ms", "peak_mb", "dense_choose_ms"} <= set(r)
        assert r["choose_ms"] > 0 and r["record_ms"] > 0 and r["peak_mb"] > 0
        assert r["dense_choose_ms"] > 0  # T <= 1000: the dense comparison runs
        per_relation = min(max(1, round(0.01 * r["types"])), 100)  # 1% of T, at most --related
        assert r["nonzero"] == r["types"] * 6 * per_relation and r["max_related"] == 100
    assert (tmp_path / "bench_kb.md").read_text().count("\n| ") >= 3
    assert (tmp_path / "bench_kb.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "| types |" in out and "bench_kb.json" in out
    with (tmp_path / "bench_kb.csv").open(newline="") as f:
        table = list(csv.DictReader(f))
    assert [int(r["types"]) for r in table] == [50, 100]
    assert [float(r["choose_ms"]) for r in table] == [r["choose_ms"] for r in rows]
    assert all(r["dense_ratio"] != "" for r in table)


def test_bench_dense_and_sparse_agree():
    from ctxsearch.knowledge.base import KnowledgeBase
    from ctxsearch.scripts.experiments.bench_kb import DenseKB, fill_random, synthetic_catalog

    cat = synthetic_catalog(60)
    kb = KnowledgeBase(cat)
    fill_random(kb, 0.05, np.random.default_rng(0))
    dense = DenseKB.from_kb(kb)
    for a, name in enumerate(cat.type_names):
        assert dense.type_impact(a) == pytest.approx(kb.type_impact(name), abs=1e-12)
    cands = list(range(0, 60, 3))
    assert cat.type_names[dense.choose(cands)] == kb.choose([cat.type_names[a] for a in cands])


def test_bad_bench_sizes(capsys):
    with pytest.raises(SystemExit) as info:
        main(["bench", "kb", "--sizes", "ten"])
    assert info.value.code == 2
    assert "comma-separated" in capsys.readouterr().err


def test_bench_kb_without_out_writes_nothing(capsys, tmp_path, monkeypatch):
    """A benchmark without --out writes nothing tracked (it once wrote results/ by default)."""
    monkeypatch.chdir(tmp_path)
    rc, out, err = run_cli(capsys, "bench", "kb", "--sizes", "50", "--reps", "1")
    assert rc == 0, err
    assert "| types |" in out and "no files written" in out
    assert list(tmp_path.iterdir()) == []
