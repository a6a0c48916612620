"""A navmesh as ovon's per-floor navigability grids (`ovon.sim.navgrid.navmesh_navigation` makes them the
`SceneNav` every consumer reads), so geodesics, the agent's collisions and sliding, starts and episode
generation run on habitat's navigable area unchanged.

Method: every walkable detail triangle (`polys.navmesh_triangles`) is sampled at the cell centres of
one xz grid (a cell is navigable when its centre lies on a walkable triangle: the test habitat's
`is_navigable` makes at a point). Samples go to floors by height (bands around `Scene.floor_heights`
when a scene gives them, else around the navmesh's own big horizontal areas); per floor and cell the
lowest sample wins. Two neighbouring cells (8-neighbourhood) that are on different habitat islands, or
whose heights differ by more than the navmesh's walkable climb, are both dropped, so the grid never
joins what the navmesh keeps apart. No radius erosion and no drivable opening: the navmesh is eroded
already. `free` (un-eroded floor, used for visual line of sight) is the navigable area grown back by
the radius the navmesh was eroded with.
"""

from __future__ import annotations

import hashlib
import math
import warnings
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy import ndimage

from ovon.config.sim import NavConfig
from ovon.scenes.hm3dsem.geometry import height_peaks
from ovon.sim.gridframe import grid_frame, hint_bands
from ovon.sim.navmesh.format import NavMesh, NavMeshError, parse_navmesh
from ovon.sim.navmesh.polys import compute_islands, navmesh_triangles, triangle_areas

_EPS_BARY = 1e-7
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


@njit(cache=True)
def _raster(T, label, ox, oz, cs, rows, cols, lo, hi, height, lab):  # noqa: ANN001
    """Lowest walkable sample per floor band and cell centre, and the island label of that sample."""
    for t in range(T.shape[0]):
        ax, ay, az = T[t, 0, 0], T[t, 0, 1], T[t, 0, 2]
        e1x, e1y, e1z = T[t, 1, 0] - ax, T[t, 1, 1] - ay, T[t, 1, 2] - az
        e2x, e2y, e2z = T[t, 2, 0] - ax, T[t, 2, 1] - ay, T[t, 2, 2] - az
        den = e1x * e2z - e1z * e2x
        if abs(den) < 1e-12:
            continue  # vertical or degenerate: covers no cell centre
        xmin = min(ax, ax + e1x, ax + e2x)
        xmax = max(ax, ax + e1x, ax + e2x)
        zmin = min(az, az + e1z, az + e2z)
        zmax = max(az, az + e1z, az + e2z)
        c0 = max(0, int(math.ceil((xmin - ox) / cs - 0.5 - 1e-9)))
        c1 = min(cols - 1, int(math.floor((xmax - ox) / cs - 0.5 + 1e-9)))
        r0 = max(0, int(math.ceil((zmin - oz) / cs - 0.5 - 1e-9)))
        r1 = min(rows - 1, int(math.floor((zmax - oz) / cs - 0.5 + 1e-9)))
        for r in range(r0, r1 + 1):
            pz = oz + (r + 0.5) * cs - az
            for c in range(c0, c1 + 1):
                px = ox + (c + 0.5) * cs - ax
                w1 = (px * e2z - pz * e2x) / den
                w2 = (e1x * pz - e1z * px) / den
                if w1 < -_EPS_BARY or w2 < -_EPS_BARY or w1 + w2 > 1.0 + _EPS_BARY:
                    continue
                y = ay + w1 * e1y + w2 * e2y
                for b in range(lo.shape[0]):
                    if lo[b] <= y < hi[b]:
                        cell = r * cols + c
                        if math.isnan(height[b, cell]) or y < height[b, cell]:
                            height[b, cell] = y
                            lab[b, cell] = label[t]
                        break


def _cut(free: np.ndarray, h: np.ndarray, lab: np.ndarray, climb: float) -> np.ndarray:
    """Cells to drop: 8-neighbours on different islands or more than `climb` apart in height."""
    cut = np.zeros_like(free)
    hh = np.where(free, h, 0.0)
    rows, cols = free.shape
    for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
        a = (slice(0, rows - dr), slice(max(0, -dc), cols - max(0, dc)))
        b = (slice(dr, None), slice(max(0, dc), cols - max(0, -dc)))
        bad = free[a] & free[b] & ((lab[a] != lab[b]) | (np.abs(hh[a] - hh[b]) > climb + 1e-5))
        cut[a] |= bad
        cut[b] |= bad
    return cut


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
    height = np.full((len(bands), rows * cols), np.nan)
    lab = np.full((len(bands), rows * cols), -1, np.int32)
    _raster(np.ascontiguousarray(tris), label, float(origin[0]), float(origin[1]), cs, rows, cols, lo, hi, height, lab)
    climb = max((t.walkable_climb for t in mesh.tiles), default=0.0)
    grids = []
    for i, (nominal, _, _) in enumerate(bands):
        h = height[i].reshape(rows, cols)
        present = ~np.isnan(h)
        navigable = present & ~_cut(present, h, lab[i].reshape(rows, cols), climb)
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
