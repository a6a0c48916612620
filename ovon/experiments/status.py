"""A cell's status: done, changed since it ran, to extend, partial, failed, running (its lock is held),
waiting for the cells it needs, missing or unavailable; from its record, its run folder's outputs, its
identity (`ovon.experiments.identity`) and its inputs (`ovon.experiments.inputs`)."""

from __future__ import annotations

from dataclasses import dataclass

from ovon.experiments.cells import Cell, Plan
from ovon.experiments.identity import EXTEND, config_change, extension, recorded_config, resolved_config
from ovon.experiments.inputs import changed_inputs, data_fingerprint, dataset_fingerprints
from ovon.experiments.outputs import finished_outputs, partial_outputs
from ovon.experiments.records import lock_holder, log_path, read_record, record_path


@dataclass
class Status:
    state: str  # done | partial | missing | failed | changed | running | waiting | unavailable | redo
    detail: str = ""

    def __str__(self) -> str:
        return f"{self.state} ({self.detail})" if self.detail else self.state


def cell_status(
    plan: Plan, cell: Cell, statuses: dict[str, Status], check_lock: bool = True, dataset: dict | None = None
) -> Status:
    """The cell's status given the statuses of the cells before it (`statuses`, by id); `dataset`:
    `dataset_fingerprints(plan)` when the caller has it (a status pass lists the files once)."""
    if cell.unavailable:
        return Status("unavailable", cell.unavailable)
    if cell.kind == "data" and cell.run is None:  # the user's own dataset (paper scale)
        if data_fingerprint(plan) is None:
            return Status("missing", f"no episode files (*.json.gz) under {plan.episodes_dir}")
        return Status("done", f"episodes {plan.episodes_dir}, scenes {plan.scenes_dir}")
    if check_lock:
        holder = lock_holder(plan, cell)
        if holder:
            return Status("running", holder)
    rec = read_record(plan, cell)
    if rec is not None and rec.get("state") == "unreadable":
        return Status("changed", f"its record {record_path(plan, cell)} is unreadable")
    old = recorded_config(plan, cell, rec) if rec is not None else None
    now = resolved_config(plan, cell) if old is not None else None
    why = config_change(cell, old, now)
    if why:
        return Status("changed", f"its resolved config changed since it ran: {why}")
    if rec is not None and rec.get("state") == "done" and finished_outputs(plan, cell):
        moved = changed_inputs(plan, cell, rec, dataset)
        if moved:
            return Status("changed", f"its input(s) {', '.join(moved)} changed since it ran")
        # a cell it reads that will be recomputed (its definition, config or inputs changed, or --redo)
        stale = [d for d in cell.deps if statuses.get(d, Status("done")).state in ("changed", "redo")]
        if stale:
            return Status("changed", f"{', '.join(stale)}, which it reads, changed since it ran")
        extended = [
            d
            for d in cell.deps
            if statuses.get(d, Status("done")).state == "partial" and statuses[d].detail.startswith(EXTEND)
        ]
        if extended:
            return Status("changed", f"{', '.join(extended)}, which it reads, is to be extended")
        more = extension(cell, rec.get("config") if isinstance(rec.get("config"), dict) else None, now)
        if more:
            return Status("partial", f"{EXTEND}: {more}")
        return Status("done", f"{rec.get('wall_s', 0) / 60:.1f} min")
    waiting = [d for d in cell.deps if statuses.get(d, Status("done")).state != "done"]
    if waiting:
        return Status("waiting", ", ".join(waiting))
    if rec is not None and rec.get("inputs"):  # an unfinished attempt read other inputs: it cannot resume
        moved = changed_inputs(plan, cell, rec, dataset)
        if moved:
            return Status("changed", f"its input(s) {', '.join(moved)} changed since its last attempt")
    left = partial_outputs(plan, cell)
    if rec is not None and rec.get("state") == "failed":
        more = f"; {left}" if left else ""
        return Status("failed", f"exit code {rec.get('rc')}, see {log_path(plan, cell)}{more}")
    if left:
        return Status("partial", left)
    return Status("missing")


def plan_status(plan: Plan, ids: list[str] | None = None, check_lock: bool = True) -> dict[str, Status]:
    """Status of every cell (or of `ids` and what they depend on), in plan order."""
    out: dict[str, Status] = {}
    dataset = dataset_fingerprints(plan)
    for cid, cell in plan.cells.items():
        out[cid] = cell_status(plan, cell, out, check_lock, dataset)
    return out if ids is None else {k: v for k, v in out.items() if k in ids}
