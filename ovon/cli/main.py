"""Entry point of the `ovon` command. Each sub-command group lives in its own `ovon.cli.<group>` module
exposing `register(subparsers)`; handlers are `func(args) -> int`."""

from __future__ import annotations

import argparse
import importlib
import sys

GROUPS = ["scenes", "sim", "dataset", "evaluate", "train", "demo", "experiment"]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="ovon", description=__doc__.splitlines()[0])
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


def main(argv: list[str] | None = None) -> int:
    from ovon.config.base import ConfigError

    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (ConfigError, FileNotFoundError, ValueError, KeyError) as e:
        msg = e.args[0] if isinstance(e, KeyError) and e.args else e
        print(f"ovon: error: {msg}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
