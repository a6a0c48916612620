"""The command-line reference page (docs/reference/cli.md, built by the MkDocs hook) says what the parser
says: one row per option, in the right columns, with the parser's own default, choices and help, the help's
`<placeholders>` and pipes escaped so that they show."""

from __future__ import annotations

import argparse
import html
import re
import sys
from pathlib import Path

import pytest

from ovon.cli.main import build_parser

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "docs" / "_hooks"))
import ovon_docs  # noqa: E402


def _tables() -> dict[str, list[list[str]]]:
    """Command -> its rows, each split into its cells (on the unescaped pipes only)."""
    out: dict[str, list[list[str]]] = {}
    current = None
    for line in ovon_docs.cli_reference().splitlines():
        m = re.match(r"^#+ `(ovon[^`]*)`$", line)
        if m:
            current = m.group(1)
            out[current] = []
        elif line.startswith("| ") and not line.startswith("| option |") and current:
            out[current].append([c.strip() for c in line.strip().strip("|").split("|")])
    return out


def _plain(cell: str) -> str:
    return html.unescape(re.sub(r"</?code>", "", cell))


def _parser(command: str) -> argparse.ArgumentParser:
    parser = build_parser()
    for word in command.split()[1:]:
        sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))  # noqa: SLF001
        parser = sub.choices[word]
    return parser


def _row(command: str, option: str) -> list[str]:
    rows = [r for r in _tables()[command] if option in _plain(r[0]).split(", ")]
    assert len(rows) == 1, (command, option, rows)
    return rows[0]


def test_every_row_has_four_cells_and_every_option_a_row():
    tables = _tables()
    for command, rows in tables.items():
        for row in rows:
            assert len(row) == 4, f"{command}: {row}"
        actions = [
            a
            for a in _parser(command)._actions  # noqa: SLF001
            if not isinstance(a, argparse._HelpAction | argparse._SubParsersAction)  # noqa: SLF001
        ]
        assert len(rows) == len(actions), command


@pytest.mark.parametrize(
    ("command", "option", "default", "choices"),
    [
        ("ovon train", "--policy", "", ["transformer", "lstm"]),
        ("ovon train", "--task", "objectnav", ["objectnav", "pointnav"]),
        ("ovon train", "--preset", "cpu-small", ["paper", "cpu-small", "tiny"]),
        ("ovon scenes generate", "--split", "train", ["train", "val"]),
        ("ovon evaluate", "--executor", "process", ["process", "ray"]),
        ("ovon evaluate", "--splits", "val_seen,val_seen_synonyms,val_unseen", None),
    ],
)
def test_rows_match_the_parser(command, option, default, choices):
    row = _row(command, option)
    action = next(a for a in _parser(command)._actions if option in a.option_strings)  # noqa: SLF001
    assert _plain(row[2]) == default == ("" if action.default is None else str(action.default))
    if choices:
        assert list(action.choices) == choices
        assert _plain(row[1]) == "one of " + ", ".join(choices)
    assert _plain(row[3]) == " ".join(action.help.split())
    # and `--help` shows the same default
    text = " ".join(_parser(command).format_help().split())
    if default:
        assert f"(default: {default})" in text
    if choices:
        assert "{" + ",".join(choices) + "}" in text


def test_placeholders_and_pipes_are_escaped():
    row = _row("ovon train", "--resume")
    assert "&lt;out&gt;/checkpoint.pt" in row[3]
    assert _plain(row[3]) == "continue from <out>/checkpoint.pt exactly"
    agent = _row("ovon evaluate", "--agent")  # its help lists the agents separated by pipes
    assert "&#124;" in agent[3] and _plain(agent[3]).startswith("random | shortest-path")


def test_the_page_uses_the_marker():
    assert "<!-- ovon:cli -->" in (ROOT / "docs" / "reference" / "cli.md").read_text()
