"""Goal objects and their viewpoints (docs/spec.md#generation, #viewpoints).

Candidates lie on a `grid_step` lattice over the object's footprint padded by `max_distance`; a
candidate is kept when it is navigable on the object's floor and within `max_distance` (measured on
the floor plane) of the object's oriented box. It faces the object's centre (yaw only); its score is
the object's frame coverage summed over the camera tilts. Viewpoints with score > `min_score` are
kept, sorted by score. The object is a goal when some single frame shows it at > `goal_min_coverage`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ovon.config.dataset import ViewpointConfig
from ovon.geometry import yaw_to_quat, yaw_towards
from ovon.scenes.model import ObjectInstance


@dataclass
class ScoredViewpoint:
    position: np.ndarray  # (3,) on the floor
    yaw: float
    score: float  # summed coverage over tilts
    best_coverage: float  # max single-frame coverage

    def rotation(self) -> list[float]:
        return yaw_to_quat(self.yaw)


def footprint_distance(obj: ObjectInstance, xz: np.ndarray) -> np.ndarray:
    """Floor-plane distance from points (N, 2) to the object's oriented box footprint (0 inside)."""
    R = np.asarray(obj.obb_rotation, dtype=np.float64)
    c = np.asarray(obj.obb_center, dtype=np.float64)
    he = np.asarray(obj.obb_half_extents, dtype=np.float64)
    d3 = np.zeros((len(xz), 3))
    d3[:, 0] = xz[:, 0] - c[0]
    d3[:, 2] = xz[:, 1] - c[2]
    local = d3 @ R  # world -> box frame (columns of R are the box axes)
    # Yaw-only boxes: local x/z span the floor plane. For tilted boxes this is still a bound.
    ex = np.maximum(np.abs(local[:, 0]) - he[0], 0.0)
    ez = np.maximum(np.abs(local[:, 2]) - he[2], 0.0)
    return np.hypot(ex, ez)


def candidate_points(obj: ObjectInstance, grid, cfg: ViewpointConfig) -> np.ndarray:
    """Navigable lattice points within `max_distance` of the box footprint, (N, 3) with floor heights."""
    lo = np.asarray(obj.aabb_min, dtype=np.float64) - cfg.max_distance
    hi = np.asarray(obj.aabb_max, dtype=np.float64) + cfg.max_distance
    # Lattice anchored at world multiples of the step, so neighbouring objects share candidates.
    xs = np.arange(math.ceil(lo[0] / cfg.grid_step), math.floor(hi[0] / cfg.grid_step) + 1) * cfg.grid_step
    zs = np.arange(math.ceil(lo[2] / cfg.grid_step), math.floor(hi[2] / cfg.grid_step) + 1) * cfg.grid_step
    if len(xs) == 0 or len(zs) == 0:
        return np.zeros((0, 3))
    X, Z = np.meshgrid(xs, zs)
    xz = np.stack([X.ravel(), Z.ravel()], axis=1)
    xz = xz[footprint_distance(obj, xz) <= cfg.max_distance + 1e-9]
    if len(xz) == 0:
        return np.zeros((0, 3))
    pts = np.zeros((len(xz), 3))
    pts[:, 0], pts[:, 2] = xz[:, 0], xz[:, 1]
    rows, cols = grid.world_to_cell(pts)
    rows, cols = np.asarray(rows), np.asarray(cols)
    inside = (rows >= 0) & (rows < grid.navigable.shape[0]) & (cols >= 0) & (cols < grid.navigable.shape[1])
    ok = np.zeros(len(pts), dtype=bool)
    ok[inside] = grid.navigable[rows[inside], cols[inside]]
    pts = pts[ok]
    pts[:, 1] = grid.heights[rows[ok], cols[ok]]
    return pts


def score_viewpoints(obj: ObjectInstance, points: np.ndarray, renderer, cfg: ViewpointConfig) -> list[ScoredViewpoint]:
    out = []
    tilts = [math.radians(t) for t in cfg.tilts_deg]
    target = np.asarray(obj.center, dtype=np.float64)
    for p in points:
        yaw = yaw_towards(p, target)
        eye = p + np.array([0.0, cfg.camera_height, 0.0])
        covs = []
        for pitch in tilts:
            sem = renderer.render(eye, yaw, pitch).semantic
            covs.append(float(np.count_nonzero(sem == obj.id)) / sem.size)
        out.append(ScoredViewpoint(p.copy(), yaw, float(sum(covs)), float(max(covs))))
    return out


def object_viewpoints(
    obj: ObjectInstance, grid, renderer, cfg: ViewpointConfig
) -> tuple[list[ScoredViewpoint], str | None]:
    """Kept viewpoints (best first) and, when the object is not a goal, the reason."""
    pts = candidate_points(obj, grid, cfg)
    if len(pts) == 0:
        return [], "no_navigable_point_within_1m"
    scored = score_viewpoints(obj, pts, renderer, cfg)
    if max(v.best_coverage for v in scored) <= cfg.goal_min_coverage:
        return [], "never_covers_5_percent"
    kept = sorted((v for v in scored if v.score > cfg.min_score), key=lambda v: (-v.score, *v.position.tolist()))
    if cfg.max_viewpoints > 0:
        kept = kept[: cfg.max_viewpoints]
    if not kept:
        return [], "no_viewpoint_above_min_score"
    return kept, None
