"""Language value map (docs/spec.md#value-map): one image-text score per frame, spread over the cells the camera sees
now with a confidence that falls from 1 on the optical axis to `min_confidence` at the cone's edges
(theta in [0, fov/2] rescaled to [0, pi/2], cos^2, remapped to [min_confidence, 1]), fused with the stored
value by confidence-weighted averaging. The cone is the explored map's view cone (same range, same line of
sight on the agent's own obstacle map).

Frontier value: the median of the stored values within `frontier_radius_m` of the waypoint, over cells that
carry a value (confidence > 0; VLFM tests value != 0, which takes a zero score for "never seen"), or -1.
"""

from __future__ import annotations

import math

import numpy as np

from ovon.agents.modular.config import ValueMapConfig, checked
from ovon.agents.modular.maps import AgentMaps
from ovon.agents.modular.sensors import Pose2D


class ValueMap:
    def __init__(self, cfg: ValueMapConfig, maps: AgentMaps) -> None:
        self.cfg = checked(cfg, "value")
        self.maps = maps
        self.value = np.zeros(maps.shape, dtype=np.float32)
        self.confidence = np.zeros(maps.shape, dtype=np.float32)
        self.half_fov = math.radians(maps.sensors.camera.hfov_deg) / 2.0
        k = int(math.ceil(cfg.frontier_radius_m / maps.cell_size))
        dr, dc = np.mgrid[-k : k + 1, -k : k + 1]
        inside = (dr * dr + dc * dc) * maps.cell_size**2 <= cfg.frontier_radius_m**2 + 1e-12
        self._disk_r, self._disk_c = dr[inside].astype(np.int64), dc[inside].astype(np.int64)

    def reset(self) -> None:
        self.value[:] = 0.0
        self.confidence[:] = 0.0

    def cone_confidence(self, rows: np.ndarray, cols: np.ndarray, row: int, col: int, yaw: float) -> np.ndarray:
        dr = (rows - row).astype(np.float64)
        dc = (cols - col).astype(np.float64)
        dist = np.hypot(dr, dc)
        cosang = (dr * -math.cos(yaw) + dc * -math.sin(yaw)) / np.maximum(dist, 1e-12)
        theta = np.where(dist > 0, np.arccos(np.clip(cosang, -1.0, 1.0)), 0.0)
        c = np.cos(np.clip(theta / self.half_fov, 0.0, 1.0) * (math.pi / 2.0)) ** 2
        lo = self.cfg.min_confidence
        return (lo + (1.0 - lo) * c).astype(np.float32)

    def update(self, score: float, pose: Pose2D) -> None:
        row, col = self.maps.cell(pose.x, pose.z)
        rows, cols = self.maps.explored_map.visible(row, col, pose.yaw)
        if rows.size == 0:
            return
        new_c = self.cone_confidence(rows, cols, row, col, pose.yaw)
        old_c = self.confidence[rows, cols]
        keep = ~((new_c < self.cfg.decision_threshold) & (new_c < old_c))
        rows, cols, new_c, old_c = rows[keep], cols[keep], new_c[keep], old_c[keep]
        old_v = self.value[rows, cols]
        total = old_c + new_c
        self.value[rows, cols] = (old_c * old_v + new_c * np.float32(score)) / total
        self.confidence[rows, cols] = (old_c * old_c + new_c * new_c) / total

    def frontier_values(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Value per frontier waypoint (see the module docstring)."""
        out = np.full(rows.shape[0], -1.0)
        n, m = self.value.shape
        for i in range(rows.shape[0]):
            rr = rows[i] + self._disk_r
            cc = cols[i] + self._disk_c
            ok = (rr >= 0) & (rr < n) & (cc >= 0) & (cc < m)
            rr, cc = rr[ok], cc[ok]
            has = self.confidence[rr, cc] > 0
            if has.any():
                out[i] = float(np.median(self.value[rr[has], cc[has]]))
        return out
