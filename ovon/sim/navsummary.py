"""Navigability of a scene at a glance (`ovon scenes inspect --nav`): per floor, the navigable area, its
islands and the area on islands large enough for starts. In `ovon.sim` because it is computed from the
navigation grids; `ovon.scenes.inspect` stays below the simulator and only prints what it is given."""

from __future__ import annotations

from typing import Any

from ovon.config.sim import AgentConfig, NavConfig
from ovon.scenes.model import Scene
from ovon.sim.navgrid import build_navigation


def navigation_summary(
    scene: Scene, min_island_radius: float, agent: AgentConfig | None = None, nav: NavConfig | None = None
) -> list[dict[str, Any]]:
    """Per floor: navigable area, islands, the area on islands of radius >= `min_island_radius` (where
    starts can be sampled: `ovon.config.dataset.StartConfig.min_island_radius`) and the strips removed
    as too narrow to drive."""
    out = []
    sn = build_navigation(scene, agent, nav)
    for g in sn.floors:
        cell = g.cell_size * g.cell_size
        big = g.island_radius >= min_island_radius
        narrow = float(g.narrow.sum()) * cell if g.narrow is not None else 0.0
        out.append({
            "floor": g.floor, "height": round(float(g.height), 3),
            "navigable_m2": round(float(g.navigable.sum()) * cell, 2),
            "islands": g.num_islands,
            "start_area_m2": round(float(g.island_area[big].sum()), 2),
            "narrow_removed_m2": round(narrow, 2),
            "source": sn.source,
        })  # fmt: skip
    return out
