"""Point-goal navigation (bee-lining) behind one protocol, used by both modular agents.

    class PointGoalNavigator(Protocol):
        name: str
        def reset(self, seed: int = 0) -> None: ...
        def act(self, observation: dict, request: NavRequest) -> int | None: ...

`request` holds the odometry pose, the target point in the episodic frame (its polar coordinates `rho`,
`theta` relative to the agent: what a learned PointNav policy takes with the depth frame), whether it is
the goal (STOP within `stop_distance_m`) or a frontier waypoint, and the agent's own maps. `act` returns
an action, or None when the target cannot be reached (the caller chooses another).

Implementations (`NavigatorConfig.kind`): "geometric" (default), "learned" (a PointNav policy trained by
`ovon train --task pointnav`: ovon.agents.modular.learned_navigator), or "package.module:Class"
constructed as `Class(cfg: NavigatorConfig, maps: AgentMaps, sensors: Sensors)`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal, Protocol, runtime_checkable

import numpy as np

from ovon.agents.modular.config import NavigatorConfig, checked
from ovon.agents.modular.maps import AgentMaps
from ovon.agents.modular.sensors import Pose2D, Sensors
from ovon.maps.planner import (
    Steering,
    action_towards,
    frontier_search,
    heading_error,
    lookahead_index,
    trace_parents,
)
from ovon.plugins import load_named
from ovon.sim.agent import MOVE_FORWARD, STOP, TURN_LEFT, TURN_RIGHT
from ovon.sim.collision import forward_delta


@dataclass
class NavRequest:
    pose: Pose2D
    target: tuple[float, float]  # (x, z) in the episodic frame
    kind: Literal["goal", "frontier"]
    maps: AgentMaps

    @property
    def rho(self) -> float:
        return math.hypot(self.target[0] - self.pose.x, self.target[1] - self.pose.z)

    @property
    def theta(self) -> float:
        """Angle of the target from the heading (radians, positive = to the left)."""
        return heading_error(self.pose.position, self.pose.yaw, self.target)


@runtime_checkable
class PointGoalNavigator(Protocol):
    name: str

    def reset(self, seed: int = 0) -> None: ...  # seed: the episode's, for navigators that sample

    def act(self, observation: dict, request: NavRequest) -> int | None: ...


class GeometricNavigator:
    """A* on the agent's own navigability (re-planned every step as the map grows) + path following.

    The plan is the multi-target A* the frontier expert uses too (`ovon.maps.planner.frontier_search`): for a goal
    point the targets are, in each of `goal_ring_bins` directions around it, the nearest navigable cell
    within the stop distance (the goal itself usually lies on an obstacle); for a frontier the waypoint.
    Heading: the furthest path cell within `lookahead_m` in line of sight; turn when it is more than
    `turn_threshold_deg` off, else MOVE_FORWARD, with the planner's `Steering` detours around obstacles the
    map predicts (and the bump sensor reports). An agent standing on a cell its map calls blocked (an
    obstacle seen within its radius) first drives to the nearest navigable cell.

    Final approach: within one forward step of the stop radius the agent heads for the goal point itself
    (the smallest turn after which one MOVE_FORWARD, free on the map, lands inside the radius), as a
    point-goal policy does. Following the plan there instead, the agent can circle a ring cell a few cm
    away that 0.25 m steps overshoot, just outside the radius until the step limit. Where no single step
    lands inside (the free space near the goal is narrower than the turns allow), the agent STOPs after
    `settle_steps` steps within one step of the radius without getting 5 cm closer: it is as close as its
    actions get it.
    """

    name = "geometric"

    def __init__(self, cfg: NavigatorConfig, maps: AgentMaps, sensors: Sensors) -> None:
        self.cfg = checked(cfg, "navigator")
        self.maps = maps
        body = sensors.body
        self.steering = Steering(
            maps, math.radians(cfg.turn_threshold_deg), math.radians(body.turn_angle_deg), body.forward_step
        )
        self.threshold = math.radians(cfg.turn_threshold_deg)
        shape = maps.shape
        self._dist = np.zeros(shape, dtype=np.int32)
        self._parent = np.zeros(shape, dtype=np.int32)
        self._stamp = np.zeros(shape, dtype=np.int32)
        self._tidx = np.full(shape, -1, dtype=np.int32)
        cap = 2 * (shape[0] + shape[1]) + 64
        self._bcell = np.empty((32, cap), dtype=np.int64)
        self._bg = np.empty((32, cap), dtype=np.int64)
        self._stamp_id = 0
        self.lookahead_cells = max(1, int(round(cfg.lookahead_m / maps.cell_size)))
        self.path: tuple[np.ndarray, np.ndarray] | None = None
        self._settle_best = math.inf  # closest approach to the goal point within one step of the radius
        self._settle_steps = 0  # steps there since it last improved

    def reset(self, seed: int = 0) -> None:
        self._settle_best = math.inf
        self._settle_steps = 0
        self.steering.reset()
        self._stamp[:] = 0
        self._stamp_id = 0
        self.path = None

    # -- planning -------------------------------------------------------------------------------
    def _goal_targets(self, x: float, z: float) -> tuple[np.ndarray, np.ndarray]:
        """Nearest navigable cell within the stop distance in each direction around the goal point."""
        m = self.maps
        cs = m.cell_size
        # stay a little inside the stop radius: the agent stops at the first step inside it
        rad = max(cs, self.cfg.stop_distance_m - 0.5 * cs)
        gr, gc = m.cell(x, z)
        k = int(math.ceil(rad / cs))
        r0, r1 = max(0, gr - k), min(m.shape[0], gr + k + 1)
        c0, c1 = max(0, gc - k), min(m.shape[1], gc + k + 1)
        rr, cc = np.nonzero(m.navigable[r0:r1, c0:c1])
        rr, cc = rr + r0, cc + c0
        px = m.origin[0] + (cc + 0.5) * cs - x
        pz = m.origin[1] + (rr + 0.5) * cs - z
        d = np.hypot(px, pz)
        keep = d <= rad
        rr, cc, d, px, pz = rr[keep], cc[keep], d[keep], px[keep], pz[keep]
        if rr.size == 0:
            return rr.astype(np.int32), cc.astype(np.int32)
        bins = ((np.arctan2(pz, px) + math.pi) / (2 * math.pi) * self.cfg.goal_ring_bins).astype(np.int64)
        bins = np.minimum(bins, self.cfg.goal_ring_bins - 1)
        order = np.lexsort((d, bins))
        first = np.ones(order.size, dtype=bool)
        first[1:] = bins[order][1:] != bins[order][:-1]
        pick = order[first]
        return rr[pick].astype(np.int32), cc[pick].astype(np.int32)

    def _start_cell(self, pose: Pose2D) -> tuple[int, int, bool]:
        """The agent cell, or the nearest navigable cell within `escape_radius_m` when the map blocks the
        agent's own cell; the flag says whether the agent stands on a navigable cell."""
        m = self.maps
        r, c = m.cell(pose.x, pose.z)
        if not m.in_bounds(r, c) or m.navigable[r, c]:
            return r, c, True
        k = max(1, int(round(self.cfg.escape_radius_m / m.cell_size)))
        r0, c0 = max(0, r - k), max(0, c - k)
        rr, cc = np.nonzero(m.navigable[r0 : r + k + 1, c0 : c + k + 1])
        if rr.size == 0:
            return r, c, False
        i = int(np.argmin((rr + r0 - r) ** 2 + (cc + c0 - c) ** 2))
        return int(rr[i] + r0), int(cc[i] + c0), False

    def on_map(self, pose: Pose2D) -> bool:
        """Whether the agent stands on a cell its map holds navigable (or off the map's bounds)."""
        return self._start_cell(pose)[2]

    def plan(self, pose: Pose2D, tr: np.ndarray, tc: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """Shortest path (rows, cols) from the agent to the cheapest target, or None."""
        m = self.maps
        r, c, _ = self._start_cell(pose)
        if tr.size == 0 or not m.in_bounds(r, c):
            return None
        self._tidx[tr, tc] = np.arange(tr.size, dtype=np.int32)
        zeros = np.zeros(tr.size, dtype=np.float64)
        while True:
            self._stamp_id += 1
            best = frontier_search(
                m.navigable,
                r,
                c,
                tr,
                tc,
                self._tidx,
                zeros,
                1.0,
                self._dist,
                self._parent,
                self._stamp,
                self._stamp_id,
                self._bcell,
                self._bg,
                m.penalty,
            )
            if best != -2:
                break
            cap = 2 * self._bcell.shape[1]
            self._bcell = np.empty((32, cap), dtype=np.int64)
            self._bg = np.empty((32, cap), dtype=np.int64)
        self._tidx[tr, tc] = -1
        if self._stamp_id > 2_000_000_000:
            self._stamp[:] = 0
            self._stamp_id = 0
        if best < 0:
            return None
        return trace_parents(self._parent, int(tr[best]), int(tc[best]), m.shape[1])

    def route(self, request: NavRequest) -> tuple[np.ndarray, np.ndarray] | None:
        """Shortest path (rows, cols) on the agent's map to the request's target: for a goal point to the
        nearest free cell within the stop distance around it, for a frontier to its cell; None when none."""
        if request.kind == "goal":
            tr, tc = self._goal_targets(*request.target)
        else:
            r, c = self.maps.cell(*request.target)
            tr, tc = np.array([r], dtype=np.int32), np.array([c], dtype=np.int32)
        return self.plan(request.pose, tr, tc)

    # -- acting ---------------------------------------------------------------------------------
    def final_approach(self, pose: Pose2D, target: tuple[float, float]) -> int | None:
        """The first action of the smallest turn (then MOVE_FORWARD) whose forward step is free on the map and
        ends within the stop distance of `target`; None when no heading does (or the target is farther)."""
        st = self.steering
        stop = self.cfg.stop_distance_m
        if math.hypot(target[0] - pose.x, target[1] - pose.z) >= stop + st.step:
            return None
        n = int(round(math.pi / st.turn))
        for k in sorted(range(-n, n + 1), key=lambda k: (abs(k), -k)):  # straight first, left before right
            h = pose.yaw + k * st.turn
            dx, dz = forward_delta(h, st.step)
            if math.hypot(pose.x + dx - target[0], pose.z + dz - target[1]) >= stop or not st.free(pose.position, h):
                continue
            return MOVE_FORWARD if k == 0 else (TURN_LEFT if k > 0 else TURN_RIGHT)
        return None

    def _settled(self, rho: float) -> bool:
        """Within one step of the stop radius for `settle_steps` steps without getting 5 cm closer."""
        if rho >= self.cfg.stop_distance_m + self.steering.step:
            self._settle_best, self._settle_steps = math.inf, 0
            return False
        if rho < self._settle_best - 0.05:
            self._settle_best, self._settle_steps = rho, 0
            return False
        self._settle_steps += 1
        return self._settle_steps >= self.cfg.settle_steps

    def act(self, observation: dict, request: NavRequest) -> int | None:
        pose = request.pose
        if request.kind == "goal" and request.rho < self.cfg.stop_distance_m:
            self.steering.record(pose.position, pose.yaw, STOP)
            return STOP
        if request.kind == "goal":
            if self._settled(request.rho):
                self.steering.record(pose.position, pose.yaw, STOP)
                return STOP
            action = self.final_approach(pose, request.target)
            if action is not None:
                self.path = None
                self.steering.record(pose.position, pose.yaw, action)
                return action
        m = self.maps
        path = self.route(request)
        self.path = path
        if path is None:
            return None
        pr, pc = path
        r, c, on_map = self._start_cell(pose)
        k = lookahead_index(m.navigable, r, c, pr, pc, 0, min(pr.size, self.lookahead_cells + 1))
        if k == 0 and pr.size > 1:
            k = 1
        x, z = m.cell_centre(int(pr[k]), int(pc[k]))
        if pr.size == 1:  # already at the target cell: head for the target point itself
            x, z = request.target
        err = heading_error(pose.position, pose.yaw, (x, z))
        if not on_map:  # escaping a cell the map blocks: the map cannot predict collisions here
            action = action_towards(err, self.threshold)
            self.steering.record(pose.position, pose.yaw, action)
            return action
        return self.steering.act(pose.position, pose.yaw, err)


NAVIGATORS: dict[str, str] = {
    "geometric": "ovon.agents.modular.navigation:GeometricNavigator",
    "learned": "ovon.agents.modular.learned_navigator:LearnedNavigator",
}


def make_navigator(cfg: NavigatorConfig, maps: AgentMaps, sensors: Sensors) -> PointGoalNavigator:
    """The navigator `cfg.kind` names (built-ins and plug-ins alike get `(cfg, maps, sensors)`)."""
    return load_named(cfg.kind, NAVIGATORS, "navigator.kind")(cfg, maps, sensors)
