"""Small value types and protocols shared across the simulator (the contracts between modules)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np


@dataclass
class Frame:
    rgb: np.ndarray | None  # (H, W, 3) uint8; None when the camera skips RGB (camera.rgb = False)
    depth: np.ndarray  # (H, W) float32, metres, z-depth along the optical axis; 0 where nothing was hit
    semantic: np.ndarray  # (H, W) int32 instance ids, 0 = none


@dataclass
class AgentState:
    position: np.ndarray  # (3,) float64, on the floor surface (Habitat frame, y up)
    yaw: float  # radians about +y; 0 looks along -z, positive turns left
    pitch: float = 0.0  # camera pitch, radians, positive looks up

    def copy(self) -> AgentState:
        return AgentState(np.array(self.position, dtype=np.float64), float(self.yaw), float(self.pitch))


class Renderer(Protocol):
    """Renders one camera view of one scene. Implementations: GL (moderngl/EGL) and embree."""

    width: int
    height: int

    def render(self, eye: np.ndarray, yaw: float, pitch: float) -> Frame:
        """`eye` = camera position in world (agent position + camera height); yaw/pitch in radians."""
        ...

    def close(self) -> None: ...
