"""The layering and size rules of the architecture (ARCHITECTURE.md), checked on the source:
layers point down, no import circle, no class over 400 lines, no file over 800 lines, no
function over 60 lines in agent/, no function with more than 8 parameters anywhere, a mode is an
enum member (never a string compared outside parsing), no duck-typed probes in the loop and the
search, and only the modules named in ARCHITECTURE.md read the true layout during a search."""

from __future__ import annotations

import ast
from enum import StrEnum
from pathlib import Path

from ctxsearch.knowledge import options

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("knowledge", "envs", "agent")
LAYERS = ("knowledge", "envs", "agent", "scripts")
MAX_CLASS_LINES = 400
MAX_FILE_LINES = 800
MAX_FUNCTION_LINES = 60  # in agent/
MAX_PARAMETERS = 8  # everywhere (self and cls not counted)
# Gymnasium passes a task's whole configuration to its constructor as keyword arguments
# (gymnasium.make(id, **kwargs), make_vec likewise): there the keyword-only ones are not counted.
KEYWORD_CONFIG = {"agent/gym_env.py": {"__init__"}}
# Files that are data tables rather than code, exempt from the file size (none today).
DATA_TABLES: set[str] = set()
# Where a mode's text may be compared: where it is parsed.
PARSING = {"knowledge/options.py"}
# The search modules that may read the true layout or the style (ARCHITECTURE.md: the walk of
# one search episode). The behaviours and the non-oracle policies never do.
TRUTH_READERS = {"oracle", "draw", "runner", "maps", "priors", "draw_store"}
SEARCH_BEHAVIOUR = {"context", "coverage", "regions", "frontier", "online", "policies"}

# Import circles that are known and accepted (none).
KNOWN_CIRCLES: set[tuple[str, str]] = set()


def _files(layers=PACKAGES) -> dict[str, ast.Module]:
    out = {}
    for pkg in layers:
        for p in sorted((ROOT / pkg).rglob("*.py")):
            rel = p.relative_to(ROOT).as_posix()
            out[rel] = ast.parse(p.read_text(), rel)
    return out


def _imports(tree: ast.Module) -> set[str]:
    """Every module imported anywhere in the file (functions and TYPE_CHECKING blocks too)."""
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
            names.update(f"{node.module}.{a.name}" for a in node.names)
    return names


def _module_name(rel: str) -> str:
    return "ctxsearch." + rel[:-3].replace("/", ".").removesuffix(".__init__")


def _layer(module: str) -> str:
    """The project layer a module name belongs to (``ctxsearch.agent.search`` -> ``agent``), or
    its top-level package for anything outside the project (``mujoco``)."""
    parts = module.split(".")
    return parts[1] if parts[0] == "ctxsearch" and len(parts) > 1 else parts[0]


def test_layers_point_down():
    for rel, tree in _files().items():
        imported = _imports(tree)
        if rel.startswith("envs/"):
            assert not any(_layer(m) in ("agent", "scripts") for m in imported), rel
        if rel.startswith("knowledge/"):
            bad = {"agent", "envs", "scripts", "mujoco", "dm_control"}
            assert not any(_layer(m) in bad for m in imported), rel


def test_no_import_circle():
    mods = _files()
    known = {_module_name(r) for r in mods}
    graph = {
        _module_name(r): {
            m
            for m in _imports(t)
            if m in known and m != _module_name(r) and (_module_name(r), m) not in KNOWN_CIRCLES
        }
        for r, t in mods.items()
    }
    assert sum(map(len, graph.values())) > 50  # the graph sees the project's own imports
    state: dict[str, int] = {}

    def visit(m: str, path: list[str]) -> None:
        state[m] = 1
        for n in sorted(graph[m]):
            assert state.get(n) != 1, " -> ".join([*path, m, n])
            if n not in state:
                visit(n, [*path, m])
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m, [])


def _functions(tree: ast.Module):
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            a = node.args
            params = [x.arg for x in a.posonlyargs + a.args + a.kwonlyargs]
            yield (
                node,
                node.end_lineno - node.lineno + 1,
                [p for p in params if p not in ("self", "cls")],
            )


def test_no_function_over_60_lines_in_agent():
    long = [
        f"{rel}:{fn.name} has {n} lines"
        for rel, tree in _files(("agent",)).items()
        for fn, n, _ in _functions(tree)
        if n > MAX_FUNCTION_LINES
    ]
    assert long == []


def test_no_function_with_more_than_8_parameters_anywhere():
    files = _files(LAYERS)
    assert any(rel.startswith("scripts/") for rel in files)  # the check looks there too
    many = []
    for rel, tree in files.items():
        for fn, _, params in _functions(tree):
            if fn.name in KEYWORD_CONFIG.get(rel, ()):
                params = params[: len(params) - len(fn.args.kwonlyargs)]
            if len(params) > MAX_PARAMETERS:
                many.append(f"{rel}:{fn.name} has {len(params)} parameters")
    assert many == []


def test_no_class_over_400_lines_and_no_file_over_800():
    big = []
    for rel, tree in _files(LAYERS).items():
        lines = (ROOT / rel).read_text().count("\n")
        if lines > MAX_FILE_LINES and rel not in DATA_TABLES:
            big.append(f"{rel} has {lines} lines")
        for node in ast.walk(tree):
            if isinstance(node, ast.ClassDef):
                n = node.end_lineno - node.lineno + 1
                if n > MAX_CLASS_LINES:
                    big.append(f"{rel}:{node.name} has {n} lines")
    assert big == []


def _mode_strings() -> set[str]:
    """The values of every mode enum of knowledge.options."""
    kinds = [v for v in vars(options).values() if isinstance(v, type) and issubclass(v, StrEnum)]
    assert len(kinds) >= 5
    return {m.value for k in kinds if k is not StrEnum for m in k}


def test_a_mode_is_an_enum_member_never_a_string_compared():
    """``x == "built"``, ``x in ("wilson", ...)``: a mode compared as text outside parsing."""
    modes = _mode_strings()
    found = []
    for rel, tree in _files(LAYERS).items():
        if rel in PARSING:
            continue
        for node in ast.walk(tree):
            if not isinstance(node, ast.Compare):
                continue
            for side in (node.left, *node.comparators):
                elts = side.elts if isinstance(side, ast.Tuple | ast.List | ast.Set) else [side]
                texts = {e.value for e in elts if isinstance(e, ast.Constant)}
                if texts & modes:
                    found.append(f"{rel}:{node.lineno} compares {sorted(texts & modes)}")
    assert found == []


def test_the_search_behaviour_never_reads_the_truth():
    """The context, the behaviours and the policies import neither the ground truth, the room
    generators nor the world; only the modules of ``TRUTH_READERS`` may."""
    truth = {"ctxsearch.envs.truth", "ctxsearch.envs.floorplan", "ctxsearch.envs.rooms",
             "ctxsearch.envs.world", "ctxsearch.envs.styles", "ctxsearch.envs.houses"}  # fmt: skip
    names = {p.stem for p in (ROOT / "agent" / "search").glob("*.py")} - {"__init__"}
    assert names >= SEARCH_BEHAVIOUR and names >= TRUTH_READERS
    for name in SEARCH_BEHAVIOUR:
        rel = f"agent/search/{name}.py"
        tree = ast.parse((ROOT / rel).read_text())
        assert not {m for m in _imports(tree) if m.rsplit(".", 1)[0] in truth or m in truth}, rel
        layout_args = [
            a.arg
            for fn, _, _ in _functions(tree)
            for a in fn.args.args + fn.args.kwonlyargs
            if a.arg in ("layout", "truth")
        ]
        assert layout_args == [], rel


def test_no_duck_typed_probes_in_the_loop_and_the_search():
    core = [
        "agent/acquisition.py", "agent/learning.py", "agent/resume.py", "agent/run_state.py",
        "agent/exploration.py", "agent/interfaces.py", "agent/perception_modes.py",
        "agent/viewplan.py", "agent/learn_log.py", "agent/recording.py",
        *(f"agent/search/{p.name}" for p in (ROOT / "agent" / "search").glob("*.py")),
    ]  # fmt: skip
    mods = _files()
    for rel in core:
        for node in ast.walk(mods[rel]):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
                assert node.func.id not in ("getattr", "hasattr"), f"{rel}:{node.lineno}"


def test_the_robot_never_reads_the_layout_rules():
    """A house style's [layout] rules are world-generation data (envs.plans): nothing in agent/
    imports them or reads ``HouseStyle.layout_rules``; the robot learns adjacency by looking."""
    rules = {"ctxsearch.envs.house_rules", "ctxsearch.envs.plans"}
    for rel, tree in _files(("agent",)).items():
        assert not {m for m in _imports(tree) if m in rules or m.rsplit(".", 1)[0] in rules}, rel
        attrs = {n.attr for n in ast.walk(tree) if isinstance(n, ast.Attribute)}
        names = {n.id for n in ast.walk(tree) if isinstance(n, ast.Name)}
        assert not {"layout_rules", "LayoutRules"} & (attrs | names), rel
