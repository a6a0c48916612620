"""Navmesh polygons as habitat-sim sees them: walkable detail triangles, polygon connectivity, islands.

Definitions follow habitat-sim's `PathFinder` (src/esp/nav/PathFinder.cpp), so `ovon scenes inspect
X.navmesh` prints the numbers habitat prints:

* area: 3D area of the detail triangles of every polygon whose flags include WALK (a polygon under
  1e-5 m^2 is disabled and counts nothing);
* islands: connected components of polygons over Detour links (shared edges inside a tile, portal
  edges matched across neighbouring tiles as `dtNavMesh::connectExtLinks` does); polygons are visited
  in tile-slot then polygon order and a new island starts at every unvisited polygon; a neighbour joins
  only when it passes habitat's query filter (flags include WALK);
* island radius: the largest 3D distance from the island's vertex centroid to its polygons' vertices
  (vertices counted once per polygon that uses them, as habitat accumulates them).

Off-mesh connections (habitat never writes them) are ignored.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ovon.sim.navmesh.format import EXT_LINK, FLAG_WALK, MAX_VERTS_PER_POLY, POLY_GROUND, NavMesh, NavMeshTile

ZERO_AREA = 1e-5  # m^2: habitat disables polygons smaller than this


@dataclass
class PolyIndex:
    """Global polygon numbering over the tiles in slot order: polygon k of tile `order[i]` has id base[i] + k."""

    order: list[int]
    base: np.ndarray  # (len(order) + 1,) int64

    @property
    def count(self) -> int:
        return int(self.base[-1])


@dataclass
class Islands:
    """Habitat's island system of a navmesh."""

    poly_island: np.ndarray  # (num polys,) int32 island of every (ground) polygon, -1 for off-mesh links
    area: np.ndarray  # (num islands,) m^2 of walkable detail triangles
    radius: np.ndarray  # (num islands,) m
    poly_area: np.ndarray  # (num polys,) m^2 of each polygon's detail triangles
    walkable: np.ndarray  # (num polys,) bool: flags include WALK and area >= ZERO_AREA

    @property
    def count(self) -> int:
        return int(len(self.area))

    @property
    def total_area(self) -> float:
        return float(self.area.sum())


def poly_index(mesh: NavMesh) -> PolyIndex:
    order = mesh.tile_order()
    counts = [len(mesh.tiles[i].polys) for i in order]
    return PolyIndex(order, np.concatenate([[0], np.cumsum(counts)]).astype(np.int64))


def tile_triangles(tile: NavMeshTile) -> tuple[np.ndarray, np.ndarray]:
    """(T, 3, 3) float64 detail triangles of the tile's ground polygons and (T,) their polygon index.
    A detail index below the polygon's vertex count names a polygon vertex, above it a detail vertex
    (`vert_base + index - vert_count`), as Detour reads them."""
    p = tile.polys
    g = np.flatnonzero((p["area_type"] >> 6) == POLY_GROUND)
    if len(g) == 0:
        return np.zeros((0, 3, 3)), np.zeros(0, np.int64)
    d = tile.detail_meshes[g]
    tc = d["tri_count"].astype(np.int64)
    owner_local = np.repeat(np.arange(len(g)), tc)
    rows = np.repeat(d["tri_base"].astype(np.int64) - np.cumsum(tc) + tc, tc) + np.arange(int(tc.sum()))
    idx = tile.detail_tris[rows, :3].astype(np.int64)  # (T, 3)
    nv = p["vert_count"][g].astype(np.int64)[owner_local][:, None]
    pverts = p["verts"][g].astype(np.int64)[owner_local]  # (T, 6)
    poly_v = np.take_along_axis(pverts, np.minimum(idx, MAX_VERTS_PER_POLY - 1), axis=1)
    detail_v = d["vert_base"].astype(np.int64)[owner_local][:, None] + idx - nv
    from_poly = idx < nv
    pts = np.where(
        from_poly[..., None],
        tile.verts[np.where(from_poly, poly_v, 0)],
        tile.detail_verts[np.where(from_poly, 0, detail_v)] if len(tile.detail_verts) else 0.0,
    )
    return pts.astype(np.float64), g[owner_local]


def triangle_areas(tris: np.ndarray) -> np.ndarray:
    """3D area of each (3, 3) triangle (habitat: |(v1 - v0) x (v2 - v1)| / 2)."""
    return 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 1]), axis=1)


def navmesh_triangles(
    mesh: NavMesh, islands: Islands | None = None, walkable_only: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """(T, 3, 3) detail triangles of the whole navmesh and (T,) global polygon ids (`poly_index`);
    with `walkable_only`, only polygons habitat can walk on (`Islands.walkable`)."""
    pidx = poly_index(mesh)
    keep = (islands or compute_islands(mesh)).walkable if walkable_only else None
    all_t, all_p = [], []
    for i, ti in enumerate(pidx.order):
        t, owner = tile_triangles(mesh.tiles[ti])
        gid = owner + pidx.base[i]
        if keep is not None:
            sel = keep[gid]
            t, gid = t[sel], gid[sel]
        all_t.append(t)
        all_p.append(gid)
    if not all_t:
        return np.zeros((0, 3, 3)), np.zeros(0, np.int64)
    return np.concatenate(all_t), np.concatenate(all_p)


# ------------------------------------------------------------------------------------ connectivity


def _slab(va: np.ndarray, vb: np.ndarray, side: int) -> tuple[float, tuple[float, float], tuple[float, float]]:
    """(border coordinate, (min along the border, y), (max along the border, y)) of a portal edge
    (Detour's getSlabCoord / calcSlabEndPoints)."""
    if side in (0, 4):
        pos, a, b = float(va[0]), (float(va[2]), float(va[1])), (float(vb[2]), float(vb[1]))
    else:
        pos, a, b = float(va[2]), (float(va[0]), float(va[1])), (float(vb[0]), float(vb[1]))
    return (pos, a, b) if a[0] < b[0] else (pos, b, a)


def _overlap_slabs(amin, amax, bmin, bmax, px: float, py: float) -> bool:  # noqa: ANN001
    """Detour's overlapSlabs: the two border segments overlap along the border and in height."""
    minx = max(amin[0] + px, bmin[0] + px)
    maxx = min(amax[0] - px, bmax[0] - px)
    if minx > maxx:
        return False
    ad = (amax[1] - amin[1]) / (amax[0] - amin[0]) if amax[0] != amin[0] else 0.0
    ak = amin[1] - ad * amin[0]
    bd = (bmax[1] - bmin[1]) / (bmax[0] - bmin[0]) if bmax[0] != bmin[0] else 0.0
    bk = bmin[1] - bd * bmin[0]
    dmin = (bd * minx + bk) - (ad * minx + ak)
    dmax = (bd * maxx + bk) - (ad * maxx + ak)
    if dmin * dmax < 0:
        return True
    thr = (py * 2) ** 2
    return dmin * dmin <= thr or dmax * dmax <= thr


_SIDE_STEP = {0: (1, 0), 1: (1, 1), 2: (0, 1), 3: (-1, 1), 4: (-1, 0), 5: (-1, -1), 6: (0, -1), 7: (1, -1)}


def _portals(tile: NavMeshTile) -> list[tuple[int, int, np.ndarray, np.ndarray, int]]:
    """(polygon, side, va, vb, edge) of every portal edge of a tile."""
    out = []
    for k, p in enumerate(tile.polys):
        n = int(p["vert_count"])
        for j in range(n):
            nei = int(p["neis"][j])
            if nei & EXT_LINK:
                out.append((k, nei & 0xFF, tile.verts[p["verts"][j]], tile.verts[p["verts"][(j + 1) % n]], j))
    return out


@dataclass
class Links:
    """Detour's links: source and target global polygon ids, the source polygon's edge they cross, and the
    part of that edge (tmin..tmax of 0..1, Detour's bmin / bmax over 255) the link spans."""

    src: np.ndarray
    dst: np.ndarray
    edge: np.ndarray
    tmin: np.ndarray
    tmax: np.ndarray


def links(mesh: NavMesh, pidx: PolyIndex | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Detour's links as (source, target) global polygon ids (`portal_links`)."""
    ln = portal_links(mesh, pidx)
    return ln.src, ln.dst


def portal_links(mesh: NavMesh, pidx: PolyIndex | None = None) -> Links:
    """Detour's links: internal neighbours (`neis`), then polygons across tile borders matched as
    `dtNavMesh::connectExtLinks` does (with the overlap it clamps the portal to)."""
    pidx = pidx or poly_index(mesh)
    src: list[np.ndarray] = []
    dst: list[np.ndarray] = []
    edges: list[np.ndarray] = []
    slot = {ti: i for i, ti in enumerate(pidx.order)}
    for i, ti in enumerate(pidx.order):
        p = mesh.tiles[ti].polys
        used = np.arange(MAX_VERTS_PER_POLY)[None, :] < p["vert_count"][:, None]
        ground = ((p["area_type"] >> 6) == POLY_GROUND)[:, None]
        nei = p["neis"].astype(np.int64)
        k, j = np.nonzero(used & ground & (nei != 0) & ((nei & EXT_LINK) == 0))
        src.append(k + pidx.base[i])
        dst.append(nei[k, j] - 1 + pidx.base[i])
        edges.append(j)
    at: dict[tuple[int, int], list[int]] = {}
    for ti, t in enumerate(mesh.tiles):
        at.setdefault((t.x, t.y), []).append(ti)
    portals = {ti: _portals(mesh.tiles[ti]) for ti in range(len(mesh.tiles))} if len(mesh.tiles) > 1 else {}
    ext_s: list[int] = []
    ext_d: list[int] = []
    ext_e: list[int] = []
    ext_t: list[tuple[float, float]] = []
    for ti, t in enumerate(mesh.tiles if len(mesh.tiles) > 1 else []):
        base = int(pidx.base[slot[ti]])
        for k, side, va, vb, j in portals[ti]:
            dx, dy = _SIDE_STEP.get(side, (0, 0))
            targets = [u for u in at.get((t.x + dx, t.y + dy), []) if u != ti]
            targets += [u for u in at.get((t.x, t.y), []) if u != ti and (dx, dy) != (0, 0)]
            apos, amin, amax = _slab(va, vb, side)
            opposite = (side + 4) & 7
            for u in targets:
                tu = mesh.tiles[u]
                seen = set()
                for m, s2, vc, vd, _ in portals[u]:
                    if s2 != opposite or m in seen:
                        continue
                    bpos, bmin, bmax = _slab(vc, vd, side)
                    if abs(apos - bpos) > 0.01 or not _overlap_slabs(amin, amax, bmin, bmax, 0.01, tu.walkable_climb):
                        continue
                    seen.add(m)  # findConnectingPolys takes one edge per polygon
                    ext_s.append(base + k)
                    ext_d.append(int(pidx.base[slot[u]]) + m)
                    ext_e.append(j)
                    # the overlap along the border, as a fraction of this edge (connectExtLinks' bmin / bmax)
                    axis = 2 if side in (0, 4) else 0
                    span = float(vb[axis] - va[axis])
                    lo, hi = max(amin[0], bmin[0]), min(amax[0], bmax[0])
                    t0, t1 = ((lo - va[axis]) / span, (hi - va[axis]) / span) if span else (0.0, 1.0)
                    t0, t1 = (round(min(max(t, 0.0), 1.0) * 255) / 255 for t in sorted((t0, t1)))
                    ext_t.append((t0, t1))
    src.append(np.asarray(ext_s, np.int64))
    dst.append(np.asarray(ext_d, np.int64))
    edges.append(np.asarray(ext_e, np.int64))
    n_int = sum(len(e) for e in edges[:-1])
    tt = np.asarray(ext_t, np.float64).reshape(-1, 2)
    return Links(
        src=np.concatenate(src).astype(np.int64),
        dst=np.concatenate(dst).astype(np.int64),
        edge=np.concatenate(edges).astype(np.int64),
        tmin=np.concatenate([np.zeros(n_int), tt[:, 0]]),
        tmax=np.concatenate([np.ones(n_int), tt[:, 1]]),
    )


def compute_islands(mesh: NavMesh) -> Islands:
    """habitat-sim's IslandSystem + removeZeroAreaPolys for this navmesh (see the module docstring)."""
    pidx = poly_index(mesh)
    n = pidx.count
    flags = np.zeros(n, np.int64)
    ground = np.zeros(n, bool)
    parea = np.zeros(n)
    vsum = np.zeros((n, 3))
    vcount = np.zeros(n)
    pverts: list[np.ndarray] = []  # (n, 6, 3) polygon vertices, unused slots nan
    for i, ti in enumerate(pidx.order):
        t = mesh.tiles[ti]
        base = int(pidx.base[i])
        sl = slice(base, base + len(t.polys))
        flags[sl] = t.polys["flags"]
        ground[sl] = (t.polys["area_type"] >> 6) == POLY_GROUND
        tris, owner = tile_triangles(t)
        np.add.at(parea, owner + base, triangle_areas(tris))
        used = np.arange(MAX_VERTS_PER_POLY)[None, :] < t.polys["vert_count"][:, None]
        v = (
            t.verts[np.where(used, t.polys["verts"], 0)].astype(np.float64)
            if len(t.verts)
            else np.zeros((len(t.polys), MAX_VERTS_PER_POLY, 3))
        )
        v[~used] = np.nan
        pverts.append(v)
        vsum[sl] = np.nansum(v, axis=1)
        vcount[sl] = used.sum(axis=1)
    allv = np.concatenate(pverts) if pverts else np.zeros((0, MAX_VERTS_PER_POLY, 3))
    src, dst = links(mesh, pidx)
    passes = (flags & FLAG_WALK) != 0
    island = _components(n, src, dst, ground, passes)
    m = int(island.max()) + 1 if n and island.max() >= 0 else 0
    on = island >= 0
    cnt = np.bincount(island[on], weights=vcount[on], minlength=m)
    centroid = np.stack([np.bincount(island[on], weights=vsum[on, k], minlength=m) for k in range(3)], 1)
    centroid /= np.maximum(cnt, 1)[:, None]
    dist = np.linalg.norm(allv - centroid[np.maximum(island, 0)][:, None, :], axis=2)
    radius = np.zeros(m)
    np.maximum.at(radius, island[on], np.nanmax(np.where(np.isnan(dist), -np.inf, dist), axis=1)[on])
    walkable = ground & passes & (parea >= ZERO_AREA)
    area = np.zeros(m)
    np.add.at(area, island[walkable], parea[walkable])
    return Islands(poly_island=island, area=area, radius=radius, poly_area=parea, walkable=walkable)


def _components(n: int, src: np.ndarray, dst: np.ndarray, ground: np.ndarray, passes: np.ndarray) -> np.ndarray:
    """Island of every polygon as habitat's expandFrom assigns them: polygons in id order, an unvisited
    one starts an island, a linked neighbour joins when it passes the filter (-1: off-mesh links)."""
    keep = ground[src] & ground[dst] & passes[dst]
    src, dst = src[keep], dst[keep]
    island = np.full(n, -1, np.int32)
    if passes[ground].all():
        # everyone passes: plain connected components (links are symmetric), numbered by first polygon
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components

        g = coo_matrix((np.ones(len(src)), (src, dst)), shape=(n, n))
        _, lab = connected_components(g, directed=True, connection="weak")
        gl = lab[ground]
        _, first = np.unique(gl, return_index=True)
        order = np.argsort(first, kind="stable")
        remap = np.empty(len(first), np.int32)
        remap[order] = np.arange(len(first), dtype=np.int32)
        uniq = np.unique(gl)
        island[ground] = remap[np.searchsorted(uniq, gl)]
        return island
    adj: list[list[int]] = [[] for _ in range(n)]
    for a, b in zip(src.tolist(), dst.tolist(), strict=True):
        adj[a].append(b)
    label = 0
    for start in range(n):
        if island[start] >= 0 or not ground[start]:
            continue
        island[start] = label
        stack = [start]
        while stack:
            q = stack.pop()
            for r in adj[q]:
                if island[r] < 0:
                    island[r] = label
                    stack.append(r)
        label += 1
    return island
