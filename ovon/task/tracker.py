"""One episode's ground-truth bookkeeping: distance to goal, path length, collisions, success, SPL,
SoftSPL and the failure label (docs/spec.md#metrics, #failure-labels). Everything here uses the *true*
pose, never noisy sensors.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from ovon.config.task import TaskConfig

FAILURE_LABELS = (
    "timeout_missed_goal",
    "timeout_ignored_goal",
    "timeout_left_goal",
    "stop_wrong_object",
    "stop_too_far",
    "stop_left_goal",
    "stop_never_saw_goal",
)


@dataclass
class Distractor:
    """An instance of a category that is not a goal; used to detect STOP at a wrong object."""

    instance_id: int
    category: str
    aabb_min: np.ndarray  # (3,)
    aabb_max: np.ndarray  # (3,)

    def floor_distance(self, p: np.ndarray) -> float:
        """Distance on the floor plane from `p` to the box footprint (0 inside)."""
        dx = max(self.aabb_min[0] - p[0], 0.0, p[0] - self.aabb_max[0])
        dz = max(self.aabb_min[2] - p[2], 0.0, p[2] - self.aabb_max[2])
        return math.hypot(dx, dz)


@dataclass
class EpisodeMetrics:
    success: bool
    spl: float
    soft_spl: float
    distance_to_goal: float
    start_distance: float
    path_length: float
    steps: int
    collisions: int
    called_stop: bool
    goal_seen: bool
    failure: str | None  # one of FAILURE_LABELS, None on success
    # where the episode ended, for failure analysis: floor distance to the nearest goal box footprint on the
    # episode's floor (None when the tracker has no boxes), and whether a goal shows in the last frame
    distance_to_object: float | None = None
    goal_in_view: bool = False

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass
class EpisodeTracker:
    """Feed it the true position after every step (and the semantic frame for failure analysis)."""

    distance_fn: object  # callable(position (3,)) -> geodesic distance to the nearest goal viewpoint
    goal_ids: frozenset[int]
    cfg: TaskConfig = field(default_factory=TaskConfig)
    distractors: list[Distractor] = field(default_factory=list)
    coverage: object = None  # ovon.task.coverage.Coverage when the reward has an exploration term
    goal_known: bool = False  # PointNav: the goal is given, so it counts as seen from the start
    object_distance_fn: object = None  # callable(position (3,)) -> floor distance to the nearest goal box

    def reset(self, position: np.ndarray, semantic: np.ndarray | None = None, yaw: float | None = None) -> None:
        self.position = np.asarray(position, dtype=np.float64).copy()
        self.new_area = 0.0
        if self.coverage is not None and yaw is not None:
            self.coverage.reset(self.position, yaw)
        self.d0 = float(self.distance_fn(self.position))
        self.distance = self.d0
        self.prev_distance = self.d0
        self.best_distance = self.d0  # the smallest distance reached so far this episode
        self.prev_best = self.d0
        self.path_length = 0.0
        self.steps = 0
        self.collisions = 0
        self.last_collided = False
        self.called_stop = False
        self.stopped_outside = False  # the last step was a STOP outside the region that did not end the episode
        self.failed_stops = 0  # such STOPs this episode (cfg.failed_stop_ends false)
        self.goal_seen = self.goal_known
        self.in_region = self.distance < self.cfg.success_distance
        self.entered_region = self.in_region
        self.left_region = False
        self.seen_ids: set[int] = set()
        self.in_view_ids: frozenset[int] = frozenset()  # seen (threshold) in the latest frame
        self._goal_id_array = np.array(sorted(self.goal_ids), dtype=np.int64)
        self.goal_view_max = 0.0  # largest fraction of a frame showing goal instances so far
        self.goal_view_gain = 0.0  # its increase at the last step (the dense_goal_view reward's unit)
        if semantic is not None:
            self._observe(semantic)
        self.goal_view_gain = 0.0

    @property
    def done(self) -> bool:
        return self.called_stop or self.steps >= self.cfg.max_steps

    def _observe(self, semantic: np.ndarray) -> None:
        flat = semantic.ravel()
        counts = np.bincount(flat[flat > 0], minlength=1)
        need = self.cfg.seen_fraction * flat.size
        ids = np.nonzero(counts >= need)[0]
        self.in_view_ids = frozenset(int(i) for i in ids)
        self.seen_ids.update(self.in_view_ids)
        if len(self._goal_id_array):
            g = self._goal_id_array[self._goal_id_array < len(counts)]
            goal_pixels = counts[g].sum()
            if (counts[g] >= need).any():  # one goal instance covers the threshold (not several together)
                self.goal_seen = True
            frac = float(goal_pixels) / max(1, flat.size)
            self.goal_view_gain = max(0.0, frac - self.goal_view_max)
            self.goal_view_max = max(self.goal_view_max, frac)

    def update(
        self,
        position: np.ndarray,
        stop: bool,
        collided: bool,
        semantic: np.ndarray | None = None,
        yaw: float | None = None,
    ) -> None:
        """Record one step: the action taken (STOP or not) and the resulting true pose."""
        position = np.asarray(position, dtype=np.float64)
        self.new_area = 0.0
        if self.coverage is not None and yaw is not None:
            self.new_area = self.coverage.update(position, yaw)
        self.path_length += float(np.linalg.norm(position - self.position))
        self.position = position.copy()
        self.steps += 1
        self.collisions += int(bool(collided))
        self.last_collided = bool(collided)
        self.prev_distance = self.distance
        self.distance = float(self.distance_fn(position))
        self.prev_best = self.best_distance
        if self.distance < self.best_distance:
            self.best_distance = self.distance
        inside = self.distance < self.cfg.success_distance
        if inside:
            self.entered_region = True
        elif self.in_region:
            self.left_region = True
        self.in_region = inside
        self.goal_view_gain = 0.0
        if semantic is not None:
            self._observe(semantic)
        self.stopped_outside = False
        if stop:
            if inside or self.cfg.failed_stop_ends:
                self.called_stop = True
            else:
                self.stopped_outside = True
                self.failed_stops += 1

    @property
    def success(self) -> bool:
        return self.called_stop and self.distance < self.cfg.success_distance

    def reward(self) -> float:
        """Reward of the last step (docs/spec.md#rewards): dense shaping or the sparse fine-tuning reward."""
        r = self.cfg.reward
        if r.kind == "dense":
            if self.success:
                return r.dense_success
            if r.dense_progress == "best":
                delta = self.best_distance - self.prev_best
            else:
                delta = self.distance - self.prev_distance
            if not math.isfinite(delta):
                delta = 0.0
            failed_stop = r.dense_failed_stop if (self.called_stop or self.stopped_outside) else 0.0
            return (
                -delta
                + r.dense_slack
                + failed_stop
                + r.dense_coverage * self.new_area
                + r.dense_goal_view * self.goal_view_gain
            )
        if r.kind == "sparse":
            collision = r.sparse_collision if self.last_collided else 0.0
            return (r.sparse_success if self.success else 0.0) + r.sparse_slack + collision
        raise ValueError(f"unknown reward kind {r.kind!r}; use dense or sparse")

    def failure_label(self) -> str | None:
        if self.success:
            return None
        if not self.called_stop:
            if self.left_region:
                return "timeout_left_goal"
            # Inside the success region at timeout counts as "ignored": it had the goal, never stopped. A point
            # goal is always "seen" (given), so there only entering the region counts.
            if (self.goal_seen and not self.goal_known) or self.entered_region:
                return "timeout_ignored_goal"
            return "timeout_missed_goal"
        # Only an object in view at the STOP counts (last frame, seen threshold): one glimpsed earlier
        # next to the stop says nothing about why the agent stopped.
        for d in self.distractors:
            if d.instance_id in self.in_view_ids and d.floor_distance(self.position) <= self.cfg.wrong_object_distance:
                return "stop_wrong_object"
        if self.left_region:
            return "stop_left_goal"
        if self.goal_seen:
            return "stop_too_far"
        return "stop_never_saw_goal"

    def metrics(self) -> EpisodeMetrics:
        d0, dt, L = self.d0, self.distance, self.path_length
        to_object = None if self.object_distance_fn is None else float(self.object_distance_fn(self.position))
        if not math.isfinite(d0):
            raise ValueError("the start is not connected to any goal viewpoint (distance is inf)")
        eff = 1.0 if d0 <= 0 else d0 / max(d0, L)
        success = self.success
        progress = (1.0 if dt <= d0 else 0.0) if d0 <= 0 else max(0.0, 1.0 - dt / d0)
        return EpisodeMetrics(
            success=success,
            spl=float(success) * eff,
            soft_spl=progress * eff,
            distance_to_goal=dt,
            start_distance=d0,
            path_length=L,
            steps=self.steps,
            collisions=self.collisions,
            called_stop=self.called_stop,
            goal_seen=self.goal_seen,
            failure=self.failure_label(),
            distance_to_object=to_object,
            goal_in_view=bool(self.goal_ids & self.in_view_ids),
        )
