"""Hostile inputs on the surfaces added after issue 9 (issue 24): special files given as input
files (FIFOs, devices, dangling symlinks, symlink loops), nesting and size limits, the store's
symlinks and day stamps, drift schedules, flags of the change test, Ctrl-C, an unreachable Ray
cluster and the Gymnasium task's arguments. Each gets one line ``ctxsearch: error: ...`` and
exit 2 (130 for Ctrl-C), quickly, and a refused file is left as it was."""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import signal
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ctxsearch.envs.detector import DetectorError, load_detector
from ctxsearch.envs.houses import HOUSES_DIR, HouseError, load_house, resolve_style
from ctxsearch.envs.styles import STYLES_DIR, StyleError, load_style
from ctxsearch.envs.truth import TruthError, load_truth
from ctxsearch.knowledge import files
from ctxsearch.knowledge.catalog import DEFAULT_CATALOG, load_catalog
from ctxsearch.knowledge.errors import CatalogError, CtxsearchError
from ctxsearch.scripts.cli import main
from tests.procs import wait_until_importing

CATALOG = load_catalog()


@contextlib.contextmanager
def no_hang(seconds: int = 10):
    """Fail (instead of hanging the suite) if the body blocks for ``seconds``."""

    def expired(signum, frame):
        raise TimeoutError(f"blocked for {seconds} s")

    old = signal.signal(signal.SIGALRM, expired)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def _one_line(capsys, *fragments: str) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("ctxsearch: error: "), err
    assert "Traceback" not in err, err
    for f in fragments:
        assert f in err, err
    return err


# ---- special files as input files -------------------------------------------------------------
def _special(tmp_path: Path, kind: str, name: str) -> Path:
    p = tmp_path / name
    if kind == "fifo":
        os.mkfifo(p)
    elif kind == "dev-zero":
        p.symlink_to("/dev/zero")
    elif kind == "dangling":
        p.symlink_to(tmp_path / "nowhere.toml")
    elif kind == "loop":
        p.symlink_to(tmp_path / f"loop-{name}")
        (tmp_path / f"loop-{name}").symlink_to(p)
    elif kind == "directory":
        p.mkdir()
    return p


SPECIAL = {
    "fifo": "FIFO",
    "dev-zero": "character device",
    "dangling": "symlink to a file that does not exist",
    "loop": "symlink loop",
    "directory": "is a directory",
}
LOADERS = {
    "catalog": (load_catalog, CatalogError),
    "style": (lambda p: load_style(p, CATALOG), StyleError),
    "house": (lambda p: load_house(p, CATALOG), HouseError),
    "world style": (lambda p: resolve_style(p, CATALOG), StyleError),
    "detector": (lambda p: load_detector(p, CATALOG), DetectorError),
    "truth": (lambda p: load_truth(p, CATALOG, "office"), TruthError),
}


@pytest.mark.parametrize("kind", sorted(SPECIAL))
@pytest.mark.parametrize("loader", sorted(LOADERS))
def test_a_special_file_is_refused_by_every_loader_without_blocking(tmp_path, loader, kind):
    load, error = LOADERS[loader]
    p = _special(tmp_path, kind, "input.toml")
    with no_hang(), pytest.raises(error) as exc:
        load(p)
    msg = str(exc.value)
    assert msg.startswith(str(p)) and "\n" not in msg, msg
    assert SPECIAL[kind] in msg, msg


@pytest.mark.parametrize("kind", ["fifo", "dev-zero"])
def test_a_special_file_as_a_house_room_style_is_refused_naming_the_house(tmp_path, kind):
    _special(tmp_path, kind, "den.toml")
    text = (HOUSES_DIR / "apartment.toml").read_text()
    house = tmp_path / "h.toml"
    text = text.replace('name = "apartment"', 'name = "h"')
    house.write_text(text.replace("[rooms]\n", '[rooms]\n"den.toml" = 1\n'))  # [layout] is last
    with no_hang(), pytest.raises(HouseError, match=r"h.toml: field 'rooms.den.toml': .*den.toml"):
        load_house(house, CATALOG)


def test_the_cli_refuses_special_files_as_catalog_style_and_truth(tmp_path, capsys):
    fifo = _special(tmp_path, "fifo", "f.toml")
    zero = _special(tmp_path, "dev-zero", "z.toml")
    with no_hang():
        assert main(["kb", "show", str(tmp_path / "kb.sqlite"), "--catalog", str(fifo)]) == 2
        _one_line(capsys, "f.toml: is a FIFO")
        out = str(tmp_path / "t.json")
        assert main(["truth", "--style", str(zero), "--samples", "1", "--out", out]) == 2
        _one_line(capsys, "z.toml: is a character device (through a symlink)")
        assert main(["truth", "--style", str(fifo), "--samples", "1", "--out", out]) == 2
        _one_line(capsys, "f.toml: is a FIFO")
    assert not Path(out).exists()


# ---- nesting and size -------------------------------------------------------------------------
@pytest.mark.parametrize("loader", sorted(LOADERS))
def test_a_file_nested_100000_deep_is_refused_before_parsing(tmp_path, loader):
    load, error = LOADERS[loader]
    p = tmp_path / "deep.toml"
    deep = 100_000
    if loader == "truth":
        p.write_text("[" * deep + "]" * deep)
    else:
        p.write_text("a = " + "[" * deep + "]" * deep + "\n")
    with pytest.raises(error, match="nested more than 64 levels deep") as exc:
        load(p)
    assert str(exc.value).startswith(str(p))


def test_nesting_just_within_the_limit_parses_and_one_past_it_does_not(tmp_path):
    p = tmp_path / "n.toml"
    depth = files.MAX_NESTING
    p.write_text("a = " + "[" * depth + "]" * depth + "\n")
    assert files.read_toml(p)["a"] is not None
    p.write_text("a = " + "[" * (depth + 1) + "]" * (depth + 1) + "\n")
    with pytest.raises(files.InputFileError, match="nested more than"):
        files.read_toml(p)
    j = tmp_path / "n.json"
    j.write_text('{"a": ' + "[" * depth + "]" * depth + "}")
    with pytest.raises(files.InputFileError, match="nested more than"):
        files.read_json(j)  # the object is one level more
    j.write_text('{"a": ' + "[" * (depth - 1) + "]" * (depth - 1) + "}")
    assert files.read_json(j) == {"a": json.loads("[" * (depth - 1) + "]" * (depth - 1))}


def test_brackets_in_strings_and_comments_do_not_count_as_nesting(tmp_path):
    p = tmp_path / "s.toml"
    deep = "[" * 500
    p.write_text(
        f'a = "{deep}"\nb = \'{deep}\'\n# {deep}\nc = """\n{deep}\\"""\n"""\nd = \'\'\'{deep}\'\'\'\n'
    )
    assert files.read_toml(p)["a"] == deep
    j = tmp_path / "s.json"
    j.write_text(json.dumps({"a": deep + '\\"' + deep}))
    assert files.read_json(j)["a"] == deep + '\\"' + deep


@given(doc=st.recursive(st.integers(), lambda c: st.lists(c, max_size=3), max_leaves=30))
@settings(max_examples=60, deadline=None, derandomize=True, database=None)
def test_the_nesting_scan_measures_json_arrays_exactly(doc):
    def depth(d):
        return 1 + max(map(depth, d), default=0) if isinstance(d, list) else 0

    assert files.nesting_depth(json.dumps(doc), "json") == depth(doc)


def test_a_file_larger_than_the_limit_is_refused_without_reading_it(tmp_path, monkeypatch):
    p = tmp_path / "big.toml"
    with open(p, "wb") as f:  # sparse: 1 byte past the limit
        f.truncate(files.MAX_FILE_BYTES + 1)
    with pytest.raises(StyleError, match=f"larger than {files.MAX_FILE_BYTES:_} bytes"):
        load_style(p, CATALOG)
    p.write_bytes(b'name = "x"\n' * 10)
    with pytest.raises(files.InputFileError, match="larger than 50 bytes"):
        files.read_bytes(p, limit=50)
    assert files.read_bytes(p, limit=110) == b'name = "x"\n' * 10


def test_the_shipped_files_are_well_within_the_limits():
    shipped = [DEFAULT_CATALOG, *STYLES_DIR.glob("*.toml"), *HOUSES_DIR.glob("*.toml")]
    for p in shipped:
        text = p.read_text()
        assert len(text.encode()) < files.MAX_FILE_BYTES / 100
        assert files.nesting_depth(text, "toml") <= 4, p


# ---- drift schedules ----------------------------------------------------------------------------
def _drift_style(tmp_path: Path, entries: list[tuple[str, float, int]]) -> Path:
    text = (STYLES_DIR / "office.toml").read_text().replace('name = "office"', 'name = "drifty"')
    for rule, p, day in entries:
        text += f'\n[[drift]]\nrule = "{rule}"\np = {p}\nfrom_day = {day}\n'
    out = tmp_path / "drifty.toml"
    out.write_text(text)
    return out


def test_two_drift_entries_for_the_same_rule_and_day_are_refused(tmp_path, capsys):
    rule = "Desk/ON-TOP-OF-DESK/Monitor"
    p = _drift_style(tmp_path, [(rule, 0.9, 2), (rule, 0.1, 2)])
    before = p.read_bytes()
    with pytest.raises(StyleError, match=r"field 'drift\[1\]': a second entry for .* from day 2"):
        load_style(p, CATALOG)
    out = str(tmp_path / "t.json")
    assert main(["truth", "--style", str(p), "--samples", "1", "--out", out]) == 2
    _one_line(capsys, "drifty.toml: field 'drift[1]'", "drift[0] is the first")
    assert p.read_bytes() == before


def test_drift_entries_of_one_rule_on_different_days_apply_in_day_order(tmp_path):
    rule = "Desk/ON-TOP-OF-DESK/Monitor"
    style = load_style(_drift_style(tmp_path, [(rule, 0.1, 5), (rule, 0.9, 2)]), CATALOG)
    p = {d: next(r.p for r in style.on_day(d).rules if r.type == "Monitor") for d in (1, 2, 5, 9)}
    assert p == {1: 0.85, 2: 0.9, 5: 0.1, 9: 0.1}


def test_with_drift_refuses_duplicates_given_in_code_too():
    from ctxsearch.envs.styles import Drift

    style = load_style("office", CATALOG)
    d = Drift("Desk/ON-TOP-OF-DESK/Monitor", 0.5, 3)
    with pytest.raises(StyleError, match="a second entry"):
        style.with_drift((d, Drift(d.rule, 0.2, 3)), CATALOG)


# ---- helpers shared with the store and ray tests ------------------------------------------------
def sha(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


def test_a_refused_input_file_is_left_as_it_was(tmp_path):
    p = tmp_path / "deep.json"
    p.write_bytes(b"[" * 1000)
    before = sha(p)
    with pytest.raises(CtxsearchError):
        load_truth(p, CATALOG)
    assert sha(p) == before and sorted(x.name for x in tmp_path.iterdir()) == ["deep.json"]


# ---- the store: symlinks and day stamps ---------------------------------------------------------
def _store(tmp_path: Path, name: str = "kb.sqlite") -> Path:
    from ctxsearch.knowledge.store import EvidenceStore

    p = tmp_path / name
    with EvidenceStore.open(p, CATALOG) as s:
        on = next(r for r in CATALOG.type("Desk").relation_names if "ON-TOP" in r)
        for i in range(3):
            s.record(
                run="r", style="office", room_seed=1, object_id=i, ref_type="Desk",
                sim_time=float(i), strategy="hif", related=[(on, "Monitor", 10 + i)],
            )  # fmt: skip
        s.mark_room("r", "office", 1, "done", end_time=3.0)
    return p


@pytest.mark.parametrize("kind", ["dangling", "loop", "dev-zero", "directory", "fifo"])
def test_a_store_path_that_is_not_a_regular_file_is_refused_and_nothing_is_created(
    tmp_path, capsys, kind
):
    from ctxsearch.knowledge.store import EvidenceStore, StoreError

    p = _special(tmp_path, kind, "kb.sqlite")
    before = sorted(x.name for x in tmp_path.iterdir())
    why = {"dev-zero": "character device", "fifo": "FIFO"}.get(kind, SPECIAL[kind])
    with no_hang():
        with pytest.raises(StoreError, match=why):
            EvidenceStore.open(p, CATALOG)  # would create a new store
        argv = ["learn", "--style", "office", "--rooms", "1", "--perception", "oracle"]
        assert main([*argv, "--no-progress", "--kb", str(p)]) == 2
        _one_line(capsys, "kb.sqlite: not a ctxsearch knowledge store", why)
        assert main(["kb", "merge", str(p), str(_store(tmp_path, "in.sqlite"))]) == 2
        _one_line(capsys, "kb.sqlite: not a ctxsearch knowledge store", why)
    assert sorted(x.name for x in tmp_path.iterdir() if x.name != "in.sqlite") == before
    assert not (tmp_path / "nowhere.toml").exists()  # the dangling link's target: not created


def test_a_symlink_to_a_store_is_read_and_written_through(tmp_path):
    from ctxsearch.knowledge.store import EvidenceStore

    real = _store(tmp_path)
    link = tmp_path / "link.sqlite"
    link.symlink_to(real)
    with EvidenceStore.open(link, CATALOG) as s:
        s.mark_room("r", "office", 2, "started")
    with EvidenceStore.open(real, CATALOG, read_only=True) as s:
        assert s.room_status("r", "office", 2) == "started"


def _with_day(p: Path, table: str, day: str) -> None:
    import sqlite3

    conn = sqlite3.connect(p)
    conn.execute("PRAGMA ignore_check_constraints = 1")  # written past the CHECK (day >= 0)
    with conn:
        conn.execute(
            f"UPDATE {table} SET day = {day} WHERE rowid = (SELECT MIN(rowid) FROM {table})"
        )
    conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    conn.close()


@pytest.mark.parametrize("table", ["examinations", "rooms"])
@pytest.mark.parametrize("day", [str(2**62), "-5", "'tomorrow'", "2.5", "1000001", "x'00'"])
def test_a_store_with_a_bad_day_stamp_is_refused_by_every_command_untouched(
    tmp_path, capsys, table, day
):
    p = _store(tmp_path)
    _with_day(p, table, day)
    before = {x.name: sha(x) for x in tmp_path.iterdir()}
    runs = [
        ["kb", "stats", str(p)],
        ["kb", "show", str(p), "--forget", "detect"],
        ["kb", "show", str(p), "--forget", "half-life"],
        ["learn", "--style", "office", "--rooms", "2", "--perception", "oracle", "--no-progress",
         "--kb", str(p)],
        ["kb", "merge", str(tmp_path / "out.sqlite"), str(p)],
    ]  # fmt: skip
    for argv in runs:
        with no_hang():
            assert main(argv) == 2, argv
        _one_line(capsys, "kb.sqlite: damaged knowledge store", "is not a day in [0, 1000000]")
    assert {x.name: sha(x) for x in tmp_path.iterdir()} == before


def test_the_last_day_a_store_holds_is_read(tmp_path, capsys):
    from ctxsearch.knowledge.store import MAX_DAY, EvidenceStore

    p = _store(tmp_path)
    _with_day(p, "examinations", str(MAX_DAY))
    with EvidenceStore.open(p, CATALOG, read_only=True) as s:
        assert max(e.day for e in s.examinations()) == MAX_DAY
    with no_hang(20):  # the change test over 10^6 days tests only the days with evidence
        assert main(["kb", "show", str(p), "--forget", "detect"]) == 0
    assert "day 1000000" in capsys.readouterr().out
    with EvidenceStore.open(p, CATALOG) as s, pytest.raises(CtxsearchError, match="day must be"):
        s.mark_room("r", "office", 1, "done", day=MAX_DAY + 1)


# ---- flags of the change test -------------------------------------------------------------------
@pytest.mark.parametrize("rate", ["1e-300", "5e-324", "0.999999"])
def test_any_false_alarm_rate_in_0_1_gives_a_table(tmp_path, capsys, rate):
    p = _store(tmp_path)
    assert main(["kb", "show", str(p), "--forget", "detect", "--false-alarm", rate]) == 0
    out = capsys.readouterr().out
    assert "ON-TOP-OF-DESK" in out and f"detect:{float(rate):g}" in out


@pytest.mark.parametrize("rate", ["0", "1", "nan", "-1e-300", "inf"])
def test_a_false_alarm_rate_outside_0_1_is_a_usage_error(tmp_path, capsys, rate):
    with pytest.raises(SystemExit) as e:
        main(
            ["kb", "show", str(tmp_path / "kb.sqlite"), "--forget", "detect", "--false-alarm", rate]
        )
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert "--false-alarm" in err.splitlines()[-1] and "Traceback" not in err


# ---- Ctrl-C -------------------------------------------------------------------------------------
def _interrupt(argv: list[str], delay: float, cwd: Path) -> tuple[int, str]:
    """Run ``argv`` as a user would, send it SIGINT (Ctrl-C) ``delay`` s after its interpreter
    started on the program's imports (numpy mapped into it, where /proc says; a signal before
    that lands in CPython's own start-up, ``site``, which no program can catch: on a loaded
    machine 0.2 s after the fork may still be there); (code, stderr)."""
    import subprocess
    import time

    proc = subprocess.Popen(
        argv,
        cwd=cwd,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        env={**os.environ, "MUJOCO_GL": "egl"},
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),  # as from a terminal
    )
    wait_until_importing(proc)
    time.sleep(delay)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    return proc.returncode, err.decode(errors="replace")


def test_ctrl_c_while_the_cli_modules_load_is_one_line_and_130(tmp_path):
    import subprocess
    import sys

    # As the console script: its first ctxsearch line (scripts/__init__) takes over SIGINT.
    code = (
        "import os, signal, sys, time\n"
        "sys.argv[0] = 'ctxsearch'\n"
        "import ctxsearch.scripts\n"
        "os.kill(os.getpid(), signal.SIGINT)\n"
        "time.sleep(5)\n"
        "print('not interrupted')\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, timeout=30)
    assert r.returncode == 130 and r.stderr == b"ctxsearch: interrupted\n" and r.stdout == b""


def test_ctrl_c_during_learning_is_one_line_130_and_the_store_stays_usable(tmp_path, capsys):
    import shutil
    import sys

    from ctxsearch.knowledge.store import EvidenceStore

    exe = shutil.which("ctxsearch", path=str(Path(sys.executable).parent))
    assert exe is not None
    kb = tmp_path / "kb.sqlite"
    argv = ["learn", "--style", "apartment", "--perception", "oracle", "--no-progress"]
    assert main([*argv, "--rooms", "1", "--kb", str(kb)]) == 0  # the store, and warm imports
    capsys.readouterr()
    with EvidenceStore.open(kb, CATALOG, read_only=True) as s:
        counts = [s.examinations_count()]
    for delay in (0.2, 0.8):  # the same run resumed, 40 rooms: Ctrl-C well before its end
        code, err = _interrupt([exe, *argv, "--rooms", "40", "--kb", str(kb)], delay, tmp_path)
        assert "Traceback" not in err, err
        assert (code, err.count("\n")) in {(130, 1), (0, 0)}, (delay, code, err)
        assert err == "" or err.startswith("ctxsearch: interrupted"), err
        with EvidenceStore.open(kb, CATALOG, read_only=True) as s:  # readable after each
            counts.append(s.examinations_count())
    assert counts == sorted(counts)  # nothing lost, resumed each time
    assert main(["kb", "stats", str(kb)]) == 0


def test_a_keyboard_interrupt_in_a_command_is_one_line_and_the_handler_is_restored(
    monkeypatch, capsys
):
    import ctxsearch.scripts.cmd_kb as cmd_kb

    def interrupted(args):
        raise KeyboardInterrupt

    before = signal.getsignal(signal.SIGINT)
    monkeypatch.setattr(cmd_kb, "run_stats", interrupted)  # the parser binds it when built
    assert main(["kb", "stats", "x.sqlite"]) == 130
    assert capsys.readouterr().err == "ctxsearch: interrupted\n"
    assert signal.getsignal(signal.SIGINT) is before


# ---- the Gymnasium task's arguments -------------------------------------------------------------
@pytest.mark.parametrize(
    ("kwargs", "needle"),
    [
        ({"budget_s": float("inf")}, "budget_s must be a number of seconds in (0, 1e+09]"),
        ({"budget_s": float("nan")}, "budget_s must be"),
        ({"budget_s": 1e300}, "budget_s must be"),
        ({"budget_s": True}, "budget_s must be"),
        ({"budget_s": "300"}, "budget_s must be"),
        ({"top_k": True}, "top_k must be a whole number, got True"),
        ({"top_k": 2.0}, "top_k must be a whole number"),
        ({"top_k": 10**12}, "top_k must be in [1, 10000]"),
        ({"width": True}, "image size must be whole pixels"),
        ({"style": 5}, "style must be a name or a path"),
        ({"style": ""}, "style must be a name or a path"),
        ({"detector": ["perfect"]}, "detector must be a name or a path"),
        ({"kb": 3.0}, "kb must be a name or a path"),
        ({"render_mode": ["rgb_array"]}, "render_mode must be a string"),
        ({"style": "x/\x00.toml"}, "NUL byte"),
        ({"detector": "\x00"}, "NUL byte"),
    ],
)
def test_the_gym_task_refuses_arguments_of_the_wrong_type_or_range(kwargs, needle):
    from ctxsearch.agent.gym_env import ObjectSearchEnv

    args = {"style": "office", "detector": "perfect", "width": 32, "height": 24, **kwargs}
    with pytest.raises(CtxsearchError) as err:
        ObjectSearchEnv(**args)
    assert needle in str(err.value) and "\n" not in str(err.value), str(err.value)


def test_the_gym_task_takes_numpy_numbers_and_a_deeply_nested_style_is_refused(tmp_path):
    import numpy as np

    from ctxsearch.agent.gym_env import ObjectSearchEnv

    env = ObjectSearchEnv(
        "office", "perfect", width=32, height=24, budget_s=np.float32(60), top_k=np.int64(3)
    )
    assert (env.budget_s, env.top_k, type(env.top_k)) == (60.0, 3, int)
    assert env.observation_space["elapsed"].high[0] == pytest.approx(120.0)
    deep = tmp_path / "deep.toml"
    deep.write_text("a = " + "[" * 60_000 + "]" * 60_000 + "\n")
    with pytest.raises(StyleError, match="nested more than 64 levels deep"):
        ObjectSearchEnv(str(deep), "perfect", width=32, height=24)


def test_a_stop_signal_where_exceptions_are_ignored_comes_again_later(monkeypatch):
    """A stop signal landing in a finalizer or in importlib's module-lock callback (where Python
    prints "Exception ignored" and goes on) is not raised there: it is sent again a moment later,
    to land in ordinary code; anywhere else it is a ``Stopped`` at once."""
    import signal
    import types

    import ctxsearch.scripts as scripts

    sent = []

    class FakeTimer:
        def __init__(self, delay, fn, args):
            sent.append((delay, fn, args))

        def start(self):
            pass

    monkeypatch.setattr(scripts.threading, "Timer", FakeTimer)
    monkeypatch.setattr(scripts, "received", [])

    def frame(name, filename="x.py"):
        return types.SimpleNamespace(
            f_code=types.SimpleNamespace(co_name=name, co_filename=filename)
        )

    scripts.raise_stopped(signal.SIGINT, frame("__del__"))
    scripts.raise_stopped(signal.SIGTERM, frame("cb", "<frozen importlib._bootstrap>"))
    assert [(d, a[1]) for d, _, a in sent] == [(scripts.DEFER_S, signal.SIGINT),
                                               (scripts.DEFER_S, signal.SIGTERM)]  # fmt: skip
    assert scripts.received == []
    with pytest.raises(scripts.Stopped):
        scripts.raise_stopped(signal.SIGINT, frame("run"))
    assert scripts.received == [signal.SIGINT]
