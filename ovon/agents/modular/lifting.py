"""Detections -> 3D goal points: depth back-projection at the odometry pose (noisy when odometry noise is
on), stored for the episode; the goal point is the stored point nearest to the agent (planar distance).

A mask is eroded first (edge pixels mix object and background depth); a box-only detection (OWLv2) keeps
its central part. VLFM's DBSCAN outlier removal is not needed for oracle masks and is not done.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from ovon.agents.modular.config import LiftConfig, checked
from ovon.agents.modular.sensors import DepthProjector, Pose2D
from ovon.models.detectors.base import Detection


class GoalMemory:
    def __init__(self, cfg: LiftConfig, projector: DepthProjector) -> None:
        self.cfg = checked(cfg, "lifting")
        self.projector = projector
        self.reset()

    def reset(self) -> None:
        self.points = np.zeros((0, 3), dtype=np.float32)
        self.detections = 0

    def pixels(self, det: Detection, depth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(rows, cols) of the pixels a detection lifts: object pixels with a depth inside the range."""
        pix = det.pixels(depth.shape, self.cfg.box_shrink)
        if det.mask is not None and self.cfg.mask_erode_px > 0:
            eroded = ndimage.binary_erosion(pix, iterations=self.cfg.mask_erode_px)
            if eroded.any():  # a small mask is kept whole rather than lost
                pix = eroded
        cam = self.projector.camera
        # a pixel at the sensor's minimum is clamped, not measured: the surface is nearer, somewhere on the ray
        near = max(self.cfg.min_range_m, cam.min_depth + 1e-4)
        pix &= (depth < cam.max_depth * self.cfg.max_range_fraction) & (depth >= near)
        rr, cc = np.nonzero(pix)
        k = self.cfg.points_per_detection
        if rr.size > k:  # an evenly spaced subset: the nearest point barely moves, the cost is bounded
            idx = np.linspace(0, rr.size - 1, k).astype(np.int64)
            rr, cc = rr[idx], cc[idx]
        return rr, cc

    def add(self, detections: list[Detection], depth: np.ndarray, pose: Pose2D, pitch: float = 0.0) -> int:
        """Lift and store the detections of one frame; returns the number of points added."""
        added = 0
        for det in detections:
            rr, cc = self.pixels(det, depth)
            if rr.size == 0:
                continue
            pts = self.projector.project(depth, pose, pitch, rr, cc)
            self.points = np.concatenate([self.points, pts])[-self.cfg.max_points :]
            added += int(rr.size)
            self.detections += 1
        return added

    def goal_point(self, pose: Pose2D) -> tuple[float, float] | None:
        """(x, z) of the stored point nearest to the agent, or None before any detection."""
        if self.points.shape[0] == 0:
            return None
        d = (self.points[:, 0] - pose.x) ** 2 + (self.points[:, 2] - pose.z) ** 2
        i = int(np.argmin(d))
        return float(self.points[i, 0]), float(self.points[i, 2])
