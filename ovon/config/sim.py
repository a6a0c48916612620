"""Simulator configs: the Stretch embodiment (docs/spec.md#agent) and the navigability grid.

Every field has a declared domain (`ovon.config.base`); the bounds are what the simulator can run
(a 0-wide camera, a 0 m step or a 180 deg field of view are refused before any work)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar, Literal

from ovon.config.base import in_range, less, non_negative, positive


@dataclass(frozen=True)
class AgentConfig:
    radius: float = in_range(0.17, 0.0, 2.0, lo_open=True)
    height: float = in_range(1.41, 0.0, 5.0, lo_open=True)
    max_climb: float = in_range(0.10, 0.0, 2.0)
    forward_step: float = in_range(0.25, 0.0, 5.0, lo_open=True)
    turn_angle_deg: float = in_range(30.0, 0.0, 180.0, lo_open=True)
    look_angle_deg: float = in_range(30.0, 0.0, 90.0, lo_open=True)
    min_pitch_deg: float = in_range(-60.0, -90.0, 0.0)
    max_pitch_deg: float = in_range(60.0, 0.0, 90.0)
    allow_sliding: bool = False


@dataclass(frozen=True)
class CameraConfig:
    """Task rig: 360 wide x 640 tall portrait, HFOV 42 deg, 1.31 m high (paper); CPU presets shrink it."""

    width: int = in_range(360, 1, 4096)
    height: int = in_range(640, 1, 4096)
    hfov_deg: float = in_range(42.0, 0.0, 180.0, lo_open=True, hi_open=True)
    camera_height: float = in_range(1.31, 0.0, 5.0, lo_open=True)
    min_depth: float = non_negative(0.5)
    max_depth: float = positive(5.0)
    backend: Literal["auto", "gl", "embree"] = "auto"
    # Render the RGB channel. Off when no consumer reads it (oracle encoders need depth + semantic):
    # saves the colour pass and its read-back. Depth and the semantic frame are always rendered.
    rgb: bool = True
    # GL only: draw only the mesh chunks that can be visible (frustum + depth-buffer occlusion tests). Exact:
    # frames are bitwise identical either way; off is the reference path (tests, benchmarks).
    cull: bool = True

    rules: ClassVar = (less("min_depth", "max_depth"),)


@dataclass(frozen=True)
class NavConfig:
    # Lower bounds keep the grid finite: 1 cm cells already mean 10^6 cells per 10 m x 10 m floor.
    cell_size: float = in_range(0.05, 0.01, 1.0)
    cell_height: float = in_range(0.05, 0.01, 1.0)
    max_slope_deg: float = in_range(30.0, 0.0, 90.0, hi_open=True)
    floor_separation: float = positive(1.0)  # walkable surfaces more than this apart in y are separate floors
    # Where navigability comes from: the habitat navmesh beside the mesh (<id>.navmesh or <id>.basis.navmesh),
    # the mesh itself, or auto = the navmesh when the scene has one.
    source: Literal["auto", "navmesh", "mesh"] = "auto"


@dataclass(frozen=True)
class NoiseConfig:
    actuation: Literal["none", "gaussian", "ilqr", "proportional", "movebase"] = "none"
    actuation_multiplier: float = in_range(1.0, 0.0, 100.0)
    odometry: bool = False
    # bounded: a fresh error on each reading (the paper); drift: errors integrated by dead reckoning
    odometry_mode: Literal["bounded", "drift"] = "bounded"
    odometry_position_m: float = non_negative(0.007)
    odometry_heading_deg: float = non_negative(2.0)


@dataclass(frozen=True)
class SimConfig:
    agent: AgentConfig = field(default_factory=AgentConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    nav: NavConfig = field(default_factory=NavConfig)
    noise: NoiseConfig = field(default_factory=NoiseConfig)


def cpu_sim_config() -> SimConfig:
    """The CPU camera, the default of every command and CPU preset (`ovon evaluate`, the demo, training):
    the paper's camera geometry (9:16 portrait, 42 deg HFOV, so 68.6 deg vertical) at 72 wide x 128 tall,
    1/25 of the 360x640 pixels. The shipped checkpoints and cpu-small's policies were trained with it, so a
    learned policy or PointNav navigator runs under the defaults."""
    return SimConfig(camera=CameraConfig(width=72, height=128))
