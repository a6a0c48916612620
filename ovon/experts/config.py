"""Expert configs: every number of the paper's expert is a config value (docs/spec.md#experts).

The agent's turn angle and forward step, the camera's FOV and the success radius are NOT here: the
experts derive them from the sim/task config (`ovon.experts.rig.Embodiment`), their one source."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from ovon.config.base import in_range, non_negative, positive


@dataclass(frozen=True)
class FrontierExpertConfig:
    """Frontier-exploration teacher (docs/spec.md#frontier-expert); defaults are the paper's / upstream's values."""

    view_range_m: float = positive(3.0)  # cells further than this never become explored
    pocket_area_m2: float = non_negative(1.5)  # unexplored components smaller than this (m^2) count as explored
    linear_speed: float = positive(0.25)  # m/s, for the estimated time of a frontier
    turn_speed_deg: float = positive(10.0)  # deg/s, for the estimated time of a frontier
    # geodesic distance to the nearest viewpoint that starts the bee-line
    beeline_distance_m: float = non_negative(3.5)
    # stop this much inside the success radius (grid lookups are +-half a cell)
    stop_margin_m: float = non_negative(0.05)
    stop_heading_tol_deg: float = in_range(15.0, 0.0, 180.0)  # final turn to the viewpoint's heading
    # spec: turn when the next waypoint is more than one turn (30 deg) off; 15 (half a turn) is straighter
    turn_threshold_deg: float = in_range(30.0, 0.0, 180.0)
    lookahead_m: float = positive(1.0)  # furthest path point (in line of sight) used as the heading target
    min_frontier_m: float = non_negative(0.15)  # frontiers with fewer cells than this length / cell size are ignored
    frontier_reached_m: float = non_negative(0.5)  # re-choose once the agent is this close to the frontier's waypoint
    frontier_keep_radius_m: float = non_negative(0.5)  # the target survives while a frontier cell lies this close to it
    path_deviation_m: float = positive(0.5)  # re-plan when the agent is further than this from its planned path
    stuck_steps: int = positive(15)  # no progress toward the frontier for this many steps: blacklist it
    rechoose_every: int = non_negative(10)  # re-choose the frontier every N steps anyway (0 = only on events)
    no_frontier_behaviour: Literal["beeline", "stop"] = "beeline"


@dataclass(frozen=True)
class ShortestPathExpertConfig:
    """Shortest-path (SPOC-style) expert: forward whenever the waypoint is within half a turn."""

    stop_margin_m: float = non_negative(0.05)
    stop_heading_tol_deg: float = in_range(15.0, 0.0, 180.0)
    # half a turn: the heading error after a turn is always <= 15 deg
    turn_threshold_deg: float = in_range(15.0, 0.0, 180.0)
    lookahead_m: float = positive(1.0)
    turn_to_viewpoint_heading: bool = True
