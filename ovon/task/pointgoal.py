"""PointNav: reach a point given relative to the start pose (the task PPO learns first, and the bee-lining
module of the modular agents).

Why here: the goal is a one-source geodesic distance field (ovon.sim), success and SPL are the ObjectNav
tracker's (ovon.task.tracker) with that field; only the episode sampling and the goal observation are new.

The observation is what a real robot can compute: the goal in the start frame (given once, as habitat's
PointNav gives it) moved into the frame of the *estimated* pose (odometry), as (rho, cos theta, sin theta),
theta positive to the left. With odometry noise it is wrong by the odometry's error, as in the paper.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ovon.config.task import TaskConfig
from ovon.geometry import heading_vector
from ovon.sim.geodesic import DistanceField, distance_field
from ovon.task.episode import EpisodeSpec

POINT_GOAL = "point"  # the goal text of a PointNav episode (there is no object)
GOAL_VECTOR_DIM = 3  # rho (m), cos theta, sin theta
SAMPLE_TRIES = 50


def goal_vector(rho: float, theta: float) -> np.ndarray:
    """(rho, cos theta, sin theta) float32: the policy's goal input (theta wraps without a jump)."""
    return np.array([rho, math.cos(theta), math.sin(theta)], dtype=np.float32)


def goal_in_start_frame(start_position: np.ndarray, start_yaw: float, goal: np.ndarray) -> np.ndarray:
    """The goal as (forward, left) metres in the start frame (the frame odometry reports in)."""
    d = np.asarray(goal, dtype=np.float64) - np.asarray(start_position, dtype=np.float64)
    f = heading_vector(start_yaw)
    left = np.array([f[2], 0.0, -f[0]])
    return np.array([float(d @ f), float(d @ left)])


def point_goal_vector(odometry: np.ndarray, goal_forward_left: np.ndarray) -> np.ndarray:
    """Goal vector relative to the odometry pose (forward, left, dyaw in the start frame)."""
    fo, lo, dyaw = (float(v) for v in np.asarray(odometry, dtype=np.float64)[:3])
    dx, dl = float(goal_forward_left[0]) - fo, float(goal_forward_left[1]) - lo
    c, s = math.cos(dyaw), math.sin(dyaw)
    fwd, lft = c * dx + s * dl, -s * dx + c * dl
    return goal_vector(math.hypot(fwd, lft), math.atan2(lft, fwd))


def sample_point_goal(
    grids: Sequence,
    rng: np.random.Generator,
    task: TaskConfig,
) -> tuple[object, np.ndarray, np.ndarray, DistanceField]:
    """(grid, start, goal, field to the goal): a goal uniform on a floor's navigable area (start islands,
    not furniture tops), a start uniform among the cells whose geodesic distance to it lies in
    [point_min_distance_m, point_max_distance_m]. ValueError when no floor has such a pair."""
    lo, hi = task.point_min_distance_m, task.point_max_distance_m
    usable = [g for g in grids if g.navigable.any()]
    if not usable:
        raise ValueError("no navigable floor for a point goal")
    for _ in range(SAMPLE_TRIES):
        grid = usable[int(rng.integers(len(usable)))]
        goal = grid.random_point(rng)
        field = distance_field(grid, goal[None])
        ok = grid.navigable & (field.dist >= lo) & (field.dist <= hi)
        islands = grid.start_islands()
        if len(islands) != grid.num_islands:
            ok &= np.isin(grid.islands, islands)
        cells = np.flatnonzero(ok.ravel())
        if len(cells) == 0:
            continue
        r, c = divmod(int(cells[rng.integers(len(cells))]), grid.navigable.shape[1])
        start = grid.cell_to_world(r, c)
        if lo <= field.distance(start) <= hi:
            return grid, start, goal, field
    raise ValueError(
        f"no start within {lo}-{hi} m (geodesic) of a goal in {SAMPLE_TRIES} tries; "
        "fix: widen task.point_min_distance_m / task.point_max_distance_m"
    )


def pointnav_specs(scene_ids: Sequence[str], per_scene: int = 1, split: str = "train") -> list[EpisodeSpec]:
    """`per_scene` PointNav episodes per scene; start and goal are sampled at reset from the episode's
    seed, so an evaluation seed fixes every pair and every agent sees the same ones."""
    return [
        EpisodeSpec(episode_id=f"pointnav-{i}", scene=str(s), goal_category=POINT_GOAL, split=split)
        for s in scene_ids
        for i in range(per_scene)
    ]
