"""Entry point of the `ovon` command. Each sub-command group lives in its own `ovon.cli.<group>` module
exposing `register(subparsers)`; handlers are `func(args) -> int`.

Errors are one line on stderr (`ovon: error: ...`, exit 2): bad input is refused by the config domains,
the agent check, the dataset readers and the run folder before any work. Warnings (skipped episodes,
records set aside) are one line each (`ovon: warning: ...`). An exception nobody anticipated is still one
line, marked as an internal error, with its traceback behind OVON_DEBUG=1."""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
import warnings

GROUPS = ["scenes", "sim", "dataset", "evaluate", "serve", "train", "demo", "experiment"]


class OneLineParser(argparse.ArgumentParser):
    """argparse prints the usage block before its error; one line naming the option is enough."""

    def error(self, message: str):  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(prog="ovon", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
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

    errors: tuple[type[BaseException], ...] = (ConfigError, ValueError, KeyError, FileNotFoundError,
                                               NotADirectoryError, IsADirectoryError, PermissionError, WorkerDied)
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


def _run(args: argparse.Namespace) -> int:
    debug = bool(os.environ.get("OVON_DEBUG"))
    with warnings.catch_warnings():
        if not debug:
            warnings.showwarning = _show_warning
        try:
            return int(args.func(args) or 0)
        except KeyboardInterrupt:
            print("ovon: interrupted (re-run the same command to resume)", file=sys.stderr)
            return 130
        except expected_errors() as e:
            if debug:
                raise
            msg = e.args[0] if isinstance(e, KeyError) and e.args else e
            if isinstance(e, PermissionError | IsADirectoryError | NotADirectoryError) and e.filename:
                msg = f"{e.filename}: {e.strerror}; fix: choose a path you can write / read"
            print(f"ovon: error: {_one_line(msg)}", file=sys.stderr)
            return 2
        except MemoryError:
            print("ovon: error: out of memory; fix: smaller settings (e.g. --set sim.camera.width=160) or fewer "
                  "--workers", file=sys.stderr)
            return 2
        except Exception as e:  # noqa: BLE001 - last resort: still one line, marked as a bug
            if debug:
                raise
            vector = sys.modules.get("ovon.env.vector")
            if vector is not None and isinstance(e, getattr(vector, "WorkerError", ())):
                print(f"ovon: error: {_one_line(e)}", file=sys.stderr)  # an env's own one-line error
                return 2
            print(f"ovon: internal error: {type(e).__name__}: {_one_line(e)[:300]} (a bug in ovon: please report it; "
                  "OVON_DEBUG=1 shows the traceback)", file=sys.stderr)
            return 3


if __name__ == "__main__":
    sys.exit(main())
