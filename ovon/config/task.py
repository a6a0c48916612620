"""Task configs: episode length, success, the failure-analysis thresholds and the RL rewards (docs/spec.md#task)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Literal

from ovon.config.base import in_range, less, non_negative, positive


@dataclass(frozen=True)
class RewardConfig:
    kind: Literal["dense", "sparse"] = "dense"
    dense_success: float = 2.5
    # The distance term: "delta" = minus the change of the geodesic distance to the goal (the paper's);
    # "best" = the decrease of the smallest distance reached so far this episode (0 when not closer than ever
    # before; a walk away costs nothing and coming back pays nothing, so it cannot be farmed). RL from scratch
    # at CPU scale: started near a goal it cannot see, a random step more often leads away than toward it,
    # and "delta" taught PPO to turn in place.
    dense_progress: Literal["delta", "best"] = "delta"
    dense_slack: float = -0.01  # paper; upstream code used -0.001
    # Added when STOP is called outside the success region (paper: 0). RL from scratch at CPU scale:
    # ending the episode at once avoids every later slack penalty, and PPO collapses to STOP-at-once
    # within ~15k steps, long before it can learn where goals are; a failed-STOP cost removes that exit.
    dense_failed_stop: float = 0.0
    # Per m^2 of floor newly seen (camera cone within `coverage_range_m`, true map; paper: 0). RL from
    # scratch at CPU scale: progress alone leaves PPO turning in place; this makes the early policy explore.
    dense_coverage: float = 0.0
    coverage_range_m: float = positive(3.0)
    # The cone that counts as covered: 0 = the camera's horizontal field of view (floor *seen*, which turning
    # in place also gains); 360 = every direction within `coverage_range_m` (floor *visited*: only moving
    # gains it, the count-based exploration bonus that turning cannot farm).
    coverage_fov_deg: float = in_range(0.0, 0.0, 360.0)
    # Per unit of the largest fraction of the frame that has shown goal instances so far in the episode (the
    # reward is its increase, so looking at the goal again pays nothing; at most this much per episode;
    # paper: 0). RL from scratch at CPU scale: the distance reward alone says nothing the agent can see until
    # the goal is in view; this pays for bringing it into view and for approaching it until it fills the frame.
    dense_goal_view: float = non_negative(0.0)
    sparse_success: float = 5.0
    sparse_slack: float = -0.001
    sparse_collision: float = -0.003


@dataclass(frozen=True)
class TaskConfig:
    # objectnav: reach an instance of the goal text (the paper's task). pointnav: reach a point given in
    # the start frame, observed as its polar coordinates from odometry (the bee-lining module's task).
    kind: Literal["objectnav", "pointnav"] = "objectnav"
    max_steps: int = in_range(500, 1, 1_000_000)
    success_distance: float = positive(0.25)
    # pointnav: start/goal pairs are sampled on one floor's navigable area with a geodesic distance in
    # [point_min_distance_m, point_max_distance_m].
    point_min_distance_m: float = positive(1.0)
    point_max_distance_m: float = positive(6.0)
    # "goal seen" = at least this fraction of the frame shows a goal instance
    seen_fraction: float = in_range(0.01, 0.0, 1.0, lo_open=True)
    wrong_object_distance: float = non_negative(1.0)  # STOP within this of another category's (seen) instance
    # A STOP outside the success region ends the episode as a failure (the task; evaluation always). false is
    # for training only (RL from scratch at CPU scale): such a STOP costs `reward.dense_failed_stop` and the
    # episode goes on, so trying STOP where the goal might be does not forfeit the rest of the episode and
    # PPO can learn where STOP pays; a STOP inside the region still ends it as a success.
    failed_stop_ends: bool = True
    reward: RewardConfig = RewardConfig()
    rules: ClassVar = (less("point_min_distance_m", "point_max_distance_m"),)


def pointnav_task() -> TaskConfig:
    """The PointNav task of the training presets and of `ovon evaluate --task pointnav` without a checkpoint:
    success within 0.36 m (2 agent radii, habitat's PointNav challenge), 150 steps, goals 1-6 m away, and a
    failed STOP costs 1 (habitat: 0; without it PPO collapsed to STOP-at-once, docs/concepts/learned-policies.md)."""
    return TaskConfig(
        kind="pointnav",
        max_steps=150,
        success_distance=0.36,
        point_min_distance_m=1.0,
        point_max_distance_m=6.0,
        reward=RewardConfig(dense_failed_stop=-1.0),
    )
