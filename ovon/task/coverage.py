"""Floor area the agent has seen, from its true pose: the exploration term of the RL reward.

Why: with the paper's dense reward alone (progress towards the goal + slack), PPO at CPU scale settles
into turning in place or pushing into a wall, because random forward moves lose progress as often as they
gain it. Rewarding newly seen floor area (the standard ObjectNav exploration shaping, e.g. Ye et al. 2021)
makes the early policy explore, which is what finds goals. "Seen" is the frontier expert's definition:
in the camera's horizontal view cone, within range, with line of sight on the true map (ovon.maps), so
the reward uses no rendering. Training signal only: never an observation.
"""

from __future__ import annotations

import math

from ovon.maps.visibility import ExploredMap


class Coverage:
    def __init__(self, grid, fov_deg: float, range_m: float) -> None:
        self.grid = grid
        self.map = ExploredMap(grid.free | grid.navigable, grid.navigable, grid.cell_size, fov_deg, range_m)
        self.cell_area = float(grid.cell_size) ** 2

    def _see(self, position, yaw: float) -> float:
        row, col = self.grid.world_to_cell(position)
        n = self.map.update(row, col, yaw)
        if n == 0:
            return 0.0
        # floor area only: cells of the navigable map
        return float(self.map.navigable[self.map.new_r, self.map.new_c].sum()) * self.cell_area

    def reset(self, position, yaw: float) -> float:
        self.map.reset()
        return self._see(position, yaw)

    def update(self, position, yaw: float) -> float:
        """Newly seen floor area (m^2) from this pose."""
        if not math.isfinite(yaw):
            return 0.0
        return self._see(position, yaw)
