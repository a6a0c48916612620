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

from ovon.config.base import Pattern

# The name of an agent's row in table.md (and a label of figures): a '|' or a line break would split the row or
# the table. `EvalConfig.name` and a served agent's name share it.
ROW_NAME = Pattern(
    r"(?=.*\S)[^|\x00-\x1f\x7f-\x9f\u2028\u2029]{1,100}",
    "1 to 100 characters without '|', line breaks or control characters (a row of table.md)",
)


@runtime_checkable
class Agent(Protocol):
    def reset(self, episode_info: dict) -> None: ...

    def act(self, observation: dict) -> int: ...


@runtime_checkable
class DebugView(Protocol):
    def debug_frame(self, size: int) -> np.ndarray | None: ...


def is_privileged(agent: object) -> bool:
    return bool(getattr(agent, "privileged", False))
