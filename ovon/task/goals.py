"""Goal sets of an episode: the instances that count and the points the agent must reach."""

from __future__ import annotations

import numpy as np

from ovon.scenes.model import ObjectInstance, Scene
from ovon.task.episode import EpisodeSpec
from ovon.task.tracker import Distractor


def goal_instances(scene: Scene, spec: EpisodeSpec) -> list[ObjectInstance]:
    """Instances of the goal category and its children (or exactly the ids the episode lists)."""
    scene.require_semantics(f"ObjectNav goals ({spec.goal_category!r})")  # a bare mesh: say what is missing
    if spec.goal_instance_ids:
        wanted = set(spec.goal_instance_ids)
        objs = [o for o in scene.objects if o.id in wanted]
        # Children categories' instances count too, even when the file lists only the main ones.
        cats = set(spec.children_categories)
        objs += [o for o in scene.objects if o.category in cats and o.id not in wanted]
        return objs
    cats = set(spec.goal_categories)
    objs = [o for o in scene.objects if o.category in cats]
    if not objs:
        raise ValueError(
            f"scene {scene.scene_id} has no instance of {sorted(cats)}; it has: {', '.join(scene.categories)}"
        )
    return objs


def points_near_objects(grid, objects: list[ObjectInstance], radius: float = 1.0) -> np.ndarray:
    """Navigable cell centres within `radius` of any object's box footprint on this floor: the
    viewpoint set for ad-hoc episodes that have no generated viewpoints."""
    rows, cols = np.nonzero(grid.navigable)
    xs = grid.origin[0] + (cols + 0.5) * grid.cell_size
    zs = grid.origin[1] + (rows + 0.5) * grid.cell_size
    keep = np.zeros(len(rows), dtype=bool)
    for o in objects:
        dx = np.maximum(np.maximum(o.aabb_min[0] - xs, 0.0), xs - o.aabb_max[0])
        dz = np.maximum(np.maximum(o.aabb_min[2] - zs, 0.0), zs - o.aabb_max[2])
        keep |= (dx * dx + dz * dz) <= radius * radius
    ys = grid.heights[rows[keep], cols[keep]]
    return np.stack([xs[keep], ys, zs[keep]], axis=1)


def distractors(scene: Scene, goal_categories: list[str]) -> list[Distractor]:
    cats = set(goal_categories)
    return [
        Distractor(o.id, o.category, np.asarray(o.aabb_min), np.asarray(o.aabb_max))
        for o in scene.objects
        if o.category and o.category not in cats
    ]
