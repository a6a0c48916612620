"""Paths in commands and reports as tokens: the run root `$ROOT`, a dataset read from elsewhere `$EPISODES`
/ `$SCENES`, so that nothing names the machine it ran on and a command pastes into a shell after
`ROOT=... EPISODES=... SCENES=...`."""

from __future__ import annotations

import json
import re
import shlex
from typing import Any

from ovon.experiments.cells import Cell, Plan
from ovon.experiments.plan import display

ROOT_TOKEN, EPISODES_TOKEN, SCENES_TOKEN = "$ROOT", "$EPISODES", "$SCENES"
TOKENS = (ROOT_TOKEN, EPISODES_TOKEN, SCENES_TOKEN)


def path_tokens(plan: Plan) -> list[tuple[str, str]]:
    """(path, token) pairs that commands and reports write as a token: the run root as `$ROOT`, and a dataset
    read from elsewhere (`data.source: paths`) as `$EPISODES` / `$SCENES`."""
    pairs = [] if str(plan.root) in ("", ".") else [(str(plan.root), ROOT_TOKEN)]
    if plan.scale.data.source == "paths":
        pairs += [(str(plan.episodes_dir), EPISODES_TOKEN), (str(plan.scenes_dir), SCENES_TOKEN)]
    return sorted(pairs, key=lambda p: -len(p[0]))  # the most specific path first


def _tokenised(path: str, pairs: list[tuple[str, str]]) -> str:
    for prefix, token in pairs:
        if path == prefix or path.startswith(prefix.rstrip("/") + "/"):
            return token + path[len(prefix.rstrip("/")) :]
    return path


def _portable(plan: Plan, arg: str) -> str:
    """`arg` with a leading root or dataset path (or a `key=` value starting with one) written as its token."""
    pairs = path_tokens(plan)
    whole = _tokenised(arg, pairs)
    if whole != arg:
        return whole
    key, eq, value = arg.partition("=")
    return key + eq + _tokenised(value, pairs) if eq else arg


def portable_text(plan: Plan, text: str) -> str:
    """Free text (a status detail) with every root or dataset path in it written as its token."""
    for prefix, token in path_tokens(plan):
        text = re.sub(re.escape(prefix.rstrip("/")) + r"(?=/|$|[\s,;:)'\"])", lambda _m, t=token: t, text)
    return text


def shell_word(arg: str) -> str:
    """`arg` quoted for a POSIX shell, leaving the path tokens expandable: `$ROOT/cpu/train/x` stays bare
    (or double-quoted around other special characters), so a command can be pasted after `ROOT=...`."""
    plain = arg
    for token in TOKENS:
        plain = plain.replace(token, "T")
    if plain == arg or "$" in plain:
        return shlex.quote(arg)
    if shlex.quote(plain) == plain:
        return arg
    return f'"{arg}"' if not any(c in plain for c in '"\\`') else shlex.quote(arg)


def portable_display(plan: Plan, cell: Cell, argv: list[str]) -> str:
    """The command as `display` writes it, with its paths written as tokens (see `path_tokens`)."""
    return " ".join([display(cell, []), *(shell_word(_portable(plan, a)) for a in argv)])


def full_commands(plan: Plan, cell: Cell) -> list[str]:
    """The cell's commands, rendered from it, as text with the root written `$ROOT` and a dataset outside
    it `$EPISODES` / `$SCENES` (moving either changes nothing): for display, records and reports."""
    return [portable_display(plan, cell, argv) for argv in cell.commands]


def tokenised_values(plan: Plan, value: Any) -> Any:
    """A JSON-able value (a resolved config) with every root or dataset path in its strings as its token."""
    value = json.loads(json.dumps(value, default=str))
    pairs = path_tokens(plan)

    def walk(v: Any) -> Any:
        if isinstance(v, dict):
            return {k: walk(x) for k, x in v.items()}
        if isinstance(v, list):
            return [walk(x) for x in v]
        return _tokenised(v, pairs) if isinstance(v, str) else v

    return walk(value)
