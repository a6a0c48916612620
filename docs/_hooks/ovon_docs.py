"""MkDocs hook: the reference pages are generated from the code at build time, so they cannot drift.

- `<!-- ovon:cli -->` becomes every `ovon` command and option, read from the argparse parser
  (`ovon.cli.main.build_parser`).
- `<!-- ovon:config -->` becomes every config key of the user-facing configs, flattened to the dotted key
  `--set` takes, with its type, default, declared domain (`ovon.config.base`, the same words as the error
  messages) and the comment or docstring written beside the field.
- `benchmarks/README.md` is the page `benchmarks.md`, as it is.
- `<!-- ovon:looks -->` becomes the table of every shape family's looks (`ovon.scenes.procedural.looks`).
- `<!-- ovon:results -->` becomes the list of the committed experiment reports; each
  `experiments/results/<name>/report.md` is added to the site as it is, with its figures, as
  `results/<name>/report.md`.
- `<!-- ovon:headline -->` becomes the results tables of the committed reports
  (`ovon.experiments.headline`, the same text as the README's generated block).

Nothing here downloads anything. tests/test_docs_build.py imports this module too.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import html
import importlib
import inspect
import re
import textwrap
import typing
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "experiments" / "results"

# (class name, modules that may hold it, where its keys are set). The modules are tried in order, so a
# class that moves between them during a refactor is still found.
CONFIG_ROOTS: list[tuple[str, tuple[str, ...], str]] = [
    (
        "TrainConfig",
        ("ovon.train.config",),
        "`ovon train --set KEY=VALUE` (or a YAML file given as `--config`); `--preset` picks the starting values.",
    ),
    (
        "EvalConfig",
        ("ovon.evaluate.config", "ovon.evaluate.harness"),
        "`ovon evaluate`: the top-level keys are its options (`--agent`, `--splits`, ...); `--set` takes the "
        "`sim.*`, `task.*` and `remote.*` keys. In Python: `EvalConfig(...)`.",
    ),
    (
        "GenerationConfig",
        ("ovon.config.dataset", "ovon.dataset.config"),
        "`ovon dataset generate --set KEY=VALUE`; `--preset fast|paper` picks the starting values.",
    ),
    (
        "PolicyAgentArgs",
        ("ovon.agents.policy_agent",),
        "`ovon evaluate --agent policy --agent-arg KEY=VALUE`.",
    ),
    (
        "VLFMConfig",
        ("ovon.agents.modular.config",),
        "`ovon evaluate --agent vlfm --agent-arg KEY=VALUE` (`preset=cpu|paper` first, then any key).",
    ),
    (
        "DAgRLODConfig",
        ("ovon.agents.modular.config",),
        "`ovon evaluate --agent dagrl-od --agent-arg KEY=VALUE`.",
    ),
    (
        "Scale",
        ("ovon.experiments.definitions",),
        "`ovon experiment run --set KEY=VALUE` and the scales of `ovon/experiments/defs/scales.yaml`.",
    ),
]


# ----------------------------------------------------------------------------------------------------
# small helpers


def _cell(text: Any) -> str:
    """Text safe inside a Markdown table cell."""
    return " ".join(str(text).split()).replace("|", "\\|")


def _code(text: Any) -> str:
    s = str(text).replace("|", "\\|")
    return f"`` {s} ``" if "`" in s else f"`{s}`"


def find_class(name: str, modules: tuple[str, ...]) -> type:
    errors = []
    for module in modules:
        try:
            cls = getattr(importlib.import_module(module), name, None)
        except ImportError as e:
            errors.append(f"{module}: {e}")
            continue
        if cls is not None:
            return cls
    raise LookupError(f"config {name} is in none of {', '.join(modules)} ({'; '.join(errors)}); update CONFIG_ROOTS")


# ----------------------------------------------------------------------------------------------------
# the command line


def _commands(parser: argparse.ArgumentParser, prefix: str) -> list[tuple[str, argparse.ArgumentParser, str]]:
    """(full command, its parser, its one-line help) for the parser and every sub-command, depth first."""
    out: list[tuple[str, argparse.ArgumentParser, str]] = []
    for action in parser._actions:  # noqa: SLF001 - argparse keeps its sub-parsers only there
        if isinstance(action, argparse._SubParsersAction):  # noqa: SLF001
            helps = {a.dest: a.help or "" for a in action._choices_actions}  # noqa: SLF001
            for name, sub in action.choices.items():
                full = f"{prefix} {name}"
                out.append((full, sub, helps.get(name, "")))
                out += _commands(sub, full)
    return out


def _html_cell(text: Any) -> str:
    """Plain text safe inside a Markdown table cell: one line, HTML-escaped (a `<out>` placeholder stays
    visible), pipes as the entity so they never split the row."""
    escaped = html.escape(" ".join(str(text).split()), quote=False).replace("|", "&#124;")
    # a `code span` would show the entities literally: made an HTML <code> element instead
    return re.sub(r"`([^`]+)`", r"<code>\1</code>", escaped)


def _html_code(text: Any) -> str:
    return f"<code>{_html_cell(text)}</code>"


def option_help(action: argparse.Action, prog: str = "ovon") -> str:
    """An option's help as `--help` words it (its `%(default)s` style fields filled in)."""
    text = action.help or ""
    if "%" in text:
        try:
            text = text % {**vars(action), "prog": prog}
        except (KeyError, TypeError, ValueError):
            pass
    return text


def option_fields(action: argparse.Action) -> tuple[str, str, str, str]:
    """(option names, value it takes, default shown, help) of one argparse action, as plain text."""
    from ovon.cli.main import shown_default

    names = ", ".join(action.option_strings) if action.option_strings else (action.metavar or action.dest)
    if action.nargs == 0:  # store_true / store_false / count / version: a flag
        value = "flag"
    elif action.choices is not None:
        value = "one of " + ", ".join(str(c) for c in action.choices)
    else:
        value = str(action.metavar or action.dest.upper())
        if action.nargs in ("+", "*"):
            value += " ..."
    if action.required:
        value += " (required)"
    if isinstance(action, argparse._AppendAction):  # noqa: SLF001
        value += " (repeatable)"
    default = None if isinstance(action, argparse._VersionAction) else shown_default(action.default)  # noqa: SLF001
    return names, value, default or "", option_help(action)


def _option_row(action: argparse.Action) -> str:
    names, value, default, help_ = option_fields(action)
    shown = _html_code(default) if default else ""
    return f"| {_html_code(names)} | {_html_cell(value)} | {shown} | {_html_cell(help_)} |"


def cli_reference() -> str:
    """Every `ovon` command with its options, from the parser the `ovon` command runs."""
    from ovon.cli.main import build_parser

    parser = build_parser()
    lines = []
    for full, sub, help_ in _commands(parser, "ovon"):
        depth = full.count(" ")
        lines.append(f"{'#' * (depth + 1)} `{full}`\n")
        if help_ or sub.description:
            lines.append(_html_cell(sub.description or help_) + "\n")
        actions = [a for a in sub._actions if not isinstance(a, argparse._HelpAction | argparse._SubParsersAction)]  # noqa: SLF001
        if actions:
            lines.append("| option | value | default | what it does |")
            lines.append("|---|---|---|---|")
            lines += [_option_row(a) for a in actions]
            lines.append("")
    return "\n".join(lines)


def cli_commands() -> list[str]:
    """The full name of every command (for the docs tests)."""
    from ovon.cli.main import build_parser

    return [full for full, _, _ in _commands(build_parser(), "ovon")]


# ----------------------------------------------------------------------------------------------------
# the configs


def field_notes(cls: type) -> dict[str, str]:
    """The comment lines right above each field, its inline comment, or the string literal after it (an
    attribute docstring), from the class's source. Inherited fields come from the base class's source."""
    notes: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        if not dataclasses.is_dataclass(klass) or klass is object:
            continue
        try:
            lines, start = inspect.getsourcelines(klass)
        except (OSError, TypeError):
            continue
        source = textwrap.dedent("".join(lines))
        body = ast.parse(source).body[0]
        src = source.splitlines()
        stmts = getattr(body, "body", [])
        for i, node in enumerate(stmts):
            if not isinstance(node, ast.AnnAssign) or not isinstance(node.target, ast.Name):
                continue
            text: list[str] = []
            j = node.lineno - 2  # the line above, 0-based
            above: list[str] = []
            while j >= 0 and src[j].strip().startswith("#"):
                above.insert(0, src[j].strip().lstrip("#").strip())
                j -= 1
            text += above
            for k in range(node.lineno - 1, node.end_lineno):
                line = src[k]
                if "#" in line:
                    comment = _inline_comment(line)
                    if comment:
                        text.append(comment)
            nxt = stmts[i + 1] if i + 1 < len(stmts) else None
            if isinstance(nxt, ast.Expr) and isinstance(getattr(nxt, "value", None), ast.Constant):
                if isinstance(nxt.value.value, str):
                    text.append(inspect.cleandoc(nxt.value.value))
            if text:
                notes[node.target.id] = " ".join(" ".join(text).split())
    return notes


def _inline_comment(line: str) -> str:
    """The `# ...` comment at the end of a code line (not a `#` inside a string)."""
    import io
    import tokenize

    try:
        for tok in tokenize.generate_tokens(io.StringIO(line.strip() + "\n").readline):
            if tok.type == tokenize.COMMENT:
                return tok.string.lstrip("#").strip()
    except (tokenize.TokenError, IndentationError):
        return ""
    return ""


def _type_text(tp: Any) -> str:
    if isinstance(tp, type) and not typing.get_args(tp):
        return tp.__name__
    text = repr(tp).replace("typing.", "")
    for mod in ("ovon.", "builtins."):
        while mod in text:
            start = text.index(mod)
            end = start
            while end < len(text) and (text[end].isalnum() or text[end] in "._"):
                end += 1
            text = text[:start] + text[start:end].rsplit(".", 1)[-1] + text[end:]
    return text


def _default_text(value: Any) -> str:
    if value is dataclasses.MISSING:
        return "(required)"
    if isinstance(value, bool) or value is None:  # as `--set` and YAML write them
        return _code({True: "true", False: "false", None: "null"}[value])
    if isinstance(value, tuple):
        value = list(value)
    return _code(repr(value) if isinstance(value, str) else value)


def config_rows(cls: type, instance: Any, prefix: str = "") -> list[tuple[str, str, str, str, str]]:
    """(dotted key, type, default, domain, notes) of every leaf field of the config tree `cls`; defaults
    are those of `instance` (a nested config's default depends on its parent's default factory)."""
    from ovon.config import base

    hints = typing.get_type_hints(cls)
    notes = field_notes(cls)
    rows = []
    for f in dataclasses.fields(cls):
        key = f"{prefix}{f.name}"
        tp = hints[f.name]
        value = getattr(instance, f.name, dataclasses.MISSING) if instance is not None else dataclasses.MISSING
        sub = tp if dataclasses.is_dataclass(tp) else None
        if sub is not None and dataclasses.is_dataclass(value):
            rows += config_rows(sub, value, key + ".")
            continue
        domain = base._expected(f, tp)  # noqa: SLF001 - the words the error messages use
        rows.append((key, _type_text(tp), _default_text(value), domain, notes.get(f.name, "")))
    return rows


def _instance(cls: type) -> Any:
    try:
        return cls()
    except Exception:  # noqa: BLE001 - a config with required fields: no defaults to show
        return None


def config_reference() -> str:
    lines = []
    for name, modules, where in CONFIG_ROOTS:
        cls = find_class(name, modules)
        lines.append(f"## `{name}`\n")
        lines.append(f"Set with {where} Defined in `{cls.__module__}`.\n")
        doc = inspect.getdoc(cls)
        if doc and not doc.startswith(f"{name}("):
            lines.append(_cell(doc) + "\n")
        lines.append("| key | type | default | accepted values | notes |")
        lines.append("|---|---|---|---|---|")
        for key, tp, default, domain, notes in config_rows(cls, _instance(cls)):
            lines.append(f"| {_code(key)} | {_code(tp)} | {default} | {_cell(domain)} | {_cell(notes)} |")
        lines.append("")
    return "\n".join(lines)


def config_keys() -> dict[str, list[str]]:
    """Root name -> every dotted key (for the docs tests)."""
    out = {}
    for name, modules, _ in CONFIG_ROOTS:
        cls = find_class(name, modules)
        out[name] = [row[0] for row in config_rows(cls, _instance(cls))]
    return out


# ----------------------------------------------------------------------------------------------------
# results


def result_reports() -> list[Path]:
    return sorted(RESULTS.glob("*/report.md"))


def results_index() -> str:
    lines = []
    for report in result_reports():
        name = report.parent.name
        title = next(
            (ln[2:].strip() for ln in report.read_text(encoding="utf-8").splitlines() if ln.startswith("# ")), name
        )
        lines.append(f"- [`{name}`: {title}]({name}/report.md)")
    return "\n".join(lines) + "\n"


def headline_tables() -> str:
    from ovon.experiments.headline import headline

    return headline(RESULTS)  # the page is results/index.md: the reports sit beside it


# ----------------------------------------------------------------------------------------------------
# MkDocs events


MARKERS = {
    "<!-- ovon:cli -->": cli_reference,
    "<!-- ovon:config -->": config_reference,
    "<!-- ovon:results -->": results_index,
    "<!-- ovon:headline -->": lambda: headline_tables(),  # defined below
    "<!-- ovon:looks -->": lambda: looks_reference(),  # defined below
}


def on_files(files, config, **kwargs):  # noqa: ANN001, ANN201 - MkDocs' hook signature
    """Add each committed report and the files beside it (figures) as pages and assets under results/."""
    from mkdocs.structure.files import File

    for report in result_reports():
        folder = report.parent
        for path in sorted(folder.rglob("*")):
            if path.is_file() and (path == report or path.suffix in (".png", ".jpg", ".svg")):
                uri = f"results/{path.relative_to(RESULTS).as_posix()}"
                if files.get_file_from_path(uri) is None:
                    files.append(File.generated(config, uri, abs_src_path=str(path)))
    benchmarks = ROOT / "benchmarks" / "README.md"
    if benchmarks.is_file() and files.get_file_from_path("benchmarks.md") is None:
        files.append(File.generated(config, "benchmarks.md", abs_src_path=str(benchmarks)))
    return files


def looks_reference() -> str:
    """Every shape family with the look of each of its names (synonyms share one), from the generator."""
    from ovon.scenes.procedural.looks import look_of
    from ovon.scenes.vocabulary import load_vocabulary

    vocab = load_vocabulary()
    families: dict[str, list[str]] = {}
    for name in vocab.names:
        families.setdefault(vocab[name].family, []).append(name)
    lines = ["| family | look | names |", "|---|---|---|"]
    for family in sorted(families):
        looks: dict[str, list[str]] = {}
        for name in families[family]:
            looks.setdefault(look_of(vocab[name], vocab).describe(), []).append(name)
        for i, (look, names) in enumerate(sorted(looks.items(), key=lambda kv: kv[1][0])):
            lines.append(f"| {family if i == 0 else ''} | {_cell(look)} | {_cell(', '.join(names))} |")
    return "\n".join(lines)


def on_page_markdown(markdown, page, config, files, **kwargs):  # noqa: ANN001, ANN201
    for marker, make in MARKERS.items():
        if marker in markdown:
            markdown = markdown.replace(marker, make())
    return markdown
