"""Identities of what a cell reads: the episode dataset (content), the scenes (names and sizes) and the
policies of the training cells it needs (content). A cell whose inputs changed since it ran is "changed"."""

from __future__ import annotations

import contextlib
import hashlib
import json
from pathlib import Path
from typing import Any

from ovon.atomic import write_json
from ovon.experiments.cells import Cell, Plan

_HASHES: dict[tuple, str] = {}


HASH_CACHE = ".file_hashes.json"  # under the scale's folder: content hashes by path, size and mtime


def file_hash(path: Path, persistent: dict[str, list] | None = None) -> str | None:
    """Content hash of a file (cached by size and mtime within the process, and in `persistent` when
    given), None when absent."""
    try:
        st = path.stat()
    except OSError:
        return None
    key = (str(path), st.st_size, st.st_mtime_ns)
    if key not in _HASHES:
        known = (persistent or {}).get(key[0])
        if known is not None and known[:2] == [st.st_size, st.st_mtime_ns]:
            _HASHES[key] = known[2]
        else:
            h = hashlib.sha256()
            with open(path, "rb") as f:
                for block in iter(lambda: f.read(1 << 20), b""):
                    h.update(block)
            _HASHES[key] = h.hexdigest()
    if persistent is not None:
        persistent[key[0]] = [st.st_size, st.st_mtime_ns, _HASHES[key]]
    return _HASHES[key]


def _read_hash_cache(path: Path) -> dict[str, list]:
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}  # absent or torn by a crash: it is only a cache
    ok = isinstance(data, dict) and all(isinstance(v, list) and len(v) == 3 for v in data.values())
    return data if ok else {}


def episode_files(root: Path, hidden: bool = False) -> list[Path]:
    """The episode files (`*.json.gz`) under `root`, sorted. Files under a hidden folder are left out
    (`hidden=False`): `ovon dataset generate` keeps its goal cache in `<out>/.cache/`, which no episode
    reader opens, so deleting or regrowing it must not make every cell that read the episodes stale."""
    if not root.is_dir():
        return []
    files = (p for p in root.rglob("*.json.gz") if p.is_file())
    if not hidden:
        files = (p for p in files if not any(part.startswith(".") for part in p.relative_to(root).parent.parts))
    return sorted(files)


def episodes_content_fingerprint(plan: Plan, hidden: bool = False) -> str | None:
    """Identity of the episode files by their content: an episode file edited to the same size (a changed
    goal, a moved start) makes what read it stale. Why cheap enough: each file is read once per size and
    mtime; the hashes persist in the scale folder's `.file_hashes.json`, so a status pass stats the files.
    `hidden=True`: as records written before `episode_files` left hidden folders out."""
    root = plan.episodes_dir
    files = episode_files(root, hidden)
    if not files:
        return None
    cache_path = plan.base / HASH_CACHE
    cache = _read_hash_cache(cache_path)
    before = dict(cache)
    h = hashlib.sha256()
    for p in files:
        h.update(f"{p.relative_to(root).as_posix()}\0{file_hash(p, cache)}\n".encode())
    if cache != before and plan.base.is_dir():
        with contextlib.suppress(OSError):  # read-only root: hash again next time
            write_json(cache_path, cache)
    return h.hexdigest()


def data_fingerprint(plan: Plan, hidden: bool = False) -> str | None:
    """Identity of the episode dataset: names and sizes of its episode files (cheap for any size)."""
    root = plan.episodes_dir
    h = hashlib.sha256()
    files = episode_files(root, hidden)
    if not files:
        return None
    for p in files:
        h.update(f"{p.relative_to(root).as_posix()}\0{p.stat().st_size}\n".encode())
    return h.hexdigest()


def scenes_fingerprint(plan: Plan) -> str | None:
    """Identity of the scenes: names and sizes of the files under the scenes root (another release of a
    scene dataset at the same path differs), without reading them."""
    root = plan.scenes_dir
    if not root.is_dir():
        return None
    h = hashlib.sha256()
    for p in sorted(p for p in root.rglob("*") if p.is_file()):
        h.update(f"{p.relative_to(root).as_posix()}\0{p.stat().st_size}\n".encode())
    return h.hexdigest()


def dataset_fingerprints(plan: Plan) -> dict[str, str | None]:
    """The episodes' and the scenes' identities, which every non-data cell reads. `data` (names and sizes)
    is kept beside `episodes` (content) so that records from before the content was recorded still compare."""
    return {
        "data": data_fingerprint(plan),
        "episodes": episodes_content_fingerprint(plan),
        "scenes": scenes_fingerprint(plan),
    }


def inputs(plan: Plan, cell: Cell, dataset: dict | None = None) -> dict[str, Any]:
    """Identities of what the cell reads (absent values are None); `dataset`: `dataset_fingerprints(plan)`
    when the caller has it (a status pass lists the files once, not once per cell)."""
    if cell.kind == "data":
        return {}
    out: dict[str, Any] = dict(dataset if dataset is not None else dataset_fingerprints(plan))
    for dep in cell.deps:
        if dep.startswith("train:"):
            out[dep] = file_hash(plan.cells[dep].folder / "policy.pt")
    return out


# records written before the episode fingerprints left hidden folders out hold these values
_WITH_HIDDEN = {"data": data_fingerprint, "episodes": episodes_content_fingerprint}


def changed_inputs(plan: Plan, cell: Cell, rec: dict, dataset: dict | None = None) -> list[str]:
    """The inputs the record holds that differ now (records written before an input was recorded compare
    only what they hold)."""
    now = inputs(plan, cell, dataset)
    moved = [k for k, v in (rec.get("inputs") or {}).items() if now.get(k) != v]
    return [k for k in moved if not (k in _WITH_HIDDEN and _WITH_HIDDEN[k](plan, hidden=True) == rec["inputs"][k])]
