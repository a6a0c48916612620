"""A navmesh as ovon's per-floor navigability grids (`ovon.sim.navgrid.navmesh_navigation` makes them the
`SceneNav` every consumer reads), so geodesics, the agent's collisions and sliding, starts and episode
generation run on habitat's navigable area unchanged.

Method: every walkable detail triangle (`polys.navmesh_triangles`) is sampled at the cell centres of
one xz grid (`ovon.sim.cellsample`, the rasteriser of mesh grids too; a cell is navigable when its
centre lies on a walkable triangle: the test habitat's `is_navigable` makes at a point). Samples go to
floors by height (bands around `Scene.floor_heights` when a scene gives them, else around the navmesh's
own big horizontal areas); per floor and cell the lowest sample wins. Two neighbouring cells
(8-neighbourhood) that are on different habitat islands, or whose heights differ by more than the
navmesh's walkable climb, are both dropped, so the grid never joins what the navmesh keeps apart. No
radius erosion and no drivable opening: the navmesh is eroded already. `free` (un-eroded floor, used for
visual line of sight) is the navigable area grown back by the radius the navmesh was eroded with.
"""

from __future__ import annotations

import hashlib
import math
import warnings
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ovon.config.sim import NavConfig
from ovon.scenes.hm3dsem.geometry import height_peaks
from ovon.sim.cellsample import band_surface, cell_samples, pick
from ovon.sim.gridframe import grid_frame, hint_bands, step_cut
from ovon.sim.navmesh.format import NavMesh, NavMeshError, parse_navmesh
from ovon.sim.navmesh.polys import compute_islands, navmesh_triangles, triangle_areas

_MIN_AREA2 = 1e-12  # twice the xz area below which a navmesh triangle covers no cell centre
RADIUS_TOLERANCE = 0.01  # m: a navmesh eroded for another agent radius than sim.agent.radius is reported


class NavMeshWarning(UserWarning):
    """A navmesh is used although it does not quite fit the configuration; the message says how."""


@dataclass
class FloorSurface:
    """One floor of a navmesh on ovon's grid (`ovon.sim.navgrid` turns it into a `NavGrid`)."""

    floor: int
    height: float
    origin: np.ndarray  # world (x, z) of the corner of cell (0, 0)
    cell_size: float
    navigable: np.ndarray  # bool (rows, cols)
    free: np.ndarray  # bool (rows, cols): navigable grown back by the navmesh's radius (line of sight)
    heights: np.ndarray  # float32 (rows, cols), nan off the navmesh


MIN_FLOOR_AREA = 2.0  # m^2 of walkable surface at one height to count as a floor (no scene hints)


def lowest_samples(
    tris: np.ndarray,
    label: np.ndarray,
    origin: np.ndarray,
    cs: float,
    rows: int,
    cols: int,
    lo: np.ndarray,
    hi: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """(bands, rows * cols) height of the lowest sample of the (T, 3, 3) triangles per floor band [lo, hi)
    and cell centre (nan where none: `ovon.sim.cellsample`), and the `label` of its triangle (-1). The
    bands are disjoint (`floor_bands`), so each sample counts for one floor at most."""
    n = len(tris)
    V = np.ascontiguousarray(tris, dtype=np.float64).reshape(-1, 3)
    s = cell_samples(V, np.arange(3 * n).reshape(n, 3), origin, cs, rows, cols, area_tol=_MIN_AREA2)
    tag = np.asarray(label, dtype=np.int32)[s.tri]
    every = np.ones(len(s.ys), dtype=np.bool_)
    height = np.full((len(lo), rows * cols), np.nan)
    lab = np.full((len(lo), rows * cols), -1, np.int32)
    for b in range(len(lo)):
        k = band_surface(s, every, lo[b], hi[b])
        height[b], lab[b] = pick(s.ys, k, np.nan), pick(tag, k, -1)
    return height, lab


def floor_bands(tris: np.ndarray, hints: list[float] | None, sep: float) -> list[tuple[float, float, float]]:
    """(nominal height, lo, hi) per floor: around the scene's floors when given, else around the big
    horizontal areas of the navmesh (everything of the navmesh lands on some floor)."""
    if len(tris) == 0:
        return []
    y = tris[:, :, 1].mean(axis=1)
    if not hints:
        w = triangle_areas(tris)
        hints = sorted(height_peaks(y, w, 0.1, MIN_FLOOR_AREA, sep))
    bands = hint_bands(hints, sep)
    ymin, ymax = float(tris[:, :, 1].min()), float(tris[:, :, 1].max())
    h0, lo0, hi0 = bands[0]
    bands[0] = (h0, min(lo0, ymin - 1e-3), hi0)
    h1, lo1, hi1 = bands[-1]
    bands[-1] = (h1, lo1, max(hi1, ymax + 1e-3))
    return bands


def rasterise(mesh: NavMesh, nav: NavConfig, floor_heights: list[float] | None = None) -> list[FloorSurface]:
    """The navmesh's walkable area as one grid per floor (see the module docstring)."""
    islands = compute_islands(mesh)
    tris, pids = navmesh_triangles(mesh, islands)
    if len(tris) == 0:
        return []
    label = islands.poly_island[pids].astype(np.int32)
    cs = float(nav.cell_size)
    radius = mesh.agent_radius()
    origin, rows, cols = grid_frame(tris.reshape(-1, 3), cs)
    pad = int(math.ceil(radius / cs))  # room for `free`, the navigable area grown back by the radius
    origin, rows, cols = origin - pad * cs, rows + 2 * pad, cols + 2 * pad
    bands = floor_bands(tris, floor_heights, float(nav.floor_separation))
    lo = np.array([b[1] for b in bands])
    hi = np.array([b[2] for b in bands])
    height, lab = lowest_samples(tris, label, origin, cs, rows, cols, lo, hi)
    climb = max((t.walkable_climb for t in mesh.tiles), default=0.0)
    grids = []
    for i, (nominal, _, _) in enumerate(bands):
        h = height[i].reshape(rows, cols)
        present = ~np.isnan(h)
        navigable = present & ~step_cut(present, h, climb, lab[i].reshape(rows, cols))
        free = navigable.copy()
        if radius > 0 and navigable.any():
            free = ndimage.distance_transform_edt(~navigable) * cs <= radius + 1e-6
        grids.append(FloorSurface(i, float(nominal), origin.copy(), cs, navigable, free, h.astype(np.float32)))
    return grids


def navmesh_key(data: bytes, nav: NavConfig, floor_heights: list[float] | None) -> str:
    """Cache key of a navmesh's grids: file content + the params the rasterisation reads."""
    h = hashlib.sha1(data)
    h.update(
        repr((sorted(map(float, floor_heights or [])), nav.cell_size, nav.floor_separation, "navmesh-v1")).encode()
    )
    return "navmesh-" + h.hexdigest()


def floors_from_bytes(
    data: bytes, name: str, nav: NavConfig, floor_heights: list[float] | None, agent_radius: float
) -> list[FloorSurface]:
    """Parse a navmesh file's bytes and rasterise it; warns (`NavMeshWarning`) when the navmesh was
    eroded for another agent radius than `agent_radius`."""
    mesh = parse_navmesh(data, name)
    radius = mesh.agent_radius()
    if abs(radius - agent_radius) > RADIUS_TOLERANCE:
        warnings.warn(
            f"{name}: the navmesh was eroded for an agent radius of {radius:.3f} m, sim.agent.radius is "
            f"{agent_radius:.3f} m; navigability and collisions follow the navmesh",
            NavMeshWarning,
            stacklevel=3,
        )
    return rasterise(mesh, nav, floor_heights)


def check_inside(floors: list, bounds: tuple[np.ndarray, np.ndarray], name: str, mesh_name: str = "") -> None:
    """Refuse a navmesh whose navigable cells lie mostly outside the scene mesh's bounds (+ 1 m): the
    navmesh of another scene, or a mesh read with another up axis."""
    lo, hi = (np.asarray(b, dtype=np.float64) for b in bounds)
    pts = []
    for g in floors:
        rr, cc = np.nonzero(g.navigable)
        step = max(1, len(rr) // 2000)
        rr, cc = rr[::step], cc[::step]
        y = g.heights[rr, cc].astype(np.float64)
        pts.append(
            np.stack(
                [
                    g.origin[0] + (cc + 0.5) * g.cell_size,
                    np.where(np.isfinite(y), y, g.height),
                    g.origin[1] + (rr + 0.5) * g.cell_size,
                ],
                axis=1,
            )
        )
    p = np.concatenate(pts) if pts else np.zeros((0, 3))
    if len(p) and ((p < lo - 1.0) | (p > hi + 1.0)).any(axis=1).mean() > 0.5:
        raise NavMeshError(
            name,
            f"lies outside the scene mesh {mesh_name or ''} (mesh bounds {np.round(lo, 2).tolist()} "
            f".. {np.round(hi, 2).tolist()})",
            "is it the navmesh of another scene, or is the mesh's "
            "up axis different (--up)? --set sim.nav.source=mesh computes navigability from the mesh",
        )
