"""A cell's identity: its resolved config, compared the way its run folder compares one (`ovon.runfolder`).

Why the config and not the command line: the command is only rendered from the typed cell; what a run
folder is (and refuses to become) is its resolved config. A data cell's is its GenerationConfig and scene
counts, a training cell's its TrainConfig (presets and `--set` resolved) and world size, an evaluation
cell's the EvalConfig `ovon evaluate` builds (agent arguments, noise, camera, task) with the agent's own
config where its class resolves one (`resolved_config(**agent_args)`, e.g. VLFM's preset). A preset
changed in code changes it where the definition does not. The runner records it when a cell runs
(paths as tokens); a record from before that is compared with its run folder's `run_identity.json`.
A cell whose config differs from the recorded one outside the keys that may change is "changed": never
silently reused, never silently recomputed (`--redo` moves the old folder aside).
"""

from __future__ import annotations

import contextlib
import json

from ovon.config.base import to_dict
from ovon.evaluate.harness import MAY_CHANGE as EVAL_MAY_CHANGE
from ovon.experiments.cells import Cell, DataRun, EvalRun, Plan, TrainRun
from ovon.experiments.tokens import tokenised_values
from ovon.runfolder import IDENTITY_FILE, differences

# A training cell's budget may grow after it finished: the runner resumes its folder to the new budget (no
# schedule depends on the budget, so the result is the run trained that long from the start). A smaller
# budget makes the cell "changed": a finished training is never cut back.
TRAIN_BUDGET = ("max_updates", "total_steps")
# What extends a finished cell (it is then re-run, adding what is missing): an evaluation's seeds, episodes
# and splits, a training's budget.
EXTENDS = {"train": TRAIN_BUDGET, "eval": ("seeds", "episodes", "splits"), "data": ()}
EXTEND = "to extend"  # the detail of a finished cell whose budget, seeds, episodes or splits grew
# Keys of a resolved config that say where or how fast a cell runs, or what extends it: they may change
# without making a finished cell stale. Inputs (the dataset, a checkpoint) are compared by content
# (`ovon.experiments.inputs`), not by path.
MAY_CHANGE = {
    "train": (
        "env_workers",
        "threads",
        "rollout_threads",
        "device",
        "encoder.device",
        "progress",
        "log_every",
        "checkpoint_every",
        "keep_checkpoints",
        "text_cache",
        "bc.record_workers",
        *TRAIN_BUDGET,
    ),
    "eval": EVAL_MAY_CHANGE,  # what the run folder itself lets change (one list)
    "data": (),
}


def resolved_config(plan: Plan, cell: Cell) -> dict | None:
    """The cell's config now, as JSON with paths as tokens; None when it has none (the user's own dataset)
    or cannot be resolved now (e.g. its checkpoint is gone)."""
    if cell.run is None:
        return None
    try:
        return tokenised_values(plan, _config(cell))
    except (OSError, ValueError, TypeError, KeyError, ImportError):  # ConfigError is a ValueError
        return None


def _config(cell: Cell) -> dict:
    if isinstance(cell.run, DataRun | TrainRun):
        return cell.run.identity()
    assert isinstance(cell.run, EvalRun)
    return eval_identity(cell)


def eval_identity(cell: Cell) -> dict:
    """The EvalConfig that `ovon evaluate` builds from the cell's command (its own parser's defaults
    included), with the agent's resolved config."""
    from ovon.agents import load_agent_class
    from ovon.evaluate.config import eval_config
    from ovon.experiments.plan import parse_cli

    cfg = eval_config(parse_cli(cell.commands[-1], cell.id))
    out = to_dict(cfg)
    agent = getattr(load_agent_class(cfg.agent), "resolved_config", None)  # an agent's own presets (VLFM)
    if callable(agent):
        out["agent_config"] = to_dict(agent(**dict(cfg.agent_kwargs)))
    return out


def run_folder_config(plan: Plan, cell: Cell) -> dict | None:
    """The config the cell's run folder stored when its command created it (`run_identity.json`; the data
    cell's is the episodes folder's), paths as tokens; None without one."""
    folder = plan.episodes_dir if cell.kind == "data" else cell.folder
    with contextlib.suppress(OSError, ValueError, KeyError, TypeError):
        stored = json.loads((folder / IDENTITY_FILE).read_text())["config"]
        stored = stored["generation"] if cell.kind == "data" else stored
        if isinstance(stored, dict):
            return tokenised_values(plan, stored)
    return None


def recorded_config(plan: Plan, cell: Cell, record: dict) -> dict | None:
    """The config the cell last ran with: its record's, else (a record from before configs were recorded)
    its run folder's."""
    old = record.get("config")
    return old if isinstance(old, dict) else run_folder_config(plan, cell)


def config_change(cell: Cell, old: dict | None, now: dict | None) -> str:
    """ "" when `now` is the config `old` (or either is unknown), else the first differing key, e.g.
    `finetune.anchor "none" -> "kl"` (and how many more differ)."""
    if old is None or now is None:
        return ""
    diffs = differences(old, now, MAY_CHANGE[cell.kind])
    if cell.kind == "train":
        diffs = budget_shrunk(old, now) + diffs
    if not diffs:
        return ""
    return diffs[0] + (f" (and {len(diffs) - 1} more)" if len(diffs) > 1 else "")


def extension(cell: Cell, old: dict | None, now: dict | None) -> str:
    """ "" unless an unchanged finished cell is to be extended (more seeds, episodes or splits, a larger
    budget), else the first such difference, e.g. `seeds [0, 1] -> [0, 1, 2]`."""
    if old is None or now is None:
        return ""
    keys = EXTENDS[cell.kind]
    diffs = differences({k: old[k] for k in keys if k in old}, {k: now[k] for k in keys if k in now})
    return diffs[0] if diffs else ""


def budget_shrunk(old: dict, now: dict) -> list[str]:
    """The budget keys of a training config that went down (`max_updates` 0 = no cap)."""
    out = []
    for key in TRAIN_BUDGET:
        a, b = old.get(key), now.get(key)
        if not (isinstance(a, int) and isinstance(b, int)):
            continue
        cap_a, cap_b = (a or float("inf"), b or float("inf")) if key == "max_updates" else (a, b)
        if cap_b < cap_a:
            out.append(f"{key} {a} -> {b} (a finished training is never cut back)")
    return out


def config_unknown(plan: Plan, ids: list[str]) -> list[str]:
    """Finished cells whose record predates resolved configs: only their run folder's identity can be
    compared."""
    from ovon.experiments.records import read_record

    out = []
    for cid in ids:
        cell = plan.cells[cid]
        rec = read_record(plan, cell) if cell.run is not None else None
        if rec and rec.get("state") == "done" and "config" not in rec:
            out.append(cid)
    return out
