"""Property-based tests (hypothesis) of every loader of user files: any bytes in, either a loaded
value or the one-line error (CtxsearchError, starting with the file's path), never a traceback,
never a modified input, never a new file beside it.

Adding a loader is one entry in ``LOADERS``: a name -> Loader(load, a valid example's bytes,
the file's name, its format). Each loader is fuzzed three ways: arbitrary bytes, byte-level
mutations of the valid example, and (for TOML, JSON and SQLite) structure-aware mutations that
put hostile values (NaN, inf, huge, negative, wrong types, control characters) into the example's
fields. CI is reproducible: derandomized, a modest number of examples, no deadline, no example database.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
import os
import shutil
import sqlite3
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ctxsearch.agent.search import draw_store
from ctxsearch.agent.search.draw import DrawSpec, check_draw, draw_episodes
from ctxsearch.envs.detector import DETECTORS_DIR, load_detector
from ctxsearch.envs.houses import HOUSES_DIR, load_house
from ctxsearch.envs.styles import STYLES_DIR, load_style
from ctxsearch.envs.truth import ground_truth, load_truth
from ctxsearch.knowledge.catalog import DEFAULT_CATALOG, load_catalog
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.store import EvidenceStore

CATALOG = load_catalog()
# CTXSEARCH_FUZZ_EXAMPLES=2000 for a long local run (then also CTXSEARCH_FUZZ_RANDOM=1 to draw
# other examples than CI's fixed ones).
FUZZ = settings(
    max_examples=int(os.environ.get("CTXSEARCH_FUZZ_EXAMPLES", "40")),
    deadline=None,
    derandomize=not os.environ.get("CTXSEARCH_FUZZ_RANDOM"),
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)


@dataclass(frozen=True)
class Loader:
    """A loader under test: ``load(path)`` reads the file at path (raising CtxsearchError for a
    bad one); ``example`` is a valid file's bytes; ``kind`` picks the structure-aware fuzzer."""

    load: Callable[[Path], object]
    example: Callable[[], bytes]
    name: str
    kind: str  # "toml" | "json" | "sqlite"
    focus: tuple = ()  # structure-aware mutations only under this path (e.g. ("drift",))


def _store_example() -> bytes:
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "kb.sqlite"
        with EvidenceStore.open(p, CATALOG) as s:
            on = next(r for r in CATALOG.type("Desk").relation_names if "ON-TOP" in r)
            for i in range(3):
                s.record(
                    run="r",
                    style="office",
                    room_seed=1,
                    object_id=i,
                    ref_type="Desk",
                    sim_time=float(i),
                    strategy="hif",
                    related=[(on, "Monitor", 10 + i)],
                )
            s.mark_room("r", "office", 1, "done", end_time=3.0)
        return p.read_bytes()


def _open_store(p: Path) -> object:
    with EvidenceStore.open(p, CATALOG, read_only=True) as s:
        kb = s.knowledge_base()
        list(s.examinations())
        s.rooms()
        return kb


def _truth_example() -> bytes:
    doc = ground_truth("office", 2, 0, CATALOG)
    for e in doc["entries"]:  # as `ctxsearch truth` writes it: strict JSON, NaN as null
        e["se_room"] = None if math.isnan(e["se_room"]) else e["se_room"]
    return json.dumps(doc).encode()


def _drift_example() -> bytes:
    """The office style with a drift schedule (two rules, three days)."""
    return (STYLES_DIR / "office.toml").read_bytes() + (
        b'\n[[drift]]\nrule = "Desk/ON-TOP-OF-DESK/Laptop"\np = 0.9\nfrom_day = 2\n'
        b'\n[[drift]]\nrule = "Desk/ON-TOP-OF-DESK/Laptop"\np = 0.1\nfrom_day = 5\n'
        b'\n[[drift]]\nrule = "Desk/ON-TOP-OF-DESK/Monitor"\np = 0.5\nfrom_day = 5\n'
    )


def _draw_spec():
    """The draw the fuzzed file is read as: one office episode (benchmark seed 5)."""
    return DrawSpec.make(load_style("office", CATALOG), 1, 5, CATALOG, 60.0)


def _draw_example() -> bytes:
    """A kept episode draw as ``bench search --draw-cache`` writes it."""
    return json.dumps(draw_store.to_json(draw_episodes(_draw_spec(), CATALOG))).encode()


def _load_draw(p: Path) -> object:
    """The draw cache's reader as a loader: a file that is not the draw asked for is a miss (the
    command draws again), here the one-line error."""
    draw = draw_store.load(p.parent, p.stem)
    if draw is None or not check_draw(draw, _draw_spec(), CATALOG):
        raise CtxsearchError(f"{p}: not the episode draw asked for (a miss: drawn again)")
    return draw


LOADERS = {
    "catalog": Loader(load_catalog, DEFAULT_CATALOG.read_bytes, "types.toml", "toml"),
    "style": Loader(
        lambda p: load_style(p, CATALOG),
        (STYLES_DIR / "office.toml").read_bytes,
        "style.toml",
        "toml",
    ),
    "store": Loader(_open_store, _store_example, "kb.sqlite", "sqlite"),
    "truth": Loader(lambda p: load_truth(p, CATALOG, "office"), _truth_example, "t.json", "json"),
    "house": Loader(
        lambda p: load_house(p, CATALOG),
        (HOUSES_DIR / "apartment.toml").read_bytes,
        "h.toml",
        "toml",
    ),
    "detector": Loader(
        lambda p: load_detector(p, CATALOG),
        (DETECTORS_DIR / "realistic.toml").read_bytes,
        "d.toml",
        "toml",
    ),
    # The catalog's [[class]] tables (the type hierarchy) and a style's [[drift]] schedule: the
    # same loaders, their structure-aware mutations aimed at those tables.
    "classes": Loader(load_catalog, DEFAULT_CATALOG.read_bytes, "types.toml", "toml", ("class",)),
    "drift": Loader(
        lambda p: load_style(p, CATALOG).on_day(5), _drift_example, "style.toml", "toml", ("drift",)
    ),
    # The episode draw kept on disk (bench search --draw-cache): read, then checked against the
    # draw asked for; anything else is a miss.
    "draw": Loader(_load_draw, _draw_example, "draw.json", "json"),
}
_EXAMPLES: dict[str, bytes] = {}


def example(name: str) -> bytes:
    """The loader's valid example (built once)."""
    if name not in _EXAMPLES:
        _EXAMPLES[name] = LOADERS[name].example()
    return _EXAMPLES[name]


def check(name: str, data: bytes) -> None:
    """The property: ``data`` as the loader's file loads or gives the one-line error, and the
    file (and its directory) is left as it was."""
    loader = LOADERS[name]
    d = Path(tempfile.mkdtemp(prefix=f"fuzz-{name}-"))
    try:
        p = d / loader.name
        p.write_bytes(data)
        before = hashlib.sha256(data).hexdigest()
        try:
            loader.load(p)
        except CtxsearchError as exc:
            msg = str(exc)
            assert "\n" not in msg and "\r" not in msg, msg
            assert msg.startswith(str(p)), msg
        assert hashlib.sha256(p.read_bytes()).hexdigest() == before, "input modified"
        assert sorted(x.name for x in d.iterdir()) == [loader.name], "files created beside it"
    finally:
        shutil.rmtree(d, ignore_errors=True)


# ---- strategies ---------------------------------------------------------------------------------
HOSTILE = st.sampled_from(
    [
        math.nan,
        math.inf,
        -math.inf,
        1e300,
        -1e300,
        0,
        -1,
        0.0,
        10**30,
        "",
        "x\n\x1b[2J",
        "\x00",
        True,
        [],
        {},
        [math.nan, 1.0, 1.0],
        [[1.0, math.nan], [1.0, 1.0], [1.0, 1.0]],
        {"a": 1},
    ]
)


@st.composite
def byte_mutations(draw, name: str) -> bytes:
    """The valid example with a few bytes replaced, inserted or cut."""
    data = bytearray(example(name))
    for _ in range(draw(st.integers(1, 4))):
        op = draw(st.sampled_from(["flip", "insert", "truncate", "delete"]))
        i = draw(st.integers(0, max(0, len(data) - 1)))
        if op == "flip" and data:
            data[i] = draw(st.integers(0, 255))
        elif op == "insert":
            data[i:i] = draw(st.binary(min_size=1, max_size=8))
        elif op == "truncate":
            del data[i:]
        elif data:
            del data[i : i + draw(st.integers(1, 64))]
    return bytes(data)


def _paths(doc, prefix=()):
    """Every (path to a leaf or container) in a parsed document."""
    yield prefix
    if isinstance(doc, dict):
        for k, v in doc.items():
            yield from _paths(v, (*prefix, k))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            yield from _paths(v, (*prefix, i))


def _replace(doc, path, value):
    if not path:
        return value
    head, *rest = path
    if isinstance(doc, dict):
        return {k: (_replace(v, rest, value) if k == head else v) for k, v in doc.items()}
    return [(_replace(v, rest, value) if i == head else v) for i, v in enumerate(doc)]


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return (
            "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
        )
    if isinstance(v, int):
        return str(v)
    if isinstance(v, str):
        return json.dumps(v)  # JSON string escapes are TOML basic-string escapes
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return "{" + ", ".join(f"{json.dumps(str(k))} = {_toml_value(x)}" for k, x in v.items()) + "}"


def to_toml(doc: dict) -> bytes:
    """A TOML document (inline tables only) that tomllib reads back as ``doc``."""
    return "\n".join(f"{json.dumps(str(k))} = {_toml_value(v)}" for k, v in doc.items()).encode()


@st.composite
def field_mutations(draw, name: str) -> bytes:
    """The valid example with one to three fields (or whole tables) replaced by hostile values."""
    import tomllib

    kind = LOADERS[name].kind
    raw = example(name)
    doc = tomllib.loads(raw.decode()) if kind == "toml" else json.loads(raw)
    focus = LOADERS[name].focus
    paths = [p for p in _paths(doc) if p and p[: len(focus)] == focus]
    for _ in range(draw(st.integers(1, 3))):
        doc = _replace(doc, draw(st.sampled_from(paths)), draw(HOSTILE))
        paths = [p for p in _paths(doc) if p and p[: len(focus)] == focus][:5000] or [focus]
    if kind == "toml":
        if not isinstance(doc, dict):
            return _toml_value(doc).encode()
        return to_toml(doc)
    return json.dumps(doc).encode()


_STORE_COLUMNS = {
    "meta": ["value"],
    "rooms": ["run", "style", "seed", "status", "end_time"],
    "examinations": ["run", "style", "room_seed", "object_id", "type", "sim_time", "strategy"],
    "observations": ["examination_id", "relation", "type", "related_id"],
}
_SQL_HOSTILE = [
    "NULL",
    "'abc'",
    "-1",
    "9e999",
    "-9e999",
    "x'00ff'",
    "''",
    "'x'||char(10,27)",
    "2.5",
]


@st.composite
def store_mutations(draw, name: str) -> bytes:
    """The valid store with hostile values written into some rows, or a crafted schema object."""
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "kb.sqlite"
        p.write_bytes(example(name))
        conn = sqlite3.connect(p)
        for _ in range(draw(st.integers(1, 3))):
            table = draw(st.sampled_from(sorted(_STORE_COLUMNS)))
            col = draw(st.sampled_from(_STORE_COLUMNS[table]))
            value = draw(st.sampled_from(_SQL_HOSTILE))
            if table == "meta":
                key = draw(
                    st.sampled_from(["alpha", "schema_version", "app", "catalog_fingerprint"])
                )
                with contextlib.suppress(sqlite3.IntegrityError):  # NOT NULL
                    conn.execute(f"UPDATE meta SET value = {value} WHERE key = ?", (key,))
                continue
            craft = draw(st.sampled_from(["update", "update", "trigger", "view"]))
            with_ = f"UPDATE {table} SET {col} = {value}"
            if craft == "update":
                with contextlib.suppress(sqlite3.IntegrityError):  # NOT NULL / CHECK
                    conn.execute(f"{with_} WHERE rowid = (SELECT MIN(rowid) FROM {table})")
            elif craft == "trigger":
                conn.execute(
                    f"CREATE TRIGGER IF NOT EXISTS t_{table} AFTER INSERT ON {table} BEGIN "
                    f"{with_}; END"
                )
            else:
                conn.execute(f"CREATE VIEW IF NOT EXISTS v_{table} AS SELECT * FROM {table}")
        conn.commit()
        conn.execute("PRAGMA journal_mode = DELETE")  # one file, no -wal beside it
        conn.close()
        return p.read_bytes()


def structured(name: str):
    return store_mutations(name) if LOADERS[name].kind == "sqlite" else field_mutations(name)


# ---- the properties -----------------------------------------------------------------------------
@pytest.mark.parametrize("name", sorted(LOADERS))
def test_the_valid_example_loads(name):
    check(name, example(name))
    loader = LOADERS[name]
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / loader.name
        p.write_bytes(example(name))
        assert loader.load(p) is not None


@pytest.mark.parametrize("name", sorted(LOADERS))
@FUZZ
@given(data=st.data())
def test_any_bytes_load_or_give_the_one_line_error(name, data):
    check(name, data.draw(st.binary(max_size=4096), label="bytes"))


@pytest.mark.parametrize("name", sorted(LOADERS))
@FUZZ
@given(data=st.data())
def test_byte_mutations_of_a_valid_file_load_or_give_the_one_line_error(name, data):
    check(name, data.draw(byte_mutations(name), label="mutated bytes"))


@pytest.mark.parametrize("name", sorted(LOADERS))
@FUZZ
@given(data=st.data())
def test_hostile_field_values_load_or_give_the_one_line_error(name, data):
    check(name, data.draw(structured(name), label="mutated fields"))


def test_the_toml_writer_round_trips():
    import tomllib

    for name in ("catalog", "style"):
        doc = tomllib.loads(example(name).decode())
        assert tomllib.loads(to_toml(doc).decode()) == doc


# ---- the Gymnasium task's arguments -------------------------------------------------------------
GYM_VALUES = st.one_of(
    HOSTILE,
    st.sampled_from([None, "office", "apartment", "perfect", "rgb_array", "human", 8, 64, 300.0]),
    st.integers(-(2**70), 2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=20),
)


@FUZZ
@given(data=st.data())
def test_the_gym_tasks_arguments_make_a_task_or_give_the_one_line_error(data):
    """Any values of ObjectSearchEnv's arguments: a task whose spaces hold what was asked, or a
    one-line CtxsearchError (never a traceback, never budget_s=inf or top_k=True accepted)."""
    from ctxsearch.agent.gym_env import ObjectSearchEnv

    names = ["style", "detector", "kb", "width", "height", "budget_s", "top_k", "render_mode"]
    valid = {"style": "office", "detector": "perfect", "width": 32, "height": 24}
    args = dict(valid)
    for name in data.draw(st.lists(st.sampled_from(names), min_size=1, max_size=3, unique=True)):
        args[name] = data.draw(GYM_VALUES, label=name)
    if isinstance(args.get("kb"), str) and args["kb"]:
        args["kb"] = "/nonexistent/" + args["kb"].replace("/", "_")  # never a file of the repo
    try:
        env = ObjectSearchEnv(**args)
    except CtxsearchError as exc:
        assert "\n" not in str(exc) and "\r" not in str(exc)
        return
    assert math.isfinite(env.budget_s) and 0 < env.budget_s <= 1e9
    assert type(env.top_k) is int and env.top_k >= 1
    assert not isinstance(args.get("top_k"), bool) and not isinstance(args.get("budget_s"), bool)
    assert env.observation_space["rgb"].shape == (env.height, env.width, 3)
