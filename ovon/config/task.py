"""Task configs: episode length, success, the failure-analysis thresholds and the RL rewards (docs/spec.md#task)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from ovon.config.base import in_range, non_negative, positive


@dataclass(frozen=True)
class RewardConfig:
    kind: Literal["dense", "sparse"] = "dense"
    dense_success: float = 2.5
    dense_slack: float = -0.01  # paper; upstream code used -0.001
    # Added when STOP is called outside the success region (paper: 0). RL from scratch at CPU scale:
    # ending the episode at once avoids every later slack penalty, and PPO collapses to STOP-at-once
    # within ~15k steps, long before it can learn where goals are; a failed-STOP cost removes that exit.
    dense_failed_stop: float = 0.0
    # Per m^2 of floor newly seen (camera cone within `coverage_range_m`, true map; paper: 0). RL from
    # scratch at CPU scale: progress alone leaves PPO turning in place; this makes the early policy explore.
    dense_coverage: float = 0.0
    coverage_range_m: float = positive(3.0)
    sparse_success: float = 5.0
    sparse_slack: float = -0.001
    sparse_collision: float = -0.003


@dataclass(frozen=True)
class TaskConfig:
    max_steps: int = in_range(500, 1, 1_000_000)
    success_distance: float = positive(0.25)
    # "goal seen" = at least this fraction of the frame shows a goal instance
    seen_fraction: float = in_range(0.01, 0.0, 1.0, lo_open=True)
    wrong_object_distance: float = non_negative(1.0)  # STOP within this of another category's (seen) instance
    reward: RewardConfig = RewardConfig()
