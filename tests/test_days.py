"""A world that changes: days in the generator, schema 4's day stamps, drift schedules,
forgetting read from the log, learn --days and re-examination."""

from __future__ import annotations

import hashlib
import json
import sqlite3
from pathlib import Path

import numpy as np
import pytest

from ctxsearch.agent.learning import LearnConfig, learn
from ctxsearch.envs.floorplan import generate_layout, layout_dict
from ctxsearch.envs.houses import resolve_style
from ctxsearch.envs.styles import Drift, StyleError, load_style, parse_style
from ctxsearch.envs.truth import ground_truth, lookup
from ctxsearch.knowledge.drift import DayEvidence, ForgetKnowledgeBase, Forgetting, evidence_of
from ctxsearch.knowledge.errors import StoreError
from ctxsearch.knowledge.store import EXAM_KEY, SCHEMA_VERSION, EvidenceStore, NewExamination
from ctxsearch.scripts.cli import main
from tests.old_stores import as_version

# sha256 of the layouts of office, kitchen and apartment seeds 0, 1, 7 as the code before days
# generated them (computed with that code): day 0 must stay exactly that. The apartment of then is
# today's apartment_shuffled (the apartment without its layout rules, on its random stream), its
# layouts hashed under the name they had.
BEFORE_DAYS = "59c6211170b27d290c45141b52a9e43f0ee56391496fbf760b0f9fdf2cdde47a"
LAPTOP = "Desk/ON-TOP-OF-DESK/Laptop"


def _digest(catalog, day: int | None) -> str:
    h = hashlib.sha256()
    for name in ("office", "kitchen", "apartment_shuffled"):
        st = resolve_style(name, catalog)
        for s in (0, 1, 7):
            layout = (
                generate_layout(st, s, catalog)
                if day is None
                else generate_layout(st, s, catalog, day)
            )
            doc = layout_dict(layout) | {"style": name.removesuffix("_shuffled")}
            h.update(json.dumps(doc, sort_keys=True).encode())
    return h.hexdigest()


def test_day_0_is_the_layout_of_before_days(catalog):
    assert _digest(catalog, None) == BEFORE_DAYS
    assert _digest(catalog, 0) == BEFORE_DAYS


@pytest.mark.parametrize("name", ["office", "apartment"])
def test_furniture_stays_small_objects_move(catalog, name):
    """Offices place their small objects anew every day ([stay] "*" = 0); an apartment's rooms
    keep some of theirs (tests/test_persistence.py), but not all of them."""
    st = resolve_style(name, catalog)

    def split(layout):
        fur = [(o.id, o.type, o.position, o.yaw) for o in layout.objects
               if catalog.type(o.type).is_furniture]  # fmt: skip
        small = [(o.type, o.position) for o in layout.objects
                 if not catalog.type(o.type).is_furniture]  # fmt: skip
        return fur, small

    d0, d1, d2 = (generate_layout(st, 3, catalog, d) for d in (0, 1, 2))
    assert split(d0)[0] == split(d1)[0] == split(d2)[0]  # same furniture, ids and poses
    assert split(d0)[1] != split(d1)[1] and split(d1)[1] != split(d2)[1]
    assert (d0.width, d0.depth, d0.door) == (d1.width, d1.depth, d1.door)
    for layout in (d1, d2):  # unique ids; small objects fill the smallest free ones
        ids = sorted(o.id for o in layout.objects)
        assert len(set(ids)) == len(ids) and ids[0] == 1
        assert ids[-1] <= max(len(d0.objects), len(layout.objects))
    assert generate_layout(st, 3, catalog, 1) == d1  # a day is reproducible


def _drift_style(catalog, tmp_path: Path, drift: str) -> Path:
    """The office with ``drift`` and its small objects placed anew every day (the rules' drift
    alone)."""
    text = Path(load_style("office", catalog).path).read_text() + '\n[stay]\n"*" = 0.0\n' + drift
    path = tmp_path / "office_drift.toml"
    path.write_text(text)
    return path


def test_a_drift_schedule_changes_the_truth_from_its_day_on(catalog, tmp_path):
    path = _drift_style(
        catalog, tmp_path, f'\n[[drift]]\nrule = "{LAPTOP}"\np = 1.0\nfrom_day = 2\n'
    )
    st = load_style(path, catalog)
    assert st.drift == (Drift(LAPTOP, 1.0, 2),)
    assert st.on_day(1) is st and st.on_day(0) is st
    p = {
        day: lookup(ground_truth(st, 12, 0, catalog, day=day), "Desk", "ON-TOP-OF-DESK", "Laptop")[
            "p"
        ]
        for day in (0, 2)
    }
    assert p[0] < 0.5 and p[2] > 0.8  # p = 1 where a laptop fits
    base = load_style("office", catalog)
    assert generate_layout(st, 5, catalog) == generate_layout(base, 5, catalog)  # day 0


@pytest.mark.parametrize(
    ("drift", "field", "message"),
    [
        (
            'rule = "Desk/ON-TOP-OF-DESK/Bed"\np = 0.5\nfrom_day = 3',
            "drift[0].rule",
            "no placement rule",
        ),
        (
            'rule = "Desk/IN-FRONT-OF-DESK/Chair"\np = 0.5\nfrom_day = 3',
            "drift[0].rule",
            "furniture",
        ),
        (f'rule = "{LAPTOP}"\np = 1.5\nfrom_day = 3', "drift[0].p", "probability"),
        (f'rule = "{LAPTOP}"\np = 0.5\nfrom_day = 0', "drift[0].from_day", "integer day"),
        (f'rule = "{LAPTOP}"\np = 0.5', "drift[0].from_day", "missing"),
        (f'rule = "{LAPTOP}"\np = 0.5\nfrom_day = 2\nwhen = 1', "drift[0].when", "unknown"),
    ],
)
def test_drift_schedule_errors_name_the_file_and_field(
    catalog, tmp_path, capsys, drift, field, message
):
    path = _drift_style(catalog, tmp_path, f"\n[[drift]]\n{drift}\n")
    with pytest.raises(StyleError, match=message) as err:
        load_style(path, catalog)
    assert err.value.field == field and str(path) in str(err.value)
    assert (
        main(["room", "--style", str(path), "--seed", "1", "--out", str(tmp_path / "r.png")]) == 2
    )
    out = capsys.readouterr().err.strip()
    assert out.startswith("ctxsearch: error: ") and f"field '{field}'" in out and "\n" not in out


def test_drift_must_be_a_list_of_tables(catalog, tmp_path):
    doc = {"room": {"width": 6.0, "depth": 5.0}, "furniture": {"Desk": 2}, "drift": {"p": 1}}
    with pytest.raises(StyleError, match="array of tables"):
        parse_style(doc, tmp_path / "x.toml", catalog)


# ---- the store: schema 4 (day stamps; schema 5 adds views, tests/test_corrected.py) ----------------------------------------------------------------------
def _exam(store, oid: int, day: int = 0, related=(("ON-TOP-OF-DESK", "Cup", 9),), run="r1"):
    return store.append(
        NewExamination(run, "office", 1, oid, "Desk", 10.0 * oid, "hif", tuple(related), day)
    )


def test_a_desk_examined_yesterday_is_a_new_trial_today_and_still_counts_once(catalog, tmp_path):
    assert EXAM_KEY[-2:] == ("day", "object_id") and SCHEMA_VERSION >= 4
    with EvidenceStore.open(tmp_path / "s.sqlite", catalog) as s:
        _exam(s, 1, day=0)
        _exam(s, 1, day=1)  # the same desk, the next day
        with pytest.raises(StoreError, match="already examined in run 'r1' on day 1"):
            _exam(s, 1, day=1)
        assert s.examinations_count() == 2
        assert [e.day for e in s.examinations()] == [0, 1]
        assert s.knowledge_base().n("Desk") == 2
        assert s.examined_before("r1", "office", 1, 1) == {1}
        assert s.examined_before("r1", "office", 1, 0) == set()
        s.mark_room("r1", "office", 1, "done", end_time=5.0, day=0)
        s.mark_room("r1", "office", 1, "started", day=1)
        assert s.room_status("r1", "office", 1, 1) == "started"
        assert s.room_end_time("r1", "office", 1, 0) == 5.0
        assert s.rooms() == [("r1", "office", 1, "started")]  # not every visit done
        assert s.visits() == [("r1", "office", 1, 0, "done"), ("r1", "office", 1, 1, "started")]


def _v3_store(path: Path, catalog) -> Path:
    with EvidenceStore.open(path, catalog) as s:
        for oid in range(1, 6):
            _exam(s, oid, related=[("ON-TOP-OF-DESK", "Cup", 20 + oid), ("NEAR-DESK", "Chair", 30)])
        s.mark_room("r1", "office", 1, "done", end_time=55.0)
    as_version(path, 3)  # now exactly as ctxsearch with schema 3 wrote it
    return path


def _file_digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_a_schema_3_store_is_read_as_day_0_and_migrated_keeping_every_row(catalog, tmp_path):
    path = _v3_store(tmp_path / "v3.sqlite", catalog)
    before = _file_digest(path)
    conn = sqlite3.connect(path)
    cols = [r[1] for r in conn.execute("PRAGMA table_info(examinations)")]
    rows3 = conn.execute("SELECT id, object_id, type, sim_time FROM examinations").fetchall()
    obs3 = conn.execute("SELECT * FROM observations ORDER BY rowid").fetchall()
    conn.close()
    assert "day" not in cols and len(rows3) == 5 and len(obs3) == 10
    with EvidenceStore.open(path, catalog, read_only=True) as s:  # kb show: no migration
        assert s.version == 3 and [e.day for e in s.examinations()] == [0] * 5
        assert s.visits() == [("r1", "office", 1, 0, "done")]
        assert s.room_status("r1", "office", 1, 1) is None
    assert main(["kb", "show", str(path)]) == 0
    assert _file_digest(path) == before
    with EvidenceStore.open(path, catalog) as s:
        _exam(s, 1, day=1)  # the first write migrates, in its own transaction
        assert s.version == SCHEMA_VERSION
    conn = sqlite3.connect(path)
    assert conn.execute("SELECT value FROM meta WHERE key='schema_version'").fetchone() == (
        str(SCHEMA_VERSION),
    )
    rows4 = conn.execute(
        "SELECT id, object_id, type, sim_time FROM examinations WHERE day = 0"
    ).fetchall()
    obs4 = conn.execute("SELECT * FROM observations ORDER BY rowid").fetchall()
    rooms = conn.execute("SELECT run, style, seed, day, status, end_time FROM rooms").fetchall()
    conn.close()
    assert rows4 == rows3 and obs4[: len(obs3)] == obs3
    assert rooms == [("r1", "office", 1, 0, "done", 55.0)]


def test_a_failed_migrating_write_leaves_a_schema_3_store_as_it_was(catalog, tmp_path):
    path = _v3_store(tmp_path / "v3.sqlite", catalog)
    before = _file_digest(path)
    with EvidenceStore.open(path, catalog) as s:
        with pytest.raises(StoreError, match="already examined"):
            _exam(s, 3, day=0)  # the migration ran in the transaction, then the insert failed
        assert s.version == 3
    assert _file_digest(path) == before


# ---- forgetting from the log -----------------------------------------------------------------
def test_half_life_counts_from_the_log_match_a_hand_computation(catalog, tmp_path):
    with EvidenceStore.open(tmp_path / "s.sqlite", catalog) as s:
        _exam(s, 1, day=0)  # a Cup on it
        _exam(s, 2, day=0, related=())
        _exam(s, 1, day=1, related=())
        _exam(s, 2, day=2)
        ev = evidence_of(s.examinations())
    kb = ForgetKnowledgeBase(catalog, 0.1, ev, 2, Forgetting("half-life", half_life=1.0))
    # weights 2^-(2 - day): 0.25, 0.25, 0.5, 1; hits on days 0 and 2
    assert kb.counts("Desk", ("ON-TOP-OF-DESK", "Cup")) == pytest.approx((1.25, 2.0))
    assert kb.counts("Desk", ("NEAR-DESK", "Bed")) == pytest.approx((0.0, 2.0))
    assert kb.n("Desk") == 4 and kb.y("ON-TOP-OF-DESK", "Cup") == 2  # raw counts: the paper's
    lo, hi = kb.interval("ON-TOP-OF-DESK", "Cup")
    from ctxsearch.knowledge import intervals

    assert (lo, hi) == pytest.approx(tuple(float(v) for v in intervals.interval(1.25, 2.0, 0.1)))
    none = ForgetKnowledgeBase(catalog, 0.1, ev, 2, Forgetting())
    assert none.counts("Desk", ("ON-TOP-OF-DESK", "Cup")) == (2.0, 4.0)
    day1 = ForgetKnowledgeBase(catalog, 0.1, ev, 1, Forgetting())  # nothing from the future
    assert day1.counts("Desk", ("ON-TOP-OF-DESK", "Cup")) == (1.0, 3.0)


def _crafted(rng, p_before, p_after, days=20, change=10, per_day=8) -> DayEvidence:
    ev = DayEvidence.empty()
    for day in range(days):
        p = p_before if day < change else p_after
        for _ in range(per_day):
            ev.add("Desk", day, {("ON-TOP-OF-DESK", "Laptop")} if rng.random() < p else set())
    return ev


def test_detect_flags_a_crafted_change_and_a_stable_entry_at_its_rate():
    rng = np.random.default_rng(4)
    f = Forgetting("detect", false_alarm=0.05)
    key = ("ON-TOP-OF-DESK", "Laptop")
    runs = 150
    stable = sum(bool(_crafted(rng, 0.3, 0.3).alarms(f, "Desk", key, 19)) for _ in range(runs))
    # at most 5% in expectation; 3 binomial standard deviations of tolerance over 150 runs
    assert stable / runs <= 0.05 + 3 * np.sqrt(0.05 * 0.95 / runs)
    changed = [_crafted(rng, 0.3, 0.9).alarms(f, "Desk", key, 19) for _ in range(40)]
    assert np.mean([bool(a) for a in changed]) >= 0.9
    assert all(a[0] >= 10 for a in changed if a)  # never before the change
    ev = _crafted(rng, 0.3, 0.9)
    kb = ForgetKnowledgeBase(
        __import__("ctxsearch.knowledge.catalog").knowledge.catalog.load_catalog(), 0.1, ev, 19, f
    )
    y, n = kb.counts("Desk", key)
    assert n < 8 * 20 and y / n > 0.7  # only the evidence since the change


# ---- learn --days -----------------------------------------------------------------------------
def _config(kb: Path, rooms: int = 1, **kw) -> LearnConfig:
    return LearnConfig("office", rooms, kb, perception="oracle", progress=False, **kw)


def _log(path: Path, catalog) -> list:
    with EvidenceStore.open(path, catalog, read_only=True) as s:
        return [(e.run, e.room_seed, e.day, e.object_id, e.sim_time, e.related)
                for e in s.examinations()]  # fmt: skip


def test_learn_days_resumes_and_extends_exactly(catalog, tmp_path):
    full = tmp_path / "full.sqlite"
    s = learn(_config(full, days=3))
    assert s.days == 3 and {d for _r, _s, d, *_ in _log(full, catalog)} == {0, 1, 2}
    # --days 1, then --days 3 (adds days 1-2), interrupted twice on the way
    part = tmp_path / "part.sqlite"
    learn(_config(part))
    learn(_config(part, days=3, max_examinations=5))
    learn(_config(part, days=3, max_examinations=9))
    learn(_config(part, days=3))
    assert _log(part, catalog) == _log(full, catalog)
    # the paper's policy: furniture examined on day 0 is not examined again on later days
    with EvidenceStore.open(full, catalog, read_only=True) as st:
        exams = list(st.examinations())
    first = {(e.room_seed, e.object_id) for e in exams if e.day == 0}
    later = [e for e in exams if e.day > 0]
    assert later and all(
        (e.room_seed, e.object_id) not in first for e in later if catalog.type(e.type).is_furniture
    )


def test_reexamine_impact_examines_known_furniture_again(catalog, tmp_path):
    never = learn(_config(tmp_path / "a.sqlite", days=2))
    every = learn(_config(tmp_path / "b.sqlite", days=2, reexamine="impact", reexamine_rate=0.0))
    none_again = learn(
        _config(tmp_path / "c.sqlite", days=2, reexamine="impact", reexamine_rate=1e9)
    )
    assert never.revisits == 0 == none_again.revisits and every.revisits > 0
    assert every.examinations > never.examinations == none_again.examinations
    assert every.run.endswith("/reexamine=impact:0/forget=none")
    log = _log(tmp_path / "b.sqlite", catalog)
    desks_day1 = {(seed, oid) for _r, seed, d, oid, *_ in log if d == 1}
    desks_day0 = {(seed, oid) for _r, seed, d, oid, *_ in log if d == 0}
    assert desks_day1 & desks_day0  # the same objects, examined again on day 1


def test_learn_days_cli_and_kb_show_forget(tmp_path, capsys):
    kb = tmp_path / "kb.sqlite"
    args = ["learn", "--style", "office", "--rooms", "1", "--perception", "oracle", "--kb", str(kb)]
    assert main([*args, "--no-progress", "--days", "2", "--forget", "half-life"]) == 0
    assert "days: 2" in capsys.readouterr().out
    assert main(["kb", "show", str(kb), "--forget", "half-life", "--half-life", "1"]) == 0
    assert "forgetting half-life:1 on day 1" in capsys.readouterr().out
    assert main(["kb", "show", str(kb), "--day", "1"]) == 2
    assert "--day" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_:
        main([*args, "--days", "0"])
    assert exit_.value.code == 2


# ---- bench drift ------------------------------------------------------------------------------
def test_bench_drift_writes_its_files(tmp_path, capsys):
    out = tmp_path / "drift"
    argv = ["bench", "drift", "--days", "2", "--rooms", "1", "--truth-samples", "2",
            "--episodes", "1", "--drift", f"{LAPTOP}:1.0:1", "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    for name in ("drift.json", "drift.md", "drift.csv", "drift.png"):
        assert (out / name).stat().st_size > 0
    doc = json.loads((out / "drift.json").read_text())
    assert doc["drift"] == [{"rule": LAPTOP, "p": 1.0, "from_day": 1}]
    assert set(doc["results"]) == {f"{e}/{m}" for e in ("every-day", "impact")
                                   for m in ("none", "half-life", "detect")}  # fmt: skip
    assert "alarm_rate" in doc["results"]["every-day/detect"]
    # each method's location search on the last day (the given map: location needs it)
    assert set(doc["search"]) == {"none", "half-life", "detect"}
    assert all(s["episodes"] == 1 and s["mean_time_s"] > 0 for s in doc["search"].values())
    n_entries = doc["entries"]["changed"] + doc["entries"]["unchanged"]
    lines = (out / "drift.csv").read_text().splitlines()
    assert len(lines) == 1 + 2 * 3 * 2 * n_entries and lines[0].startswith("evidence,method,day")
    assert "| every-day/none |" in (out / "drift.md").read_text()
    assert main(["bench", "drift", "--drift", "Desk/NOPE/Cup:0.5:3", "--out", str(out)]) == 2
    assert "no placement rule named 'Desk/NOPE/Cup'" in capsys.readouterr().err


def test_search_with_forgetting_reads_wilson_and_refuses_another_interval(tmp_path, capsys):
    """The search ranks by the corrected interval by default; forgetting has Wilson intervals
    only, so ``search --forget`` reads them (and says so), and an explicit other interval is a
    one-line error."""
    from ctxsearch.scripts.cli import main

    kb = str(tmp_path / "days.sqlite")
    learn = ["learn", "--style", "office", "--rooms", "2", "--days", "2", "--perception", "oracle"]
    assert main([*learn, "--kb", kb, "--no-progress"]) == 0
    capsys.readouterr()
    search = [
        "search",
        "--kb",
        kb,
        "--style",
        "office",
        "--target",
        "Cup",
        "--budget-seconds",
        "60",
    ]
    assert main([*search, "--show-config"]) == 0
    assert 'interval = "corrected"' in capsys.readouterr().out
    assert main([*search, "--forget", "half-life"]) == 0
    assert "intervals: wilson" in capsys.readouterr().out
    assert main([*search, "--forget", "half-life", "--interval", "corrected"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "does not combine with --interval corrected" in err[0]
