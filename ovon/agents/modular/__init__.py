"""Modular baselines built from the agent's own sensors: VLFM (`--agent vlfm`) and DAgRL+OD
(`--agent dagrl-od`), with their maps, value map, lifting and point-goal navigation."""

from ovon.agents.modular.config import DAgRLODConfig, ModularConfig, VLFMConfig, modular_config
from ovon.agents.modular.dagrl_od import DAgRLODAgent
from ovon.agents.modular.navigation import GeometricNavigator, NavRequest, PointGoalNavigator
from ovon.agents.modular.vlfm import VLFMAgent

__all__ = [
    "DAgRLODAgent",
    "DAgRLODConfig",
    "GeometricNavigator",
    "ModularConfig",
    "NavRequest",
    "PointGoalNavigator",
    "VLFMAgent",
    "VLFMConfig",
    "modular_config",
]
