"""What the modular agents know about themselves and where they are: calibration, the odometry pose and
depth back-projection. Nothing here reads privileged data.

Episodic frame: the Habitat convention (y up, yaw 0 looks along -z, positive yaw turns left) with the start
pose at the origin and yaw 0, so odometry (forward, left, dyaw) is the point (x, z) = (-left, -forward) with
yaw = dyaw. The floor is at y = 0 (one floor per episode), so a point's y is its height above the floor.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ovon.config.sim import AgentConfig, CameraConfig
from ovon.sim.render.camera import focal_length, rotation


@dataclass(frozen=True)
class Pose2D:
    x: float
    z: float
    yaw: float

    @property
    def position(self) -> np.ndarray:
        """(3,) on the floor, for the path-following helpers that take Habitat positions."""
        return np.array([self.x, 0.0, self.z])


def pose_from_odometry(odometry) -> Pose2D:
    forward, left, dyaw = (float(v) for v in np.asarray(odometry, dtype=np.float64)[:3])
    return Pose2D(-left, -forward, dyaw)


@dataclass(frozen=True)
class Sensors:
    """The robot's calibration: camera intrinsics and mounting, body size and the action magnitudes."""

    camera: CameraConfig
    body: AgentConfig

    @classmethod
    def from_episode_info(cls, info: dict | None) -> Sensors:
        """From `episode_info["camera"]` / `["embodiment"]` (the simulator config of the run), else the
        simulator defaults."""
        info = info or {}
        cam = _fill(CameraConfig, info.get("camera"))
        body = _fill(AgentConfig, info.get("embodiment"))
        return cls(cam, body)


def _fill(cls, data: dict | None):
    if not data:
        return cls()
    names = {f.name for f in dataclasses.fields(cls)}
    return cls(**{k: v for k, v in data.items() if k in names})


class DepthProjector:
    """Back-projects z-depth pixels into the episodic frame (pinhole model of `ovon.sim.render.camera`)."""

    def __init__(self, camera: CameraConfig, stride: int = 1) -> None:
        self.camera = camera
        self.stride = int(stride)
        self._key: tuple[int, int] | None = None
        self._u = self._v = np.zeros(0, dtype=np.float32)

    def _rays(self, h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
        if self._key != (h, w):
            f = focal_length(w, h, self.camera.hfov_deg)
            self._u = ((np.arange(w, dtype=np.float64) + 0.5 - w / 2.0) / f).astype(np.float32)
            self._v = ((h / 2.0 - (np.arange(h, dtype=np.float64) + 0.5)) / f).astype(np.float32)
            self._key = (h, w)
        return self._u, self._v

    def project(self, depth: np.ndarray, pose: Pose2D, pitch: float, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """(N, 3) float32 points [x, height above floor, z] of the given pixels."""
        u, v = self._rays(*depth.shape)
        d = depth[rows, cols].astype(np.float32)
        cam = np.stack([u[cols] * d, v[rows] * d, -d], axis=1)
        r = rotation(pose.yaw, pitch).astype(np.float32)
        eye = np.array([pose.x, self.camera.camera_height, pose.z], dtype=np.float32)
        return cam @ r.T + eye

    def frame_points(self, depth: np.ndarray, pose: Pose2D, pitch: float, max_fraction: float = 0.999) -> np.ndarray:
        """Points of every `stride`-th pixel that hit something (depth below the range limit)."""
        h, w = depth.shape
        s = self.stride
        sub = depth[::s, ::s]
        rr, cc = np.nonzero(sub < self.camera.max_depth * max_fraction)
        return self.project(depth, pose, pitch, rr * s, cc * s)
