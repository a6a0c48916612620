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
import secrets
from collections.abc import Callable
from pathlib import Path
from typing import Any, BinaryIO


def check_output_path(
    path: str | Path,
    what: str = "--out",
    *,
    folder: bool = False,
    expected: str = "",
    example: str = "",
    suffixes: tuple[str, ...] = (),
    writable: bool = True,
    error: type[ValueError] = ValueError,
) -> Path:
    """Refuse an output path that cannot be written, before any work: one line naming the option, the
    path, why, and the fix. Why here: every writer of the project goes through this module, and a
    command that renders or trains first would otherwise fail at its very end (`f/x.png` with `f` a file).

    Refused: an empty or blank path ("" is the current folder: files would be scattered there); a path under an
    existing file; `folder=True`: an existing file; `folder=False`: an existing folder, or a name not
    ending with one of `suffixes`; `writable`: a folder to create (or write in) that this process cannot
    write (False for a folder only read now, e.g. a run root that a dry run or a report reads).
    `expected` / `example` describe a file path for messages (e.g. "the path of a .png file",
    "frame.png"); `error`: the exception class raised (a subclass of ValueError). Returns `Path(path)`."""
    text = str(path)
    noun = "folder" if folder else "file"
    shown = expected or f"the path of a {noun}"
    if not text.strip():
        hint = example or ("runs/NAME" if folder else "PATH")
        why = "'' would write into the current folder" if not text else f"{text!r} is blank"
        raise error(f"{what} is empty ({why}); expected {shown}; fix: pass {what} {hint}")
    p = Path(text)
    existing = next((a for a in (p, *p.parents) if os.path.lexists(a)), Path("."))
    if existing != p and not existing.is_dir():
        raise error(
            f"{what} {text}: {existing} is an existing file, not a folder, so nothing can be written "
            f"under it; fix: choose another {what} (or move {existing} away)"
        )
    if existing == p and folder and not p.is_dir():
        raise error(
            f"{what} {text} is an existing file, not a folder; fix: choose a folder path (it is created when absent)"
        )
    if existing == p and not folder and p.is_dir():
        raise error(f"{what} {text!r} is a folder; expected {shown}; fix: e.g. {what} {p / (example or 'out')}")
    if suffixes and not folder and not p.name.lower().endswith(tuple(s.lower() for s in suffixes)):
        raise error(
            f"{what} {text!r}: expected {shown} (a name ending with {' or '.join(suffixes)}); fix: e.g. "
            f"{what} {p.with_name(p.stem + suffixes[0])}"
        )
    into = existing if existing.is_dir() else existing.parent
    if writable and not os.access(into, os.W_OK | os.X_OK):
        raise error(f"{what} {text}: cannot write in {into} (permission denied); fix: choose a {noun} you can write")
    return p


# Mode asked for when a temp file is created: the kernel clears the umask's bits (and a folder's default
# ACL applies), so the file gets exactly the permissions `open(path, "w")` would give it.
NEW_FILE_MODE = 0o666
_TEMP_TRIES = 100


def _create_temp(folder: Path, name: str, suffix: str = ".tmp") -> tuple[int, Path]:
    """Create and open a new, empty temp file `.<name>.<random><suffix>` in `folder`: (fd, path).

    Why not `tempfile.mkstemp`: it creates its files with mode 0600 whatever the umask, and `os.replace`
    keeps that mode, so every scene, episode shard, categories.json and run file was unreadable by the other
    users or containers sharing the data. Created here with `O_CREAT | O_EXCL` (never an existing file or a
    symlink, as mkstemp) and mode 0666, which the kernel reduces by the process umask, as for a plain
    `open()`: no umask to read (reading it with `os.umask` sets it, a race with other threads), and a
    folder's default ACL is honoured too. The name keeps the `.<name>.<random>.tmp` shape that
    `ovon.runfolder` sweeps after a killed run and that dataset readers skip (a leading dot)."""
    flags = os.O_RDWR | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
    flags |= getattr(os, "O_BINARY", 0)
    for _ in range(_TEMP_TRIES):
        tmp = folder / f".{name}.{secrets.token_hex(6)}{suffix}"
        try:
            return os.open(tmp, flags, NEW_FILE_MODE), tmp
        except FileExistsError:
            continue
    raise FileExistsError(
        f"{folder}: no free temp file name for {name} after {_TEMP_TRIES} tries; fix: remove the "
        f"stale .{name}.*{suffix} files there"
    )


def _fsync(path: Path) -> None:
    """Flush a file written by another library (by path) to disk before it is renamed into place."""
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_BINARY", 0))
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def atomic_write_with(path: str | Path, write: Callable[[BinaryIO], Any]) -> Path:
    """Call `write(f)` on a temp file in the target folder, fsync, then `os.replace` it into place.

    The one atomic writer of the project: every file a run or a generator produces goes through it (or
    through `atomic_write_path` for writers that need a file name). The file gets the permissions a plain
    `open()` would give it (0666 less the umask, see `_create_temp`), not mkstemp's 0600."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = _create_temp(path.parent, path.name)

    def fill() -> None:
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())

    return _fill_then_rename(tmp, path, fill)


def atomic_write_path(path: str | Path, write: Callable[[Path], Any]) -> Path:
    """`atomic_write_with` for writers that take a file name, not a file object (a video encoder, a
    library's `save(path)`): `write(tmp)` writes a temp path in the target folder that ends with the
    target's suffix (encoders choose the format by it), then it is fsynced and renamed into place; on any
    error it is removed, and the previous file stays. Same permissions as a plain `open()`."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = _create_temp(path.parent, path.stem, suffix=f".tmp{path.suffix}")
    os.close(fd)

    def fill() -> None:
        write(tmp)
        _fsync(tmp)

    return _fill_then_rename(tmp, path, fill)


def _fill_then_rename(tmp: str | Path, path: Path, fill: Callable[[], Any]) -> Path:
    """`fill()` the temp file, then rename it over `path`; on any error the temp file goes and `path` stays."""
    try:
        fill()
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
