"""`ovon dataset validate`: checks a dataset against dataset.md independently of the generator's code:
schema (through the reader), goal keys and ids, viewpoint ordering and scores, and for every episode
that the start is navigable, on the goals' floor, and within the geodesic limits of a goal viewpoint
along a single-floor path."""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ovon.config.dataset import GenerationConfig
from ovon.config.sim import AgentConfig, NavConfig
from ovon.dataset.io import EpisodeDataset, goals_for
from ovon.dataset.records import goal_key, resolve_scene_path


@dataclass
class ValidationReport:
    episodes: int = 0
    shards: int = 0
    errors: list[str] = field(default_factory=list)
    counts: Counter = field(default_factory=Counter)

    @property
    def ok(self) -> bool:
        return not self.errors

    def error(self, kind: str, msg: str) -> None:
        self.counts[kind] += 1
        if len(self.errors) < 200:
            self.errors.append(msg)


def _check_episode(ep, goals, nav, cfg: GenerationConfig, where: str, rep: ValidationReport, tol: float) -> None:
    from ovon.sim.geodesic import distance_field

    q = np.asarray(ep.start_rotation, dtype=np.float64)
    if abs(q[0]) > 1e-5 or abs(q[2]) > 1e-5 or abs(np.linalg.norm(q) - 1) > 1e-4:
        rep.error("rotation", f"{where}: start_rotation {ep.start_rotation} is not a unit pure-yaw quaternion")
    if not goals:
        rep.error("no_goals", f"{where}: no goals for {ep.goal_categories}")
        return
    start = np.asarray(ep.start_position, dtype=np.float64)
    if not nav.is_navigable(start):
        rep.error("start_not_navigable", f"{where}: start {ep.start_position} is not navigable")
        return
    grid = nav.grid_for(start)
    vps = np.array([vp.position for g in goals for vp in g.view_points], dtype=np.float64)
    same_floor = np.array([nav.floor_index(v) == grid.floor for v in vps])
    if not same_floor.any():
        rep.error("other_floor", f"{where}: no goal viewpoint on the start's floor {grid.floor}")
        return
    d = distance_field(grid, vps[same_floor]).distance(start)
    sc = cfg.starts
    if not math.isfinite(d):
        rep.error("unreachable", f"{where}: no goal viewpoint reachable from the start")
        return
    if d < sc.min_geodesic - tol or d > sc.max_geodesic + tol:
        rep.error("geodesic_range", f"{where}: geodesic {d:.3f} m outside [{sc.min_geodesic}, {sc.max_geodesic}]")
    stored = (ep.info or {}).get("geodesic_distance")
    if stored is not None and abs(float(stored) - d) > max(tol, 0.02 * d):
        rep.error("geodesic_mismatch", f"{where}: info.geodesic_distance {stored} but recomputed {d:.3f}")
    path = distance_field(grid, vps[same_floor]).path(start)
    if len(path) and float(np.ptp(path[:, 1])) > sc.max_height_span + 1e-6:
        rep.error("multi_floor", f"{where}: path height span {np.ptp(path[:, 1]):.2f} m")


def validate_dataset(
    root: str | Path, scenes: str | Path, splits: list[str] | None = None, cfg: GenerationConfig | None = None,
    max_episodes_per_scene: int | None = None, tol: float = 0.05,
) -> ValidationReport:
    from ovon.sim.navgrid import build_navigation
    from ovon.sim.world import load_scene_any

    cfg = cfg or GenerationConfig()
    root = Path(root)
    if splits is None:
        splits = [d.name for d in sorted(root.iterdir()) if d.is_dir() and (d / "content").is_dir()]
    rep = ValidationReport()
    nav_cache: dict[str, object] = {}
    for split in splits:
        ds = EpisodeDataset(root, split)
        for scene, shard in ds.iter_scenes():
            rep.shards += 1
            for key, goals in shard.goals_by_category.items():
                for gi, g in enumerate(goals):
                    w = f"{split}/{scene}: goals_by_category[{key!r}][{gi}]"
                    _ = g.instance_id  # raises a DatasetError naming the id when malformed
                    ious = [vp.iou for vp in g.view_points]
                    if not ious:
                        rep.error("no_viewpoints", f"{w}: goal without viewpoints")
                    if any(a < b for a, b in zip(ious, ious[1:])):
                        rep.error("viewpoint_order", f"{w}: view_points not sorted by iou")
                    if ious and min(ious) <= cfg.viewpoints.min_score:
                        rep.error("viewpoint_score", f"{w}: a viewpoint scores <= {cfg.viewpoints.min_score}")
            eps = shard.episodes[:max_episodes_per_scene] if max_episodes_per_scene else shard.episodes
            for i, ep in enumerate(eps):
                rep.episodes += 1
                where = f"{split}/{scene}: episodes[{i}] (id {ep.episode_id})"
                key = goal_key(ep.scene_id, ep.object_category)
                if key not in shard.goals_by_category:
                    rep.error("missing_goal_key", f"{where}: goals_by_category has no {key!r}")
                    continue
                path = str(resolve_scene_path(ep.scene_id, scenes))
                if path not in nav_cache:
                    nav_cache[path] = build_navigation(load_scene_any(path), AgentConfig(), NavConfig())
                goals = goals_for(ep, shard.goals_by_category)
                _check_episode(ep, goals, nav_cache[path], cfg, where, rep, tol)
    return rep
