"""The end-to-end demo on a tiny scale: its files, its report, and a second run that reuses the store."""

from __future__ import annotations

import pytest

from ctxsearch.scripts.experiments.demo import DemoConfig, run_demo


@pytest.mark.render
def test_demo_writes_its_files_and_reruns(tmp_path):
    out = tmp_path / "demo"
    lines: list[str] = []
    config = DemoConfig(out, rooms=1, quick=True, perception="oracle", progress=False)
    res = run_demo(config, echo=lines.append)
    for name in ("kb.sqlite", "learn.rrd", "search.rrd", "report.md"):
        assert (out / name).is_file(), name
    assert sorted(p.name for p in out.glob("*.rrd")) == ["learn.rrd", "search.rrd"]
    assert res.learned_now
    report = (out / "report.md").read_text()
    assert "## 1. Learning" in report and "## 2. Search" in report and "rerun " in report
    assert "| indirect |" in report and "| frontier |" in report
    assert any(line.strip().startswith("rerun ") and "learn.rrd" in line for line in lines)
    # A second run reuses the complete store and redoes the searches.
    lines2: list[str] = []
    res2 = run_demo(config, echo=lines2.append)
    assert not res2.learned_now
    assert any("reusing" in line for line in lines2)
    assert (out / "learn.rrd").is_file() and (out / "search.rrd").is_file()
    assert res2.lines[:2] == res.lines[:2]  # same searches, same outcome
