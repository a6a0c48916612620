"""Geodesic distance fields over a floor's navigable grid (fast marching, cached per goal set).

Why fast marching (scikit-fmm, second order): measured on a 20 m x 20 m empty floor at 0.05 m cells
(benchmarks/geodesic_speed.py) it is within ~0.3% of the straight-line distance, where a 16-neighbour
Dijkstra is up to ~2.7% long (its directions are 0, 26.6, 45 deg), and it is fast enough (a full
400x400 field in well under 0.5 s). The Dijkstra variant stays available as `method="dijkstra"`.

Goals: each goal point is used as-is when its cell is navigable, otherwise it is snapped to the nearest
navigable cell centre of the grid if that is within `max_snap` (0.5 m); goals farther away are ignored
(as Habitat snaps endpoints to the navmesh; no offset is added). The source is seeded with exact
Euclidean distances in a small window around each goal, so distances are not biased by half a cell.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import skfmm
from numba import njit

from ovon.lru import LRU
from ovon.sim.heap import heap_pop, heap_push
from ovon.sim.los import los_between
from ovon.sim.navgrid import NavGrid, SceneNav

MAX_SNAP = 0.5  # m: goals farther than this from any navigable cell of the grid are ignored
_SEED_RADIUS = 3  # cells: window around a goal where the level set is the exact Euclidean distance
SEED_CIRCLE_CELLS = 2.5  # cells within this radius of a goal keep their exact distance; the front starts there
CACHE_SIZE = 256  # fields per process (a 400x400 field is 0.6 MB); training resets revisit goal sets
_CACHE = LRU(CACHE_SIZE)  # (grid, goal set, snap, method) -> DistanceField


# ----------------------------------------------------------------------------------------------
# numba kernels
# ----------------------------------------------------------------------------------------------

# 16-neighbourhood: 8 king moves + 8 knight moves; knight moves need both cells they cross.
# fmt: off
_NBR = np.array(
    [[0, 1], [1, 0], [0, -1], [-1, 0], [1, 1], [1, -1], [-1, 1], [-1, -1],
     [1, 2], [2, 1], [-1, 2], [-2, 1], [1, -2], [2, -1], [-1, -2], [-2, -1]],
    dtype=np.int64,
)
# fmt: on


@njit(cache=True)
def _step_ok(nav, r, c, dr, dc):
    """Move (dr, dc) from (r, c) stays on the grid and does not cut a corner."""
    rows, cols = nav.shape
    r2 = r + dr
    c2 = c + dc
    if r2 < 0 or c2 < 0 or r2 >= rows or c2 >= cols or not nav[r2, c2]:
        return False
    adr = abs(dr)
    adc = abs(dc)
    if adr == 1 and adc == 1:
        return nav[r + dr, c] and nav[r, c + dc]
    if adr == 2:  # crosses (r + dr/2, c) and (r + dr/2, c + dc)
        h = dr // 2
        return nav[r + h, c] and nav[r + h, c + dc]
    if adc == 2:
        h = dc // 2
        return nav[r, c + h] and nav[r + dr, c + h]
    return True


@njit(cache=True)
def _dijkstra16(nav, init, cs):
    """Dijkstra over the 16-neighbourhood from cells with finite `init` (their start distance)."""
    rows, cols = nav.shape
    dist = init.copy()
    done = np.zeros((rows, cols), dtype=np.bool_)
    cap = rows * cols * 4 + 16
    hk = np.empty(cap)
    hi = np.empty(cap, dtype=np.int64)
    n = 0
    for r in range(rows):
        for c in range(cols):
            if math.isfinite(dist[r, c]):
                n = heap_push(hk, hi, n, dist[r, c], r * cols + c)
    while n > 0:
        d, idx, n = heap_pop(hk, hi, n)
        r = idx // cols
        c = idx % cols
        if done[r, c]:
            continue
        done[r, c] = True
        for j in range(16):
            dr = _NBR[j, 0]
            dc = _NBR[j, 1]
            if not _step_ok(nav, r, c, dr, dc):
                continue
            r2 = r + dr
            c2 = c + dc
            nd = d + cs * math.sqrt(dr * dr + dc * dc)
            if nd < dist[r2, c2] and n < cap:
                dist[r2, c2] = nd
                n = heap_push(hk, hi, n, nd, r2 * cols + c2)
    return dist


@njit(cache=True)
def _descend(dist, nav, r, c):
    """Steepest descent (most decrease per metre) over the 16-neighbourhood until a minimum."""
    rows, cols = dist.shape
    out_r = np.empty(rows * cols + 1, dtype=np.int64)
    out_c = np.empty(rows * cols + 1, dtype=np.int64)
    n = 0
    out_r[0] = r
    out_c[0] = c
    n = 1
    while True:
        cur = dist[r, c]
        best = 0.0
        br = -1
        bc = -1
        for j in range(16):
            dr = _NBR[j, 0]
            dc = _NBR[j, 1]
            if not _step_ok(nav, r, c, dr, dc):
                continue
            v = dist[r + dr, c + dc]
            if not v < cur:
                continue
            slope = (cur - v) / math.sqrt(dr * dr + dc * dc)
            if slope > best:
                best = slope
                br = r + dr
                bc = c + dc
        if br < 0 or n >= out_r.shape[0]:
            break
        r = br
        c = bc
        out_r[n] = r
        out_c[n] = c
        n += 1
    return out_r[:n], out_c[:n]


@njit(cache=True)
def _shortcut(nav, rr, cc):
    """Greedy string pulling: keep a cell only where line of sight from the last kept one breaks."""
    n = rr.shape[0]
    keep = np.empty(n, dtype=np.int64)
    m = 0
    keep[m] = 0
    m += 1
    anchor = 0
    i = 1
    while i < n:
        if not los_between(nav, rr[anchor], cc[anchor], rr[i], cc[i]):
            anchor = i - 1
            keep[m] = anchor
            m += 1
        i += 1
    if keep[m - 1] != n - 1:
        keep[m] = n - 1
        m += 1
    return keep[:m]


# ----------------------------------------------------------------------------------------------
# fields
# ----------------------------------------------------------------------------------------------


@dataclass(eq=False)
class DistanceField:
    """Metres from every cell of `grid` to the nearest goal; inf where no goal is reachable."""

    grid: NavGrid
    dist: np.ndarray  # float32 (rows, cols)
    goals: np.ndarray  # (K, 3) goal points actually used (after snapping); empty when none
    max_snap: float = MAX_SNAP

    def __post_init__(self) -> None:
        g = self.grid
        self._ox = float(g.origin[0])
        self._oz = float(g.origin[1])
        self._cs = float(g.cell_size)
        self._rows, self._cols = g.navigable.shape
        self._d = self.dist.astype(np.float64)  # .item() on float64 returns a Python float quickly

    def _value(self, r: int, c: int) -> float:
        if 0 <= r < self._rows and 0 <= c < self._cols:
            return self._d.item(r, c)
        return math.inf

    def distance(self, xyz) -> float:
        """Bilinear interpolation of the field between the reachable cell centres around the point.

        Off the navigable area (no reachable neighbour) it is the value at the nearest navigable cell
        plus the straight distance to it, when that is within `max_snap`; inf otherwise.
        """
        x = float(xyz[0])
        z = float(xyz[2])
        u = (x - self._ox) / self._cs - 0.5
        v = (z - self._oz) / self._cs - 0.5
        c0 = math.floor(u)
        r0 = math.floor(v)
        fu = u - c0
        fv = v - r0
        wsum = 0.0
        acc = 0.0
        d = self._value(r0, c0)
        if d != math.inf:
            w = (1.0 - fu) * (1.0 - fv)
            wsum += w
            acc += w * d
        d = self._value(r0, c0 + 1)
        if d != math.inf:
            w = fu * (1.0 - fv)
            wsum += w
            acc += w * d
        d = self._value(r0 + 1, c0)
        if d != math.inf:
            w = (1.0 - fu) * fv
            wsum += w
            acc += w * d
        d = self._value(r0 + 1, c0 + 1)
        if d != math.inf:
            w = fu * fv
            wsum += w
            acc += w * d
        if wsum > 1e-9:
            return acc / wsum
        return self._off_grid(x, z)

    def _off_grid(self, x: float, z: float) -> float:
        r = math.floor((z - self._oz) / self._cs)
        c = math.floor((x - self._ox) / self._cs)
        nr, nc = self.grid.nearest_cell(r, c)
        if nr < 0:
            return math.inf
        off = math.hypot(self._ox + (nc + 0.5) * self._cs - x, self._oz + (nr + 0.5) * self._cs - z)
        if off > self.max_snap:
            return math.inf
        return self._value(nr, nc) + off

    def start_cell(self, xyz) -> tuple[int, int]:
        """The navigable cell a path from xyz starts in: its own, else the nearest within max_snap."""
        g = self.grid
        r, c = g.world_to_cell(xyz)
        if g.in_bounds(r, c) and g.navigable[r, c]:
            return r, c
        nr, nc = g.nearest_cell(r, c)
        if nr < 0:
            return -1, -1
        p = g.cell_to_world(nr, nc)
        if math.hypot(p[0] - float(xyz[0]), p[2] - float(xyz[2])) > self.max_snap:
            return -1, -1
        return nr, nc

    def path(self, xyz) -> np.ndarray:
        """Shortest path (K, 3) from xyz to the nearest goal: field descent, then line-of-sight
        shortcutting on the navigable mask; y from the grid heights. Empty (0, 3) when unreachable."""
        g = self.grid
        r, c = self.start_cell(xyz)
        if r < 0 or not math.isfinite(self._d.item(r, c)):
            return np.zeros((0, 3))
        rr, cc = _descend(self._d, g.navigable, r, c)
        keep = _shortcut(g.navigable, rr, cc)
        pts = [g.cell_to_world(int(rr[k]), int(cc[k])) for k in keep]
        start = np.array([float(xyz[0]), pts[0][1], float(xyz[2])])
        pts[0] = start
        end = pts[-1]
        if len(self.goals):
            gi = int(np.argmin(np.hypot(self.goals[:, 0] - end[0], self.goals[:, 2] - end[2])))
            goal = self.goals[gi].copy()
            gr, gc = g.world_to_cell(goal)
            goal[1] = g.cell_to_world(gr, gc)[1]
            if len(pts) == 1:
                pts.append(goal)
            else:
                pts[-1] = goal
        out = np.asarray(pts, dtype=np.float64)
        # drop zero-length segments (start or goal inside the first/last kept cell)
        if len(out) > 1:
            seg = np.hypot(np.diff(out[:, 0]), np.diff(out[:, 2]))
            out = np.concatenate([out[:1], out[1:][seg > 1e-9]])
        return out

    def path_length(self, xyz) -> float:
        """Length of `path(xyz)` in 3D (y from the floor surface, as habitat measures its paths): the
        string-pulled shortest path, closer to habitat's geodesic distance than the field value
        (benchmarks/navmesh_agreement.py); inf when unreachable."""
        pts = self.path(xyz)
        if len(pts) == 0:
            return math.inf
        return float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum())


def _snap_goals(grid: NavGrid, goals: np.ndarray, max_snap: float) -> np.ndarray:
    if len(goals) == 0:
        return np.zeros((0, 3), np.float64)
    rows, cols = grid.world_to_cell(goals)
    h, w = grid.navigable.shape
    inside = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
    ok = np.zeros(len(goals), bool)
    ok[inside] = grid.navigable[rows[inside], cols[inside]]
    # Goals on navigable cells pass as they are; the rest snap (rare), in place, so the order is kept.
    out = np.array(goals, dtype=np.float64).reshape(-1, 3)
    for i in np.flatnonzero(~ok):
        nr, nc = grid.nearest_cell(int(rows[i]), int(cols[i]))
        if nr < 0:
            continue
        q = grid.cell_to_world(nr, nc)
        if math.hypot(q[0] - out[i, 0], q[2] - out[i, 2]) <= max_snap:
            out[i] = q
            ok[i] = True
    return out[ok]


@njit(cache=True)
def _seed_kernel(seed, gx, gz, grow, gcol, r0, c0, w, ox, oz, cs):  # noqa: ANN001
    rows, cols = seed.shape
    for k in range(gx.shape[0]):
        ra = max(grow[k] - w - r0, 0)
        rb = min(grow[k] + w + 1 - r0, rows)
        ca = max(gcol[k] - w - c0, 0)
        cb = min(gcol[k] + w + 1 - c0, cols)
        for r in range(ra, rb):
            z = oz + (float(r + r0) + 0.5) * cs
            for c in range(ca, cb):
                x = ox + (float(c + c0) + 0.5) * cs
                d = math.hypot(z - gz[k], x - gx[k])
                if d < seed[r, c]:
                    seed[r, c] = d


def _seed(grid: NavGrid, goals: np.ndarray, r0: int, c0: int, shape: tuple[int, int]) -> np.ndarray:
    """Exact Euclidean distance to the nearest goal in a window around each goal (inf elsewhere),
    on the crop starting at (r0, c0)."""
    seed = np.full(shape, np.inf)
    rows, cols = grid.world_to_cell(goals)
    _seed_kernel(
        seed,
        np.ascontiguousarray(goals[:, 0]),
        np.ascontiguousarray(goals[:, 2]),
        rows,
        cols,
        int(r0),
        int(c0),
        _SEED_RADIUS,
        float(grid.origin[0]),
        float(grid.origin[1]),
        float(grid.cell_size),
    )
    return seed


def _compute(grid: NavGrid, goals: np.ndarray, method: str) -> np.ndarray:
    dist = np.full(grid.navigable.shape, np.inf, dtype=np.float32)
    if len(goals) == 0:
        return dist
    rows, cols = grid.world_to_cell(goals)
    ids = np.unique(grid.islands[rows, cols])
    ids = ids[ids >= 0]
    if len(ids) == 0:
        return dist
    sel = np.isin(grid.islands, ids)
    rr = np.flatnonzero(sel.any(axis=1))
    cc = np.flatnonzero(sel.any(axis=0))
    r0, r1, c0, c1 = rr[0], rr[-1] + 1, cc[0], cc[-1] + 1
    sub = sel[r0:r1, c0:c1]
    seed = _seed(grid, goals, r0, c0, sub.shape)
    seed[~sub] = np.inf
    cs = grid.cell_size
    if method == "fmm":
        # Cells within rho of a goal keep their exact distance and the front starts from that circle: a
        # circle of 2.5 cells is resolved well enough that the field is not biased long (with 0.75 cells it
        # was ~1 cm long at any distance: +1% at 1 m; benchmarks/navmesh_agreement.py).
        rho = SEED_CIRCLE_CELLS * cs
        phi = np.where(np.isfinite(seed), seed - rho, (_SEED_RADIUS + 1) * cs)
        if not (phi[sub] < 0).any():
            return dist
        # pad by one masked cell so the front never touches the array border
        phi_p = np.pad(phi, 1, constant_values=1.0)
        mask_p = np.pad(~sub, 1, constant_values=True)
        d = skfmm.distance(np.ma.MaskedArray(phi_p, mask_p), dx=cs, order=2)
        d = np.ma.filled(d, np.inf)[1:-1, 1:-1] + rho
        inside = np.isfinite(seed) & (phi < 0)
        d[inside] = seed[inside]
        d[~sub] = np.inf
    elif method == "dijkstra":
        d = _dijkstra16(sub, seed, cs)
    else:
        raise ValueError(f"unknown geodesic method {method!r} (fmm | dijkstra)")
    dist[r0:r1, c0:c1] = d
    return dist


def distance_field(
    grid: NavGrid, goals: np.ndarray, *, max_snap: float = MAX_SNAP, method: str = "fmm"
) -> DistanceField:
    """Distance field to a goal set (K, 3), cached (LRU) per grid and goal set."""
    g = np.asarray(goals, dtype=np.float64).reshape(-1, 3)
    key = (grid.uid, np.round(g, 4).tobytes(), float(max_snap), method)

    def make() -> DistanceField:
        used = _snap_goals(grid, g, max_snap)
        return DistanceField(grid, _compute(grid, used, method), used, max_snap)

    return _CACHE.get(key, make)


GEODESIC_MEASURES = ("auto", "navmesh", "field", "path")


def geodesic_distance(nav: SceneNav, a, b, how: str = "auto") -> float:
    """Geodesic distance from a to b ((3,) or (K, 3) goals: the nearest); inf when unreachable. `how`:
    "navmesh" (habitat's own answer on the navmesh the scene was read from: polygon A* and funnel,
    `ovon.sim.navmesh.pathfind`; exact on habitat's golden geodesics), "field" (the distance field, what
    episodes and metrics use on a scene built from triangles: `distance_to_goals`), "path" (3D length of
    the string-pulled grid path); "auto": "navmesh" when the scene came from a navmesh file, else "field"."""
    if how not in GEODESIC_MEASURES:
        raise ValueError(f"unknown geodesic measure {how!r} ({' | '.join(GEODESIC_MEASURES)})")
    goals = np.asarray(b, dtype=np.float64).reshape(-1, 3)
    from_navmesh = nav.from_navmesh
    if how == "navmesh" and not from_navmesh:
        raise ValueError(
            f"geodesic measure 'navmesh' needs a scene read from a habitat navmesh, got one built from {nav.source!r}; "
            "fix: load it with ovon.sim.navmesh.load_navmesh or use how='field'"
        )
    if how == "navmesh" or (how == "auto" and from_navmesh):
        from ovon.sim.navmesh.pathfind import path_finder

        return path_finder(nav.source).geodesic_distance(a, goals)
    if not nav.floors:
        return math.inf
    fa = nav.floor_index(a)
    same = np.array([nav.floor_index(g) == fa for g in goals], dtype=bool)
    if not same.any():
        return math.inf
    f = distance_field(nav.floors[fa], goals[same])
    return f.distance(a) if how in ("field", "auto") else f.path_length(a)


def distance_to_goals(nav: SceneNav, field: DistanceField, goals: np.ndarray) -> Callable[[np.ndarray], float]:
    """The distance-to-goal measure of a scene (what d0, SPL, soft SPL, success, generated starts and
    validation read): on a scene read from a habitat navmesh, habitat's own (the polygons' multi-goal
    geodesic to `goals`, goals snapped once); elsewhere `field.distance`, the grid's field to the same
    goals. One rule, so an episode is generated, validated and scored by the same number."""
    if not nav.from_navmesh:
        return field.distance
    from ovon.sim.navmesh.pathfind import path_finder

    return path_finder(nav.source).distance_to(goals)


def clear_cache() -> None:
    _CACHE.clear()
