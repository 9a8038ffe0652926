"""The system check run by `make` before the virtualenv exists: one line and exit 1 when Mesa EGL is missing."""

from __future__ import annotations

import ctypes.util
import importlib.util
from pathlib import Path

SYSCHECK = Path(__file__).resolve().parents[1] / "scripts" / "syscheck.py"


def _load():
    spec = importlib.util.spec_from_file_location("syscheck", SYSCHECK)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_passes_when_egl_and_gl_are_found(monkeypatch, capsys):
    mod = _load()
    monkeypatch.setattr(ctypes.util, "find_library", lambda name: f"lib{name}.so.1")
    assert mod.main() == 0
    assert capsys.readouterr().err == ""


def test_missing_egl_gives_one_line_with_the_install_command(monkeypatch, capsys):
    mod = _load()
    monkeypatch.setattr(
        ctypes.util, "find_library", lambda name: None if name == "EGL" else f"lib{name}.so"
    )
    assert mod.main() == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "libEGL" in err[0] and "apt-get install" in err[0]
