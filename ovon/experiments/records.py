"""A cell's files beside its run folder: its record, its log and its lock.

Why records: a cell is finished when its command exited 0 and its outputs exist; the record
(`<root>/<scale>/cells/<kind>-<name>.json`, written atomically) says so, with the command, the
identities of what it read (data listing, init/checkpoint content hashes), the number of attempts and
the wall time, the code it ran with (`ovon 0.1.0 (commit[+dirty])`, per attempt) and its resolved
config (`ovon.experiments.identity`). The lock is `ovon.runfolder.FileLock`, the one lock of run folders.
"""

from __future__ import annotations

import json
from pathlib import Path

from ovon.atomic import check_output_path, write_json
from ovon.experiments.cells import Cell, Plan
from ovon.experiments.definitions import DefinitionError
from ovon.runfolder import FileLock, RunFolderError


def record_path(plan: Plan, cell: Cell) -> Path:
    return plan.base / "cells" / f"{cell.kind}-{cell.name}.json"


def log_path(plan: Plan, cell: Cell) -> Path:
    return plan.base / "logs" / f"{cell.kind}-{cell.name}.log"


def lock_path(plan: Plan, cell: Cell) -> Path:
    return plan.base / "locks" / f"{cell.kind}-{cell.name}.lock"


def read_record(plan: Plan, cell: Cell) -> dict | None:
    """The cell's record, None when it has none, {"state": "unreadable"} when it is torn or garbage. A
    file where a folder of the root should be is not an unreadable record (every cell would read as
    "changed"): it is refused as the root it is."""
    path = record_path(plan, cell)
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        return None
    except NotADirectoryError:
        check_output_path(plan.root, "--root", folder=True, writable=False, error=DefinitionError)
        check_output_path(
            path.parent, f"--root {plan.root}: the cells folder", folder=True, writable=False, error=DefinitionError
        )
        return {"state": "unreadable"}
    except (OSError, ValueError):
        return {"state": "unreadable"}


def write_record(plan: Plan, cell: Cell, record: dict) -> None:
    write_json(record_path(plan, cell), record)


def cell_lock(plan: Plan, cell: Cell) -> FileLock | None:
    """The cell's lock (flock, released by the kernel when its holder dies, so a killed run never leaves a
    stale lock; works across machines on a shared file system with flock), or None when another process
    holds it."""
    try:
        return FileLock(lock_path(plan, cell), what="--root")
    except RunFolderError:
        return None


def lock_holder(plan: Plan, cell: Cell) -> str | None:
    """Who holds the cell's lock right now ("pid N on HOST, since ..."), None when nobody does (a status
    check creates nothing)."""
    return FileLock.holder(lock_path(plan, cell))
