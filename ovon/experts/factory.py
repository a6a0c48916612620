"""Experts by name, with their embodiment derived from the run's sim/task configs."""

from __future__ import annotations

from ovon.config.sim import SimConfig
from ovon.config.task import TaskConfig
from ovon.experts.config import FrontierExpertConfig, ShortestPathExpertConfig
from ovon.experts.frontier_expert import FrontierExpert
from ovon.experts.rig import Embodiment
from ovon.experts.shortest_path import ShortestPathExpert


def make_expert(name: str, cfg=None, sim: SimConfig | None = None, task: TaskConfig | None = None):
    """The expert named `name` ("frontier" | "shortest-path") with its config (None = defaults) and the
    embodiment of `sim` / `task`."""
    body = Embodiment.of(sim, task)
    if name == "frontier":
        return FrontierExpert(cfg or FrontierExpertConfig(), body)
    if name == "shortest-path":
        return ShortestPathExpert(cfg or ShortestPathExpertConfig(), body)
    raise ValueError(f"unknown expert {name!r}; valid: frontier, shortest-path")
