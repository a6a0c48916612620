"""habitat-sim navmeshes (`<id>.navmesh`, `<id>.basis.navmesh`) as ovon navigability.

Why: habitat users have a navmesh for every scene, and episodes whose geodesic distances and success
were computed on it; reading it lets ovon run on the very same navigable area and be checked against
habitat (benchmarks/navmesh_agreement.py). Modules: `format` (the file: read, write, checks), `polys`
(triangles, islands and areas as habitat defines them), `raster` (the per-floor grids ovon runs on).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ovon.config.sim import AgentConfig, NavConfig
from ovon.sim.navgrid import SceneNav, navmesh_navigation
from ovon.sim.navmesh.format import (
    NavMesh,
    NavMeshError,
    NavMeshSettings,
    NavMeshTile,
    parse_navmesh,
    read_navmesh,
    write_navmesh,
)
from ovon.sim.navmesh.polys import Islands, compute_islands, navmesh_triangles
from ovon.sim.navmesh.raster import NavMeshWarning

__all__ = [
    "NavMesh",
    "NavMeshError",
    "NavMeshSettings",
    "NavMeshTile",
    "NavMeshWarning",
    "compute_islands",
    "load_navmesh",
    "navmesh_summary",
    "navmesh_triangles",
    "parse_navmesh",
    "read_navmesh",
    "write_navmesh",
]


def load_navmesh(
    path: str | Path,
    agent: AgentConfig | None = None,
    nav: NavConfig | None = None,
    floor_heights: list[float] | None = None,
) -> SceneNav:
    """A habitat navmesh file as ovon navigability (`SceneNav`, what `build_navigation` returns), cached
    in-process by file content and params. `floor_heights` (a scene's floors) numbers the floors as the
    scene does; without it the floors are the navmesh's own big horizontal areas. A navmesh eroded for
    another radius than `agent.radius` is used as it is, with a `NavMeshWarning`."""
    return navmesh_navigation(path, agent, nav, floor_heights)


def navmesh_summary(
    path: str | Path,
    agent: AgentConfig | None = None,
    nav: NavConfig | None = None,
    grids: bool = False,
    max_islands: int = 50,
) -> dict[str, Any]:
    """Plain-data summary of a navmesh file: habitat's navigable area and islands (count, area, radius),
    the settings it was baked with, and with `grids` ovon's rasterised floors."""
    mesh = read_navmesh(path)
    isl: Islands = compute_islands(mesh)
    tris, _ = navmesh_triangles(mesh, isl)
    order = np.argsort(-isl.area, kind="stable")
    out: dict[str, Any] = {
        "path": str(path),
        "version": mesh.version,
        "tiles": len(mesh.tiles),
        "polygons": int(sum(len(t.polys) for t in mesh.tiles)),
        "walkable_polygons": int(isl.walkable.sum()),
        "agent_radius": round(mesh.agent_radius(), 4),
        "settings": None
        if mesh.settings is None
        else {k: (round(v, 4) if isinstance(v, float) else v) for k, v in vars(mesh.settings).items()},
        "bounds_min": tris.reshape(-1, 3).min(axis=0).round(3).tolist() if len(tris) else None,
        "bounds_max": tris.reshape(-1, 3).max(axis=0).round(3).tolist() if len(tris) else None,
        "navigable_area_m2": round(isl.total_area, 4),
        "num_islands": isl.count,
        "islands": [
            {"island": int(i), "area_m2": round(float(isl.area[i]), 4), "radius_m": round(float(isl.radius[i]), 4)}
            for i in order[:max_islands]
        ],
    }
    if grids:
        if agent is None and mesh.agent_radius() > 0:
            agent = AgentConfig(radius=min(mesh.agent_radius(), 2.0))  # the agent the navmesh was baked for
        sn = load_navmesh(path, agent, nav)
        out["grid"] = [
            {
                "floor": g.floor,
                "height": round(float(g.height), 3),
                "cell_size": g.cell_size,
                "navigable_m2": round(float(g.navigable.sum()) * g.cell_size**2, 2),
                "islands": g.num_islands,
            }
            for g in sn.floors
        ]
    return out
