"""What the simulator needs to run one episode, independent of the on-disk format.

`EpisodeSpec` is built from a dataset `Episode` + its goals (released HM3D-OVON files or ours) or
directly from a scene and a goal category (ad-hoc episodes from Python / the Gymnasium env).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ovon.geometry import quat_to_yaw


@dataclass
class GoalViewpoint:
    position: np.ndarray  # (3,)
    yaw: float


@dataclass
class EpisodeSpec:
    episode_id: str
    scene: str  # scene path (folder or glb) or "procedural:<seed>"
    goal_category: str  # the goal text
    start_position: np.ndarray | None = None  # None: a random navigable start (ad-hoc episodes)
    start_yaw: float | None = None
    children_categories: list[str] = field(default_factory=list)
    goal_instance_ids: list[int] = field(default_factory=list)  # empty: all instances of the categories
    viewpoints: list[GoalViewpoint] = field(default_factory=list)  # empty: navigable cells near goals
    split: str = ""
    info: dict = field(default_factory=dict)
    # The dataset's own scene id, as written in the episode file ("" for ad-hoc episodes). Seeds and records
    # use it instead of `scene`, a resolved path, so results do not depend on where the data lives.
    scene_id: str = ""

    @property
    def scene_key(self) -> str:
        """The scene as seeds and records name it: the dataset's id, or `scene` for ad-hoc episodes."""
        return self.scene_id or self.scene

    @property
    def goal_categories(self) -> list[str]:
        return [self.goal_category, *self.children_categories]


def spec_from_episode(episode, goals, scene_path: str, split: str = "") -> EpisodeSpec:
    """Adapter from `ovon.dataset.records` (an `Episode` and its `ObjectGoal`s) to an `EpisodeSpec`."""
    viewpoints = [
        GoalViewpoint(np.asarray(vp.position, dtype=np.float64), quat_to_yaw(vp.rotation))
        for g in goals
        for vp in g.view_points
    ]
    ids = sorted({g.instance_id for g in goals})
    return EpisodeSpec(
        episode_id=str(episode.episode_id),
        scene=scene_path,
        goal_category=episode.object_category,
        start_position=np.asarray(episode.start_position, dtype=np.float64),
        start_yaw=quat_to_yaw(episode.start_rotation),
        children_categories=list(episode.children_object_categories or []),
        goal_instance_ids=ids,
        viewpoints=viewpoints,
        split=split,
        info=dict(episode.info or {}),
        scene_id=str(episode.scene_id),
    )
