"""Entry point of the `ovon` command. Each sub-command group lives in its own `ovon.cli.<group>` module
exposing `register(subparsers)`; handlers are `func(args) -> int`.

Errors are one line on stderr (`ovon: error: ...`, exit 2): bad input is refused by the config domains,
the agent check, the dataset readers and the run folder before any work; an OSError naming a path (an
output under an existing file, a missing or unreadable file) is one line naming that path. Warnings
(skipped episodes, records set aside) are one line each (`ovon: warning: ...`). An exception nobody
anticipated is still one line, marked as an internal error, with its traceback behind OVON_DEBUG=1."""

from __future__ import annotations

import argparse
import errno
import importlib
import os
import signal
import sys
import warnings
from pathlib import Path

GROUPS = ["scenes", "sim", "dataset", "evaluate", "compare", "serve", "train", "perception", "demo", "experiment"]


DESCRIPTION = (
    "ovon: the HM3D-OVON open-vocabulary object-navigation benchmark (arXiv 2409.14296). Make scenes and "
    "episodes, evaluate an agent on the val splits, train the baselines, compare runs. "
    "`ovon COMMAND --help` shows a command's options."
)


def shown_default(default: object) -> str | None:
    """A default as `--help` and the CLI reference show it, None when there is nothing to show."""
    if default is None or default is argparse.SUPPRESS or default is False or default in ([], "", ()):
        return None
    if isinstance(default, list | tuple):
        return " ".join(str(d) for d in default)
    return str(default)


class DefaultsFormatter(argparse.HelpFormatter):
    """Help that ends with the option's default, unless the help already says it (or there is none)."""

    def _get_help_string(self, action: argparse.Action) -> str:
        help_ = action.help or ""
        shown = shown_default(action.default)
        if shown is None or "default" in help_.lower() or not (action.option_strings or action.nargs in "?*"):
            return help_
        return f"{help_} (default: {shown.replace('%', '%%')})"


class OneLineParser(argparse.ArgumentParser):
    """argparse prints the usage block before its error; one line naming the option is enough. Help shows
    each option's default."""

    def __init__(self, *args, **kwargs) -> None:
        kwargs.setdefault("formatter_class", DefaultsFormatter)
        super().__init__(*args, **kwargs)

    def error(self, message: str):  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {_did_you_mean(message)} (see {self.prog} --help)\n")


def _did_you_mean(message: str) -> str:
    """argparse's "invalid choice: 'evalute' (choose from ...)" with the closest choice suggested."""
    import difflib
    import re

    m = re.match(r"argument (\S+): invalid choice: '([^']*)' \(choose from (.*)\)$", message)
    if m is None:
        return message
    choices = re.findall(r"'([^']*)'", m.group(3)) or [c.strip() for c in m.group(3).split(",")]
    close = difflib.get_close_matches(m.group(2), choices, n=1)
    hint = f"; did you mean {close[0]}?" if close else ""
    what = f"argument {m.group(1)}: invalid choice" if m.group(1).startswith("-") else "unknown command"
    return f"{what} {m.group(2)!s} (expected one of {', '.join(choices)}){hint}"


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("ovon")
    except PackageNotFoundError:
        return "unknown (not installed; run `make install`)"


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(prog="ovon", description=DESCRIPTION)
    parser.add_argument("--version", action="version", version=f"ovon {_version()}", help="print the version and exit")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in GROUPS:
        try:
            module = importlib.import_module(f"ovon.cli.{name}")
        except ModuleNotFoundError as e:
            if e.name == f"ovon.cli.{name}":
                continue
            raise
        module.register(sub)
    return parser


def _one_line(msg: object) -> str:
    return " ".join(str(msg).split())


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"ovon: warning: {_one_line(message)}", file=sys.stderr)


def expected_errors() -> tuple[type[BaseException], ...]:
    """Exceptions that carry a message written for the user (the command's input was wrong)."""
    from ovon.config.base import ConfigError
    from ovon.parallel import WorkerDied

    errors: tuple[type[BaseException], ...] = (
        ConfigError,
        ValueError,
        KeyError,
        FileNotFoundError,
        FileExistsError,
        NotADirectoryError,
        IsADirectoryError,
        PermissionError,
        WorkerDied,
    )
    remote = sys.modules.get("ovon_agent")  # a served agent that failed, hung or went away (its own line)
    return errors + ((remote.RemoteError,) if remote is not None else ())


def _terminated(signum, frame) -> None:
    # once: a second SIGTERM (a process group's stop, then the experiment runner's own) must not cut the
    # clean-up that the first one started
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    raise KeyboardInterrupt


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    # SIGTERM (kill, cluster schedulers, `timeout`) stops a command as Ctrl-C does: its env workers are shut
    # down and their shared memory freed, and the same command resumes it. The default action would kill
    # this process alone and leave the shared memory behind
    try:
        previous = signal.signal(signal.SIGTERM, _terminated)
    except ValueError:  # not the main thread: leave signals alone
        previous = None
    try:
        return _run(args)
    finally:
        # after a SIGTERM it stays ignored until the process exits (a late second one would kill it mid-exit)
        if previous is not None and signal.getsignal(signal.SIGTERM) is _terminated:
            signal.signal(signal.SIGTERM, previous)


# Options naming where a command writes. Given empty they would name the current folder (Path("") is
# Path(".")) and a run's files would be scattered there: refused for every command, before its own checks
# (a library function given Path("") cannot tell it from an intended ".").
OUTPUT_OPTIONS = {"out": "--out", "root": "--root"}


def check_output_options(args: argparse.Namespace) -> None:
    """Refuse an output option given as "" (or blanks), one line naming it."""
    from ovon.atomic import check_output_path

    for dest, flag in OUTPUT_OPTIONS.items():
        value = getattr(args, dest, None)
        if isinstance(value, str) and not value.strip():
            check_output_path(value, flag, expected="a path", example="PATH")


def _run(args: argparse.Namespace) -> int:
    debug = bool(os.environ.get("OVON_DEBUG"))
    with warnings.catch_warnings():
        if not debug:
            warnings.showwarning = _show_warning
        try:
            check_output_options(args)
            return int(args.func(args) or 0)
        except KeyboardInterrupt:
            print("ovon: interrupted (re-run the same command to resume)", file=sys.stderr)
            return 130
        except MemoryError:
            if debug:
                raise
            print(
                "ovon: error: out of memory; fix: smaller settings (e.g. --set sim.camera.width=160) or fewer "
                "--workers",
                file=sys.stderr,
            )
            return 2
        except Exception as e:  # noqa: BLE001 - last resort: still one line, marked as a bug when it is one
            if debug:
                raise
            line = user_error(e)
            if line is not None:
                print(f"ovon: error: {_one_line(line)}", file=sys.stderr)
                return 2
            print(
                f"ovon: internal error: {type(e).__name__}: {_one_line(e)[:300]} (a bug in ovon: please report it; "
                "OVON_DEBUG=1 shows the traceback)",
                file=sys.stderr,
            )
            return 3


def user_error(e: BaseException) -> str | None:
    """The one-line message of an error caused by the command's input or its environment (a bad path, a
    full disk), None for a bug. An OSError that names a path is the user's: the path is theirs."""
    if isinstance(e, OSError) and e.filename:
        return os_error_line(e)
    if isinstance(e, OSError) and e.errno in (errno.ENOSPC, errno.EDQUOT):
        return f"{e.strerror or e}; fix: free disk space (or choose an output folder on another disk)"
    if isinstance(e, expected_errors()):
        return e.args[0] if isinstance(e, KeyError) and e.args else str(e)
    vector = sys.modules.get("ovon.env.vector")
    if vector is not None and isinstance(e, getattr(vector, "WorkerError", ())):
        return str(e)  # an env's own one-line error
    return None


def os_error_line(e: OSError) -> str:
    """An OSError naming a path as one line: the path, what is wrong with it, the fix. The usual cause of
    FileExistsError / NotADirectoryError is an output path under an existing file (`--out f/x.png` with
    `f` a file): that file is named."""
    path = os.fsdecode(e.filename)
    blocker = _file_in_the_way(path) if isinstance(e, FileExistsError | NotADirectoryError) else None
    if blocker is not None:
        where = f"{path} is" if blocker == path else f"{path}: {blocker} is"
        return f"{where} an existing file, not a folder; fix: choose another path (or move {blocker} away)"
    why = e.strerror or type(e).__name__
    other = f" -> {os.fsdecode(e.filename2)}" if e.filename2 else ""
    if isinstance(e, FileNotFoundError):
        fix = "check the path (and the folder the command runs in, for a relative path)"
    elif isinstance(e, IsADirectoryError):
        fix = "pass the path of a file, not of a folder"
    elif isinstance(e, PermissionError):
        fix = "choose a path you can write / read"
    else:
        fix = "check the path, or choose another one"
    return f"{path}{other}: {why}; fix: {fix}"


def _file_in_the_way(path: str) -> str | None:
    """The path itself or the folder above it that exists and is not a folder, None when there is none."""
    p = Path(path)
    for a in (p, *p.parents):
        if os.path.lexists(a):
            return None if a.is_dir() else str(a)
    return None


if __name__ == "__main__":
    sys.exit(main())
