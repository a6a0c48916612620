"""Start poses (docs/spec.md#starts): every rejection is counted by reason so a thin dataset explains
itself."""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ovon.config.dataset import StartConfig

REJECTION_REASONS = (
    "unreachable",
    "oracle_cannot_finish",
    "too_close",
    "too_far",
    "ratio_below_min",
    "ratio_rejected",
    "multi_floor_path",
)


@dataclass
class Start:
    position: np.ndarray
    yaw: float
    geodesic: float
    euclidean: float


def sample_start(
    grid,
    field,
    viewpoints: np.ndarray,
    cfg: StartConfig,
    rng: np.random.Generator,
    reasons: Counter,
    accept: Callable[[np.ndarray, float], bool] | None = None,
    distance: Callable[[np.ndarray], float] | None = None,
) -> Start | None:
    """One start for a goal set (all viewpoints of the category and its children on this floor).

    `accept(position, yaw)`, when given, is the last check (the generator passes the oracle rollout).
    `distance` is the scene's distance-to-goal (`ovon.sim.geodesic.distance_to_goals`; default the field's):
    the number the episode records and is scored by; the field still gives the path for the floor check."""
    distance = distance or field.distance
    for _ in range(cfg.max_tries):
        p = grid.random_point(rng, cfg.min_island_radius)
        d = distance(p)
        if not math.isfinite(d):
            reasons["unreachable"] += 1
            continue
        if d < cfg.min_geodesic:
            reasons["too_close"] += 1
            continue
        if d > cfg.max_geodesic:
            reasons["too_far"] += 1
            continue
        euclid = float(np.min(np.linalg.norm(viewpoints - p, axis=1)))
        ratio = d / max(euclid, 1e-6)
        if ratio < cfg.min_geo_euclid_ratio:
            reasons["ratio_below_min"] += 1
            continue
        # PointNav-style: paths that are nearly straight lines are kept only sometimes.
        if cfg.pointnav_ratio_rejection and ratio < 1.1 and rng.random() > 20.0 * (ratio - 0.98) ** 2:
            reasons["ratio_rejected"] += 1
            continue
        path = field.path(p)
        if len(path) and float(np.ptp(path[:, 1])) > cfg.max_height_span:
            reasons["multi_floor_path"] += 1
            continue
        yaw = float(rng.uniform(-math.pi, math.pi))
        if accept is not None and not accept(p, yaw):
            reasons["oracle_cannot_finish"] += 1
            continue
        return Start(p, yaw, d, euclid)
    return None


def oracle_finishes(
    grid,
    position,
    yaw: float,
    viewpoints: list[tuple[np.ndarray, float]],
    distance: Callable[[np.ndarray], float],
    max_steps: int,
    success_distance: float,
    agent=None,
) -> bool:  # noqa: ANN001
    """Whether the shortest-path oracle (`ovon evaluate --agent shortest-path`, noise-free) finishes an
    episode from this start: the same expert and kinematics on the same grid, without rendering; success is
    judged by `distance` (the scene's distance-to-goal, as the episode will be scored).

    Why: a distance field can pass where the discrete agent cannot (a corner it clips, a corridor at an
    angle it cannot hold); a generated episode the oracle fails would count against every agent."""
    from ovon.experts.gridsim import rollout
    from ovon.experts.shortest_path import ShortestPathExpert
    from ovon.sim.types import AgentState

    state = AgentState(np.asarray(position, dtype=np.float64).copy(), float(yaw), 0.0)
    states, actions, _ = rollout(ShortestPathExpert(), grid, state, viewpoints, max_steps=max_steps, agent=agent)
    return bool(actions) and actions[-1] == 0 and distance(states[-1].position) < success_distance
