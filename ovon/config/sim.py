"""Simulator configs: the Stretch embodiment of task.md and the navigability grid."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal


@dataclass(frozen=True)
class AgentConfig:
    radius: float = 0.17
    height: float = 1.41
    max_climb: float = 0.10
    forward_step: float = 0.25
    turn_angle_deg: float = 30.0
    look_angle_deg: float = 30.0
    min_pitch_deg: float = -60.0
    max_pitch_deg: float = 60.0
    allow_sliding: bool = False


@dataclass(frozen=True)
class CameraConfig:
    """Task rig: 360 wide x 640 tall portrait, HFOV 42 deg, 1.31 m high (paper); CPU presets shrink it."""

    width: int = 360
    height: int = 640
    hfov_deg: float = 42.0
    camera_height: float = 1.31
    min_depth: float = 0.5
    max_depth: float = 5.0
    backend: Literal["auto", "gl", "embree"] = "auto"
    # Render the RGB channel. Off when no consumer reads it (oracle encoders need depth + semantic):
    # saves the colour pass and its read-back. Depth and the semantic frame are always rendered.
    rgb: bool = True


@dataclass(frozen=True)
class NavConfig:
    cell_size: float = 0.05
    cell_height: float = 0.05
    max_slope_deg: float = 30.0
    floor_separation: float = 1.0  # walkable surfaces more than this apart in y are separate floors


@dataclass(frozen=True)
class NoiseConfig:
    actuation: Literal["none", "gaussian", "ilqr", "proportional", "movebase"] = "none"
    actuation_multiplier: float = 1.0
    odometry: bool = False
    odometry_position_m: float = 0.007
    odometry_heading_deg: float = 2.0


@dataclass(frozen=True)
class SimConfig:
    agent: AgentConfig = field(default_factory=AgentConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    nav: NavConfig = field(default_factory=NavConfig)
    noise: NoiseConfig = field(default_factory=NoiseConfig)


def cpu_sim_config() -> SimConfig:
    """Fast CPU preset: small landscape frames, same geometry."""
    return SimConfig(camera=CameraConfig(width=160, height=120))
