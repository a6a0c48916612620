"""What a cell's run folder holds: its finished outputs, or what a killed or failed attempt left."""

from __future__ import annotations

import json
import os
from pathlib import Path

from ovon.experiments.cells import Cell, Plan
from ovon.experiments.inputs import data_fingerprint


def finished_outputs(plan: Plan, cell: Cell) -> bool:
    if cell.kind == "train":
        return (cell.folder / "policy.pt").is_file()
    if cell.kind == "eval":
        return (cell.folder / "summary.json").is_file()
    return data_fingerprint(plan) is not None


def partial_outputs(plan: Plan, cell: Cell) -> str:
    """What a killed or failed attempt left ("" when nothing), e.g. "update 120/400"."""
    if cell.kind == "train":
        if not (cell.folder / "checkpoint.pt").is_file():
            return ""
        update = last_update(cell.folder)
        return f"update {update}/{cell.total or '?'}" if update is not None else "checkpoint"
    if cell.kind == "eval":
        n = count_lines(cell.folder / "episodes.jsonl")
        return f"{n}/{cell.total or '?'} episodes" if n else ""
    return "some files" if cell.folder.is_dir() and any(cell.folder.iterdir()) else ""


def last_update(folder: Path) -> int | None:
    path = folder / "metrics.jsonl"
    try:
        with open(path, "rb") as f:
            f.seek(0, os.SEEK_END)
            f.seek(max(0, f.tell() - 4096))
            lines = [ln for ln in f.read().splitlines() if ln.strip()]
        for ln in reversed(lines):
            try:
                return int(json.loads(ln)["update"])
            except (ValueError, KeyError):
                continue
    except OSError:
        return None
    return None


def count_lines(path: Path) -> int:
    try:
        with open(path, "rb") as f:
            return sum(1 for ln in f if ln.endswith(b"\n"))
    except OSError:
        return 0
