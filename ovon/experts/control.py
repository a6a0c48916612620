"""Path following on the experts' cached distance fields (the geodesic module's `dist` arrays).

* `descend_path`: steepest descent on a cached distance field, so a step never runs a search when a cached
  field answers by lookup (docs/spec.md#expert-speed).
* `nearest_path_index`: where the agent is along a stored path (progress, or a path to drop).
* `turn_action_to_yaw`: the turn toward a viewpoint's yaw once its position is reached.

The planner both the experts and the modular agents use (line of sight lookahead, steering, frontier
search) is `ovon.maps.planner`.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from ovon.geometry import wrap_angle
from ovon.sim.agent import TURN_LEFT, TURN_RIGHT


@nb.njit(cache=True, nogil=True)
def descend_path(dist: np.ndarray, r: int, c: int, max_cells: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Greedy 8-neighbour descent of `dist` from (r, c) for at most `max_cells` moves.

    Diagonal moves need both side cells finite (no squeezing past a corner). Returns (rows, cols, n)."""
    rows, cols = dist.shape
    pr = np.empty(max_cells + 1, dtype=np.int32)
    pc = np.empty(max_cells + 1, dtype=np.int32)
    pr[0] = r
    pc[0] = c
    n = 1
    cur = dist[r, c]
    for _ in range(max_cells):
        best = cur
        br = -1
        bc = -1
        for dr in range(-1, 2):
            for dc in range(-1, 2):
                if dr == 0 and dc == 0:
                    continue
                nr = r + dr
                nc = c + dc
                if nr < 0 or nr >= rows or nc < 0 or nc >= cols:
                    continue
                v = dist[nr, nc]
                if not v < best:
                    continue
                if dr != 0 and dc != 0:
                    if not (np.isfinite(dist[r + dr, c]) and np.isfinite(dist[r, c + dc])):
                        continue
                best = v
                br = nr
                bc = nc
        if br < 0:
            break
        r = br
        c = bc
        cur = best
        pr[n] = r
        pc[n] = c
        n += 1
    return pr, pc, n


@nb.njit(cache=True, nogil=True)
def nearest_path_index(pr: np.ndarray, pc: np.ndarray, lo: int, hi: int, r: int, c: int) -> tuple[int, int]:
    """Index in [lo, hi) of the path cell closest to (r, c) and its squared distance (cells^2)."""
    best = lo
    bd = 1 << 60
    for k in range(lo, hi):
        d = (pr[k] - r) * (pr[k] - r) + (pc[k] - c) * (pc[k] - c)
        if d < bd:
            bd = d
            best = k
    return best, bd


def turn_action_to_yaw(yaw: float, want: float, tol_rad: float) -> int | None:
    """The turn that brings `yaw` toward `want`, or None when already within `tol`."""
    err = wrap_angle(want - yaw)
    if abs(err) <= tol_rad:
        return None
    return TURN_LEFT if err > 0 else TURN_RIGHT
