"""Atomic, byte-deterministic writers.

Why: generation runs per scene and must be resumable (a killed run never leaves a half-written shard
that a re-run would mistake for a finished one), and the same inputs + seed must give byte-identical
files (gzip stores a timestamp and a file name by default; both are suppressed here).
"""

from __future__ import annotations

import gzip
import io
import json
import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any, BinaryIO


def atomic_write_with(path: str | Path, write: Callable[[BinaryIO], Any]) -> Path:
    """Call `write(f)` on a temp file in the target folder, fsync, then `os.replace` it into place.

    The one atomic writer of the project: every file a run or a generator produces goes through it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    return path


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write `data` atomically (temp file + fsync + rename)."""
    return atomic_write_with(path, lambda f: f.write(data))


def atomic_write_text(path: str | Path, text: str) -> Path:
    return atomic_write_bytes(path, text.encode("utf-8"))


def json_dumps(obj: Any, indent: int | None = None) -> str:
    """Stable JSON text: insertion key order (records build their dicts in a fixed order), fixed
    separators, no NaN (the released files are strict JSON)."""
    if indent is None:
        return json.dumps(obj, separators=(", ", ": "), ensure_ascii=False, allow_nan=False)
    return json.dumps(obj, indent=indent, ensure_ascii=False, allow_nan=False)


def gzip_bytes(data: bytes, compresslevel: int = 6) -> bytes:
    """gzip with mtime=0 and no file name in the header, so equal input gives equal bytes."""
    buf = io.BytesIO()
    with gzip.GzipFile(filename="", mode="wb", fileobj=buf, mtime=0, compresslevel=compresslevel) as gz:
        gz.write(data)
    return buf.getvalue()


def write_json_gz(path: str | Path, obj: Any) -> Path:
    """Atomically write `obj` as deterministic gzipped JSON."""
    return atomic_write_bytes(path, gzip_bytes(json_dumps(obj).encode("utf-8")))


def write_json(path: str | Path, obj: Any, indent: int = 2) -> Path:
    """Atomically write `obj` as pretty, deterministic JSON (trailing newline)."""
    return atomic_write_text(path, json_dumps(obj, indent=indent) + "\n")
