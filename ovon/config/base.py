"""Typed dataclass configs: YAML files, presets, `key=value` overrides, and declared field domains.

Why: every number of the paper is a config value; a wrong key or an out-of-domain value must fail
loudly, before any work, with ONE line naming the key, the value, what is accepted and how to fix it
(a negative success distance used to score every episode 0% without a word).

Declaring a domain (the one mechanism; `validate` checks it, and so does every `build` / `from_dict` /
`merge`)::

    @dataclass(frozen=True)
    class CameraConfig:
        width: int = in_range(360, 1, 4096)          # an integer in [1, 4096]
        hfov_deg: float = in_range(42.0, 0, 180, lo_open=True, hi_open=True)
        min_depth: float = non_negative(0.5)
        max_depth: float = positive(5.0)
        rules: ClassVar = (less("min_depth", "max_depth"),)   # relations between fields

Field helpers: `positive`, `non_negative`, `in_range`, `one_of`, `non_empty(each=...)`, `each`,
`existing_file`, `existing_dir`, or `constrained(default, Domain)` for any `Domain`. Types are checked
too (an int field refuses 1.5 and true, a float field refuses nan and inf, a `Literal` lists its choices,
a str field takes a `pathlib.Path` and `validate` stores its str), so a field without a helper still has
the domain of its type. `flag="--episodes"` names the command-line
option that sets a field (used in the fix of the message instead of `--set key=`).
"""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import difflib
import math
import os
import re
import types
import typing
from collections.abc import Callable, Iterator, Mapping
from dataclasses import MISSING
from pathlib import Path
from typing import Any, TypeVar

import yaml

T = TypeVar("T")


class ConfigError(ValueError):
    """A config key, value or file is wrong; the message says which and how to fix it."""


# ----------------------------------------------------------------------------------------------------
# domains


class Domain:
    """A set of accepted values. `accepts(v)` for a value already of the field's type; `describe(noun)`
    says it in words given the type's noun ("an integer" -> "an integer > 0")."""

    def accepts(self, value: Any) -> bool:  # pragma: no cover - interface
        raise NotImplementedError

    def describe(self, noun: str) -> str:  # pragma: no cover - interface
        raise NotImplementedError


def _num(x: float) -> str:
    return f"{x:g}" if isinstance(x, float) else str(x)


@dataclasses.dataclass(frozen=True)
class Range(Domain):
    """lo <= v <= hi (either bound may be open or None)."""

    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False

    def accepts(self, value: Any) -> bool:
        if self.lo is not None and (value < self.lo or (self.lo_open and value == self.lo)):
            return False
        return not (self.hi is not None and (value > self.hi or (self.hi_open and value == self.hi)))

    def describe(self, noun: str) -> str:
        if self.hi is None:
            return f"{noun} {'>' if self.lo_open else '>='} {_num(self.lo)}" if self.lo is not None else noun
        if self.lo is None:
            return f"{noun} {'<' if self.hi_open else '<='} {_num(self.hi)}"
        return f"{noun} in {'(' if self.lo_open else '['}{_num(self.lo)}, {_num(self.hi)}{')' if self.hi_open else ']'}"


def Positive() -> Range:  # noqa: N802 - reads as a domain name
    return Range(0, None, lo_open=True)


def NonNegative() -> Range:  # noqa: N802
    return Range(0, None)


@dataclasses.dataclass(frozen=True)
class OneOf(Domain):
    choices: tuple

    def accepts(self, value: Any) -> bool:
        return value in self.choices

    def describe(self, noun: str) -> str:
        return "one of " + ", ".join(repr(c) for c in self.choices)


@dataclasses.dataclass(frozen=True)
class NonEmpty(Domain):
    """A non-empty string or sequence; `each` (optional) is the domain of every element; `distinct`: no
    element twice (`--seeds 0,0` would run every episode twice)."""

    each: Domain | None = None
    distinct: bool = False

    def accepts(self, value: Any) -> bool:
        if isinstance(value, str):
            return value.strip() != ""
        if self.distinct and len(set(value)) != len(value):
            return False
        return len(value) > 0 and (self.each is None or all(self.each.accepts(v) for v in value))

    def describe(self, noun: str) -> str:
        if noun == "a string":
            return "a non-empty string"
        inner = noun.removeprefix("a list of ")
        inner = self.each.describe(inner) if self.each else inner
        return f"a non-empty list of {'distinct ' if self.distinct else ''}{inner}"


@dataclasses.dataclass(frozen=True)
class Pattern(Domain):
    """A string matching `regex` entirely (e.g. a name that cannot climb out of a folder)."""

    regex: str
    text: str

    def accepts(self, value: Any) -> bool:
        return isinstance(value, str) and re.fullmatch(self.regex, value) is not None and value not in (".", "..")

    def describe(self, noun: str) -> str:
        return self.text


@dataclasses.dataclass(frozen=True)
class Each(Domain):
    """Every element of a (possibly empty) sequence lies in `domain`."""

    domain: Domain

    def accepts(self, value: Any) -> bool:
        return all(self.domain.accepts(v) for v in value)

    def describe(self, noun: str) -> str:
        return "a list of " + self.domain.describe(noun.removeprefix("a list of "))


@dataclasses.dataclass(frozen=True)
class ExistingPath(Domain):
    """A path that exists (a file or a folder); `optional`: "" (or None) means "not given"."""

    kind: str = "file"  # file | dir | any (a file or a folder)
    optional: bool = False
    empty: str = "for none"  # what an empty value means, for messages (e.g. "with --task pointnav")

    def accepts(self, value: Any) -> bool:
        if value in ("", None):
            return self.optional
        p = Path(str(value)).expanduser()
        if self.kind == "any":
            return p.exists()
        return p.is_file() if self.kind == "file" else p.is_dir()

    def describe(self, noun: str) -> str:
        if noun == "strings":  # an element of a list
            return "existing files" if self.kind == "file" else "existing folders"
        what = {"file": "an existing file", "dir": "an existing folder"}.get(self.kind, "an existing file or folder")
        return what + (f" (or empty {self.empty})" if self.optional else "")


def ExistingFile(optional: bool = False) -> ExistingPath:  # noqa: N802
    return ExistingPath("file", optional)


def ExistingDir(optional: bool = False, empty: str = "for none") -> ExistingPath:  # noqa: N802
    return ExistingPath("dir", optional, empty)


@dataclasses.dataclass(frozen=True)
class Rule:
    """A relation between fields of one config, e.g. `min_depth < max_depth`."""

    keys: tuple[str, ...]
    test: Callable[..., bool]
    expected: str

    def holds(self, cfg: Any) -> bool:
        return bool(self.test(*(self.value(cfg, k) for k in self.keys)))

    @staticmethod
    def value(cfg: Any, key: str) -> Any:
        """A key of this config or, dotted, of a nested one (`ppo.minibatches`)."""
        for part in key.split("."):
            cfg = getattr(cfg, part)
        return cfg


def less(a: str, b: str, strict: bool = True) -> Rule:
    op = "<" if strict else "<="
    return Rule((a, b), (lambda x, y: x < y) if strict else (lambda x, y: x <= y), f"{a} {op} {b}")


def rule(keys: tuple[str, ...], test: Callable[..., bool], expected: str) -> Rule:
    return Rule(tuple(keys), test, expected)


# ----------------------------------------------------------------------------------------------------
# field helpers: `width: int = positive(360)`


def constrained(
    default: Any = MISSING, domain: Domain | None = None, *, default_factory: Any = MISSING, flag: str | None = None
) -> Any:
    """A dataclass field whose values must lie in `domain` (checked by `validate`)."""
    meta = {"domain": domain, "flag": flag}
    if default_factory is not MISSING:
        return dataclasses.field(default_factory=default_factory, metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


def domain_of(cls: type, name: str) -> Domain:
    """The declared domain of field `name` of config `cls` (so an option that sets it shares it)."""
    return {f.name: f for f in dataclasses.fields(cls)}[name].metadata["domain"]


def positive(default: Any = MISSING, **kw: Any) -> Any:
    return constrained(default, Positive(), **kw)


def non_negative(default: Any = MISSING, **kw: Any) -> Any:
    return constrained(default, NonNegative(), **kw)


def in_range(
    default: Any, lo: float | None, hi: float | None, *, lo_open: bool = False, hi_open: bool = False, **kw: Any
) -> Any:
    return constrained(default, Range(lo, hi, lo_open, hi_open), **kw)


def one_of(default: Any, *choices: Any, **kw: Any) -> Any:
    return constrained(default, OneOf(tuple(choices)), **kw)


def non_empty(default: Any = MISSING, each: Domain | None = None, distinct: bool = False, **kw: Any) -> Any:
    return constrained(default, NonEmpty(each, distinct), **kw)


def each(default: Any, domain: Domain, **kw: Any) -> Any:
    return constrained(default, Each(domain), **kw)


def existing_file(default: Any = "", optional: bool = False, **kw: Any) -> Any:
    return constrained(default, ExistingPath("file", optional), **kw)


def existing_dir(default: Any = "", optional: bool = False, **kw: Any) -> Any:
    return constrained(default, ExistingPath("dir", optional), **kw)


# ----------------------------------------------------------------------------------------------------
# types: coercion from YAML / strings, and the check of values built in Python


def _field_types(cls: type) -> dict[str, Any]:
    hints = typing.get_type_hints(cls)
    return {f.name: hints[f.name] for f in dataclasses.fields(cls)}


def _is_union(tp: Any) -> bool:
    return typing.get_origin(tp) in (typing.Union, types.UnionType)


def _noun(tp: Any) -> str:
    """The type in words, for messages."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if _is_union(tp):
        inner = [a for a in args if a is not type(None)]
        return " or ".join(_noun(a) for a in inner)
    if origin is typing.Literal:
        return "one of " + ", ".join(repr(a) for a in args)
    if origin in (list, tuple):
        if origin is tuple and args and args[-1] is not Ellipsis:
            return f"{len(args)} values ({', '.join(_noun(a) for a in args)})"
        inner = _noun(args[0]) if args else "values"
        return "a list of " + _plural(inner)
    if origin is dict or tp is dict:
        return "a mapping"
    if dataclasses.is_dataclass(tp):
        return f"a mapping of {tp.__name__} fields"
    return {int: "an integer", float: "a number", bool: "true or false", str: "a string"}.get(tp, str(tp))


def _plural(noun: str) -> str:
    for a, b in (("an integer", "integers"), ("a number", "numbers"), ("a string", "strings")):
        if noun.startswith(a):
            return b + noun[len(a) :]
    return noun


class _TypeMismatch(Exception):
    pass


def _coerce(value: Any, tp: Any, where: str = "") -> Any:
    """`value` (from YAML, a `--set` string or Python) as type `tp`; raises _TypeMismatch (or a ConfigError
    naming the nested key for a config inside a list)."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if dataclasses.is_dataclass(tp):
        if isinstance(value, tp):
            return value
        if not isinstance(value, Mapping):
            raise _TypeMismatch
        return _from_dict(tp, value, where)
    if _is_union(tp):
        if value is None and type(None) in args:
            return None
        if isinstance(value, str) and value.strip().lower() in ("none", "null", "~") and type(None) in args:
            return None
        for a in args:
            if a is type(None):
                continue
            try:
                return _coerce(value, a, where)
            except _TypeMismatch:
                continue
        raise _TypeMismatch
    if origin is typing.Literal:
        for a in args:
            if value == a and type(value) is type(a):
                return a
            if isinstance(a, str) is False and isinstance(value, str) and str(a) == value:
                return a
        raise _TypeMismatch
    if origin in (list, tuple):
        if isinstance(value, str):
            value = [v.strip() for v in value.split(",") if v.strip() != ""]
        if not isinstance(value, list | tuple):
            raise _TypeMismatch
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(args) != len(value):
                raise _TypeMismatch
            return tuple(_coerce(v, a, f"{where}[{i}]") for i, (v, a) in enumerate(zip(value, args)))
        inner = args[0] if args else Any
        out = [_coerce(v, inner, f"{where}[{i}]") for i, v in enumerate(value)]
        return tuple(out) if origin is tuple else out
    if origin is dict or tp is dict:
        if not isinstance(value, dict):
            raise _TypeMismatch
        return dict(value)
    if tp is bool:
        if isinstance(value, bool):
            return value
        if isinstance(value, str) and value.strip().lower() in ("true", "1", "yes", "on"):
            return True
        if isinstance(value, str) and value.strip().lower() in ("false", "0", "no", "off"):
            return False
        raise _TypeMismatch
    if tp is int:
        if isinstance(value, bool):
            raise _TypeMismatch
        if isinstance(value, int):
            return value
        try:
            f = float(value)
        except (TypeError, ValueError, OverflowError):
            raise _TypeMismatch from None
        if not math.isfinite(f) or f != int(f):
            raise _TypeMismatch
        return int(f)
    if tp is float:
        if isinstance(value, bool):
            raise _TypeMismatch
        try:
            f = float(value)
        except (TypeError, ValueError, OverflowError):
            raise _TypeMismatch from None
        if not math.isfinite(f):
            raise _TypeMismatch
        return f
    if tp is str:
        if isinstance(value, dict | list | tuple):
            raise _TypeMismatch
        return "" if value is None else str(value)
    return value


def _type_ok(value: Any, tp: Any) -> bool:
    """Whether a value built in Python (not parsed) is of type `tp` (ints where ints, finite floats)."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if dataclasses.is_dataclass(tp):
        return isinstance(value, tp)
    if _is_union(tp):
        return any(_type_ok(value, a) for a in args)
    if tp is type(None):
        return value is None
    if origin is typing.Literal:
        return any(value == a and type(value) is type(a) for a in args)
    if origin in (list, tuple):
        if not isinstance(value, list | tuple):
            return False
        if origin is tuple and args and args[-1] is not Ellipsis:
            return len(args) == len(value) and all(_type_ok(v, a) for v, a in zip(value, args))
        return not args or all(_type_ok(v, args[0]) for v in value)
    if origin is dict or tp is dict:
        return isinstance(value, dict)
    if tp is bool:
        return isinstance(value, bool)
    if tp is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if tp is float:
        return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
    if tp is str:
        # a path object (pathlib.Path) where a path is a str field: `validate` stores it as its str
        return isinstance(value, str) or _str_path(value) is not None
    return True


def _str_path(value: Any) -> str | None:
    """`value` as the str it stands for when it is a path object (os.PathLike giving a str), else None.
    Why: `from_dict` reads `Path(...)` into a str field, so a config built in Python must take it too (a
    Path for `data=` was refused as "not an existing folder" although the folder existed)."""
    if isinstance(value, str) or not isinstance(value, os.PathLike):
        return None
    text = os.fspath(value)
    return text if isinstance(text, str) else None


def _accepts_str(tp: Any) -> bool:
    return tp is str or (_is_union(tp) and str in typing.get_args(tp))


def _paths_as_str(cfg: Any) -> None:
    """Replace path objects held by str fields of the config tree `cfg` with their str (in place, frozen
    configs included): what a config holds is written to JSON files (run identities) and compared as text."""
    if not dataclasses.is_dataclass(cfg) or isinstance(cfg, type):
        return
    hints = _field_types(type(cfg))
    for f in dataclasses.fields(cfg):
        value, tp = getattr(cfg, f.name), hints[f.name]
        text = _str_path(value) if _accepts_str(tp) else None
        if text is not None:
            object.__setattr__(cfg, f.name, text)
        elif dataclasses.is_dataclass(value):
            _paths_as_str(value)
        elif isinstance(value, list | tuple):
            args = typing.get_args(tp)
            if typing.get_origin(tp) in (list, tuple) and args and args[0] is str:  # list[str], tuple[str, ...]
                if any(_str_path(v) is not None for v in value):
                    object.__setattr__(cfg, f.name, type(value)(_str_path(v) or v for v in value))
            for v in value:
                _paths_as_str(v)


# ----------------------------------------------------------------------------------------------------
# messages

# Where the values being checked come from, for the fix a message suggests: a command line (None: `--set
# KEY=VALUE`) or a definition file (`edit FILE at KEY`). Keys of a file that no command reads with --set
# (an experiment's findings, cells.yaml) would otherwise get a fix the user cannot apply.
_VALUES_FILE: contextvars.ContextVar[str | None] = contextvars.ContextVar("ovon_values_file", default=None)


@contextlib.contextmanager
def values_from_file(path: str | Path) -> Iterator[None]:
    """Within the block, messages name a value as `FILE:KEY` and its fix as `edit FILE at KEY`: for
    configs read from the file `path` with a `where` that starts with it ("main.yaml",
    "cells.yaml:train.dagger")."""
    token = _VALUES_FILE.set(str(path))
    try:
        yield
    finally:
        _VALUES_FILE.reset(token)


# Or an option that passes KEY=VALUE pairs to a config (`--agent-arg`): messages then name the value as
# `--agent-arg KEY` and its fix as `--agent-arg KEY=VALUE` (an agent's settings cannot be --set).
_VALUES_OPTION: contextvars.ContextVar[str | None] = contextvars.ContextVar("ovon_values_option", default=None)


@contextlib.contextmanager
def values_from_option(option: str) -> Iterator[None]:
    """Within the block, messages name a value as `OPTION KEY` and its fix as `OPTION KEY=VALUE`: for configs
    built from the KEY=VALUE pairs of one command-line option (an agent's `--agent-arg`, which are also its
    keyword arguments in Python)."""
    token = _VALUES_OPTION.set(option)
    try:
        yield
    finally:
        _VALUES_OPTION.reset(token)


def _in_file(key: str) -> tuple[str, str] | None:
    """(file, key inside the file) inside `values_from_file`, else None (the key is --set on a command line)."""
    source = _VALUES_FILE.get()
    if source is None:
        return None
    for sep in (":", "."):
        if key.startswith(source + sep):
            return source, key[len(source) + 1 :]
    return source, key


def _shown_key(key: str) -> str:
    option = _VALUES_OPTION.get()
    if option is not None:
        return f"{option} {key}"
    found = _in_file(key)
    return key if found is None else f"{found[0]}:{found[1]}"


def _fix_value(key: str, expected: str) -> str:
    """The fix that gives `key` a value that is `expected`."""
    option = _VALUES_OPTION.get()
    if option is not None:
        return f"{option} {key}=VALUE with VALUE {expected}"
    found = _in_file(key)
    if found is None:
        return f"--set {key}=VALUE with VALUE {expected}"
    return f"edit {found[0]} at {found[1]} to {expected}"


def _fix_group(where: str) -> str:
    """The fix that sets the fields of the group `where` one by one."""
    option = _VALUES_OPTION.get()
    if option is not None:
        return f"{option} {where + '.' if where else ''}FIELD=VALUE"
    found = _in_file(where)
    if found is None:
        return f"--set {where + '.' if where else ''}FIELD=VALUE"
    return f"edit {found[0]} at {found[1] or 'its top level'}: write `FIELD: VALUE` lines under it"


def _short(v: Any) -> str:
    """repr of a value, head and tail kept when long (a path's file name is at its end)."""
    s = repr(v)
    return s if len(s) <= 120 else s[:50] + "..." + s[-60:]


def _expected(f: dataclasses.Field, tp: Any) -> str:
    dom: Domain | None = f.metadata.get("domain")
    base = tp
    optional = _is_union(tp) and type(None) in typing.get_args(tp)
    if optional:
        inner = [a for a in typing.get_args(tp) if a is not type(None)]
        base = inner[0] if len(inner) == 1 else tp
    noun = _noun(base)
    text = dom.describe(noun) if dom is not None else noun
    if optional:
        text += ", or leave it out" if f.metadata.get("flag") else ", or null"
    return text


def _default_of(f: dataclasses.Field) -> Any:
    if f.default is not MISSING:
        return f.default
    if f.default_factory is not MISSING:  # type: ignore[misc]
        try:
            return f.default_factory()  # type: ignore[misc]
        except Exception:  # noqa: BLE001 - only for the message
            return MISSING
    return MISSING


def _config_type(tp: Any) -> type | None:
    """The config class of a field typed `SomeConfig` or `SomeConfig | None`, else None."""
    if dataclasses.is_dataclass(tp):
        return tp
    if _is_union(tp):
        inner = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(inner) == 1 and dataclasses.is_dataclass(inner[0]):
            return inner[0]
    return None


def _not_a_config(owner: type, key: str, value: Any, sub: type) -> str:
    """A config field built in Python with something other than its config class (a dict, typically):
    `from_dict` reads mappings, a constructor does not."""
    kind = type(value).__name__
    got = f"{'an' if kind[:1].lower() in 'aeiou' else 'a'} {kind}"
    if isinstance(value, Mapping):
        how = (
            f"pass {sub.__name__}(...) there, or build the whole config with from_dict({owner.__name__}, "
            "{...}), which reads nested mappings"
        )
    else:
        how = f"pass {sub.__name__}(...) there"
    return f"{_shown_key(key)} = {_short(value)}: expected a {sub.__name__}, got {got}; fix: {how}"


def _violation(key: str, value: Any, f: dataclasses.Field, tp: Any) -> str:
    expected = _expected(f, tp)
    flag = f.metadata.get("flag")
    default = _default_of(f)
    hide = default is MISSING or default is None or default == "" or dataclasses.is_dataclass(default)
    shown = "" if hide else f" (default {_short(default)})"
    how = f"pass {flag} with {expected}" if flag else _fix_value(key, expected)
    return f"{flag or _shown_key(key)} = {_short(value)}: expected {expected}; fix: {how}{shown}"


def _check_keys(data: Mapping[Any, Any], valid: list[str], where: str, cls: type) -> None:
    """Refuse keys that are not strings (a YAML `1: 2`, a dict built in Python), then unknown keys."""
    odd = [k for k in data if not isinstance(k, str)]
    if odd:
        k = odd[0]
        raise ConfigError(
            f"config key {_short(k)} ({type(k).__name__}) of {where or cls.__name__} is not a name; "
            f"valid keys{' of ' + where if where else ''}: {', '.join(valid)}; fix: use those names "
            "(strings) as keys"
        )
    unknown = set(data) - set(valid)
    if unknown:
        raise _unknown(unknown, valid, where)


def _unknown(unknown: set[str], valid: list[str], where: str) -> ConfigError:
    hints = []
    for k in sorted(unknown):
        close = difflib.get_close_matches(k, valid, n=1)
        key = _shown_key(f"{where}.{k}" if where else k)
        hints.append(key + (f" (did you mean {close[0]!r}?)" if close else ""))
    return ConfigError(
        f"unknown config key(s) {', '.join(hints)}; valid keys{' of ' + where if where else ''}: {', '.join(valid)}"
    )


# ----------------------------------------------------------------------------------------------------
# validation


def violations(cfg: Any, where: str = "") -> list[str]:
    """Every out-of-domain value of a config tree, one message each (empty when valid)."""
    out: list[str] = []
    if not dataclasses.is_dataclass(cfg):
        return out
    hints = _field_types(type(cfg))
    bad_keys: set[str] = set()
    for f in dataclasses.fields(cfg):
        value = getattr(cfg, f.name)
        key = f"{where}.{f.name}" if where else f.name
        tp = hints[f.name]
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            if not _type_ok(value, tp):
                out.append(_violation(key, value, f, tp))
            out += violations(value, key)
            continue
        if not _type_ok(value, tp):
            sub = _config_type(tp)
            if sub is not None and not (value is None and type(None) in typing.get_args(tp)):
                out.append(_not_a_config(type(cfg), key, value, sub))
            else:
                out.append(_violation(key, value, f, tp))
            bad_keys.add(f.name)
            continue
        if isinstance(value, list | tuple | dict):  # configs inside lists / mappings have domains too
            items = value.items() if isinstance(value, dict) else enumerate(value)
            for i, v in items:
                if dataclasses.is_dataclass(v) and not isinstance(v, type):
                    out += violations(v, f"{key}[{i!r}]" if isinstance(value, dict) else f"{key}[{i}]")
        dom: Domain | None = f.metadata.get("domain")
        if dom is not None and value is not None and not dom.accepts(value):
            out.append(_violation(key, value, f, tp))
            bad_keys.add(f.name)
    for r in getattr(type(cfg), "rules", ()) or ():
        if bad_keys.intersection(k.split(".")[0] for k in r.keys):
            continue
        if not r.holds(cfg):
            prefix = f"{where}." if where else ""
            values = ", ".join(f"{_shown_key(prefix + k)} = {_short(Rule.value(cfg, k))}" for k in r.keys)
            expected = " ".join(f"{prefix}{t}" if t in r.keys else t for t in r.expected.split(" "))
            found = _in_file(prefix + r.keys[0])
            option = _VALUES_OPTION.get()
            how = (
                f"pass {option} KEY=VALUE for them"
                if option is not None
                else "--set the values"
                if found is None
                else f"edit {found[0]}"
            )
            out.append(f"{values}: expected {expected}; fix: {how} so that {expected} holds")
    return out


def validate(cfg: T, where: str = "") -> T:
    """Raise one ConfigError (one line) naming every field outside its domain; returns `cfg` when valid.

    Every command calls this (through `build`, `from_dict` or `merge`, or directly) before any work. Path
    objects in str fields are stored as their str (in place), as `from_dict` does."""
    problems = violations(cfg, where)
    if problems:
        raise ConfigError(
            problems[0] if len(problems) == 1 else f"{len(problems)} invalid config values: " + " | ".join(problems)
        )
    _paths_as_str(cfg)
    return cfg


# ----------------------------------------------------------------------------------------------------
# building


def _coerce_field(cls: type, f: dataclasses.Field, tp: Any, value: Any, key: str) -> Any:
    if dataclasses.is_dataclass(tp):
        if isinstance(value, tp):
            return value
        if not isinstance(value, dict):
            raise ConfigError(
                f"{_shown_key(key)} = {_short(value)}: expected a mapping of {tp.__name__} fields "
                f"({', '.join(x.name for x in dataclasses.fields(tp))}); fix: {_fix_group(key)}"
            )
        return _from_dict(tp, value, key)
    try:
        return _coerce(value, tp, key)
    except _TypeMismatch:
        raise ConfigError(_violation(key, value, f, tp)) from None


def _from_dict(cls: type[T], data: Mapping[str, Any], where: str) -> T:
    if not isinstance(data, Mapping):
        raise ConfigError(f"{where or cls.__name__} = {_short(data)}: expected a mapping of {cls.__name__} fields")
    types_ = _field_types(cls)
    _check_keys(data, sorted(types_), where, cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    kwargs = {k: _coerce_field(cls, fields[k], types_[k], v, f"{where}.{k}" if where else k) for k, v in data.items()}
    return cls(**kwargs)


def from_dict(cls: type[T], data: Mapping[str, Any], where: str = "") -> T:
    """Build `cls` from a (possibly partial) dict and validate it; unknown keys name the valid ones."""
    return validate(_from_dict(cls, data, where), where)


def from_args(cls: type[T], args: Any, **extra: Any) -> T:
    """A command's arguments (an argparse Namespace) as the dataclass `cls`, through `from_dict`: every
    field of `cls` found on `args` (None = not given: the default), plus `extra`. One mechanism for the
    options of a command and for config files: same coercion, same declared domains, same message."""
    names = {f.name for f in dataclasses.fields(cls)}
    data = {k: getattr(args, k) for k in names if getattr(args, k, None) is not None}
    data.update({k: v for k, v in extra.items() if v is not None})
    return from_dict(cls, data)


def to_dict(cfg: Any) -> dict[str, Any]:
    return dataclasses.asdict(cfg)


def _merge(cfg: T, data: Mapping[str, Any], where: str) -> T:
    if not isinstance(data, Mapping):
        raise ConfigError(
            f"{where or type(cfg).__name__} = {_short(data)}: expected a mapping of "
            f"{type(cfg).__name__} fields; fix: {_fix_group(where)}"
        )
    types_ = _field_types(type(cfg))
    _check_keys(data, sorted(types_), where, type(cfg))
    fields = {f.name: f for f in dataclasses.fields(cfg)}
    changes = {}
    for k, v in data.items():
        cur = getattr(cfg, k)
        key = f"{where}.{k}" if where else k
        if dataclasses.is_dataclass(cur) and isinstance(v, Mapping):
            changes[k] = _merge(cur, v, key)
        else:
            changes[k] = _coerce_field(type(cfg), fields[k], types_[k], v, key)
    return dataclasses.replace(cfg, **changes)


def merge(cfg: T, data: Mapping[str, Any], where: str = "") -> T:
    """A copy of `cfg` with the nested values of `data` replaced (deep merge), validated."""
    return validate(_merge(cfg, data, where), where)


def _yaml_scalar(raw: str) -> Any:
    """A `--set` value: YAML scalars (0.5, true, [1, 2]); anything YAML cannot read stays a string."""
    if raw == "":
        return ""
    try:
        return yaml.safe_load(raw)
    except (yaml.YAMLError, RecursionError, ValueError):
        return raw


def parse_overrides(items: list[str] | tuple[str, ...]) -> dict[str, Any]:
    """`["a.b=1", "c=x,y"]` -> nested dict; values parsed as YAML scalars (so 0.5, true, [1,2] work)."""
    out: dict[str, Any] = {}
    for item in items:
        if "=" not in item:
            raise ConfigError(f"override {item!r} is not of the form key=value; fix: e.g. --set sim.camera.width=72")
        key, raw = item.split("=", 1)
        parts = key.strip().split(".")
        if any(not p.strip() for p in parts):
            raise ConfigError(
                f"override {item!r}: empty key part in {key.strip()!r}; fix: e.g. --set sim.camera.width=72"
            )
        value = _yaml_scalar(raw)
        node = out
        for i, p in enumerate(parts[:-1]):
            nxt = node.setdefault(p, {})
            if not isinstance(nxt, dict):
                raise ConfigError(
                    f"override {item!r}: {'.'.join(parts[: i + 1])} is set both as a value and as "
                    "a group; fix: set each key once"
                )
            node = nxt
        if isinstance(node.get(parts[-1]), dict):
            raise ConfigError(
                f"override {item!r}: {key.strip()} is a group of keys; fix: set one of its fields, "
                f"e.g. --set {key.strip()}.FIELD=VALUE"
            )
        node[parts[-1]] = value
    return out


def load_yaml(path: str | Path) -> dict[str, Any]:
    path = Path(path)
    if path.is_dir():
        raise ConfigError(f"config file {path} is a folder, not a YAML file; fix: pass the path of a YAML file")
    if not path.is_file():
        raise ConfigError(f"config file {path} does not exist; fix: pass the path of a YAML file")
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8")) or {}
    except (yaml.YAMLError, UnicodeDecodeError, RecursionError) as e:
        first = " ".join(str(e).split())[:200]
        raise ConfigError(f"config file {path} is not valid YAML ({first}); fix: correct the file") from None
    if not isinstance(data, dict):
        raise ConfigError(
            f"config file {path} must hold a mapping of config keys at the top level, got "
            f"{type(data).__name__}; fix: write `key: value` lines"
        )
    return data


def check_config_file(path: str | None, keys: str) -> None:
    """`--config` names a folder: one line before any work (reading it would fail with an OS error)."""
    if path and Path(path).is_dir():
        raise ConfigError(
            f"--config {path!r} is a folder, not a YAML file; fix: pass the path of a YAML file of {keys} keys"
        )


def build(
    cls: type[T],
    preset: T | None = None,
    yaml_path: str | Path | None = None,
    overrides: list[str] | tuple[str, ...] = (),
) -> T:
    """Preset (or defaults) <- YAML file <- command-line overrides, in that order; validated."""
    cfg = preset if preset is not None else cls()
    if yaml_path is not None:
        try:
            cfg = validate(_merge(cfg, load_yaml(yaml_path), where=""))
        except ConfigError as e:
            msg = str(e)
            raise ConfigError(msg if msg.startswith("config file") else f"config file {yaml_path}: {msg}") from None
    if overrides:
        cfg = _merge(cfg, parse_overrides(list(overrides)), where="")
    return validate(cfg)


def parse_seed_list(text: str) -> list[int]:
    """`0-3,7` -> [0, 1, 2, 3, 7] (house seeds, `--procedural`)."""
    out: list[int] = []
    for part in (p.strip() for p in text.split(",") if p.strip()):
        a, _, b = part.partition("-")
        try:
            out += list(range(int(a), int(b) + 1)) if b else [int(a)]
        except ValueError:
            raise ValueError(f"seed list {text!r}: {part!r} is not an integer or a range like 0-7") from None
    return out
