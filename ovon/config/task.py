"""Task configs: episode length, success, the failure-analysis thresholds and the RL rewards (task.md)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class RewardConfig:
    kind: str = "dense"  # dense | sparse
    dense_success: float = 2.5
    dense_slack: float = -0.01  # paper; upstream code used -0.001
    # Added when STOP is called outside the success region (paper: 0). RL from scratch at CPU scale:
    # ending the episode at once avoids every later slack penalty, and PPO collapses to STOP-at-once
    # within ~15k steps, long before it can learn where goals are; a failed-STOP cost removes that exit.
    dense_failed_stop: float = 0.0
    sparse_success: float = 5.0
    sparse_slack: float = -0.001
    sparse_collision: float = -0.003


@dataclass(frozen=True)
class TaskConfig:
    max_steps: int = 500
    success_distance: float = 0.25
    seen_fraction: float = 0.01  # "goal seen" = at least this fraction of the frame shows a goal instance
    wrong_object_distance: float = 1.0  # STOP within this of another category's (seen) instance
    reward: RewardConfig = RewardConfig()
