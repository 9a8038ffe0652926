"""The README's shell examples, kept from rotting.

Every line of the README's ``bash`` blocks is read as a new user would run it, in order, from the
repository root. Three checks:

1. every ``ctxsearch`` line parses with the real parser (its sub-command, flags and values exist);
2. every file a line reads (a store given to ``search``, ``bench search`` or ``kb``, a recording
   given to ``rerun`` or ``view``) is written by an earlier line, and no line writes into the
   tracked ``results/`` (a benchmark without ``--out`` writes nothing);
3. the cheap lines run, in order, in a temporary directory, in this process, in a smoke mode
   (``smoke``: tiny counts, e.g. ``--rooms 10`` -> 1, ``learn`` stopped after 2 examinations),
   each exiting with 0. The others are skipped for the reason ``SKIP`` gives (their own tests
   run them), but still go through checks 1 and 2.
"""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from ctxsearch.scripts.cli import build_parser, main

README = Path(__file__).resolve().parents[1] / "README.md"

# Lines not run (first words -> why); everything else that starts with `ctxsearch` runs.
SKIP = {
    "make": "builds the venv and runs the demo or the whole suite",
    "source": "activates the venv: this test runs in it",
    "rerun": "rerun's native viewer needs a display",
    "ctxsearch view": "serves until Ctrl-C (tests/test_cli_view.py starts and stops it)",
    "ctxsearch search": "draws a held-out episode: ~10 s each (tests/test_cli_search.py)",
    "ctxsearch bench learning": "minutes even when shrunk (tests/test_bench_tables.py)",
    "ctxsearch bench search": "draws episodes: ~20 s even for 1 (tests/test_cli_search.py)",
    "ctxsearch bench home": "learns over days and searches with every arm (tests/test_memory.py)",
    "ctxsearch bench hierarchy": "learns 20 rooms (tests/test_hierarchy.py)",
    "ctxsearch bench intervals": "camera learning runs per detector setting",
    "ctxsearch bench curve": "learning and search per k (tests/test_bench_curve.py)",
    "ctxsearch bench transfer": "learning and search per style",
}
# Flags whose values make a line long, and the smoke value for each.
SMOKE_VALUES = {"--rooms": "1", "--samples": "2", "--days": "2"}
# Flags added per sub-command in the smoke run.
SMOKE_EXTRA = {
    "learn": ["--max-examinations", "2", "--no-progress"],
    "room": ["--views", "1"],
    "truth": ["--no-progress"],
    "bench kb": ["--sizes", "50", "--reps", "1"],
    "bench sim": ["--rooms", "1", "--gazes", "2", "--explore", "0"],
    "bench rooms": ["--houses", "1", "--styles", "apartment"],
}


def readme_commands() -> list[list[str]]:
    """The README's shell lines in order, as argument lists (comments and continuations done)."""
    blocks = re.findall(r"```bash\n(.*?)```", README.read_text(), flags=re.S)
    lines = []
    for block in blocks:
        text = block.replace("\\\n", " ")
        for line in text.splitlines():
            words = shlex.split(line, comments=True)
            if words:
                lines.append(words)
    return lines


def skip_reason(words: list[str]) -> str | None:
    joined = " ".join(words)
    for prefix, why in SKIP.items():
        if joined == prefix or joined.startswith(prefix + " "):
            return why
    return None


def _sub(words: list[str]) -> str:
    """``learn``, ``kb show``, ``bench sim``, ...: the sub-command a ctxsearch line runs."""
    return " ".join(words[1:3]) if words[1] in ("kb", "bench") else words[1]


def smoke(words: list[str]) -> list[str]:
    """The arguments (without ``ctxsearch``) of the line's smoke run."""
    args = list(words[1:])
    for i, a in enumerate(args[:-1]):
        if a in SMOKE_VALUES:
            args[i + 1] = SMOKE_VALUES[a]
    extra = SMOKE_EXTRA.get(_sub(words), [])
    for i in range(0, len(extra)):  # a flag given by the line is replaced, not repeated
        if extra[i].startswith("--") and extra[i] in args:
            j = args.index(extra[i])
            has_value = i + 1 < len(extra) and not extra[i + 1].startswith("--")
            del args[j : j + (2 if has_value else 1)]
    return args + extra


def _reads_and_writes(words: list[str]) -> tuple[list[str], list[str]]:
    """(files the line reads, files it writes)."""
    opt = {a: b for a, b in zip(words, words[1:], strict=False) if a.startswith("--")}
    if words[0] in ("rerun",) or words[:2] == ["ctxsearch", "view"]:
        return words[-1:], []
    if words[0] != "ctxsearch":
        return [], []
    sub = _sub(words)
    writes = [opt[k] for k in ("--out", "--record", "--draw-cache") if k in opt]
    if sub == "learn":
        return [], writes + [opt["--kb"]]
    if sub in ("kb show", "kb stats"):
        return [words[3]], []
    if sub == "kb merge":
        return words[4:], [words[3]]
    return ([opt["--kb"]] if "--kb" in opt else []), writes


def test_every_readme_line_parses_and_reads_only_what_an_earlier_line_wrote():
    commands = readme_commands()
    assert len(commands) > 30 and ["make", "demo"] in commands
    parser = build_parser()
    written: set[str] = set()
    for words in commands:
        if words[0] == "ctxsearch":
            args = parser.parse_args(words[1:])  # argparse exits on a bad flag: the test fails
            assert args.func is not None
        elif skip_reason(words) is None:
            pytest.fail(f"a README line neither runs nor is skipped: {' '.join(words)}")
        reads, writes = _reads_and_writes(words)
        for f in reads:
            assert f in written or any(f.startswith(w.rstrip("/") + "/") for w in written), (
                f"README: {' '.join(words)} reads {f}, which no earlier example writes"
            )
        for f in writes:
            assert not f.startswith("results"), f"README: {' '.join(words)} writes into results/"
        written.update(writes)


def test_smoke_values_shrink_the_long_lines():
    line = shlex.split("ctxsearch learn --style office --rooms 10 --kb k --max-examinations 9")
    assert smoke(line) == ["learn", "--style", "office", "--rooms", "1", "--kb", "k",
                           "--max-examinations", "2", "--no-progress"]  # fmt: skip
    assert skip_reason(["ctxsearch", "search", "--kb", "k"]) is not None
    assert skip_reason(["ctxsearch", "bench", "sim", "--out", "o"]) is None


@pytest.mark.render
def test_readme_examples_run_in_smoke_mode(tmp_path, monkeypatch, capsys):
    """The cheap lines, in order, in a fresh directory: each exits with 0."""
    monkeypatch.chdir(tmp_path)
    ran = []
    for words in readme_commands():
        if words[0] != "ctxsearch" or skip_reason(words) is not None:
            continue
        argv = smoke(words)
        code = main(argv)
        out = capsys.readouterr()
        assert code == 0, f"README line failed: ctxsearch {' '.join(argv)}\n{out.err[-2000:]}"
        ran.append(_sub(words))
    cheap = {"room", "truth", "learn", "kb show", "kb stats", "kb merge", "bench kb", "bench rooms"}
    assert cheap <= set(ran)
    assert ran.count("learn") >= 8
    assert (tmp_path / "out" / "kb.sqlite").is_file() and (
        tmp_path / "out" / "all.sqlite"
    ).is_file()
    assert not (tmp_path / "results").exists()
