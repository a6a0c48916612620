"""Navigability grids computed from any triangle mesh (procedural house or real scan).

Why a grid and not a navmesh: habitat-sim (Recast) is not installable here, and a 2D grid per floor
gives collision checks, islands, snapping and fast-marching geodesics with plain numpy. A scene that has
a habitat navmesh beside its mesh gets its grids from that navmesh instead (`nav.source`,
`navmesh_navigation`, `ovon.sim.navmesh.raster`): the steps below are then replaced by rasterising the
navmesh's walkable polygons (already eroded by habitat: no erosion, no drivable opening).

Method (one pass over the triangles for each stage, compiled with numba):

1. Surface samples: every non-vertical triangle is rasterised at the cell *centres* of the xz grid
   (`ovon.sim.cellsample`, the rasteriser navmeshes use too: exactly what a vertical ray per cell would
   hit, all hits at once). A sample is a floor candidate
   when its triangle faces up with a slope below `max_slope_deg` (winding decides "up", as in Recast).
2. Clearance: every triangle (vertical walls included) is clipped to each cell square it overlaps; its
   y-range inside the cell blocks any candidate `h` of that cell with an overlap of
   (h + max_climb, h + agent.height). Low things (rugs, thresholds <= max_climb) do not block.
3. Floors: candidates are grouped into floors by `Scene.floor_heights` (bands around each height) or,
   without hints, by clustering the free candidate heights (gaps > `floor_separation`); clusters smaller
   than 1 m^2 or mostly without anything above them (roofs) are not floors. Per floor and cell the
   lowest free candidate in the band is the floor surface.
4. Steps: two 8-neighbour cells whose floor heights differ by more than `max_climb` are both marked not
   free (a ledge, as Recast's ledge filter does); the radius erosion then keeps the agent away from it.
5. Erosion: `navigable` = free cells whose centre is at least `agent.radius` from the centre of the
   nearest non-free cell (scipy EDT). Cell centres sit on multiples of `cell_size`, so walls at round
   coordinates fall inside a cell rather than on a boundary.
6. Drivable: the discrete agent (forward steps of `forward_step`, turns of `turn_angle_deg`, no sliding)
   drifts sideways by up to forward_step * sin(turn / 2) per step along a corridor whose direction is
   not one of its headings, so a corridor of agent centres narrower than twice that (0.13 m with
   0.25 m / 30 deg) cannot be driven reliably (measured with the shortest-path oracle on doorways of
   10 cm of play: ~15% success). Such strips are removed by a morphological opening of the navigable
   cells with a disk of that diameter; the removed cells are kept in `narrow` for reports.
7. Islands: 4-connected components of `navigable` (4 = the stencil fast marching uses, so an island is
   exactly the set a distance field can reach). Tiny islands are kept; `random_point` filters them.
   An island whose median surface lies more than `ELEVATED_M` above the floor (a table or bed top with
   head room) is "elevated": starts and goal viewpoints never use it.
"""

from __future__ import annotations

import hashlib
import itertools
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numba import njit
from scipy import ndimage

from ovon.atomic import atomic_write_with
from ovon.config.sim import AgentConfig, NavConfig
from ovon.lru import LRU
from ovon.scenes.model import Scene
from ovon.sim.cellsample import CellSamples, band_surface, cell_samples, pick, upward
from ovon.sim.gridframe import grid_frame as _grid_frame
from ovon.sim.gridframe import hint_bands, step_cut
from ovon.sim.los import los_between

MIN_FLOOR_AREA = 1.0  # m^2: smaller clusters of walkable heights are noise, not floors (no-hint mode)
MIN_COVERED_FRACTION = 0.5  # no-hint mode: a floor has a ceiling over most of it; roofs do not
ELEVATED_M = 0.3  # islands whose median surface is this far above the floor are furniture tops
START_HEIGHT_TOLERANCE_M = 0.5  # a given start's y may differ this much from its floor's surface
VERTICAL_TOL = 1e-6  # |normal_y| / |normal| below this: a vertical triangle, never a surface sample
_uid_counter = itertools.count(1)


# ----------------------------------------------------------------------------------------------
# numba kernels
# ----------------------------------------------------------------------------------------------


@njit(cache=True)
def _clip_yrange(px, py, pz, qx, qy, qz, n, x0, x1, z0, z1):
    """Sutherland-Hodgman clip of polygon (px,py,pz)[:n] to the square; returns (ymin, ymax, ok)."""
    for plane in range(4):
        m = 0
        for i in range(n):
            j = (i + 1) % n
            if plane == 0:
                di = px[i] - x0
                dj = px[j] - x0
            elif plane == 1:
                di = x1 - px[i]
                dj = x1 - px[j]
            elif plane == 2:
                di = pz[i] - z0
                dj = pz[j] - z0
            else:
                di = z1 - pz[i]
                dj = z1 - pz[j]
            if di >= 0.0:
                qx[m] = px[i]
                qy[m] = py[i]
                qz[m] = pz[i]
                m += 1
            if (di >= 0.0) != (dj >= 0.0):
                s = di / (di - dj)
                qx[m] = px[i] + s * (px[j] - px[i])
                qy[m] = py[i] + s * (py[j] - py[i])
                qz[m] = pz[i] + s * (pz[j] - pz[i])
                m += 1
        n = m
        if n == 0:
            return 0.0, 0.0, False
        for i in range(n):
            px[i] = qx[i]
            py[i] = qy[i]
            pz[i] = qz[i]
    lo = py[0]
    hi = py[0]
    for i in range(1, n):
        lo = min(lo, py[i])
        hi = max(hi, py[i])
    return lo, hi, True


@njit(cache=True)
def _block_pass(V, F, ox, oz, cs, rows, cols, ptr, ys, walk, climb, height, blocked):
    """Mark floor candidates that some triangle intrudes on within (h + climb, h + height)."""
    px = np.empty(16)
    py = np.empty(16)
    pz = np.empty(16)
    qx = np.empty(16)
    qy = np.empty(16)
    qz = np.empty(16)
    tol = 1e-5
    for t in range(F.shape[0]):
        a = F[t, 0]
        b = F[t, 1]
        c = F[t, 2]
        ymin = min(V[a, 1], V[b, 1], V[c, 1])
        ymax = max(V[a, 1], V[b, 1], V[c, 1])
        xmin = min(V[a, 0], V[b, 0], V[c, 0])
        xmax = max(V[a, 0], V[b, 0], V[c, 0])
        zmin = min(V[a, 2], V[b, 2], V[c, 2])
        zmax = max(V[a, 2], V[b, 2], V[c, 2])
        c0 = max(0, int(math.floor((xmin - ox) / cs)))
        c1 = min(cols - 1, int(math.floor((xmax - ox) / cs)))
        r0 = max(0, int(math.floor((zmin - oz) / cs)))
        r1 = min(rows - 1, int(math.floor((zmax - oz) / cs)))
        for r in range(r0, r1 + 1):
            for cc in range(c0, c1 + 1):
                cell = r * cols + cc
                s0 = ptr[cell]
                s1 = ptr[cell + 1]
                need = False
                for k in range(s0, s1):
                    if walk[k] and not blocked[k]:
                        h = ys[k]
                        if ymax > h + climb + tol and ymin < h + height - tol:
                            need = True
                            break
                if not need:
                    continue
                for i in range(3):
                    v = F[t, i]
                    px[i] = V[v, 0]
                    py[i] = V[v, 1]
                    pz[i] = V[v, 2]
                x0 = ox + cc * cs
                z0 = oz + r * cs
                lo, hi, ok = _clip_yrange(px, py, pz, qx, qy, qz, 3, x0, x0 + cs, z0, z0 + cs)
                if not ok:
                    continue
                for k in range(s0, s1):
                    if walk[k] and not blocked[k]:
                        h = ys[k]
                        if hi > h + climb + tol and lo < h + height - tol:
                            blocked[k] = True


@njit(cache=True)
def _covered(ptr, ys, walk, blocked, height, out):
    """out[k] = a free candidate k has some surface above its head (indoors, not a roof)."""
    for cell in range(ptr.shape[0] - 1):
        s1 = ptr[cell + 1]
        for k in range(ptr[cell], s1):
            if walk[k] and not blocked[k]:
                top = ys[s1 - 1]
                out[k] = top >= ys[k] + height - 1e-5


# ----------------------------------------------------------------------------------------------
# data types
# ----------------------------------------------------------------------------------------------


@dataclass(eq=False)
class NavGrid:
    """One floor: row grows with z, col with x; `origin` is the world (x, z) corner of cell (0, 0)."""

    floor: int
    height: float
    origin: np.ndarray
    cell_size: float
    navigable: np.ndarray
    free: np.ndarray
    heights: np.ndarray
    islands: np.ndarray
    island_area: np.ndarray
    island_radius: np.ndarray
    island_height: np.ndarray | None = None  # median surface height per island
    narrow: np.ndarray | None = None  # free, clear of the radius, but in strips too narrow to drive
    uid: int = field(default_factory=lambda: next(_uid_counter))
    _nearest: np.ndarray | None = field(default=None, repr=False)
    _start_cells: dict = field(default_factory=dict, repr=False)  # min_island_radius -> flat cell ids

    @property
    def shape(self) -> tuple[int, int]:
        return self.navigable.shape

    @property
    def num_islands(self) -> int:
        return int(len(self.island_area))

    def world_to_cell(self, xyz):
        """(row, col) of a point, or two int arrays for an (N, 3) array; may be out of bounds."""
        p = np.asarray(xyz, dtype=np.float64)
        if p.ndim == 1:
            col = math.floor((float(p[0]) - float(self.origin[0])) / self.cell_size)
            row = math.floor((float(p[2]) - float(self.origin[1])) / self.cell_size)
            return row, col
        cols = np.floor((p[:, 0] - self.origin[0]) / self.cell_size).astype(np.int64)
        rows = np.floor((p[:, 2] - self.origin[1]) / self.cell_size).astype(np.int64)
        return rows, cols

    def cell_to_world(self, row: int, col: int) -> np.ndarray:
        """Cell centre; y is the floor surface there (the floor's nominal height where there is none)."""
        y = self.height
        if self.in_bounds(row, col):
            h = float(self.heights[row, col])
            if not math.isnan(h):
                y = h
        return np.array(
            [
                float(self.origin[0]) + (col + 0.5) * self.cell_size,
                y,
                float(self.origin[1]) + (row + 0.5) * self.cell_size,
            ]
        )

    def in_bounds(self, row, col):
        rows, cols = self.navigable.shape
        if np.ndim(row) == 0:
            return 0 <= row < rows and 0 <= col < cols
        row = np.asarray(row)
        col = np.asarray(col)
        return (row >= 0) & (row < rows) & (col >= 0) & (col < cols)

    def is_navigable(self, xyz) -> bool:
        """Whether the agent centre may stand at this x/z (y is ignored: the grid is one floor)."""
        r, c = self.world_to_cell(xyz)
        return bool(self.in_bounds(r, c) and self.navigable[r, c])

    def island_of(self, xyz) -> int:
        r, c = self.world_to_cell(xyz)
        if not self.in_bounds(r, c):
            return -1
        return int(self.islands[r, c])

    def nearest_cell(self, row: int, col: int) -> tuple[int, int]:
        """Nearest navigable cell to a (clamped) cell; (-1, -1) when the floor has none."""
        if self._nearest is None:
            if not self.navigable.any():
                self._nearest = np.full((2,) + self.navigable.shape, -1, dtype=np.int32)
            else:
                _, idx = ndimage.distance_transform_edt(~self.navigable, return_indices=True)
                self._nearest = idx.astype(np.int32)
        rows, cols = self.navigable.shape
        row = min(max(int(row), 0), rows - 1)
        col = min(max(int(col), 0), cols - 1)
        return int(self._nearest[0, row, col]), int(self._nearest[1, row, col])

    def snap(self, xyz) -> np.ndarray:
        """Nearest navigable cell centre (nan (3,) when the floor has no navigable cell)."""
        r, c = self.world_to_cell(xyz)
        r, c = self.nearest_cell(r, c)
        if r < 0:
            return np.full(3, np.nan)
        return self.cell_to_world(r, c)

    def elevated(self) -> np.ndarray:
        """(num_islands,) bool: islands on furniture tops (median surface > ELEVATED_M above the floor)."""
        if self.island_height is None:
            return np.zeros(self.num_islands, dtype=bool)
        return self.island_height > self.height + ELEVATED_M

    def start_islands(self, min_island_radius: float = 0.0) -> np.ndarray:
        """Ids of the islands where starts and goal viewpoints may lie: radius >= min_island_radius and
        not elevated (when every big island is elevated, those are used rather than none)."""
        big = self.island_radius >= min_island_radius
        ok = np.flatnonzero(big & ~self.elevated())
        return ok if len(ok) else np.flatnonzero(big)

    def random_point(self, rng: np.random.Generator, min_island_radius: float = 0.0) -> np.ndarray:
        """Uniform navigable point (jittered inside its cell) on a start island (`start_islands`)."""
        cand = self._start_cells.get(min_island_radius)
        if cand is None:  # once per grid and radius: every training reset draws a start here
            ok = self.start_islands(min_island_radius)
            if len(ok) == 0:
                raise ValueError(f"floor {self.floor}: no island with radius >= {min_island_radius} m")
            if len(ok) == len(self.island_radius):
                cand = np.flatnonzero(self.navigable.ravel())
            else:
                cand = np.flatnonzero(np.isin(self.islands.ravel(), ok))
            self._start_cells[min_island_radius] = cand
        k = int(cand[rng.integers(len(cand))])
        r, c = divmod(k, self.navigable.shape[1])
        p = self.cell_to_world(r, c)
        jitter = rng.uniform(-0.49, 0.49, size=2) * self.cell_size
        p[0] += jitter[0]
        p[2] += jitter[1]
        return p

    def line_of_sight(self, a_rc, b_rc, mask: np.ndarray | None = None) -> bool:
        """Straight segment between two cell centres stays on `mask` (default: navigable)."""
        m = self.navigable if mask is None else mask
        return bool(los_between(m, int(a_rc[0]), int(a_rc[1]), int(b_rc[0]), int(b_rc[1])))


@dataclass(eq=False)
class SceneNav:
    """All floors of a scene; `floors[i]` matches `Scene.floor_heights[i]` when the scene has them."""

    floors: list[NavGrid]
    agent: AgentConfig
    nav: NavConfig
    key: str = ""
    source: str = "mesh"  # "mesh" (computed from the triangles) or the path of the navmesh it was read from

    @property
    def from_navmesh(self) -> bool:
        """Read from a habitat navmesh: its polygons answer geodesics, steps and distance-to-goal."""
        return self.source.endswith(".navmesh")

    @property
    def floor_heights(self) -> list[float]:
        return [g.height for g in self.floors]

    def floor_index(self, xyz) -> int:
        """Highest floor whose surface (nominal height, or its grid height at this x/z, whichever is
        lower: sunken areas count) is at or below the point + 0.3 m; 0 below every floor."""
        p = np.asarray(xyz, dtype=np.float64)
        y = float(p[1])
        tol = 0.3
        idx = 0
        for i, g in enumerate(self.floors):
            h = g.height
            r, c = g.world_to_cell(p)
            if g.in_bounds(r, c):
                hc = float(g.heights[r, c])
                if not math.isnan(hc):
                    h = min(h, hc)
            if y >= h - tol:
                idx = i
        return idx

    def grid_for(self, xyz) -> NavGrid:
        return self.floors[self.floor_index(xyz)]

    def is_navigable(self, xyz) -> bool:
        """On a scene read from a habitat navmesh, habitat's answer (over a walkable polygon, within 0.5 m of
        its surface): the grid is a cache of the polygons, and a point habitat calls navigable may fall in a
        cell the rasterisation left blocked. Elsewhere, the point's cell on its floor's grid."""
        if self.from_navmesh:
            return self._finder().is_navigable(xyz)
        return bool(self.floors) and self.grid_for(xyz).is_navigable(xyz)

    def _finder(self):  # noqa: ANN202 - a PathFinder (imported late: ovon.sim.navmesh builds on this module)
        from ovon.sim.navmesh.pathfind import path_finder

        return path_finder(self.source)

    def start_problem(self, xyz) -> str | None:
        """Why an episode may not start at `xyz`, or None: its x, z must be navigable on its floor and its y
        within START_HEIGHT_TOLERANCE_M of that floor's surface there (else the agent renders floating or
        sunk). The one rule of the dataset validator, the evaluation's off-map filter and the env's reset."""
        p = np.asarray(xyz, dtype=np.float64)
        shown = p.round(3).tolist()
        if not self.floors:
            return f"start {shown}: the scene has no navigable floor"
        grid = self.grid_for(p)
        if self.from_navmesh:  # the polygons decide, as habitat's is_navigable does; y against their surface
            from ovon.sim.navmesh.pathfind import on_polygon

            poly, snapped, _ = self._finder().nearest(p)
            if poly < 0 or not on_polygon(p, snapped):
                return f"start {shown} is not on a walkable polygon of the navmesh {self.source}"
            surface = float(snapped[1])
        elif not grid.is_navigable(p):
            return f"start {shown} is not on the navigable map (floor {grid.floor})"
        else:
            surface = float(grid.cell_to_world(*grid.world_to_cell(p))[1])
        if not abs(p[1] - surface) <= START_HEIGHT_TOLERANCE_M:
            return (
                f"start {shown} is {p[1] - surface:+.2f} m from its floor's surface (y {surface:.3f} on floor "
                f"{grid.floor}; at most {START_HEIGHT_TOLERANCE_M} m)"
            )
        return None

    def snap(self, xyz) -> np.ndarray:
        """The nearest navigable point: habitat's snap_point on a scene read from a navmesh (nan when no polygon
        lies within its pick box), else the nearest navigable cell centre of the point's floor."""
        if self.from_navmesh:
            return self._finder().snap_point(xyz)
        return self.grid_for(xyz).snap(xyz)


# ----------------------------------------------------------------------------------------------
# building
# ----------------------------------------------------------------------------------------------


@dataclass
class _Samples:
    cells: CellSamples
    walk: np.ndarray  # per sample: a floor candidate (its triangle faces up, not too steep)
    blocked: np.ndarray  # per sample: something intrudes on the agent's height above it


def _rasterise(V, F, origin, cs, rows, cols, agent: AgentConfig, max_slope_deg: float) -> _Samples:
    s = cell_samples(V, F, origin, cs, rows, cols, vertical_tol=VERTICAL_TOL)
    walk = upward(V, F, math.cos(math.radians(max_slope_deg)))[s.tri]
    blocked = np.zeros(len(s.ys), dtype=np.bool_)
    _block_pass(V, F, origin[0], origin[1], cs, rows, cols, s.ptr, s.ys, walk, agent.max_climb, agent.height, blocked)
    return _Samples(s, walk, blocked)


def _floor_bands(
    s: _Samples, hints: list[float], agent: AgentConfig, nav: NavConfig, cs: float
) -> list[tuple[float, float, float]]:
    """(nominal height, lo, hi) per floor: bands around hints, else clusters of free candidate heights."""
    sep = nav.floor_separation
    if hints:
        return hint_bands(hints, sep)
    cand = s.walk & ~s.blocked
    cov = np.zeros(len(s.cells.ys), dtype=np.bool_)
    _covered(s.cells.ptr, s.cells.ys, s.walk, s.blocked, agent.height, cov)
    hs = s.cells.ys[cand]
    cv = cov[cand]
    if len(hs) == 0:
        return []
    order = np.argsort(hs)
    hs, cv = hs[order], cv[order]
    splits = np.flatnonzero(np.diff(hs) > sep) + 1
    bands = []
    for seg_h, seg_c in zip(np.split(hs, splits), np.split(cv, splits), strict=True):
        if len(seg_h) * cs * cs < MIN_FLOOR_AREA or seg_c.mean() < MIN_COVERED_FRACTION:
            continue
        bins = np.round(seg_h / nav.cell_height).astype(np.int64)
        vals, cnt = np.unique(bins, return_counts=True)
        mode = vals[np.argmax(cnt)]
        nominal = float(np.median(seg_h[bins == mode]))
        bands.append((nominal, float(seg_h[0]) - 1e-6, float(seg_h[-1]) + 1e-6))
    return bands


def _islands(navigable: np.ndarray, origin: np.ndarray, cs: float):
    labels, n = ndimage.label(navigable)
    islands = labels.astype(np.int32) - 1
    if n == 0:
        return islands, np.zeros(0), np.zeros(0)
    rr, cc = np.nonzero(navigable)
    lab = labels[rr, cc] - 1
    cnt = np.bincount(lab, minlength=n).astype(np.float64)
    x = origin[0] + (cc + 0.5) * cs
    z = origin[1] + (rr + 0.5) * cs
    mx = np.bincount(lab, weights=x, minlength=n) / cnt
    mz = np.bincount(lab, weights=z, minlength=n) / cnt
    d = np.hypot(x - mx[lab], z - mz[lab])
    radius = np.zeros(n)
    np.maximum.at(radius, lab, d)
    return islands, cnt * cs * cs, radius


def _island_heights(islands: np.ndarray, heights: np.ndarray, n: int) -> np.ndarray:
    """Median surface height of each island."""
    out = np.zeros(n)
    if n == 0:
        return out
    rr, cc = np.nonzero(islands >= 0)
    lab = islands[rr, cc]
    h = heights[rr, cc].astype(np.float64)
    order = np.lexsort((h, lab))
    lab, h = lab[order], h[order]
    starts = np.searchsorted(lab, np.arange(n))
    ends = np.searchsorted(lab, np.arange(n), side="right")
    for i in range(n):
        seg = h[starts[i] : ends[i]]
        seg = seg[np.isfinite(seg)]
        out[i] = float(np.median(seg)) if len(seg) else np.nan
    return out


def min_drivable_width(agent: AgentConfig) -> float:
    """Narrowest corridor of agent centres the discrete agent drives reliably: twice its sideways drift
    per step when its heading is half a turn off the corridor (see the module docstring, step 6)."""
    return 2.0 * agent.forward_step * math.sin(math.radians(agent.turn_angle_deg) / 2.0)


def _drivable(free: np.ndarray, cs: float, agent: AgentConfig) -> tuple[np.ndarray, np.ndarray]:
    """(navigable, narrow): radius erosion, then opening with a disk of diameter `min_drivable_width`."""
    clearance = ndimage.distance_transform_edt(free) * cs
    eroded = free & (clearance >= agent.radius - 1e-6)
    r = min_drivable_width(agent) / 2.0 / cs  # in cells
    if r < 1.0 or not eroded.any():
        return eroded, np.zeros_like(eroded)
    core = ndimage.distance_transform_edt(eroded) > r
    navigable = eroded & (ndimage.distance_transform_edt(~core) <= r + 1e-9)
    return navigable, eroded & ~navigable


def _grid(
    floor: int, height: float, origin: np.ndarray, cs: float, free: np.ndarray, heights: np.ndarray, agent: AgentConfig
) -> NavGrid:
    navigable, narrow = _drivable(free, cs, agent)
    islands, area, radius = _islands(navigable, origin, cs)
    return NavGrid(
        floor=floor,
        height=float(height),
        origin=origin.copy(),
        cell_size=cs,
        navigable=navigable,
        free=free,
        heights=heights,
        islands=islands,
        island_area=area,
        island_radius=radius,
        island_height=_island_heights(islands, heights, len(area)),
        narrow=narrow,
    )


def _surface_grid(
    floor: int,
    height: float,
    origin: np.ndarray,
    cs: float,
    navigable: np.ndarray,
    free: np.ndarray,
    heights: np.ndarray,
) -> NavGrid:
    """A floor whose navigable cells are given as they are (a navmesh, eroded already: no second radius
    erosion and no drivable opening)."""
    islands, area, radius = _islands(navigable, origin, cs)
    return NavGrid(
        floor=floor,
        height=float(height),
        origin=origin.copy(),
        cell_size=cs,
        navigable=navigable,
        free=free,
        heights=heights,
        islands=islands,
        island_area=area,
        island_radius=radius,
        island_height=_island_heights(islands, heights, len(area)),
        narrow=np.zeros_like(navigable),
    )


def _make_grid(
    floor: int,
    height: float,
    origin: np.ndarray,
    cs: float,
    free_h: np.ndarray,
    any_h: np.ndarray,
    agent: AgentConfig,
) -> NavGrid:
    """Ledge cut + radius erosion + drivable opening + islands for one floor's per-cell heights."""
    free = ~np.isnan(free_h)
    free &= ~step_cut(free, free_h, agent.max_climb)
    heights = np.where(np.isnan(free_h), any_h, free_h).astype(np.float32)
    return _grid(floor, height, origin, cs, free, heights, agent)


def compute_navigation(
    vertices: np.ndarray,
    faces: np.ndarray,
    floor_heights: list[float] | None,
    agent: AgentConfig,
    nav: NavConfig,
) -> list[NavGrid]:
    """Uncached core of `build_navigation` for a bare mesh."""
    V = np.ascontiguousarray(vertices, dtype=np.float64)
    F = np.ascontiguousarray(faces, dtype=np.int64)
    cs = float(nav.cell_size)
    if len(F) == 0:
        return []
    origin, rows, cols = _grid_frame(V, cs)
    slope = float(nav.max_slope_deg)
    s = _rasterise(V, F, origin, cs, rows, cols, agent, slope)
    grids = []
    for i, (nominal, lo, hi) in enumerate(_floor_bands(s, list(floor_heights or []), agent, nav, cs)):
        # the floor surface: top of the lowest stack of free candidates; where none, the lowest candidate
        free_h = pick(s.cells.ys, band_surface(s.cells, s.walk & ~s.blocked, lo, hi, agent.max_climb), np.nan)
        any_h = pick(s.cells.ys, band_surface(s.cells, s.walk, lo, hi), np.nan)
        grids.append(_make_grid(i, nominal, origin, cs, free_h.reshape(rows, cols), any_h.reshape(rows, cols), agent))
    return grids


_CACHE = LRU(8)  # scenes' navigation per process: mesh key (or navmesh key and agent) -> SceneNav


def _cache_key(scene: Scene, agent: AgentConfig, nav: NavConfig) -> str:
    h = hashlib.sha1()
    v = np.ascontiguousarray(scene.mesh.vertices, dtype=np.float32)
    f = np.ascontiguousarray(scene.mesh.faces, dtype=np.int32)
    h.update(np.asarray(v.shape, dtype=np.int64).tobytes())
    h.update(v.tobytes())
    h.update(f.tobytes())
    h.update(repr((list(map(float, scene.floor_heights)), agent, nav, "navgrid-v2")).encode())
    return h.hexdigest()


def _save(path: Path, grids: list[NavGrid]) -> None:
    """Write the grids through `ovon.atomic` (a unique temp name, then rename): two processes building the
    same scene each write a whole file, and a reader sees a whole file or none. A failed write (disk
    full, read-only folder) only loses the saving: the cache is an optimisation."""
    arrays: dict[str, np.ndarray] = {"n": np.array(len(grids))}
    for i, g in enumerate(grids):
        arrays[f"meta{i}"] = np.array([g.height, g.origin[0], g.origin[1], g.cell_size])
        arrays[f"free{i}"] = g.free
        arrays[f"heights{i}"] = g.heights
    try:
        atomic_write_with(path, lambda f: np.savez_compressed(f, **arrays))
    except OSError:
        pass


def _load(path: Path, agent: AgentConfig) -> list[NavGrid] | None:
    """The cached grids, or None (a miss) when the file is absent or cannot be used for any reason: torn
    by a kill (BadZipFile, EOFError), truncated, other keys or shapes, a disk error. The caller then
    rebuilds and replaces it, so a bad file never breaks a scene for good."""
    if not path.is_file():
        return None
    try:
        grids = []
        with np.load(path, allow_pickle=False) as z:
            for i in range(int(z["n"])):
                h, ox, oz, cs = z[f"meta{i}"]
                free, heights = z[f"free{i}"], z[f"heights{i}"]
                grids.append(_grid(i, float(h), np.array([ox, oz]), float(cs), free, heights, agent))
        return grids
    except Exception:  # noqa: BLE001 - whatever is wrong with a cache file, the answer is to rebuild it
        return None


def build_navigation(
    scene: Scene, agent: AgentConfig | None = None, nav: NavConfig | None = None, cache_dir: str | Path | None = None
) -> SceneNav:
    """Navigation grids of a scene, cached in-process by mesh content + params, and on disk in
    `cache_dir` (`nav_<key>.npz`) when given: `ovon dataset generate` passes `<out>/.cache/nav`, so its
    two phases and a resumed run compute each scene's grids once.

    `nav.source` picks where navigability comes from: the habitat navmesh beside the mesh
    (`Scene.navmesh`, read by `ovon.sim.navmesh.load_navmesh`), the mesh itself, or (auto) the navmesh
    when the scene has one."""
    agent = agent or AgentConfig()
    nav = nav or NavConfig()
    source = nav.source
    if source == "navmesh" and not scene.navmesh:
        raise ValueError(
            f"sim.nav.source=navmesh but scene {scene.scene_id} has no habitat navmesh (<id>.navmesh or "
            f"<id>.basis.navmesh beside its mesh {scene.source or '(in memory)'}); put one there or use "
            "--set sim.nav.source=mesh (or auto) to compute navigability from the mesh"
        )
    if source != "mesh" and scene.navmesh:
        bounds = scene.mesh.bounds() if scene.mesh.num_faces else None
        return navmesh_navigation(scene.navmesh, agent, nav, scene.floor_heights, bounds, scene.source)
    key = _cache_key(scene, agent, nav)

    def make() -> SceneNav:
        path = Path(cache_dir) / f"nav_{key}.npz" if cache_dir is not None else None
        grids = _load(path, agent) if path is not None else None
        if grids is None:
            grids = compute_navigation(scene.mesh.vertices, scene.mesh.faces, scene.floor_heights, agent, nav)
            if path is not None:
                _save(path, grids)
        return SceneNav(floors=grids, agent=agent, nav=nav, key=key)

    return _CACHE.get(key, make)


def navmesh_navigation(
    path: str | Path,
    agent: AgentConfig | None = None,
    nav: NavConfig | None = None,
    floor_heights: list[float] | None = None,
    bounds: tuple[np.ndarray, np.ndarray] | None = None,
    mesh_name: str = "",
) -> SceneNav:
    """Navigation grids read from a habitat navmesh (`ovon.sim.navmesh.raster`: eroded already, so no
    second radius erosion and no drivable opening), cached in-process by file content + params. With the
    scene's mesh `bounds`, a navmesh lying outside the mesh is refused."""
    from ovon.sim.navmesh.format import navmesh_file_bytes
    from ovon.sim.navmesh.raster import check_inside, floors_from_bytes, navmesh_key

    agent = agent or AgentConfig()
    nav = nav or NavConfig()
    data = navmesh_file_bytes(path)
    key = navmesh_key(data, nav, floor_heights)

    def make() -> SceneNav:
        floors = floors_from_bytes(data, str(path), nav, floor_heights, agent.radius)
        grids = [
            _surface_grid(f.floor, f.height, f.origin, f.cell_size, f.navigable, f.free, f.heights) for f in floors
        ]
        return SceneNav(floors=grids, agent=agent, nav=nav, key=key, source=str(path))

    hit = _CACHE.get((key, agent), make)
    if bounds is not None:
        check_inside(hit.floors, bounds, str(path), mesh_name)
    return hit


def clear_cache() -> None:
    _CACHE.clear()
