"""What both modular agents share: the agent's own maps, the detector, lifting and bee-lining.

Per step (`observe`): pose from odometry -> obstacle/explored/frontier maps from depth (+ the bump sensor)
-> detection of the goal text -> lifted goal points. Only the detector may read
`observation["privileged"]` (oracle detection); maps, lifting and navigation use depth + odometry only.
"""

from __future__ import annotations

import math
import time
import zlib

import numpy as np

from ovon.agents.modular.config import ModularConfig
from ovon.agents.modular.lifting import GoalMemory
from ovon.agents.modular.maps import AgentMaps
from ovon.agents.modular.navigation import NavRequest, PointGoalNavigator, make_navigator
from ovon.agents.modular.sensors import Pose2D, Sensors, pose_from_odometry
from ovon.models.detectors import describe_detector, make_detector
from ovon.sim.agent import LOOK_DOWN, LOOK_UP, MOVE_FORWARD


def sensors_only(observation: dict) -> dict:
    """The observation without the privileged channel: what maps, lifting and navigation may see."""
    return {k: v for k, v in observation.items() if k != "privileged"}


def info_seed(info: dict) -> int:
    """The seed the episode info carries (else one from its episode id, stable across processes), for the
    detector's and scorer's noise and a sampling navigator's draws. Not `ovon.evaluate.runner.episode_seed`,
    which computes that seed for the info."""
    s = info.get("seed")
    if s is not None:
        return int(s)
    return zlib.crc32(str(info.get("episode_id", "")).encode())


class ModularCore:
    def __init__(self, cfg: ModularConfig, text_encoder=None) -> None:
        self.cfg = cfg
        self.detector = make_detector(cfg.detector, text_encoder)
        self.sensors: Sensors | None = None
        self.maps: AgentMaps | None = None
        self.navigator: PointGoalNavigator | None = None
        self.memory: GoalMemory | None = None
        self.pitch = 0.0
        self.last_action: int | None = None
        self.detected = False  # the detector fired at least once this episode
        self.pose = Pose2D(0.0, 0.0, 0.0)
        self.timing: dict[str, float] = {"maps": 0.0, "detect": 0.0}  # ms of the last `observe`, per phase

    @property
    def privileged(self) -> bool:
        return bool(self.detector.privileged)

    def describe_detector(self) -> str:
        return describe_detector(self.cfg.detector)

    def _build(self, sensors: Sensors) -> None:
        self.sensors = sensors
        self.maps = AgentMaps(self.cfg.maps, sensors)
        self.navigator = make_navigator(self.cfg.navigator, self.maps, sensors)
        self.memory = GoalMemory(self.cfg.lifting, self.maps.projector)

    def reset(self, episode_info: dict) -> None:
        sensors = Sensors.from_episode_info(episode_info)
        if sensors != self.sensors:
            self._build(sensors)
        assert self.maps is not None and self.navigator is not None and self.memory is not None
        self.maps.reset()
        seed = info_seed(episode_info)
        self.navigator.reset(seed)
        self.memory.reset()
        self.detector.reset(seed)
        self.pitch = 0.0
        self.last_action = None
        self.detected = False

    def observe(self, observation: dict) -> bool:
        """Update maps and goal points from one observation; False when the agent left its map."""
        assert self.maps is not None and self.memory is not None, "call reset() first"
        pose = pose_from_odometry(observation["odometry"])
        self.pose = pose
        r, c = self.maps.cell(pose.x, pose.z)
        if not self.maps.in_bounds(r, c):
            return False
        t0 = time.perf_counter()
        depth = np.asarray(observation["depth"], dtype=np.float32)
        bumped = bool(observation.get("collided", 0)) and self.last_action == MOVE_FORWARD
        self.maps.update(depth, pose, self.pitch, bumped)
        t1 = time.perf_counter()
        dets = self.detector.detect(observation, str(observation["goal"]))
        if dets and self.memory.add(dets, depth, pose, self.pitch):
            self.detected = True
        self.timing = {"maps": (t1 - t0) * 1e3, "detect": (time.perf_counter() - t1) * 1e3}
        return True

    def goal_point(self) -> tuple[float, float] | None:
        assert self.memory is not None
        return self.memory.goal_point(self.pose)

    def beeline(self, observation: dict) -> int | None:
        """Action toward the goal point (STOP within the stop distance), None when it cannot be reached."""
        goal = self.goal_point()
        if goal is None:
            return None
        assert self.navigator is not None and self.maps is not None
        return self.navigator.act(sensors_only(observation), NavRequest(self.pose, goal, "goal", self.maps))

    def navigate_to(self, observation: dict, target: tuple[float, float]) -> int | None:
        assert self.navigator is not None and self.maps is not None
        return self.navigator.act(sensors_only(observation), NavRequest(self.pose, target, "frontier", self.maps))

    def record(self, action: int) -> int:
        """Remember the action (bump sensor attribution, camera pitch); returns it."""
        assert self.sensors is not None
        body = self.sensors.body
        if action in (LOOK_UP, LOOK_DOWN):
            step = math.radians(body.look_angle_deg) * (1 if action == LOOK_UP else -1)
            lo, hi = math.radians(body.min_pitch_deg), math.radians(body.max_pitch_deg)
            self.pitch = min(hi, max(lo, self.pitch + step))
        self.last_action = int(action)
        return int(action)


__all__ = ["ModularCore", "info_seed", "sensors_only"]
