"""bench curve and bench transfer: snapshots of one learning run, paired episodes at every k, the
learned-in x searched-in table, one-line errors, and the serial results on two workers."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest

from ctxsearch.knowledge.catalog import load_catalog
from ctxsearch.knowledge.store import EvidenceStore
from ctxsearch.scripts.cli import main

# The default scenarios' policies, named by the flags that choose them per scenario.
POLICY_FLAGS = [
    "--built-policies",
    "frontier,indirect,oracle-prior-indirect",
    "--given-policies",
    "map-only,location,oracle-prior",
]
SMALL = ["--perception", "oracle", "--budget-seconds", "20", "--truth-samples", "5", "--quiet"]
SMALL += ["--detector", "perfect"]  # the realistic detector's episode checks take longer
CURVE = ["bench", "curve", "--style", "office", "--rooms", "0,1,2", "--episodes", "3"]
TRANSFER = ["bench", "transfer", "--styles", "office,biology_lab", "--rooms", "1"]
TRANSFER += ["--episodes", "2", "--scenarios", "given", "--probe-rooms", "1"]


def _strip_timing(x):
    if isinstance(x, dict):
        return {k: _strip_timing(v) for k, v in x.items() if "wall" not in k}
    if isinstance(x, list):
        return [_strip_timing(v) for v in x]
    return x


@pytest.fixture(scope="module")
def curve_dir(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("curve")
    assert main([*CURVE, *POLICY_FLAGS, *SMALL, "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def transfer_dir(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("transfer")
    assert main([*TRANSFER, *POLICY_FLAGS, *SMALL, "--out", str(out)]) == 0
    return out


def _examinations(path: Path) -> tuple[int, set[int]]:
    with EvidenceStore.open(path, load_catalog(), read_only=True) as st:
        return st.examinations_count(), {seed for _r, _s, seed, _st in st.rooms()}


def test_snapshots_grow_and_k0_is_empty(curve_dir):
    doc = json.loads((curve_dir / "curve.json").read_text())
    assert [e["k"] for e in doc["curve"]] == [0, 1, 2]
    exams = [e["examinations"] for e in doc["curve"]]
    assert exams[0] == 0 and exams[0] < exams[1] < exams[2]
    n1, rooms1 = _examinations(curve_dir / "stores" / "k=0001.sqlite")
    n2, rooms2 = _examinations(curve_dir / "stores" / "k=0002.sqlite")
    assert (n1, n2) == (exams[1], exams[2])
    assert len(rooms1) == 1 and len(rooms2) == 2 and rooms1 < rooms2  # one run, extended
    assert not (curve_dir / "stores" / "k=0000.sqlite").exists()
    k0 = json.loads((curve_dir / "k=0000" / "given" / "search.json").read_text())
    assert k0["kb_examinations"] == 0


def test_a_snapshot_is_the_store_learn_makes_after_as_many_rooms(curve_dir, tmp_path, capsys):
    """make bench searches the houses with the curve's last snapshot instead of learning the same
    30 houses again: a snapshot after k rooms holds the intervals ``ctxsearch learn --rooms k``
    (same style, seed and perception) gives."""
    kb = tmp_path / "kb.sqlite"
    argv = ["learn", "--style", "office", "--rooms", "2", "--perception", "oracle"]
    assert main([*argv, "--kb", str(kb), "--no-progress"]) == 0
    capsys.readouterr()

    def intervals(path: Path) -> list[str]:
        assert main(["kb", "show", str(path)]) == 0
        return capsys.readouterr().out.splitlines()[1:]  # the first line names the file

    snapshot = intervals(curve_dir / "stores" / "k=0002.sqlite")
    assert len(snapshot) > 5 and snapshot == intervals(kb)


def test_episodes_are_identical_across_k_and_held_out(curve_dir):
    _, learned = _examinations(curve_dir / "stores" / "k=0002.sqlite")
    for scenario in ("built", "given"):
        lists = [
            [
                {k: e[k] for k in ("room_seed", "target", "start", "budget_s")}
                for e in json.loads(
                    (curve_dir / f"k={k:04d}" / scenario / "search.json").read_text()
                )["episode_list"]
            ]
            for k in (0, 1, 2)
        ]
        assert len(lists[0]) == 3 and lists[0] == lists[1] == lists[2]
        assert not {e["room_seed"] for e in lists[0]} & learned


def test_curve_files_and_ratios(curve_dir):
    import csv

    doc = json.loads((curve_dir / "curve.json").read_text())
    assert doc["scenarios"]["given"] == {
        "map": "given",
        "baseline": "map-only",
        "context": "location",
        "asymptote": "oracle-prior",
    }
    for e in doc["curve"]:
        for sc in ("built", "given"):
            r = e["scenarios"][sc]["context_to_baseline"]
            assert r["n"] == 3 and r["wins"] + r["losses"] + r["ties"] == 3
            assert r["ci"][0] <= r["median"] <= r["ci"][1]
            pr = e["scenarios"][sc]["paired"]
            g = pr["context_to_baseline"]
            assert g["n"] == 3 and (g["wins"], g["losses"], g["ties"]) == (
                r["wins"], r["losses"], r["ties"])  # fmt: skip
            assert g["geo_mean_ci"][0] <= g["geo_mean"] <= g["geo_mean_ci"][1]
            if e["k"] == 0:  # the context policy against itself at k = 0: all ties
                assert (pr["context_to_k0"]["ties"], pr["context_to_k0"]["geo_mean"]) == (3, 1.0)
    assert (curve_dir / "curve.md").read_text().index("geometric mean") < (
        curve_dir / "curve.md"
    ).read_text().index("cells: the median")
    # the asymptote ran once: the same at every k
    assert (
        len({json.dumps(e["scenarios"]["given"]["asymptote_to_baseline"]) for e in doc["curve"]})
        == 1
    )
    rows = list(csv.DictReader((curve_dir / "curve.csv").open()))
    assert len(rows) == 3 * 2 * 3 * 3  # k x scenario x episode x policy
    ctx = [r for r in rows if r["role"] == "context" and r["map"] == "given"]
    assert {r["measured_at_k"] for r in ctx} == {"0", "1", "2"}
    assert (curve_dir / "curve.png").stat().st_size > 10_000
    assert "| 2 |" in (curve_dir / "curve.md").read_text()


def test_a_policy_searches_the_same_alone_or_with_others(tmp_path, desk_cup_store):
    """What lets the curve run the baseline and the asymptote only once."""
    from ctxsearch.agent.search.config import SearchConfig
    from ctxsearch.agent.search.draw import remembered_draws
    from ctxsearch.scripts.experiments.bench_search import bench_search

    kb = desk_cup_store(tmp_path / "kb.sqlite", rooms=3)
    base = SearchConfig(style="office", policies=("exhaustive", "location"), episodes=3,
                        budget_s=20.0).updated({"knowledge.kb": kb, "map.scenario": "given"})  # fmt: skip
    with remembered_draws():  # the episodes are drawn once (as the curve does)
        both = bench_search(base, tmp_path / "a", progress=None, bar=False)
        alone = bench_search(
            replace(base, policies=("location",)), tmp_path / "b", progress=None, bar=False
        )

    def key(rs):  # seconds to the last bits of float sums (the world's clock runs on)
        return [(round(r.sim_time, 9), r.gazes, round(r.path_m, 9)) for r in rs]

    assert key(both.results["location"]) == key(alone.results["location"])


def test_transfer_table_is_learned_in_by_searched_in(transfer_dir):
    import csv

    doc = json.loads((transfer_dir / "transfer.json").read_text())
    styles = ["office", "biology_lab"]
    for m in ("wilson", "clustered"):
        grid = doc["paired_ratio"]["given"][m]
        assert list(grid) == styles and all(list(grid[x]) == styles for x in styles)
        assert all(grid[x][y]["n"] == 2 for x in styles for y in styles)
        stats = doc["paired"]["given"][m]
        assert all(stats[x][y]["n"] == 2 for x in styles for y in styles)
        assert all(stats[x][y]["ties"] == grid[x][y]["ties"] for x in styles for y in styles)
        cost = doc["mismatched_to_in_domain"]["given"][m]
        assert list(cost["office"]) == ["biology_lab"] and list(cost["biology_lab"]) == ["office"]
        notice = doc["noticing"][m]
        assert all(0 <= notice[x][y]["excluded_share"] <= 1 for x in styles for y in styles)
    # office's store never examined most of biology_lab's reference types: a visible mismatch
    assert (
        doc["noticing"]["wilson"]["office"]["biology_lab"]["unknown_type_share"]
        > (doc["noticing"]["wilson"]["office"]["office"]["unknown_type_share"])
    )
    for style in styles:
        n, rooms = _examinations(transfer_dir / "stores" / f"{style}.sqlite")
        assert n == doc["stores"][style]["examinations"] > 0 and len(rooms) == 1
        n, probe_rooms = _examinations(transfer_dir / "stores" / f"{style}.probe.sqlite")
        assert n == doc["stores"][style]["probe_examinations"] > 0 and not rooms & probe_rooms
    rows = list(csv.DictReader((transfer_dir / "transfer.csv").open()))
    assert len(rows) == 2 * 2 + 2 * 2 * 2 * 2  # baseline per style; context per cell x interval
    md = (transfer_dir / "transfer.md").read_text()
    assert "| learned in \\ searched in | office | biology_lab |" in md
    assert "the geometric mean over episodes" in md and " p=" in md  # it leads, as in bench search
    from ctxsearch.scripts.experiments.bench_transfer import format_tables

    old = {k: v for k, v in doc.items() if k != "paired"}  # a transfer.json from before the grid
    assert "the median over episodes" in format_tables(old)


@pytest.mark.parametrize(
    "argv, message",
    [
        ([*CURVE[:5], "3,1"], "--rooms: counts must increase strictly"),
        ([*CURVE[:5], "1,1"], "--rooms: counts must increase strictly"),
        ([*CURVE[:5], "0,-1"], "--rooms: expected an integer >= 0"),
        ([*CURVE[:5], "1,x"], "--rooms: expected an integer >= 0"),
        ([*CURVE[:5], "1.5"], "--rooms: expected an integer >= 0"),
        ([*CURVE[:5], ""], "--rooms: give at least one room count"),
        ([*CURVE[:5], "1,,2"], "--rooms: an empty count"),
        (["bench", "curve", "--style", "nowhere", "--rooms", "1"], "nowhere"),
        ([*CURVE, "--built-policies", "exhaustive,teleport,oracle"], "unknown"),
        ([*CURVE, "--given-policies", "exhaustive,location"], "give three policies"),
        ([*CURVE, "--scenarios", "moon"], "unknown scenario 'moon'"),
        ([*TRANSFER[:5], "0"], "--rooms: expected a positive integer"),
        (["bench", "transfer", "--styles", "office,nowhere", "--rooms", "1"], "nowhere"),
        (["bench", "transfer", "--styles", "office", "--rooms", "1"], "at least two styles"),
        ([*TRANSFER, "--intervals", "wilson,bayes"], "--intervals: unknown 'bayes'"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(argv, message, tmp_path, capsys):
    assert main([*argv, "--out", str(tmp_path / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("ctxsearch: error:") and "\n" not in err and message in err
    assert not (tmp_path / "out" / "stores").exists()  # nothing learned before the check


def test_an_earlier_runs_stores_are_never_overwritten(curve_dir, transfer_dir, capsys):
    before = (curve_dir / "stores" / "k=0001.sqlite").read_bytes()
    assert main([*CURVE, *POLICY_FLAGS, *SMALL, "--out", str(curve_dir)]) == 2
    assert main([*TRANSFER, *POLICY_FLAGS, *SMALL, "--out", str(transfer_dir)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all("an earlier run is in the way" in e for e in err)
    assert (curve_dir / "stores" / "k=0001.sqlite").read_bytes() == before


def test_default_scenarios_match_the_cli_copy():
    from ctxsearch.scripts.cmd_context import SCENARIO_POLICIES
    from ctxsearch.scripts.experiments.scenarios import DEFAULT_SCENARIOS

    assert {n: ",".join(s.policies) for n, s in DEFAULT_SCENARIOS.items()} == SCENARIO_POLICIES


def test_the_curve_ranks_by_the_search_s_interval_unless_told(curve_dir):
    """The curve measures the search as ``bench search`` runs it: the search configuration's
    interval (corrected; clustered for a store without views, as the oracle's) unless
    ``--interval`` names one."""
    from ctxsearch.agent.search.config import SearchConfig
    from ctxsearch.scripts.cli import build_parser

    doc = json.loads((curve_dir / "curve.json").read_text())
    assert doc["interval"] == SearchConfig().knowledge.interval == "corrected"
    args = build_parser().parse_args([*CURVE, "--out", "x", "--interval", "wilson"])
    assert args.interval == "wilson"


def test_paired_ratio_counts_wins_and_losses():
    from ctxsearch.scripts.experiments.scenarios import paired_ratio

    r = paired_ratio([1.0, 4.0, 3.0, 2.0], [2.0, 2.0, 3.0, 4.0], seed=0)
    assert r["median"] == pytest.approx(0.75) and (r["wins"], r["losses"]) == (2, 1)
    assert r["ci"] == paired_ratio([1.0, 4.0, 3.0, 2.0], [2.0, 2.0, 3.0, 4.0], seed=0)["ci"]


@pytest.mark.slow
def test_two_workers_give_the_serial_json(tmp_path, transfer_dir):
    """The transfer's learning runs and its search batches as Ray tasks: the serial files."""
    argv = [*TRANSFER, *POLICY_FLAGS, *SMALL, "--out", str(tmp_path / "t"), "--workers", "2"]
    assert main(argv) == 0
    a = json.loads((transfer_dir / "transfer.json").read_text())
    b = json.loads((tmp_path / "t" / "transfer.json").read_text())
    assert _strip_timing(a) == _strip_timing(b)
    csv_a = (transfer_dir / "transfer.csv").read_text()
    assert csv_a == (tmp_path / "t" / "transfer.csv").read_text()


def test_the_remembered_scenario_searches_toured_held_out_houses_at_every_k():
    from ctxsearch.agent.search.config import HomeSource, SearchConfig
    from ctxsearch.scripts.experiments.scenarios import DEFAULT_SCENARIOS, scenario_config

    base = SearchConfig(style="apartment")
    got = scenario_config(base, DEFAULT_SCENARIOS["remembered"])
    assert got.map.home is HomeSource.TOUR
    assert got.policies == ("uniform", "memory-location", "oracle-memory")
    assert scenario_config(base, DEFAULT_SCENARIOS["given"]).map.home is None
    mine = base.updated({"map.home": "store"})
    assert scenario_config(mine, DEFAULT_SCENARIOS["remembered"]).map.home is HomeSource.STORE


def _files(d: Path) -> dict[str, bytes]:
    return {str(p.relative_to(d)): p.read_bytes() for p in sorted(d.rglob("*"))
            if p.is_file() and p.suffix != ".sqlite" and "stores" not in p.parts}  # fmt: skip


def test_a_journalled_curve_resumes_its_snapshots_and_searches(curve_dir, tmp_path, capsys):
    """With --journal, a run stopped after the first snapshot (the later one and every file
    gone) takes the missing snapshot from the run's store, reads the searches back and writes
    the files the uninterrupted run wrote; another run's stores are refused."""
    out, journal = tmp_path / "out", tmp_path / "journal"
    argv = [*CURVE, *POLICY_FLAGS, *SMALL, "--journal", str(journal)]
    assert main([*argv, "--out", str(out)]) == 0
    whole = _files(out)
    k1 = (out / "stores" / "k=0001.sqlite").read_bytes()
    (out / "stores" / "k=0002.sqlite").unlink()
    for p in out.rglob("*"):
        if p.is_file() and "stores" not in p.parts:
            p.unlink()
    assert main([*argv, "--out", str(out)]) == 0
    assert _files(out) == whole
    assert (out / "stores" / "k=0001.sqlite").read_bytes() == k1  # kept, not taken again
    assert _examinations(out / "stores" / "k=0002.sqlite") == _examinations(
        curve_dir / "stores" / "k=0002.sqlite"
    )
    capsys.readouterr()
    assert main([*argv, "--seed", "1", "--out", str(out)]) == 2
    assert "another learning run's stores" in capsys.readouterr().err
