"""Where the experiments live and what the CLI loads: layers point down (knowledge <- envs <-
agent <- scripts), no code under results/, and building the parser loads no simulator."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# Each layer and the packages it must not import (the layers above it, and for knowledge MuJoCo).
FORBIDDEN = {
    "knowledge": {"envs", "agent", "scripts", "mujoco", "dm_control"},
    "envs": {"agent", "scripts"},
    "agent": {"scripts"},
}
HEAVY = ("mujoco", "dm_control", "rerun", "scipy")


def _layer(module: str) -> str:
    """``ctxsearch.agent.search`` -> ``agent``; ``mujoco.viewer`` -> ``mujoco``."""
    parts = module.split(".")
    return parts[1] if parts[0] == "ctxsearch" and len(parts) > 1 else parts[0]


def _imported_packages(path: Path) -> set[str]:
    """The top-level packages a module imports (anywhere in it, lazy imports included)."""
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out |= {_layer(a.name) for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out.add(_layer(node.module))
    return out


@pytest.mark.parametrize("layer", sorted(FORBIDDEN))
def test_layers_import_only_downwards(layer):
    bad = {
        str(p.relative_to(ROOT)): sorted(_imported_packages(p) & FORBIDDEN[layer])
        for p in sorted((ROOT / layer).rglob("*.py"))
    }
    assert {k: v for k, v in bad.items() if v} == {}


def test_no_benchmark_or_demo_below_scripts_and_no_code_in_results():
    below = [p for layer in FORBIDDEN for p in (ROOT / layer).rglob("*.py")]
    assert not [p.name for p in below if p.stem.startswith("bench") or p.stem == "demo"]
    assert not list((ROOT / "results").rglob("*.py"))
    names = {p.stem for p in (ROOT / "scripts" / "experiments").glob("*.py")}
    assert {"bench_kb", "bench_sim", "bench_learning", "bench_search", "demo"} <= names


@pytest.mark.parametrize(
    "argv", [["--help"], ["kb", "show", "--help"], ["kb", "show", "STORE", "--type", "Desk"]]
)
def test_help_and_kb_show_load_no_simulator(argv, tmp_path):
    """`ctxsearch --help` and `kb show` import none of MuJoCo, dm_control, rerun and scipy."""
    from ctxsearch.knowledge.catalog import load_catalog
    from ctxsearch.knowledge.store import EvidenceStore

    store = tmp_path / "kb.sqlite"
    with EvidenceStore.open(store, load_catalog()):
        pass
    argv = [str(store) if a == "STORE" else a for a in argv]
    code = (
        "import json, sys\n"
        "from ctxsearch.scripts.cli import main\n"
        "try:\n    main(sys.argv[1:])\nexcept SystemExit:\n    pass\n"
        f"print(json.dumps(sorted({{m.split('.')[0] for m in sys.modules}} & set({HEAVY!r}))))"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code, *argv], capture_output=True, text=True, cwd=ROOT, check=True
    )
    *printed, loaded = proc.stdout.strip().splitlines()
    assert json.loads(loaded) == []
    assert "usage:" in proc.stdout if "--help" in argv else "0 examinations" in printed[0]


def test_every_package_folder_is_installed_under_ctxsearch():
    """pyproject.toml lists every folder of code (one with an __init__.py) under the one
    ``ctxsearch`` namespace, so ``pip install .`` ships all of it and nothing else."""
    import tomllib

    doc = tomllib.loads((ROOT / "pyproject.toml").read_text())
    listed = set(doc["tool"]["setuptools"]["packages"])
    found = {
        "ctxsearch." + ".".join(p.parent.relative_to(ROOT).parts)
        for layer in ("knowledge", "envs", "agent", "scripts")
        for p in (ROOT / layer).rglob("__init__.py")
    }
    assert found <= listed, sorted(found - listed)
    assert {n for n in listed if not n.startswith("ctxsearch")} == set()
    assert doc["tool"]["setuptools"]["package-dir"] == {"ctxsearch": "."}
