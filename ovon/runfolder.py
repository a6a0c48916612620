"""Run folders that know what they are: identity on creation, comparison on resume, one writer at a time.

Why: a resumable command (`evaluate`, `dataset generate`, `train --resume`) trusts what is already in
its output folder. Re-running it with another agent, seed or `task.max_steps` used to mix two runs in one
folder, and two processes on one folder wrote every record twice. A `RunFolder`:

- refuses an `--out` that cannot be a run folder (empty, an existing file, under a file), see
  `ovon.atomic.check_output_path`;
- writes `run_identity.json` (the kind of run, its resolved config, the identities of what it read:
  dataset content hash, scenes root, checkpoint hash) when the folder is created;
- on a later open compares them and refuses a mismatch with ONE message naming every differing key
  (old -> new); keys listed in `may_change` (worker counts, which seeds/splits to run, how a path was
  spelled) are stored but not compared, and a key present on one side only (a split added later) is
  not a mismatch;
- holds `.lock` (an `flock` on Linux/macOS; a pid file elsewhere) against a second writer; a lock
  left by a dead process is recovered, and the lock is released on `close()` / exit.

    with RunFolder.open(out, "evaluate", config=to_dict(cfg), inputs={...}, may_change=("workers",)) as run:
        ...  # write into run.path
"""

from __future__ import annotations

import atexit
import hashlib
import json
import os
import socket
import sys
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ovon.atomic import check_output_path, write_json

IDENTITY_FILE = "run_identity.json"
LOCK_FILE = ".lock"
FORMAT = 1

try:  # POSIX advisory locks: released by the kernel when the holder dies, so never stale
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]


class RunFolderError(ValueError):
    """The run folder cannot be used for this run; the message names the folder, why, and the fix."""


# ----------------------------------------------------------------------------------------------------
# identities of inputs


def file_sha256(path: str | Path) -> str:
    """Content hash of a file (checkpoints, category files)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def files_sha256(root: str | Path, files: Iterable[str | Path]) -> str:
    """One hash over the relative names and contents of `files` (sorted), e.g. the shards of a split."""
    root = Path(root)
    h = hashlib.sha256()
    for p in sorted(Path(f) for f in files):
        rel = p.relative_to(root).as_posix() if p.is_absolute() else p.as_posix()
        h.update(rel.encode() + b"\0" + file_sha256(root / rel).encode() + b"\n")
    return h.hexdigest()


def listing_sha256(root: str | Path, exclude: Iterable[str | Path] = ()) -> str:
    """Cheap identity of a big tree (a scenes root: gigabytes of meshes): relative names and sizes.
    Hidden entries and the folders in `exclude` (e.g. an output folder inside the tree) are left out."""
    root = Path(root)
    skip = {path_identity(p) for p in exclude}
    h = hashlib.sha256()
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames[:] = sorted(
            d for d in dirnames if not d.startswith(".") and path_identity(Path(dirpath) / d) not in skip
        )
        for name in sorted(filenames):
            if name.startswith("."):
                continue
            p = Path(dirpath) / name
            try:
                size = p.stat().st_size
            except OSError:
                continue
            h.update(f"{p.relative_to(root).as_posix()}\0{size}\n".encode())
    return h.hexdigest()


def path_identity(path: str | Path) -> str:
    """A path as it will be compared: absolute and normalised, so `./x/`, `x` and `/abs/x` are one folder."""
    return os.path.normpath(os.path.abspath(os.path.expanduser(str(path))))


# ----------------------------------------------------------------------------------------------------
# comparison


def flatten(d: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """{"sim": {"camera": {"width": 1}}} -> {"sim.camera.width": 1}; lists stay values."""
    out: dict[str, Any] = {}
    for k, v in d.items():
        key = f"{prefix}.{k}" if prefix else str(k)
        if isinstance(v, Mapping) and v:
            out.update(flatten(v, key))
        else:
            out[key] = v
    return out


def _jsonable(x: Any) -> Any:
    """What a value looks like after a JSON round trip (tuples -> lists), so stored and new compare equal."""
    return json.loads(json.dumps(x, default=str))


def _matches(key: str, prefixes: Iterable[str]) -> bool:
    return any(key == p or key.startswith(p + ".") for p in prefixes)


def differences(old: Mapping[str, Any], new: Mapping[str, Any], may_change: Iterable[str] = ()) -> list[str]:
    """`key: old -> new` for every key present in both identities whose value differs."""
    a, b = flatten(_jsonable(old)), flatten(_jsonable(new))
    may = tuple(may_change)
    out = []
    for k in sorted(set(a) & set(b)):
        if _matches(k, may) or a[k] == b[k]:
            continue
        out.append(f"{k} {_show(a[k])} -> {_show(b[k])}")
    return out


def _show(v: Any) -> str:
    s = json.dumps(v)
    return s if len(s) <= 48 else s[:20] + "..." + s[-20:]


# ----------------------------------------------------------------------------------------------------
# lock


def _pid_alive(pid: int) -> bool:
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True
    return True


def _holder(path: Path) -> str:
    try:
        info = json.loads(path.read_text())
        return f"pid {info.get('pid')} on {info.get('host')}, since {info.get('since')}"
    except (OSError, ValueError):
        return "another process"


class FileLock:
    """Exclusive, non-blocking lock held through the file `path` (created when absent), with the holder's
    pid, host, start time and command written in it. A second holder gets a RunFolderError naming the
    first; a lock whose process died is recovered (flock: by the kernel; pid file: by a liveness check).
    `release()` (or `with`) unlocks and removes the file. `RunFolder` holds one on `<folder>/.lock`; any
    other "one writer at a time" (e.g. an experiment cell) can hold one on its own path."""

    def __init__(self, path: str | Path, what: str = "--out") -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        folder = self.path.parent
        self.fd: int | None = None
        info = json.dumps(
            {
                "pid": os.getpid(),
                "host": socket.gethostname(),
                "since": time.strftime("%Y-%m-%d %H:%M:%S"),
                "command": " ".join(sys.argv)[:500],
            }
        )
        busy = RunFolderError(
            f"{folder} is in use by another ovon process ({{holder}}); fix: wait for it to finish, or "
            f"choose another {what}"
        )
        if fcntl is not None:
            self._flock(info, busy)
        else:  # pragma: no cover - Windows
            self._pidfile(info, busy)

    def _flock(self, info: str, busy: RunFolderError) -> None:
        for _ in range(10):
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                os.close(fd)
                raise RunFolderError(str(busy).format(holder=_holder(self.path))) from None
            # The previous holder may have unlinked the file between our open and flock: retry on the new one.
            try:
                same = os.fstat(fd).st_ino == os.stat(self.path).st_ino
            except FileNotFoundError:
                same = False
            if same:
                os.ftruncate(fd, 0)
                os.write(fd, info.encode())
                self.fd = fd
                return
            os.close(fd)
        raise RunFolderError(str(busy).format(holder="the lock file keeps changing"))

    def _pidfile(self, info: str, busy: RunFolderError) -> None:  # pragma: no cover - Windows
        for _ in range(10):
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o644)
            except FileExistsError:
                try:
                    held = json.loads(self.path.read_text())
                except (OSError, ValueError):
                    held = {}
                if held.get("host") == socket.gethostname() and not _pid_alive(int(held.get("pid", -1))):
                    self.path.unlink(missing_ok=True)  # stale: its process is gone
                    continue
                raise RunFolderError(str(busy).format(holder=_holder(self.path))) from None
            os.write(fd, info.encode())
            self.fd = fd
            return
        raise RunFolderError(str(busy).format(holder="the lock file keeps changing"))

    @staticmethod
    def holder(path: str | Path) -> str | None:
        """Who holds the lock on `path` right now ("pid N on HOST, since ..."), None when nobody does.
        Creates nothing: a status check may run on a read-only folder."""
        path = Path(path)
        if fcntl is None:  # pragma: no cover - Windows
            try:
                held = json.loads(path.read_text())
            except FileNotFoundError:
                return None
            except (OSError, ValueError):
                return _holder(path)
            alive = held.get("host") != socket.gethostname() or _pid_alive(int(held.get("pid", -1)))
            return _holder(path) if alive else None
        try:
            fd = os.open(path, os.O_RDONLY)
        except OSError:
            return None
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
            return None
        except OSError:
            return _holder(path)
        finally:
            os.close(fd)

    def release(self) -> None:
        if self.fd is None:
            return
        try:
            if os.fstat(self.fd).st_ino == os.stat(self.path).st_ino:
                self.path.unlink()
        except OSError:
            pass
        os.close(self.fd)  # closing releases the flock
        self.fd = None

    def __enter__(self) -> FileLock:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


# ----------------------------------------------------------------------------------------------------
# the run folder


@dataclass
class RunFolder:
    """An open run folder: `path`, its `identity` (as stored), whether it `resumed` an existing run."""

    path: Path
    kind: str
    identity: dict[str, Any]
    resumed: bool
    _lock: FileLock | None = field(default=None, repr=False)
    _created: bool = field(default=False, repr=False)

    @classmethod
    def open(
        cls,
        path: str | Path,
        kind: str,
        config: Mapping[str, Any],
        inputs: Mapping[str, Any] | None = None,
        resume: bool = True,
        may_change: Iterable[str] = (),
        markers: Iterable[str] = (),
        what: str = "--out",
    ) -> RunFolder:
        """Create or reopen the run folder `path` for a run of `kind` (e.g. "evaluate", "dataset", "train").

        `config`: the resolved config (JSON-able); `inputs`: identities of what the run reads (see
        `file_sha256`, `files_sha256`, `listing_sha256`, `path_identity`). `resume=False`: a folder that
        already holds a run is an error (train without `--resume`); True: it must be the same run.
        `may_change`: dotted key prefixes (of `config`, or `inputs.<key>`) not compared on resume.
        `markers`: file names that show run data from before identities existed (refused when found
        without an identity). `what`: how the user named the folder, for messages."""
        # "" (the current folder), an existing file, a path under a file, a folder that cannot be written
        path = check_output_path(path, what, folder=True, error=RunFolderError)
        created = not path.exists()
        try:
            path.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise RunFolderError(
                f"{what} {path}: cannot create the folder ({e.strerror}); fix: choose a writable folder"
            ) from None
        lock = FileLock(path / LOCK_FILE, what)
        try:
            # Keys that may change are not part of what the folder is: not stored, not compared.
            may = tuple(may_change)
            identity = {
                "format": FORMAT,
                "kind": kind,
                "config": _without(_jsonable(dict(config)), [m for m in may if not m.startswith("inputs.")]),
                "inputs": _without(
                    _jsonable(dict(inputs or {})), [m.removeprefix("inputs.") for m in may if m.startswith("inputs.")]
                ),
            }
            stored, resumed = cls._reconcile(path, kind, identity, resume, may, markers, what)
        except BaseException:
            lock.release()
            raise
        run = cls(path, kind, stored, resumed, lock, created)
        atexit.register(run.close)
        run.sweep_temp_files()
        return run

    def sweep_temp_files(self) -> list[Path]:
        """Delete the temp files of `ovon.atomic` writes a killed run left behind (`.<name>.<random>.tmp`):
        safe only while holding the lock, when no write of this folder is in flight."""
        removed = []
        for p in self.path.rglob(".*.tmp"):
            if p.is_file():
                try:
                    p.unlink()
                    removed.append(p)
                except OSError:
                    pass
        return removed

    @staticmethod
    def _reconcile(
        path: Path,
        kind: str,
        identity: dict,
        resume: bool,
        may_change: tuple[str, ...],
        markers: Iterable[str],
        what: str,
    ) -> tuple[dict, bool]:
        ident_path = path / IDENTITY_FILE
        fix = f"fix: re-run with the settings it was created with, or choose another {what}"
        if not ident_path.exists():
            found = sorted(m for m in markers if (path / m).exists())
            if found:
                raise RunFolderError(
                    f"{path} holds {', '.join(found)} but no {IDENTITY_FILE} (written by an older ovon or another "
                    f"tool), so a resume cannot be checked; fix: choose another {what}, or move those files away"
                )
            write_json(ident_path, identity)
            return identity, False
        try:
            old = json.loads(ident_path.read_text(encoding="utf-8"))
            if not isinstance(old, dict) or not isinstance(old.get("config"), dict):
                raise ValueError("not an identity object")
        except (OSError, ValueError, RecursionError) as e:
            raise RunFolderError(
                f"{ident_path} is unreadable ({type(e).__name__}); fix: choose another {what}, or restore the file"
            ) from None
        if old.get("kind") != kind:
            raise RunFolderError(
                f"{path} holds a run of kind {old.get('kind')!r}, not {kind!r}; fix: choose another {what}"
            )
        if not resume:
            raise RunFolderError(
                f"{path} already holds a {kind} run; fix: pass --resume to continue it, or choose another {what}"
            )
        diffs = differences(
            {"config": old["config"], "inputs": old.get("inputs", {})},
            {"config": identity["config"], "inputs": identity["inputs"]},
            ("config." + m if not m.startswith("inputs.") else m for m in may_change),
        )
        if diffs:
            shown = "; ".join(d.removeprefix("config.") for d in diffs[:8])
            more = f"; and {len(diffs) - 8} more" if len(diffs) > 8 else ""
            raise RunFolderError(f"{path} holds another {kind} run (settings differ: {shown}{more}); {fix}")
        # Same run: keys seen only now (a split added later) join the identity, so later changes show.
        merged = {
            **old,
            "config": _union(old["config"], identity["config"]),
            "inputs": _union(old.get("inputs", {}), identity["inputs"]),
        }
        if merged != old:
            write_json(ident_path, merged)
        return merged, True

    def close(self) -> None:
        """Release the lock (idempotent; also run at interpreter exit)."""
        if self._lock is not None:
            self._lock.release()
            self._lock = None
            atexit.unregister(self.close)

    def abandon_if_unused(self) -> None:
        """A new run that failed before writing anything leaves no identity behind (so a corrected re-run
        is not refused as "another run"), and no folder if it created it."""
        if self.resumed:
            return
        left = [p for p in self.path.iterdir() if p.name not in (IDENTITY_FILE, LOCK_FILE)]
        if left:
            return
        (self.path / IDENTITY_FILE).unlink(missing_ok=True)
        self.close()
        if self._created:
            try:
                self.path.rmdir()
            except OSError:
                pass

    def __enter__(self) -> RunFolder:
        return self

    def __exit__(self, exc_type: object, *exc: object) -> None:
        if exc_type is not None:
            self.abandon_if_unused()
        self.close()


def _without(d: Mapping[str, Any], prefixes: Iterable[str], where: str = "") -> dict[str, Any]:
    """`d` without the dotted keys (and their sub-keys) in `prefixes`."""
    prefixes = list(prefixes)
    out = {}
    for k, v in d.items():
        key = f"{where}.{k}" if where else str(k)
        if _matches(key, prefixes):
            continue
        out[k] = _without(v, prefixes, key) if isinstance(v, Mapping) else v
    return out


def _union(old: Mapping[str, Any], new: Mapping[str, Any]) -> dict[str, Any]:
    """Keys of `old`, plus those only in `new` (recursively); `old` wins where both have a value."""
    out = dict(old)
    for k, v in new.items():
        if k not in out:
            out[k] = v
        elif isinstance(out[k], Mapping) and isinstance(v, Mapping):
            out[k] = _union(out[k], v)
    return out
