"""Privileged experts: frontier exploration (the paper's DAgger teacher) and shortest path."""

from ovon.experts.config import FrontierExpertConfig, ShortestPathExpertConfig
from ovon.experts.frontier_expert import FrontierExpert
from ovon.experts.shortest_path import ShortestPathExpert

__all__ = [
    "FrontierExpert",
    "FrontierExpertConfig",
    "ShortestPathExpert",
    "ShortestPathExpertConfig",
]
