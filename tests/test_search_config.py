"""The search configuration (agent.search.config over knowledge.settings): typed once, read from
flags, files and --set with one-line errors, recorded in every result, and a run repeated from
its result file alone; no experiment patches the library."""

from __future__ import annotations

import ast
import json
import os
import pathlib
import subprocess
import sys

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ctxsearch.agent.search import config as cfg
from ctxsearch.agent.search.config import ConfigError, SearchConfig, Segments
from ctxsearch.agent.search.registry import resolve
from ctxsearch.knowledge.errors import CtxsearchError
from ctxsearch.knowledge.options import MapMode, Rank

ROOT = pathlib.Path(__file__).resolve().parents[1]


def _cli(*argv: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    return subprocess.run(
        [sys.executable, "-m", "ctxsearch.scripts.cli", *argv],
        capture_output=True, text=True, timeout=120, env=env, stdin=subprocess.DEVNULL,
    )  # fmt: skip


def test_every_key_has_a_default_a_type_and_help():
    keys = cfg.keys()
    assert "online.lookahead" in keys and "map.depth_range_m" in keys
    assert "knowledge.room_context" in keys and "belief.stop_mass" in keys
    for key, f in keys.items():
        assert f.metadata.get("help"), key
    c = SearchConfig()
    assert c.online.lookahead is False and c.map.depth_range_m == 5.0
    assert c.belief.stop_mass == 0.02 and c.knowledge.rank is Rank.LOW


def test_toml_and_json_round_trips_give_the_same_configuration(tmp_path):
    c = SearchConfig("apartment", ("frontier", "indirect@high"), seed=7, episodes=3).updated({
        "knowledge.kb": tmp_path / "k.sqlite", "knowledge.room_context": True,
        "map.scenario": "built", "map.depth_range_m": 8.5, "map.segments": "plan",
        "online.lookahead": True, "belief.stop_mass": 0.05, "detector": "perfect",
    })  # fmt: skip
    (tmp_path / "c.toml").write_text(cfg.to_toml(c))
    assert cfg.load_file(tmp_path / "c.toml") == c
    (tmp_path / "search.json").write_text(json.dumps({"config": cfg.to_dict(c), "other": 1}))
    assert cfg.load_file(tmp_path / "search.json") == c
    assert c.map.segments is Segments.PLAN and c.scenario is MapMode.BUILT


@pytest.mark.parametrize(
    "assignment, words",
    [
        ("online.lookahed=true", "unknown key 'online.lookahed'"),
        ("online.lookahead=maybe", "online.lookahead: expected true or false"),
        ("map.depth_range_m=100", "map.depth_range_m: 100.0 is out of range [1, 30]"),
        ("belief.stop_mass=-0.1", "belief.stop_mass: -0.1 is out of range"),
        ("budget_s=nan", "budget_s: expected a finite number"),
        ("seed=1.5", "seed: expected an integer"),
        ("knowledge.rank=middle", "knowledge.rank: unknown value 'middle'"),
        ("lookahead", "expected key=value"),
        ("=1", "expected key=value"),
    ],
)
def test_a_bad_set_is_one_line_naming_the_key(assignment, words):
    with pytest.raises(ConfigError) as e:
        cfg.apply_set(SearchConfig(), assignment)
    assert words in str(e.value) and "\n" not in str(e.value)
    assert isinstance(e.value, ValueError) and isinstance(e.value, CtxsearchError)


@pytest.mark.parametrize(
    "text, words",
    [
        ("[online]\nlookahead = 1\n", "online.lookahead: expected true or false"),
        ("[online]\nspeed = 1\n", "unknown key 'online.speed'"),
        ("[nowhere]\nx = 1\n", "unknown key 'nowhere'"),
        ("online = 3\n", "unknown key 'online'"),
        ("episodes = 0\n", "episodes: 0 is out of range"),
        ("seed = -1\n", "seed: -1 is out of range"),
        ("policies = [1, 2]\n", "policies: expected a list of names"),
        ("style = ''\n", "style: expected a non-empty string"),
        ("a = " + "[" * 200 + "]" * 200 + "\n", "nested"),
        ("= = =\n", "TOML syntax error"),
    ],
)
def test_a_bad_config_file_is_one_line_naming_the_file_and_the_key(tmp_path, text, words):
    p = tmp_path / "c.toml"
    p.write_text(text)
    with pytest.raises(ConfigError) as e:
        cfg.load_file(p)
    assert words in str(e.value) and str(p) in str(e.value) and "\n" not in str(e.value)


def test_a_config_that_is_not_a_regular_file_is_refused_without_blocking(tmp_path):
    fifo = tmp_path / "fifo.toml"
    os.mkfifo(fifo)
    with pytest.raises(ConfigError, match="FIFO"):
        cfg.load_file(fifo)
    with pytest.raises(ConfigError, match="directory"):
        cfg.load_file(tmp_path)
    with pytest.raises(ConfigError, match="no such file"):
        cfg.load_file(tmp_path / "none.toml")
    (tmp_path / "nan.json").write_text('{"config": {"budget_s": NaN}}')
    with pytest.raises(ConfigError, match="NaN"):
        cfg.load_file(tmp_path / "nan.json")


@settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(data=st.binary(max_size=300))
def test_any_bytes_as_a_config_give_a_configuration_or_the_one_line_error(tmp_path, data):
    for name in ("c.toml", "c.json"):
        p = tmp_path / name
        p.write_bytes(data)
        try:
            got = cfg.load_file(p)
        except ConfigError as e:
            assert "\n" not in str(e)
        else:
            assert isinstance(got, SearchConfig)


def test_cli_config_errors_exit_2_with_one_line(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[map]\ndepth_range_m = 0.5\n")
    fifo = tmp_path / "f.toml"
    os.mkfifo(fifo)
    for argv, words in [
        (["--config", str(bad)], "map.depth_range_m: 0.5 is out of range"),
        (["--config", str(fifo)], "FIFO"),
        (["--set", "online.lookahed=1"], "unknown key 'online.lookahed'"),
        (["--set", "map.segments=walls"], "map.segments: unknown value 'walls'"),
    ]:
        r = _cli("bench", "search", "--out", str(tmp_path / "o"), *argv)
        assert r.returncode == 2, r.stderr
        lines = r.stderr.strip().splitlines()
        assert len(lines) == 1 and words in lines[0] and "Traceback" not in r.stderr
    assert not (tmp_path / "o").exists()


def test_show_config_prints_what_the_flags_config_and_sets_give(tmp_path):
    base = tmp_path / "base.toml"
    base.write_text('style = "apartment"\n[online]\nlookahead = true\n[map]\nscenario = "given"\n')
    r = _cli(
        "bench", "search", "--config", str(base), "--map", "built", "--set",
        "map.depth_range_m=7", "--room-context", "--show-config",
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    got = cfg.load_file(_write(tmp_path / "shown.toml", r.stdout))
    assert got.style == "apartment" and got.online.lookahead  # from the file
    assert got.scenario is MapMode.BUILT  # the flag over the file
    assert got.map.depth_range_m == 7.0 and got.knowledge.room_context


def _write(p: pathlib.Path, text: str) -> pathlib.Path:
    p.write_text(text)
    return p


def test_room_context_is_refused_where_no_policy_or_a_knowing_one_cannot_use_it():
    with pytest.raises(CtxsearchError, match="'indirect' cannot use room context on the given"):
        resolve(("uniform", "indirect"), "given", room_context=True)
    with pytest.raises(CtxsearchError, match="no policy of frontier uses room context"):
        resolve(("frontier",), "built", room_context=True)
    specs = resolve(("frontier", "indirect", "oracle"), "built", room_context=True)
    assert [s.uses_room_context for s in specs] == [False, True, False]
    given = resolve(("uniform", "location@high", "oracle-prior"), "given", room_context=True)
    assert [s.name for s in given] == ["uniform", "location@high", "oracle-prior"]
    assert given[1].rank is Rank.HIGH and given[1].base == "location"


def test_cli_room_context_with_a_policy_that_cannot_use_it_is_one_line(tmp_path):
    r = _cli(
        "search", "--style", "office", "--target", "Cup", "--kb", str(tmp_path / "k.sqlite"),
        "--policy", "exhaustive", "--room-context",
    )  # fmt: skip
    assert r.returncode == 2 and "uses room context" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


@pytest.mark.render
def test_search_json_holds_the_configuration_and_reruns_to_the_same_episodes(
    tmp_path, desk_cup_store
):
    from ctxsearch.scripts.experiments.bench_search import bench_search

    kb = desk_cup_store(tmp_path / "kb.sqlite")
    config = SearchConfig("office", ("uniform", "location"), seed=3, budget_s=20.0, episodes=2)
    config = config.updated({
        "map.scenario": "given", "knowledge.kb": kb, "online.lookahead": True,
        "belief.stop_mass": 0.05,
    })  # fmt: skip
    bench_search(config, tmp_path / "a", progress=None, bar=False)
    doc = json.loads((tmp_path / "a" / "search.json").read_text())
    assert doc["config"]["online"]["lookahead"] is True
    assert doc["config"]["belief"]["stop_mass"] == 0.05
    assert doc["code_version"]["sources_sha256"]
    again = cfg.load_file(tmp_path / "a" / "search.json")
    assert again == config
    bench_search(again, tmp_path / "b", progress=None, bar=False)
    first = (tmp_path / "a" / "episodes.csv").read_bytes()
    assert first == (tmp_path / "b" / "episodes.csv").read_bytes()


def _python_files(*packages: str):
    for pkg in packages:
        yield from sorted((ROOT / pkg).rglob("*.py"))


def test_no_code_outside_tests_patches_the_library():
    found = []
    for f in _python_files("agent", "envs", "knowledge", "scripts"):
        tree = ast.parse(f.read_text())
        for n in ast.walk(tree):
            if isinstance(n, ast.Import | ast.ImportFrom):
                names = [a.name for a in n.names] + [getattr(n, "module", None) or ""]
                if any(x == "mock" or x.startswith("unittest.mock") for x in names):
                    found.append(f"{f.relative_to(ROOT)}:{n.lineno} imports mock")
            if isinstance(n, ast.Attribute) and n.attr in ("patch", "monkeypatch"):
                found.append(f"{f.relative_to(ROOT)}:{n.lineno} .{n.attr}")
    assert found == []


def test_no_module_level_switch_changes_behaviour():
    """An upper-case module name bound to True or False is a switch an experiment would flip:
    settings belong in the configuration."""
    found = []
    for f in _python_files("agent", "envs", "knowledge", "scripts"):
        for n in ast.parse(f.read_text()).body:
            if isinstance(n, ast.Assign | ast.AnnAssign):
                targets = n.targets if isinstance(n, ast.Assign) else [n.target]
                value = n.value
                for t in targets:
                    if (
                        isinstance(t, ast.Name)
                        and t.id.isupper()
                        and isinstance(value, ast.Constant)
                        and isinstance(value.value, bool)
                    ):
                        found.append(f"{f.relative_to(ROOT)}:{n.lineno} {t.id}")
    assert found == []
