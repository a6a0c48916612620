"""Simulator: navigability grids, geodesic distances, rendering, the environment.

Names are loaded lazily so that `import ovon.sim` (or `ovon.sim.types`) does not pull in numba,
scipy or a renderer.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ovon.sim.geodesic import DistanceField, distance_field, geodesic_distance
    from ovon.sim.navgrid import NavGrid, SceneNav, build_navigation
    from ovon.sim.navmesh import load_navmesh

_LAZY = {
    "NavGrid": "ovon.sim.navgrid",
    "SceneNav": "ovon.sim.navgrid",
    "build_navigation": "ovon.sim.navgrid",
    "load_navmesh": "ovon.sim.navmesh",
    "DistanceField": "ovon.sim.geodesic",
    "distance_field": "ovon.sim.geodesic",
    "geodesic_distance": "ovon.sim.geodesic",
}

__all__ = [
    "DistanceField",
    "NavGrid",
    "SceneNav",
    "build_navigation",
    "distance_field",
    "geodesic_distance",
    "load_navmesh",
]


def __getattr__(name: str) -> Any:
    mod = _LAZY.get(name)
    if mod is None:
        raise AttributeError(f"module 'ovon.sim' has no attribute {name!r}")
    return getattr(importlib.import_module(mod), name)
