"""Frontier-exploration expert (the paper's DAgger teacher), privileged and fast.

Per step: (1) the explored map is updated from the true pose (exact line of sight in the view cone, only
the cone's bounding box is touched), (2) pockets and frontier cells are updated around the newly explored
cells only, (3) the action: STOP logic near a viewpoint, bee-line along the cached goal field within
`beeline_distance_m`, else follow the planned path to the chosen frontier. A frontier is (re)chosen only
when there is none, it vanished, it was reached, the agent left its path, or every `rechoose_every` steps;
the choice is one pruned Dijkstra from the agent cell (see `control.frontier_search`).

`act(state)` works on any sequence of states (DAgger labels the student's states): the explored map
accumulates from the states it is given and a jump off the planned path triggers a re-plan.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy import ndimage

from ovon.experts.config import FrontierExpertConfig
from ovon.experts.control import nearest_path_index
from ovon.experts.rig import Embodiment
from ovon.experts.shortest_path import (
    DistanceFieldFn,
    GoalFollower,
    Viewpoint,
    agent_cell,
    default_distance_field_fn,
)
from ovon.maps.frontiers import FrontierMap
from ovon.maps.planner import Steering, frontier_search, heading_error, lookahead_index, trace_parents
from ovon.maps.visibility import ExploredMap
from ovon.sim.agent import STOP
from ovon.sim.types import AgentState


class FrontierExpert:
    """Frontier-exploration expert; `timing` holds the last step's ms per phase for the benchmark."""

    def __init__(
        self,
        cfg: FrontierExpertConfig | None = None,
        body: Embodiment | None = None,
        distance_field_fn: DistanceFieldFn | None = None,
    ):
        """`body`: turn angle, step, FOV and success radius (default: those of the default sim/task
        configs; `ovon.experts.rig.make_expert` derives them from the run's configs)."""
        self.cfg = cfg or FrontierExpertConfig()
        self.body = body or Embodiment.of()
        self._field_fn = distance_field_fn
        self.grid: Any = None
        self.explored_map: ExploredMap | None = None
        self.frontier_map: FrontierMap | None = None
        self.follower: GoalFollower | None = None
        self.steering: Steering | None = None
        self.timing: dict[str, float] = {"visibility": 0.0, "frontiers": 0.0, "choice": 0.0, "total": 0.0}
        self.mode = "idle"
        self.n_choices = 0

    # ------------------------------------------------------------------ episode
    def reset(self, grid: Any, goal_viewpoints: Sequence[Viewpoint], state: AgentState | None = None) -> None:
        """Start an episode: all exploration state is cleared (maps are rebuilt when the grid changes)."""
        cfg = self.cfg
        if grid is not self.grid or self.explored_map is None:
            self.grid = grid
            cs = float(grid.cell_size)
            nav = np.ascontiguousarray(grid.navigable, dtype=np.bool_)
            free = np.ascontiguousarray(grid.free, dtype=np.bool_) | nav
            self.explored_map = ExploredMap(free, nav, cs, self.body.fov_deg, cfg.view_range_m)
            min_cells = max(1, int(math.ceil(cfg.min_frontier_m / cs - 1e-9)))
            self.frontier_map = FrontierMap(nav, self.explored_map.explored, cs, cfg.pocket_area_m2, min_cells)
            self.navigable = nav
            shape = nav.shape
            self._sdist = np.zeros(shape, dtype=np.int32)
            self._sparent = np.zeros(shape, dtype=np.int32)
            self._sstamp = np.zeros(shape, dtype=np.int32)
            self._tidx = np.full(shape, -1, dtype=np.int32)
            cap = 2 * (shape[0] + shape[1]) + 64
            # planning penalty next to obstacles: 1-2 cell channels cannot be followed with 30 deg turns
            clearance = ndimage.distance_transform_cdt(nav, metric="chessboard")
            self._penalty = np.where(clearance == 1, 4, np.where(clearance == 2, 2, 0)).astype(np.uint8)
            self._bcell = np.empty((32, cap), dtype=np.int64)  # frontier search bucket queue
            self._bg = np.empty((32, cap), dtype=np.int64)
            self.steering = Steering(
                grid,
                math.radians(cfg.turn_threshold_deg),
                math.radians(self.body.turn_angle_deg),
                self.body.forward_step_m,
            )
        assert self.explored_map is not None and self.frontier_map is not None
        self.explored_map.reset()
        self.frontier_map.reset()
        self._sstamp[:] = 0
        self._stamp_id = 0
        fn = self._field_fn or default_distance_field_fn()
        self.follower = GoalFollower(grid, goal_viewpoints, fn, cfg.lookahead_m)
        assert self.steering is not None
        self.steering.reset()
        self._clear_target()
        self._blacklist: list[tuple[int, int]] = []
        self._progress_target: tuple[int, int] | None = None
        self._progress_best = math.inf
        self._progress_age = 0
        self.mode = "idle"
        self.n_choices = 0
        self.step_count = 0

    def _clear_target(self) -> None:
        self.target: tuple[int, int] | None = None
        self._path_r = np.empty(0, dtype=np.int32)
        self._path_c = np.empty(0, dtype=np.int32)
        self._path_i = 0
        self._since_choice = 0
        self._look = False

    # ------------------------------------------------------------------ step
    def act(self, state: AgentState, last_action: int | None = None) -> int:
        """The expert's action for the true `state`; `last_action` = the action actually executed before
        it when that was not this expert's (DAgger), for collision detection."""
        assert self.explored_map is not None and self.frontier_map is not None, "call reset() first"
        t0 = time.perf_counter()
        row, col = agent_cell(self.grid, state.position)
        self.explored_map.update(row, col, float(state.yaw))
        t1 = time.perf_counter()
        self.frontier_map.update(self.explored_map.new_r, self.explored_map.new_c)
        t2 = time.perf_counter()
        action = self._decide(state, row, col, last_action)
        t3 = time.perf_counter()
        self.timing = {
            "visibility": (t1 - t0) * 1e3,
            "frontiers": (t2 - t1) * 1e3,
            "choice": (t3 - t2) * 1e3,
            "total": (t3 - t0) * 1e3,
        }
        self.step_count += 1
        return action

    def _decide(self, state: AgentState, row: int, col: int, last_action: int | None) -> int:
        cfg = self.cfg
        follower = self.follower
        steer = self.steering
        assert follower is not None and steer is not None
        steer.observe(state.position, state.yaw, last_action)
        d = follower.distance(state.position)
        err: float | None
        if d <= self.body.stop_distance_m - cfg.stop_margin_m:
            self.mode = "stop"
            action = follower.stop_action(state, math.radians(cfg.stop_heading_tol_deg))
            steer.record(state.position, state.yaw, action)
            return action
        if d < cfg.beeline_distance_m:
            self.mode = "beeline"
            err = follower.heading_error(state, row, col)
        else:
            err = self._explore(state, row, col)
            if err is None:
                if cfg.no_frontier_behaviour == "beeline" and math.isfinite(d):
                    self.mode = "beeline_no_frontier"
                    err = follower.heading_error(state, row, col)
                else:
                    self.mode = "done"
        action = STOP if err is None else steer.choose(state.position, state.yaw, err)
        steer.record(state.position, state.yaw, action)
        return action

    # ------------------------------------------------------------------ exploration
    def _needs_choice(self, row: int, col: int, position: np.ndarray) -> bool:
        cfg = self.cfg
        fm = self.frontier_map
        assert fm is not None
        if self.target is None:
            return True
        if cfg.rechoose_every > 0 and self._since_choice >= cfg.rechoose_every:
            return True
        tr, tc = self.target
        w = self.grid.cell_to_world(tr, tc)
        if (
            not self._look
            and (float(w[0]) - float(position[0])) ** 2 + (float(w[2]) - float(position[2])) ** 2
            < cfg.frontier_reached_m**2
        ):
            return True
        keep = max(1, int(round(cfg.frontier_keep_radius_m / float(self.grid.cell_size))))
        return not fm.any_frontier_near(tr, tc, keep)

    def _explore(self, state: AgentState, row: int, col: int) -> float | None:
        """Heading error toward the current frontier's path, choosing one if needed; None if none."""
        cs = float(self.grid.cell_size)
        rows, cols = self.navigable.shape
        if not (0 <= row < rows and 0 <= col < cols):
            return None
        if self._needs_choice(row, col, state.position):
            self._choose(state, row, col)
        else:
            self._since_choice += 1
        if self.target is None:
            return None
        if self._look:
            return self._look_error(state)
        if self._no_progress(state):
            self._blacklist.append(self.target)
            self._choose(state, row, col)
            if self.target is None:
                return None
            if self._look:
                return self._look_error(state)
        n = self._path_r.shape[0]
        la = max(1, int(round(self.cfg.lookahead_m / cs)))
        i, d2 = nearest_path_index(self._path_r, self._path_c, self._path_i, min(n, self._path_i + 4 * la), row, col)
        if d2 > (self.cfg.path_deviation_m / cs) ** 2:
            self._choose(state, row, col)
            if self.target is None:
                return None
            if self._look:  # the new target is a frontier at the agent's feet: no path to follow
                return self._look_error(state)
            n = self._path_r.shape[0]
            i, d2 = nearest_path_index(self._path_r, self._path_c, 0, min(n, 4 * la), row, col)
        self._path_i = i
        self.mode = "explore"
        k = lookahead_index(self.navigable, row, col, self._path_r, self._path_c, i, min(n, i + la + 1))
        if k == i:
            k = min(i + 1, n - 1)
        w = self.grid.cell_to_world(int(self._path_r[k]), int(self._path_c[k]))
        return heading_error(state.position, state.yaw, (float(w[0]), float(w[2])))

    def _no_progress(self, state: AgentState) -> bool:
        """True when the agent got no closer to its frontier for `stuck_steps` steps (e.g. a channel the
        discrete headings cannot follow); the frontier is then blacklisted for the episode."""
        assert self.target is not None
        w = self.grid.cell_to_world(*self.target)
        d = math.hypot(float(w[0]) - float(state.position[0]), float(w[2]) - float(state.position[2]))
        if self.target != self._progress_target:
            self._progress_target = self.target
            self._progress_best = d
            self._progress_age = 0
            return False
        if d < self._progress_best - 0.1:
            self._progress_best = d
            self._progress_age = 0
            return False
        self._progress_age += 1
        return self._progress_age > self.cfg.stuck_steps

    def _look_error(self, state: AgentState) -> float:
        """Heading error toward the unexplored navigable cells around a frontier at the agent's feet."""
        assert self.target is not None and self.explored_map is not None
        tr, tc = self.target
        w = max(1, int(round(self.cfg.frontier_keep_radius_m / float(self.grid.cell_size))))
        r0, c0 = max(0, tr - w), max(0, tc - w)
        win = (
            self.navigable[r0 : tr + w + 1, c0 : tc + w + 1]
            & ~self.explored_map.explored[r0 : tr + w + 1, c0 : tc + w + 1]
        )
        rr, cc = np.nonzero(win)
        if rr.size == 0:
            self.target = None
            return 0.0
        cs = float(self.grid.cell_size)
        x = float(self.grid.origin[0]) + (float(cc.mean()) + c0 + 0.5) * cs
        z = float(self.grid.origin[1]) + (float(rr.mean()) + r0 + 0.5) * cs
        self.mode = "look"
        return heading_error(state.position, state.yaw, (x, z))

    def _choose(self, state: AgentState, row: int, col: int) -> None:
        """Pick the frontier with the least estimated time; plan the path to it."""
        cfg = self.cfg
        fm = self.frontier_map
        assert fm is not None
        self._clear_target()
        self.n_choices += 1
        fr = fm.frontiers()
        if len(fr) == 0:
            return
        wr, wc = fr.rows, fr.cols
        if self.navigable[row, col] and fm.islands is not None:
            isl = fm.islands[row, col]
            keep = fm.islands[wr, wc] == isl
            wr, wc = wr[keep], wc[keep]
        k = int(wr.shape[0])
        if k == 0:
            return
        cs = float(self.grid.cell_size)
        # world x/z of waypoint cell centres, relative to the agent
        ox, oz = float(self.grid.origin[0]), float(self.grid.origin[1])
        dx = ox + (wc + 0.5) * cs - float(state.position[0])
        dz = oz + (wr + 0.5) * cs - float(state.position[2])
        near = dx * dx + dz * dz < cfg.frontier_reached_m**2
        if self._blacklist:
            keep_r = cfg.frontier_keep_radius_m / cs
            bl = np.array(self._blacklist, dtype=np.float64)
            d2 = (wr[:, None] - bl[None, :, 0]) ** 2 + (wc[:, None] - bl[None, :, 1]) ** 2
            ok = (d2 > keep_r**2).all(axis=1)
            wr, wc, dx, dz, near = wr[ok], wc[ok], dx[ok], dz[ok], near[ok]
            k = int(wr.shape[0])
            if k == 0:
                return
        if near.all():
            # only frontiers at the agent's feet: face their unexplored side instead of walking onto them
            i = int(np.argmin(dx * dx + dz * dz))
            self.target = (int(wr[i]), int(wc[i]))
            self._look = True
            self._since_choice = 0
            return
        if near.any():
            wr, wc, dx, dz = wr[~near], wc[~near], dx[~near], dz[~near]
            k = int(wr.shape[0])
        want = np.arctan2(-dx, -dz)
        turn = np.abs((want - state.yaw + np.pi) % (2 * np.pi) - np.pi)
        turn_cost = np.degrees(turn) / cfg.turn_speed_deg
        cell_time = cs / 5.0 / cfg.linear_speed
        self._tidx[wr, wc] = np.arange(k, dtype=np.int32)
        while True:
            self._stamp_id += 1
            best = frontier_search(
                self.navigable,
                row,
                col,
                wr,
                wc,
                self._tidx,
                turn_cost.astype(np.float64),
                cell_time,
                self._sdist,
                self._sparent,
                self._sstamp,
                self._stamp_id,
                self._bcell,
                self._bg,
                self._penalty,
            )
            if best != -2:
                break
            cap = 2 * self._bcell.shape[1]
            self._bcell = np.empty((32, cap), dtype=np.int64)
            self._bg = np.empty((32, cap), dtype=np.int64)
        self._tidx[wr, wc] = -1
        if best < 0:
            return
        tr, tc = int(wr[best]), int(wc[best])
        self._path_r, self._path_c = trace_parents(self._sparent, tr, tc, self.navigable.shape[1])
        self.target = (tr, tc)
        self._path_i = 0
        self._since_choice = 0

    # ------------------------------------------------------------------ introspection
    @property
    def explored(self) -> np.ndarray:
        assert self.explored_map is not None
        return self.explored_map.explored

    def frontier_cells(self) -> np.ndarray:
        """(N, 2) rows/cols of the current frontier cells."""
        assert self.frontier_map is not None
        return np.stack([self.frontier_map.frontier_rows, self.frontier_map.frontier_cols], axis=1)
