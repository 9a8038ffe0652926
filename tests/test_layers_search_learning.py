"""Learning and search stay apart, and the experiments stay below the CLI, checked on the source:
what both sides share (the robot's model of its detector, the viewing constants) lives below
them in agent.sight; the benchmarks and the sweep import none of the CLI's modules."""

from __future__ import annotations

import ast
from pathlib import Path

from tests.test_architecture import _imports as imports_of

ROOT = Path(__file__).resolve().parents[1]
LEARNING = ("exam_views", "frontiers", "acquisition", "learning")
CLI = ("ctxsearch.scripts.argtypes", "ctxsearch.scripts.cli", "ctxsearch.scripts.room_segments")


def _imports(path: Path) -> set[str]:
    """Every module a file imports, anywhere in it (lazy imports too), and for ``from M import
    n`` also ``M.n`` (``from ctxsearch.agent import frontiers`` imports the module)."""
    return imports_of(ast.parse(path.read_text(), str(path)))


def _within(name: str, module: str) -> bool:
    return name == module or name.startswith(module + ".")


def _rel(path: Path) -> str:
    return path.relative_to(ROOT).as_posix()


def test_search_imports_nothing_of_learning():
    banned = [f"ctxsearch.agent.{m}" for m in LEARNING]
    bad = {
        _rel(p): sorted(n for n in _imports(p) if any(_within(n, b) for b in banned))
        for p in sorted((ROOT / "agent" / "search").rglob("*.py"))
    }
    assert {k: v for k, v in bad.items() if v} == {}


def test_learning_imports_nothing_of_search():
    bad = {
        f"agent/{m}.py": sorted(
            n for n in _imports(ROOT / "agent" / f"{m}.py") if _within(n, "ctxsearch.agent.search")
        )
        for m in LEARNING
    }
    assert {k: v for k, v in bad.items() if v} == {}


def test_sight_sits_below_learning_and_search():
    banned = ["ctxsearch.agent.search", *(f"ctxsearch.agent.{m}" for m in LEARNING)]
    imported = _imports(ROOT / "agent" / "sight.py")
    assert not [n for n in imported if any(_within(n, b) for b in banned)]


def _is_cli(name: str) -> bool:
    if any(_within(name, m) for m in CLI):
        return True
    parts = name.split(".")
    return parts[:2] == ["ctxsearch", "scripts"] and len(parts) > 2 and parts[2].startswith("cmd_")


def test_experiments_and_sweep_import_nothing_of_the_cli():
    files = [*sorted((ROOT / "scripts" / "experiments").rglob("*.py")), ROOT / "scripts/sweep.py"]
    bad = {_rel(p): sorted(n for n in _imports(p) if _is_cli(n)) for p in files}
    assert {k: v for k, v in bad.items() if v} == {}


def test_the_checks_see_the_imports():
    """The checks would catch an import of the kinds they forbid (both spellings)."""
    exam_views = _imports(ROOT / "agent" / "exam_views.py")
    assert "ctxsearch.agent.sight.DetectionCurve" in exam_views
    assert _is_cli("ctxsearch.scripts.cmd_search") and _is_cli("ctxsearch.scripts.argtypes")
    assert not _is_cli("ctxsearch.scripts.experiments.room_segments")
    assert _within("ctxsearch.agent.search.belief", "ctxsearch.agent.search")
    assert not _within("ctxsearch.agent.searching", "ctxsearch.agent.search")
