"""The agent protocol: what `ovon evaluate` drives, and what a researcher implements to plug in their own.

    class MyAgent:
        privileged = False            # True: observation["privileged"] carries ground truth (oracles only)
        def reset(self, episode_info: dict) -> None: ...
        def act(self, observation: dict) -> int: ...   # 0 STOP, 1 FORWARD, 2 LEFT, 3 RIGHT, 4 UP, 5 DOWN

`episode_info` holds episode_id, scene_id, split, goal (text), seed, and the robot's calibration ("camera",
"embodiment": the `CameraConfig` / `AgentConfig` fields of the run). `observation` holds rgb (H,W,3)
uint8, depth (H,W) float32 metres, odometry (3,) float32 (forward m, left m, dyaw rad since the start),
goal (str) — and "privileged" (`ovon.env.Privileged`) only for agents that declare it.

Optional (`DebugView`): `debug_frame(size) -> RGB uint8 image` `size` pixels high (any width), or None: what
the agent believes after its last `act` (maps, targets). `ovon video` replays the episode through a fresh
agent and draws it beside the camera and the true top-down map.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class Agent(Protocol):
    def reset(self, episode_info: dict) -> None: ...

    def act(self, observation: dict) -> int: ...


@runtime_checkable
class DebugView(Protocol):
    def debug_frame(self, size: int) -> np.ndarray | None: ...


def is_privileged(agent: object) -> bool:
    return bool(getattr(agent, "privileged", False))
