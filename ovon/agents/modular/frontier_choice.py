"""Frontier choice by value (docs/spec.md#frontier-choice): the highest value wins; the previous frontier is kept unless
another is better by more than `hysteresis`; a frontier abandoned from a spot is not picked again from that
spot (anti-cycling; VLFM hashes the robot position, the frontier and the top values for the same purpose).

Frontiers that the navigator could not reach, or toward which the agent made no progress for `stuck_steps`
steps, or that persist after the agent reached them, are blacklisted (a frontier within `keep_radius_m` of a
blacklisted point is skipped); when every frontier is blacklisted the list is cleared and they are tried
again (the map has grown since: a frontier blocked by a bump may be reachable now), so the agent STOPs for
want of frontiers only when there are none. Ties in value go to the nearest frontier, so a constant
scorer gives nearest-frontier exploration. When every candidate was abandoned from this spot the nearest
one is taken (VLFM's code takes the farthest, against its own comment).
"""

from __future__ import annotations

import math

import numpy as np

from ovon.agents.modular.config import ValueMapConfig, checked


class FrontierChooser:
    def __init__(self, cfg: ValueMapConfig, cell_size: float) -> None:
        self.cfg = checked(cfg, "value")
        self.keep_cells = cfg.keep_radius_m / cell_size
        self.reset()

    def reset(self) -> None:
        self.target: tuple[int, int] | None = None
        self.target_value = -math.inf
        self.blacklist: list[tuple[int, int]] = []
        self.abandoned: set[tuple[int, int, int, int]] = set()  # (agent row, col, frontier row, col)
        self.choices = 0  # new choices so far (a kept frontier whose waypoint moved is the same choice)
        self.cleared = 0  # times the blacklist was emptied because it held every frontier

    def _near(self, rows: np.ndarray, cols: np.ndarray, points: list[tuple[int, int]]) -> np.ndarray:
        if not points:
            return np.zeros(rows.shape[0], dtype=bool)
        p = np.asarray(points, dtype=np.float64)
        d2 = (rows[:, None] - p[None, :, 0]) ** 2 + (cols[:, None] - p[None, :, 1]) ** 2
        return (d2 <= self.keep_cells**2).any(axis=1)

    def drop_target(self, blacklist: bool = True) -> None:
        if self.target is not None and blacklist:
            self.blacklist.append(self.target)
        self.target = None
        self.target_value = -math.inf

    def choose(self, rows: np.ndarray, cols: np.ndarray, values: np.ndarray, agent: tuple[int, int]) -> int | None:
        """Index of the frontier to pursue among (rows, cols) with `values`, or None when none is left."""
        if rows.shape[0] == 0:
            self.drop_target(blacklist=False)
            return None
        ok = ~self._near(rows, cols, self.blacklist)
        if not ok.any():
            self.blacklist.clear()
            self.cleared += 1
            ok[:] = True
        idx = np.flatnonzero(ok)
        dist = np.hypot(rows[idx] - agent[0], cols[idx] - agent[1])
        order = idx[np.lexsort((dist, -values[idx]))]  # best value first, nearest on ties
        best = int(order[0])
        if self.target is not None:
            prev = np.flatnonzero(self._near(rows[order], cols[order], [self.target]))
            if prev.size:
                # the previous frontier still exists: its nearest surviving waypoint
                cand = order[prev]
                d_prev = (rows[cand] - self.target[0]) ** 2 + (cols[cand] - self.target[1]) ** 2
                keep = int(cand[int(np.argmin(d_prev))])
                if values[best] <= values[keep] + self.cfg.hysteresis:
                    return self._set(rows, cols, values, keep)
        # a new choice: skip frontiers abandoned from this spot
        if self.target is not None:
            self.abandoned.add((agent[0], agent[1], self.target[0], self.target[1]))
        gone = [(fr, fc) for (ar, ac, fr, fc) in self.abandoned if (ar, ac) == agent]
        fresh = order[~self._near(rows[order], cols[order], gone)]
        self.choices += 1
        if fresh.size:
            return self._set(rows, cols, values, int(fresh[0]))
        near = idx[int(np.argmin(dist))]
        return self._set(rows, cols, values, int(near))

    def _set(self, rows: np.ndarray, cols: np.ndarray, values: np.ndarray, i: int) -> int:
        self.target = (int(rows[i]), int(cols[i]))
        self.target_value = float(values[i])
        return i
