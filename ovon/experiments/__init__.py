"""The paper's experiments as data: definitions (YAML in `defs/`), a resumable, shardable runner that
calls `ovon train` / `ovon evaluate`, and a report that puts the paper's numbers beside ours.

    from ovon.experiments import load_experiment, resolve, run, write_experiment_report
    plan = resolve([load_experiment("main")], "cpu", "runs/experiments")
    run(plan, dry_run=True)          # each cell's status and exact command
    run(plan)                        # data, training, evaluation, report (resumes after a kill)
    write_experiment_report(plan, "experiments/results/main")
"""

from __future__ import annotations

from ovon.experiments.cells import Cell, Plan
from ovon.experiments.definitions import (
    DefinitionError,
    experiment_names,
    load_catalogue,
    load_experiment,
)
from ovon.experiments.plan import resolve
from ovon.experiments.report import write_experiment_report
from ovon.experiments.runner import RunResult, run
from ovon.experiments.select import parse_shard, select
from ovon.experiments.status import plan_status

__all__ = [
    "Cell",
    "DefinitionError",
    "Plan",
    "RunResult",
    "experiment_names",
    "load_catalogue",
    "load_experiment",
    "parse_shard",
    "plan_status",
    "resolve",
    "run",
    "select",
    "write_experiment_report",
]
