"""What an evaluation runs (`RunPlan`), apart from the harness so that a task's planner (e.g.
`ovon.evaluate.pointnav`) can build one without importing the harness that calls it."""

from __future__ import annotations

from dataclasses import dataclass

from ovon.task.episode import EpisodeSpec


@dataclass
class RunPlan:
    """What an evaluation runs, whatever its task (`plan`): the episodes per split, the row name, the
    config and inputs that identify the run folder, and the episodes skipped before the run (None: the
    task skips none, and the summary says nothing about skipping)."""

    specs: dict[str, list[EpisodeSpec]]
    name: str
    config: dict
    inputs: dict
    skipped: dict | None
    label: str  # progress bar title
