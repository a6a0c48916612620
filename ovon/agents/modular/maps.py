"""The agent's own top-down maps from depth + odometry (nothing privileged): obstacles, navigability,
explored area and frontiers.

* Obstacles: depth points whose height above the floor lies in the configured band, binned into 5 cm cells;
  they accumulate and are never cleared (as VLFM's). Optionally a blocked MOVE_FORWARD (the `collided` bump
  sensor) marks the cell just beyond the agent's radius ahead.
* Navigable: every cell farther than the inflation radius (the agent's radius) from all obstacle cells;
  unknown space is navigable, so plans are optimistic and re-planned as the map grows. Cells one and two
  cells beyond the inflation get a planning penalty (as the frontier expert's map), kept incrementally.
* Explored area and frontiers: the SAME `ovon.maps.ExploredMap` / `FrontierMap` the frontier expert runs on
  the true map; here non-navigable (inflated) cells are opaque, as in VLFM (the inflation closes the gaps
  that diverging depth rays leave in far walls, which would otherwise leak the view cone outside the house),
  and the navigability changes in place (`update_navigability`).
* The start pose is the centre of the middle cell (the simulator's grids put cell centres on multiples of
  the cell size, so with a start on a cell centre and a yaw that is a multiple of 90 degrees both grids
  coincide; a wall at a round coordinate then lies inside a cell, not on a border between two).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ovon.agents.modular.config import MapConfig, checked
from ovon.agents.modular.sensors import DepthProjector, Pose2D, Sensors
from ovon.maps import ExploredMap, FrontierMap, Frontiers


@nb.njit(cache=True, nogil=True)
def _add_obstacles(obstacle, navigable, penalty, rr, cc, off_r, off_c, off_ring, out_r, out_c):
    """Mark obstacle cells, inflate them and raise the penalty ring; returns how many cells stopped being
    navigable (written to out_r/out_c)."""
    rows, cols = obstacle.shape
    m = 0
    for k in range(rr.shape[0]):
        r = rr[k]
        c = cc[k]
        if obstacle[r, c]:
            continue
        obstacle[r, c] = True
        for j in range(off_r.shape[0]):
            nr = r + off_r[j]
            nc = c + off_c[j]
            if nr < 0 or nr >= rows or nc < 0 or nc >= cols:
                continue
            ring = off_ring[j]
            if ring == 0:
                if navigable[nr, nc]:
                    navigable[nr, nc] = False
                    out_r[m] = nr
                    out_c[m] = nc
                    m += 1
            else:
                v = 4 if ring == 1 else 2
                if penalty[nr, nc] < v:
                    penalty[nr, nc] = v
    return m


def inflation_offsets(radius_cells: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cell offsets within the inflation disk (ring 0: centre distance < radius, as the simulator's
    navigability erosion) and the two penalty rings beyond it (ring 1, ring 2)."""
    k = int(math.ceil(radius_cells)) + 2
    dr, dc = np.mgrid[-k : k + 1, -k : k + 1]
    d = np.hypot(dr, dc).ravel()
    ring = np.full(d.shape, -1, dtype=np.int8)
    ring[d < radius_cells + 2] = 2
    ring[d < radius_cells + 1] = 1
    ring[d < radius_cells] = 0
    keep = ring >= 0
    return dr.ravel()[keep].astype(np.int32), dc.ravel()[keep].astype(np.int32), ring[keep]


class AgentMaps:
    """Obstacle, navigability, explored and frontier maps in the episodic frame (start at the centre)."""

    def __init__(self, cfg: MapConfig, sensors: Sensors) -> None:
        self.cfg = checked(cfg, "maps")
        self.sensors = sensors
        cs = float(cfg.cell_size_m)
        n = int(round(cfg.size_m / cs))
        self.cell_size = cs
        self.shape = (n, n)
        # world (x, z) of cell (0, 0)'s corner; the start (0, 0) is the centre of cell (n // 2, n // 2)
        self.origin = np.full(2, -(n // 2 + 0.5) * cs)
        self.obstacle = np.zeros(self.shape, dtype=np.bool_)
        self.navigable = np.ones(self.shape, dtype=np.bool_)
        self.penalty = np.zeros(self.shape, dtype=np.uint8)
        body = sensors.body
        self.min_height = float(cfg.obstacle_min_height_m)
        self.max_height = float(body.height if cfg.obstacle_max_height_m is None else cfg.obstacle_max_height_m)
        self.radius_m = float(body.radius if cfg.inflation_radius_m is None else cfg.inflation_radius_m)
        self._off = inflation_offsets(self.radius_m / cs)
        self.projector = DepthProjector(sensors.camera, cfg.pixel_stride)
        # opaque = not navigable (VLFM)
        self.explored_map = ExploredMap(self.navigable, self.navigable, cs, sensors.camera.hfov_deg, cfg.view_range_m)
        min_cells = max(1, int(math.ceil(cfg.min_frontier_m / cs - 1e-9)))
        self.frontier_map = FrontierMap(
            self.navigable, self.explored_map.explored, cs, cfg.pocket_area_m2, min_cells, islands=False
        )
        self.new_obstacles = 0

    @property
    def explored(self) -> np.ndarray:
        return self.explored_map.explored

    def reset(self) -> None:
        self.obstacle[:] = False
        self.navigable[:] = True
        self.penalty[:] = 0
        self.explored_map.reset()
        self.frontier_map.reset()
        self.new_obstacles = 0

    # -- coordinates ----------------------------------------------------------------------------
    def cell(self, x: float, z: float) -> tuple[int, int]:
        return (
            int(math.floor((z - self.origin[1]) / self.cell_size)),
            int(math.floor((x - self.origin[0]) / self.cell_size)),
        )

    def cell_centre(self, row: int, col: int) -> tuple[float, float]:
        """World (x, z) of a cell centre."""
        return (
            float(self.origin[0]) + (col + 0.5) * self.cell_size,
            float(self.origin[1]) + (row + 0.5) * self.cell_size,
        )

    def in_bounds(self, row: int, col: int) -> bool:
        return 0 <= row < self.shape[0] and 0 <= col < self.shape[1]

    # -- updates --------------------------------------------------------------------------------
    def add_obstacle_points(self, xz: np.ndarray) -> int:
        """Obstacle points (N, 2) world x, z -> cells; returns the number of new obstacle cells."""
        if xz.shape[0] == 0:
            return 0
        cs = self.cell_size
        cols = np.floor((xz[:, 0] - self.origin[0]) / cs).astype(np.int64)
        rows = np.floor((xz[:, 1] - self.origin[1]) / cs).astype(np.int64)
        ok = (rows >= 0) & (rows < self.shape[0]) & (cols >= 0) & (cols < self.shape[1])
        flat = np.unique(rows[ok] * self.shape[1] + cols[ok])
        flat = flat[~self.obstacle.ravel()[flat]]
        if flat.size == 0:
            return 0
        rr = (flat // self.shape[1]).astype(np.int32)
        cc = (flat % self.shape[1]).astype(np.int32)
        off_r, off_c, ring = self._off
        cap = rr.size * int((ring == 0).sum()) + 1
        out_r = np.empty(cap, dtype=np.int32)
        out_c = np.empty(cap, dtype=np.int32)
        m = _add_obstacles(self.obstacle, self.navigable, self.penalty, rr, cc, off_r, off_c, ring, out_r, out_c)
        if m:
            self.frontier_map.update_navigability(out_r[:m], out_c[:m])
        return int(rr.size)

    def update(self, depth: np.ndarray, pose: Pose2D, pitch: float = 0.0, bumped: bool = False) -> None:
        """Integrate one frame: obstacles from depth (and the bump sensor), then the view cone."""
        pts = self.projector.frame_points(np.asarray(depth, dtype=np.float32), pose, pitch)
        band = (pts[:, 1] >= self.min_height) & (pts[:, 1] <= self.max_height)
        n = self.add_obstacle_points(pts[band][:, [0, 2]])
        if bumped and self.cfg.bump_obstacles:
            ahead = self.radius_m + self.cell_size
            n += self.add_obstacle_points(
                np.array([[pose.x - math.sin(pose.yaw) * ahead, pose.z - math.cos(pose.yaw) * ahead]])
            )
        self.new_obstacles = n
        r, c = self.cell(pose.x, pose.z)
        self.explored_map.update(r, c, pose.yaw)
        self.frontier_map.update(self.explored_map.new_r, self.explored_map.new_c)

    def frontiers(self) -> Frontiers:
        return self.frontier_map.frontiers()
