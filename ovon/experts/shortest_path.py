"""Shortest-path expert and the goal follower it shares with the frontier expert.

The follower reads one cached distance field to all goal viewpoints per episode
(`ovon.sim.geodesic.distance_field`); each step is a short steepest descent on that field plus a
line-of-sight look-ahead, so a step never runs a search.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ovon.experts.config import ShortestPathExpertConfig
from ovon.experts.control import descend_path, turn_action_to_yaw
from ovon.experts.rig import Embodiment
from ovon.maps.planner import Steering, heading_error, lookahead_index
from ovon.sim.agent import STOP
from ovon.sim.types import AgentState

Viewpoint = tuple[Any, float]  # (position (3,), yaw)
DistanceFieldFn = Callable[[Any, np.ndarray], Any]


def default_distance_field_fn() -> DistanceFieldFn:
    """`ovon.sim.geodesic.distance_field`, imported lazily (tests may inject a stand-in)."""
    from ovon.sim.geodesic import distance_field

    return distance_field


def agent_cell(grid: Any, position: np.ndarray) -> tuple[int, int]:
    rc = grid.world_to_cell(np.asarray(position, dtype=np.float64))
    return int(rc[0]), int(rc[1])


class GoalFollower:
    """Distance to / action toward the nearest goal viewpoint, from one cached distance field."""

    def __init__(
        self,
        grid: Any,
        viewpoints: Sequence[Viewpoint],
        distance_field_fn: DistanceFieldFn,
        lookahead_m: float,
    ) -> None:
        self.grid = grid
        self.positions = np.array([np.asarray(p, dtype=np.float64) for p, _ in viewpoints]).reshape(-1, 3)
        self.yaws = np.array([float(y) for _, y in viewpoints], dtype=np.float64)
        self.field = distance_field_fn(grid, self.positions) if len(self.positions) else None
        self.dist = None if self.field is None else np.asarray(self.field.dist)
        self.navigable = np.ascontiguousarray(grid.navigable, dtype=np.bool_)
        self.lookahead_cells = max(1, int(round(lookahead_m / float(grid.cell_size))))

    def distance(self, position: np.ndarray) -> float:
        if self.field is None:
            return math.inf
        d = float(self.field.distance(np.asarray(position, dtype=np.float64)))
        return d if math.isfinite(d) else math.inf

    def nearest_viewpoint(self, xz: tuple[float, float]) -> int:
        d = (self.positions[:, 0] - xz[0]) ** 2 + (self.positions[:, 2] - xz[1]) ** 2
        return int(np.argmin(d))

    def target_xz(self, position: np.ndarray, row: int, col: int) -> tuple[float, float] | None:
        """Heading target: furthest descent point in line of sight, or the viewpoint itself at the end."""
        if self.dist is None:
            return None
        rows, cols = self.dist.shape
        if not (0 <= row < rows and 0 <= col < cols):
            return None
        pr, pc, n = descend_path(self.dist, row, col, self.lookahead_cells)
        k = lookahead_index(self.navigable, row, col, pr, pc, 0, n)
        if k == 0 and n > 1:
            k = 1
        end = n < self.lookahead_cells + 1  # descent stopped early: reached the goal's minimum
        if end and k == n - 1:
            w = self.grid.cell_to_world(int(pr[k]), int(pc[k]))
            i = self.nearest_viewpoint((float(w[0]), float(w[2])))
            vp = self.positions[i]
            return float(vp[0]), float(vp[2])
        if n == 1:
            return None
        w = self.grid.cell_to_world(int(pr[k]), int(pc[k]))
        return float(w[0]), float(w[2])

    def heading_error(self, state: AgentState, row: int, col: int) -> float:
        """Heading error (radians, positive = left) toward the nearest viewpoint along the field."""
        t = self.target_xz(state.position, row, col)
        if t is None:
            return 0.0
        return heading_error(state.position, state.yaw, t)

    def stop_action(self, state: AgentState, tol_rad: float, turn_to_heading: bool = True) -> int:
        """At the viewpoint: turn to its heading (within tol), then STOP."""
        if not turn_to_heading or len(self.positions) == 0:
            return STOP
        i = self.nearest_viewpoint((float(state.position[0]), float(state.position[2])))
        a = turn_action_to_yaw(state.yaw, float(self.yaws[i]), tol_rad)
        return STOP if a is None else a


class ShortestPathExpert:
    """Follows the geodesic shortest path to the nearest goal viewpoint, turns to its heading, STOPs.

    `act(state)` only needs the true state, so it also labels arbitrary (DAgger) states; pass `last_action`
    when the executed action was not this expert's (collision detection uses it)."""

    def __init__(
        self,
        cfg: ShortestPathExpertConfig | None = None,
        body: Embodiment | None = None,
        distance_field_fn: DistanceFieldFn | None = None,
    ) -> None:
        self.cfg = cfg or ShortestPathExpertConfig()
        self.body = body or Embodiment.of()  # turn, step, FOV, success radius (ovon.experts.rig)
        self._field_fn = distance_field_fn
        self.follower: GoalFollower | None = None
        self.steering: Steering | None = None
        self.mode = "idle"
        self.timing: dict[str, float] = {}

    def reset(self, grid: Any, goal_viewpoints: Sequence[Viewpoint], state: AgentState | None = None) -> None:
        cfg = self.cfg
        fn = self._field_fn or default_distance_field_fn()
        self.grid = grid
        self.follower = GoalFollower(grid, goal_viewpoints, fn, cfg.lookahead_m)
        self.steering = Steering(
            grid,
            math.radians(cfg.turn_threshold_deg),
            math.radians(self.body.turn_angle_deg),
            self.body.forward_step_m,
        )
        self.mode = "idle"

    def goal_distance(self, state: AgentState) -> float:
        assert self.follower is not None, "call reset() first"
        return self.follower.distance(state.position)

    def act(self, state: AgentState, last_action: int | None = None) -> int:
        assert self.follower is not None and self.steering is not None, "call reset() first"
        cfg = self.cfg
        steer = self.steering
        steer.observe(state.position, state.yaw, last_action)
        d = self.follower.distance(state.position)
        if not math.isfinite(d):
            self.mode = "unreachable"
            action = STOP
        elif d <= self.body.stop_distance_m - cfg.stop_margin_m:
            self.mode = "stop"
            action = self.follower.stop_action(
                state, math.radians(cfg.stop_heading_tol_deg), cfg.turn_to_viewpoint_heading
            )
        else:
            self.mode = "follow"
            row, col = agent_cell(self.grid, state.position)
            err = self.follower.heading_error(state, row, col)
            action = steer.choose(state.position, state.yaw, err)
        steer.record(state.position, state.yaw, action)
        return action


__all__ = ["ShortestPathExpert", "GoalFollower"]
