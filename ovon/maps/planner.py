"""Grid planning and steering on a navigability map, shared by the privileged experts (the true map) and the
modular agents (their own map built from depth).

* `lookahead_index`: the furthest point of a path, at most `lookahead` cells ahead, that the agent cell
  sees through navigable cells (closed-supercover test): heading targets never cut wall corners.
* `heading_error` / `action_towards`: turn when the target is more than `threshold` off the heading, else
  MOVE_FORWARD; `Steering` adds detours around forwards the map says are blocked.
* `frontier_search`: one multi-target A* (bucket queue, octile costs 5/7) from the agent cell for the
  target with the least estimated time (path / speed + turn / turn speed): the frontier expert's
  "one distance field from the agent", limited to the cells that can matter; `trace_parents` reads its path.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ovon.geometry import wrap_angle
from ovon.sim.agent import MOVE_FORWARD, STOP, TURN_LEFT, TURN_RIGHT
from ovon.sim.collision import forward_delta, free_prefix
from ovon.sim.los import los_clear


@nb.njit(cache=True, nogil=True)
def lookahead_index(navigable: np.ndarray, r0: int, c0: int, pr: np.ndarray, pc: np.ndarray, lo: int, hi: int) -> int:
    """Largest index k in [lo, hi) whose path cell is in line of sight of (r0, c0); lo if none."""
    for k in range(hi - 1, lo, -1):
        r = pr[k]
        c = pc[k]
        if not navigable[r, c]:
            continue
        if los_clear(navigable, r0, c0, r, c):
            return k
    return lo


def heading_error(position: np.ndarray, yaw: float, target_xz: tuple[float, float]) -> float:
    """Signed angle (radians, positive = to the left) from the heading to the target."""
    dx = float(target_xz[0]) - float(position[0])
    dz = float(target_xz[1]) - float(position[2])
    if dx * dx + dz * dz < 1e-12:
        return 0.0
    want = math.atan2(-dx, -dz)
    return wrap_angle(want - yaw)


def action_towards(err: float, threshold_rad: float) -> int:
    """Turn toward the target when it is more than `threshold` off, else MOVE_FORWARD."""
    if abs(err) > threshold_rad:
        return TURN_LEFT if err > 0 else TURN_RIGHT
    return MOVE_FORWARD


@nb.njit(cache=True, nogil=True)
def _octile_h(r: int, c: int, target_r: np.ndarray, target_c: np.ndarray, tunits: np.ndarray) -> int:
    """min over targets of octile distance (5 / 7 units) + turning time units."""
    best = 1 << 60
    for t in range(target_r.shape[0]):
        dr = abs(r - target_r[t])
        dc = abs(c - target_c[t])
        if dr > dc:
            v = 5 * dr + 2 * dc + tunits[t]
        else:
            v = 5 * dc + 2 * dr + tunits[t]
        if v < best:
            best = v
    return best


@nb.njit(cache=True, nogil=True)
def frontier_search(
    navigable: np.ndarray,
    r0: int,
    c0: int,
    target_r: np.ndarray,
    target_c: np.ndarray,
    tidx: np.ndarray,
    turn_cost: np.ndarray,
    cell_time: float,
    dist: np.ndarray,
    parent: np.ndarray,
    stamp: np.ndarray,
    stamp_id: int,
    bcell: np.ndarray,
    bg: np.ndarray,
    penalty: np.ndarray,
) -> int:
    """Multi-target A* from (r0, c0) minimising path time + turning time; returns the best target or -1.

    Moves: 8-connected over navigable cells, integer costs 5 (straight) / 7 (diagonal, both side cells
    navigable), so a bucket queue replaces the heap. Heuristic: min over targets of the octile distance
    plus the target's turning time (floored to cost units): consistent, so keys pop in order. A target
    reached with cost g is a candidate with time g * cell_time + turn_cost; the search stops once the
    smallest key reaches the best candidate's time, which no other path can beat.
    `tidx[r, c]` = target index in that cell (-1 elsewhere); `dist`, `parent` are scratch arrays valid
    where `stamp == stamp_id`, so nothing is cleared per call. `parent` holds flat cell ids (-1 = start).
    `penalty[r, c]` (uint8, <= 8) = extra cost for entering a cell (cells next to obstacles: thin
    channels that 30-degree headings cannot follow cost more). `bcell`, `bg` (32, capacity) = bucket
    scratch; returns -2 when a bucket overflows (the caller grows them and retries: growing inside the
    kernel made numba compile for 15 s).
    """
    rows, cols = navigable.shape
    k = target_r.shape[0]
    tunits = np.empty(k, dtype=np.int64)
    for t in range(k):
        tunits[t] = int(math.floor(turn_cost[t] / cell_time))
    nb_ = 32  # keys of pending entries lie in [f, f + 7 + 8 + 7]
    cap = bcell.shape[1]
    bcount = np.zeros(nb_, dtype=np.int64)

    stamp[r0, c0] = stamp_id
    dist[r0, c0] = 0
    parent[r0, c0] = -1
    f = _octile_h(r0, c0, target_r, target_c, tunits)
    bcell[f % nb_, 0] = r0 * cols + c0
    bg[f % nb_, 0] = 0
    bcount[f % nb_] = 1
    pending = 1
    best = -1
    best_t = np.inf
    while pending > 0:
        b = f % nb_
        if bcount[b] == 0:
            f += 1
            continue
        if f * cell_time >= best_t:
            break
        bcount[b] -= 1
        pending -= 1
        cell = bcell[b, bcount[b]]
        g = bg[b, bcount[b]]
        r = cell // cols
        c = cell - r * cols
        if dist[r, c] != g:
            continue  # stale entry
        t = tidx[r, c]
        if t >= 0:
            tt = g * cell_time + turn_cost[t]
            if tt < best_t:
                best_t = tt
                best = t
        for dr in range(-1, 2):
            for dc in range(-1, 2):
                if dr == 0 and dc == 0:
                    continue
                nr = r + dr
                nc = c + dc
                if nr < 0 or nr >= rows or nc < 0 or nc >= cols:
                    continue
                if not navigable[nr, nc]:
                    continue
                if dr != 0 and dc != 0:
                    if not (navigable[r + dr, c] and navigable[r, c + dc]):
                        continue
                    ng = g + 7 + penalty[nr, nc]
                else:
                    ng = g + 5 + penalty[nr, nc]
                if stamp[nr, nc] == stamp_id and dist[nr, nc] <= ng:
                    continue
                stamp[nr, nc] = stamp_id
                dist[nr, nc] = ng
                parent[nr, nc] = cell
                nf = ng + _octile_h(nr, nc, target_r, target_c, tunits)
                nbk = nf % nb_
                if bcount[nbk] == cap:
                    return -2
                bcell[nbk, bcount[nbk]] = nr * cols + nc
                bg[nbk, bcount[nbk]] = ng
                bcount[nbk] += 1
                pending += 1
    return best


@nb.njit(cache=True, nogil=True)
def trace_parents(parent: np.ndarray, r: int, c: int, cols: int) -> tuple[np.ndarray, np.ndarray]:
    """Path from the search start to (r, c) via `parent` (flat cell ids), start first."""
    n = 1
    cell = parent[r, c]
    while cell >= 0:
        n += 1
        cell = parent[cell // cols, cell % cols]
    pr = np.empty(n, dtype=np.int32)
    pc = np.empty(n, dtype=np.int32)
    k = n - 1
    pr[k] = r
    pc[k] = c
    cell = parent[r, c]
    while cell >= 0:
        k -= 1
        pr[k] = cell // cols
        pc[k] = cell % cols
        cell = parent[cell // cols, cell % cols]
    return pr, pc


def forward_free(
    navigable: np.ndarray, ox: float, oz: float, cs: float, x: float, z: float, yaw: float, step: float
) -> bool:
    """Whether MOVE_FORWARD from (x, z) stays on navigable cells: the simulator's own test."""
    dx, dz = forward_delta(yaw, step)
    k, n = free_prefix(navigable, ox, oz, cs, x, z, dx, dz)
    return k == n


class Steering:
    """Turns a desired heading error into an action that does not walk into walls.

    Rule (docs/spec.md#action-rule): turn toward the waypoint when it is more than `threshold` off, else MOVE_FORWARD.
    A forward that the grid says would be blocked (the true map for the privileged experts, the agent's own
    map for the modular navigator) is replaced by a detour: the reachable heading (multiples of one turn)
    with a free forward step closest to the desired one, committed to until it has been taken (else
    turn-back ping-pong). A collision the map did not predict (e.g. actuation noise) triggers the same detour.

    DAgger: `last_action` = the action executed before this state, when it was not ours; a state that
    jumped elsewhere drops the commitment.
    """

    def __init__(self, grid: object, threshold_rad: float, turn_rad: float, step_m: float) -> None:
        self.navigable = np.ascontiguousarray(grid.navigable, dtype=np.bool_)  # type: ignore[attr-defined]
        self.ox = float(grid.origin[0])  # type: ignore[attr-defined]
        self.oz = float(grid.origin[1])  # type: ignore[attr-defined]
        self.cs = float(grid.cell_size)  # type: ignore[attr-defined]
        self.threshold = threshold_rad
        self.turn = turn_rad
        self.step = step_m
        self.reset()

    def reset(self) -> None:
        self.prev_pos: np.ndarray | None = None
        self.prev_yaw = 0.0
        self.last_action: int | None = None
        self.commit_yaw: float | None = None
        self.collided = False
        self.detours = 0

    def free(self, position: np.ndarray, yaw: float) -> bool:
        return bool(
            forward_free(
                self.navigable, self.ox, self.oz, self.cs, float(position[0]), float(position[2]), yaw, self.step
            )
        )

    def observe(self, position: np.ndarray, yaw: float, last_action: int | None) -> None:
        """Start a step: detect a blocked forward and state jumps from the previous step."""
        a = self.last_action if last_action is None else last_action
        self.collided = False
        if self.prev_pos is None:
            return
        dx = float(position[0]) - float(self.prev_pos[0])
        dz = float(position[2]) - float(self.prev_pos[2])
        moved = math.hypot(dx, dz)
        if a == MOVE_FORWARD and moved < 0.5 * self.step:
            self.collided = True
        if self.commit_yaw is not None:
            jumped = moved > 1.5 * self.step or (a is not None and a != self.last_action)
            if jumped:
                self.commit_yaw = None

    def _detour(self, position: np.ndarray, yaw: float, err: float) -> int:
        """Commit to the free heading closest to the desired one; return the first turn toward it."""
        self.detours += 1
        want = yaw + err
        best_k = 0
        best_cost = math.inf
        n = int(round(math.pi / self.turn))
        for k in range(-n, n + 1):
            if k == 0:
                continue
            h = yaw + k * self.turn
            if not self.free(position, h):
                continue
            cost = abs(wrap_angle(h - want)) + 1e-3 * abs(k)
            if cost < best_cost:
                best_cost = cost
                best_k = k
        if best_k == 0:  # boxed in: keep turning one way
            self.commit_yaw = None
            return TURN_LEFT
        self.commit_yaw = wrap_angle(yaw + best_k * self.turn)
        return TURN_LEFT if best_k > 0 else TURN_RIGHT

    def act(self, position: np.ndarray, yaw: float, err: float, last_action: int | None = None) -> int:
        """Action for heading error `err` (radians, positive = target to the left)."""
        self.observe(position, yaw, last_action)
        action = self.choose(position, yaw, err)
        self.record(position, yaw, action)
        return action

    def choose(self, position: np.ndarray, yaw: float, err: float) -> int:
        """Action for heading error `err`, between `observe` and `record`."""
        if self.commit_yaw is not None:
            d = wrap_angle(self.commit_yaw - yaw)
            if abs(d) < 0.5 * self.turn:
                self.commit_yaw = None
                if self.free(position, yaw):
                    return MOVE_FORWARD
                return self._detour(position, yaw, err)
            return TURN_LEFT if d > 0 else TURN_RIGHT
        a = action_towards(err, self.threshold)
        if a == MOVE_FORWARD and (self.collided or not self.free(position, yaw)):
            return self._detour(position, yaw, err)
        return a

    def record(self, position: np.ndarray, yaw: float, action: int) -> None:
        """Remember this step (also for actions decided elsewhere, e.g. STOP turns)."""
        self.prev_pos = np.array(position, dtype=np.float64)
        self.prev_yaw = yaw
        self.last_action = action
        if action == STOP:
            self.commit_yaw = None
