"""Configs: typed dataclasses per subsystem plus the YAML / override machinery in `base`."""

from ovon.config.base import ConfigError, build, from_dict, load_yaml, merge, parse_overrides, to_dict
from ovon.config.sim import AgentConfig, CameraConfig, NavConfig, NoiseConfig, SimConfig

__all__ = [
    "AgentConfig",
    "CameraConfig",
    "ConfigError",
    "NavConfig",
    "NoiseConfig",
    "SimConfig",
    "build",
    "from_dict",
    "load_yaml",
    "merge",
    "parse_overrides",
    "to_dict",
]
