"""`package.module:Name` loading, the one way users plug their own classes in (agents, detectors,
image-text scorers, point-goal navigators), and the one dispatch from a config value to a class: a
built-in's name looked up in its table (name -> `package.module:Class`), else the value itself.

Why one place: the module is looked up on `sys.path` and, for the `ovon` console script (which does not
put the working directory there), in the working directory, so `my_agent:MyAgent` next to the user's data
loads; and every failure is one line of the same shape.
"""

from __future__ import annotations

import importlib
import os
import sys
from types import ModuleType
from typing import Any


class PluginError(ValueError):
    """A `package.module:Name` that cannot be loaded; the message says which part failed."""


def import_module(module_name: str) -> ModuleType:
    """`importlib.import_module`, retried from the working directory when the top package is missing."""
    try:
        return importlib.import_module(module_name)
    except ModuleNotFoundError as e:
        if e.name and module_name.split(".")[0] == e.name.split(".")[0] and os.getcwd() not in sys.path:
            sys.path.append(os.getcwd())
            return importlib.import_module(module_name)
        raise


def is_spec(text: str) -> bool:
    """Whether `text` looks like `package.module:Name` (both parts non-empty)."""
    module, sep, name = str(text).partition(":")
    return bool(sep and module.strip() and name.strip())


def load_object(spec: str) -> Any:
    """The object `package.module:Name` (or `:Outer.Inner`) names; PluginError when it cannot be loaded."""
    module_name, sep, attr = str(spec).partition(":")
    if not is_spec(spec):
        raise PluginError(f"{spec!r} is not of the form package.module:Name")
    try:
        obj: Any = import_module(module_name)
    except Exception as e:  # noqa: BLE001 - any import failure of user code is reported in one line
        detail = " ".join(str(e).split())[:160]
        raise PluginError(f"cannot import module {module_name!r} ({type(e).__name__}: {detail})") from None
    for part in attr.split("."):
        if not hasattr(obj, part):
            raise PluginError(f"module {module_name!r} has no attribute {attr!r}")
        obj = getattr(obj, part)
    return obj


def lookup(name: str, table: dict[str, str]) -> str | None:
    """The `package.module:Name` that `name` stands for: its entry in `table` (the built-ins), or `name`
    itself when it has that form; None when it is neither."""
    target = table.get(name, name)
    return target if is_spec(target) else None


def load_named(name: str, table: dict[str, str], key: str) -> type:
    """The class config value `key` = `name` picks (a built-in by name, or `package.module:Class`); one
    PluginError line naming the key, the value and the valid names when it cannot."""
    fix = f"one of {list(table)} or package.module:Class"
    target = lookup(name, table)
    if target is None:
        raise PluginError(f"{key} = {name!r} is unknown; use {fix}")
    return load_class(target, key, fix)


def load_class(spec: str, key: str, fix: str) -> type:
    """`load_object` for a config value `key` that must name a class; one line naming key, value and fix."""
    import inspect

    try:
        obj = load_object(spec)
    except PluginError as e:
        raise PluginError(f"{key} = {spec!r}: {e}; fix: {fix}") from None
    if not inspect.isclass(obj):
        raise PluginError(f"{key} = {spec!r} is a {type(obj).__name__}, not a class; fix: {fix}")
    return obj
