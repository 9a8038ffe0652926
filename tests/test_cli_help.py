"""Every ``--help`` of the CLI renders as text a user reads: no literal ``%%`` (argparse does not
%-format a description), and every option with a default states it."""

from __future__ import annotations

import argparse

from ctxsearch.scripts.cli import build_parser


def _parsers(parser: argparse.ArgumentParser, name: str = "ctxsearch"):
    yield name, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub_name, sub in action.choices.items():
                yield from _parsers(sub, f"{name} {sub_name}")


def test_help_texts_render_and_state_every_default():
    parsers = dict(_parsers(build_parser()))
    assert "ctxsearch bench search" in parsers and "ctxsearch bench intervals" in parsers
    silent = []
    for name, parser in parsers.items():
        text = parser.format_help()
        assert "%%" not in text and "%(" not in text, name
        for a in parser._actions:
            if isinstance(a, argparse._HelpAction | argparse._SubParsersAction):
                continue
            if a.help == argparse.SUPPRESS or a.default in (None, False, argparse.SUPPRESS):
                continue
            if "default" not in (a.help or "").lower():
                silent.append(f"{name} {'/'.join(a.option_strings) or a.dest}")
    assert not silent, f"options whose help does not state their default: {silent}"
    assert "95% interval" in parsers["ctxsearch bench search"].format_help().replace("\n", " ")
