"""Shortest paths on a habitat navmesh's polygons, as habitat-sim's `PathFinder` computes them.

Why: habitat's geodesic distance is Detour's answer (snap both ends with `findNearestPoly`, an A* over
polygons with `findPath`, then the funnel of `findStraightPath`, summed in 3D). Doing the same here
gives habitat's numbers rather than a grid's approximation of them, and a query to a new goal costs an
A* over a few hundred polygons (microseconds) instead of a distance field over the whole floor.
Navigability of a point follows the polygons too (`is_navigable`): a point over a walkable polygon
within `max_y_delta` of its surface is navigable, as habitat's `is_navigable` says.

Follows recastnavigation (zlib licence) as habitat builds it: the A* node of a polygon sits at the
midpoint of the portal it was first reached through, costs are straight-line distances, the heuristic
is 0.999 x the distance to the end; the funnel works in x/z with the portal vertices' heights.
Off-mesh connections (habitat writes none) are ignored.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from ovon.lru import LRU
from ovon.sim.heap import heap_pop, heap_push
from ovon.sim.navmesh.format import MAX_VERTS_PER_POLY, NavMesh
from ovon.sim.navmesh.polys import compute_islands, poly_index, portal_links, tile_triangles

POLY_PICK_EXTENT = (2.0, 4.0, 2.0)  # m: half-extents of habitat's findNearestPoly box (PathFinder.cpp)
MAX_Y_DELTA = 0.5  # m: habitat's is_navigable default
ON_POLYGON_XZ = 1e-2  # m: habitat's is_navigable: how far (x/z) the snapped point may lie from the point
H_SCALE = 0.999  # Detour's findPath heuristic scale
_EPS = 1e-3  # m: Detour's start-on-portal test in findStraightPath
_EQ = (1.0 / 16384.0) ** 2  # dtVequal


def on_polygon(p: np.ndarray, snapped: np.ndarray) -> bool:
    """Whether a point's snap moved it at most ON_POLYGON_XZ in x/z (habitat's test of being on the mesh)."""
    return math.hypot(float(p[0] - snapped[0]), float(p[2] - snapped[2])) <= ON_POLYGON_XZ


@dataclass
class PolyGraph:
    """A navmesh's walkable polygons and links as flat arrays (what the kernels read)."""

    verts: np.ndarray  # (P, 6, 3) polygon vertices (unused slots repeat the last)
    nv: np.ndarray  # (P,) vertex count
    walkable: np.ndarray  # (P,) bool: habitat's filter (WALK flag, area >= 1e-5 m^2)
    island: np.ndarray  # (P,) habitat's island id
    bmin: np.ndarray  # (P, 3) bounds of the polygon and its detail surface
    bmax: np.ndarray
    tri_start: np.ndarray  # (P + 1,) detail triangles of polygon p: tris[tri_start[p]:tri_start[p + 1]]
    tris: np.ndarray  # (T, 3, 3)
    link_start: np.ndarray  # (P + 1,) links of polygon p: link_*[link_start[p]:link_start[p + 1]]
    link_src: np.ndarray  # (L,) source polygon
    link_edge: np.ndarray  # (L,) the source polygon's edge the link crosses
    link_to: np.ndarray  # (L,) target polygon
    link_left: np.ndarray  # (L, 3) portal end points as Detour's getPortalPoints returns them
    link_right: np.ndarray  # (L, 3)
    climb: float  # walkable climb (m): how far above a polygon a point still counts as over it

    @property
    def count(self) -> int:
        return int(len(self.nv))


def poly_graph(mesh: NavMesh) -> PolyGraph:
    pidx = poly_index(mesh)
    n = pidx.count
    verts = np.zeros((n, MAX_VERTS_PER_POLY, 3))
    nv = np.zeros(n, np.int64)
    tri_list, owner_list = [], []
    for i, ti in enumerate(pidx.order):
        t = mesh.tiles[ti]
        base = int(pidx.base[i])
        cnt = t.polys["vert_count"].astype(np.int64)
        nv[base : base + len(t.polys)] = cnt
        if len(t.polys) and len(t.verts):
            idx = t.polys["verts"].astype(np.int64)
            last = np.take_along_axis(idx, np.maximum(cnt - 1, 0)[:, None], axis=1)
            idx = np.where(np.arange(MAX_VERTS_PER_POLY)[None, :] < cnt[:, None], idx, last)
            verts[base : base + len(t.polys)] = t.verts[idx]
        tr, owner = tile_triangles(t)
        tri_list.append(tr)
        owner_list.append(owner + base)
    tris = np.concatenate(tri_list) if tri_list else np.zeros((0, 3, 3))
    owner = np.concatenate(owner_list) if owner_list else np.zeros(0, np.int64)
    order = np.argsort(owner, kind="stable")
    tris, owner = tris[order], owner[order]
    tri_start = np.searchsorted(owner, np.arange(n + 1)).astype(np.int64)
    isl = compute_islands(mesh)
    ln = portal_links(mesh, pidx)
    keep = isl.walkable[ln.src] & isl.walkable[ln.dst]
    src, dst, edge = ln.src[keep], ln.dst[keep], ln.edge[keep]
    tmin, tmax = ln.tmin[keep], ln.tmax[keep]
    o = np.lexsort((np.arange(len(src)), src))  # by source, Detour's link order kept within a polygon
    src, dst, edge, tmin, tmax = src[o], dst[o], edge[o], tmin[o], tmax[o]
    v0 = verts[src, edge]
    v1 = verts[src, (edge + 1) % np.maximum(nv[src], 1)]
    left = v0 + (v1 - v0) * tmin[:, None]
    right = v0 + (v1 - v0) * tmax[:, None]
    used = np.arange(MAX_VERTS_PER_POLY)[None, :] < nv[:, None]
    big = np.where(used[..., None], verts, np.inf)
    small = np.where(used[..., None], verts, -np.inf)
    bmin, bmax = big.min(axis=1), small.max(axis=1)
    if len(tris):
        np.minimum.at(bmin, owner, tris.min(axis=1))
        np.maximum.at(bmax, owner, tris.max(axis=1))
    climb = max((t.walkable_climb for t in mesh.tiles), default=0.0)
    return PolyGraph(
        verts=verts,
        nv=nv,
        walkable=isl.walkable.copy(),
        island=isl.poly_island.astype(np.int64),
        bmin=bmin,
        bmax=bmax,
        tri_start=tri_start,
        tris=tris,
        link_start=np.searchsorted(src, np.arange(n + 1)).astype(np.int64),
        link_src=src.astype(np.int64),
        link_edge=edge.astype(np.int64),
        link_to=dst.astype(np.int64),
        link_left=left,
        link_right=right,
        climb=float(climb),
    )


# ----------------------------------------------------------------------------------------------
# kernels
# ----------------------------------------------------------------------------------------------


@njit(cache=True)
def _tri_area2d(a, b, c):  # noqa: ANN001, ANN202 - dtTriArea2D
    return (c[0] - a[0]) * (b[2] - a[2]) - (b[0] - a[0]) * (c[2] - a[2])


@njit(cache=True)
def _inside(p, verts, n):  # noqa: ANN001, ANN202 - dtPointInPolygon (x/z)
    c = False
    j = n - 1
    for i in range(n):
        vi, vj = verts[i], verts[j]
        if ((vi[2] > p[2]) != (vj[2] > p[2])) and (p[0] < (vj[0] - vi[0]) * (p[2] - vi[2]) / (vj[2] - vi[2]) + vi[0]):
            c = not c
        j = i
    return c


@njit(cache=True)
def _seg_t(p, a, b):  # noqa: ANN001, ANN202 - dtDistancePtSegSqr2D: (squared distance, t)
    dx, dz = b[0] - a[0], b[2] - a[2]
    d = dx * dx + dz * dz
    t = 0.0
    if d > 0:
        t = ((p[0] - a[0]) * dx + (p[2] - a[2]) * dz) / d
    t = min(max(t, 0.0), 1.0)
    ex, ez = a[0] + t * dx - p[0], a[2] + t * dz - p[2]
    return ex * ex + ez * ez, t


@njit(cache=True)
def _height(p, tris, t0, t1):  # noqa: ANN001, ANN202 - getPolyHeight over the detail triangles
    best, h = np.inf, np.nan
    for k in range(t0, t1):
        a, b, c = tris[k, 0], tris[k, 1], tris[k, 2]
        v0x, v0z = c[0] - a[0], c[2] - a[2]
        v1x, v1z = b[0] - a[0], b[2] - a[2]
        v2x, v2z = p[0] - a[0], p[2] - a[2]
        den = v0x * v1z - v0z * v1x
        if abs(den) < 1e-12:
            continue
        u = (v1z * v2x - v1x * v2z) / den
        v = (v0x * v2z - v0z * v2x) / den
        out = max(-u, 0.0) + max(-v, 0.0) + max(u + v - 1.0, 0.0)  # 0 inside the triangle
        if out < best:
            best = out
            h = a[1] + (c[1] - a[1]) * u + (b[1] - a[1]) * v
            if out <= 1e-6:
                break
    return h


@njit(cache=True)
def _closest(g_verts, g_nv, tris, tri_start, poly, p, out):  # noqa: ANN001, ANN202
    """closestPointOnPoly: the point over the polygon at its surface height, else the nearest point of its
    boundary (x/z distance, interpolated in 3D). Returns whether p is over the polygon."""
    n = g_nv[poly]
    verts = g_verts[poly]
    if _inside(p, verts, n):
        out[0], out[2] = p[0], p[2]
        h = _height(p, tris, tri_start[poly], tri_start[poly + 1])
        out[1] = p[1] if np.isnan(h) else h
        return True
    best, bt, bi = np.inf, 0.0, 0
    for i in range(n):
        d, t = _seg_t(p, verts[i], verts[(i + 1) % n])
        if d < best:
            best, bt, bi = d, t, i
    a, b = verts[bi], verts[(bi + 1) % n]
    for k in range(3):
        out[k] = a[k] + (b[k] - a[k]) * bt
    return False


BUCKET = 1.0  # m: side of the x/z buckets that index polygons for findNearestPoly


def _buckets(bmin: np.ndarray, bmax: np.ndarray, walkable: np.ndarray) -> tuple[np.ndarray, ...]:
    """(origin x/z, shape, CSR start, polygon ids): every walkable polygon listed in each BUCKET it overlaps."""
    w = np.flatnonzero(walkable)
    if len(w) == 0:
        return np.zeros(2), np.ones(2, np.int64), np.zeros(2, np.int64), np.zeros(0, np.int64)
    org = bmin[w][:, [0, 2]].min(axis=0)
    lo = np.floor((bmin[w][:, [0, 2]] - org) / BUCKET).astype(np.int64)
    hi = np.floor((bmax[w][:, [0, 2]] - org) / BUCKET).astype(np.int64)
    shape = hi.max(axis=0) + 1
    cells, owners = [], []
    for i, q in enumerate(w):
        xs, zs = np.arange(lo[i, 0], hi[i, 0] + 1), np.arange(lo[i, 1], hi[i, 1] + 1)
        ids = (xs[:, None] * shape[1] + zs[None, :]).ravel()
        cells.append(ids)
        owners.append(np.full(len(ids), q, np.int64))
    cell = np.concatenate(cells) if cells else np.zeros(0, np.int64)
    owner = np.concatenate(owners) if owners else np.zeros(0, np.int64)
    o = np.lexsort((owner, cell))
    start = np.searchsorted(cell[o], np.arange(int(shape[0] * shape[1]) + 1)).astype(np.int64)
    return org.astype(np.float64), shape.astype(np.int64), start, owner[o]


@njit(cache=True)
def _nearest(g_verts, g_nv, walk, bmin, bmax, tris, tri_start, climb, p, ext, out, buckets):  # noqa: ANN001, ANN202
    """findNearestPoly within p +- ext: (polygon or -1, over it). Polygons are tried in id order, so the
    answer does not depend on the buckets."""
    org, shape, start, ids = buckets
    best_d, best, over = np.inf, -1, False
    tmp = np.empty(3)
    x0 = max(int(math.floor((p[0] - ext[0] - org[0]) / BUCKET)), 0)
    x1 = min(int(math.floor((p[0] + ext[0] - org[0]) / BUCKET)), shape[0] - 1)
    z0 = max(int(math.floor((p[2] - ext[2] - org[1]) / BUCKET)), 0)
    z1 = min(int(math.floor((p[2] + ext[2] - org[1]) / BUCKET)), shape[1] - 1)
    if x1 < x0 or z1 < z0:
        return -1, False
    # the first polygon (in id order) that p is over, within climb, has distance 0 and nothing beats it; such
    # a polygon is listed in p's own bucket (ids sorted), so look there first
    bx = int(math.floor((p[0] - org[0]) / BUCKET))
    bz = int(math.floor((p[2] - org[1]) / BUCKET))
    if 0 <= bx < shape[0] and 0 <= bz < shape[1]:
        b = bx * shape[1] + bz
        for k in range(start[b], start[b + 1]):
            q = ids[k]
            if _closest(g_verts, g_nv, tris, tri_start, q, p, tmp) and abs(p[1] - tmp[1]) <= climb:
                out[:] = tmp
                return q, True
    m = 0
    for bx in range(x0, x1 + 1):
        for bz in range(z0, z1 + 1):
            b = bx * shape[1] + bz
            m += start[b + 1] - start[b]
    cand = np.empty(m, np.int64)
    m = 0
    for bx in range(x0, x1 + 1):
        for bz in range(z0, z1 + 1):
            b = bx * shape[1] + bz
            for k in range(start[b], start[b + 1]):
                cand[m] = ids[k]
                m += 1
    cand.sort()
    prev = -1
    for q in cand:
        if q == prev:
            continue
        prev = q
        if (
            bmin[q, 0] > p[0] + ext[0]
            or bmax[q, 0] < p[0] - ext[0]
            or bmin[q, 1] > p[1] + ext[1]
            or bmax[q, 1] < p[1] - ext[1]
            or bmin[q, 2] > p[2] + ext[2]
            or bmax[q, 2] < p[2] - ext[2]
        ):
            continue
        pos_over = _closest(g_verts, g_nv, tris, tri_start, q, p, tmp)
        if pos_over:
            d = abs(p[1] - tmp[1]) - climb
            d = d * d if d > 0 else 0.0
        else:
            d = (p[0] - tmp[0]) ** 2 + (p[1] - tmp[1]) ** 2 + (p[2] - tmp[2]) ** 2
        if d < best_d:
            best_d, best, over = d, q, pos_over
            out[:] = tmp
    return best, over


@njit(cache=True)
def _dist(a, b):  # noqa: ANN001, ANN202
    return math.sqrt((a[0] - b[0]) ** 2 + (a[1] - b[1]) ** 2 + (a[2] - b[2]) ** 2)


@njit(cache=True)
def _astar(
    link_start,
    link_src,
    link_to,
    left,
    right,
    n,
    start,
    end,
    sp,
    ep,
    parent_link,
    node_pos,
    cost,
    total,
    state,
    heap_k,
    heap_v,
):  # noqa: ANN001, ANN202 - fmt: skip
    """Detour's findPath over polygons; fills parent_link; returns whether `end` was reached. `heap_k` /
    `heap_v` are scratch (the PathFinder's, so a query allocates nothing; a copy grows if they fill)."""
    for q in range(n):
        state[q] = 0  # 0 new, 1 open, 2 closed
    node_pos[start] = sp
    cost[start] = 0.0
    total[start] = _dist(sp, ep) * H_SCALE
    parent_link[start] = -1
    state[start] = 1
    size = heap_push(heap_k, heap_v, 0, total[start], start)
    while size > 0:
        # the smallest total; lazy deletion: skip entries that are no longer the node's total
        k, best, size = heap_pop(heap_k, heap_v, size)
        if state[best] != 1 or k != total[best]:
            continue
        state[best] = 2
        if best == end:
            return True
        par = link_src[parent_link[best]] if parent_link[best] >= 0 else -1
        for li in range(link_start[best], link_start[best + 1]):
            nb = link_to[li]
            if nb == par:
                continue
            if state[nb] == 0:
                for d in range(3):
                    node_pos[nb, d] = 0.5 * (left[li, d] + right[li, d])
            if nb == end:
                cst = cost[best] + _dist(node_pos[best], node_pos[nb]) + _dist(node_pos[nb], ep)
                tot = cst
            else:
                cst = cost[best] + _dist(node_pos[best], node_pos[nb])
                tot = cst + _dist(node_pos[nb], ep) * H_SCALE
            if state[nb] != 0 and tot >= total[nb]:
                continue
            cost[nb], total[nb], state[nb] = cst, tot, 1
            parent_link[nb] = li
            if size == len(heap_k):
                heap_k = np.concatenate((heap_k, np.empty(size)))
                heap_v = np.concatenate((heap_v, np.empty(size, np.int64)))
            size = heap_push(heap_k, heap_v, size, tot, nb)
    return False


@njit(cache=True)
def _append(pts, npts, p):  # noqa: ANN001, ANN202
    """Add a straight-path point unless it repeats the last one (dtVequal); grows the array."""
    if ((pts[npts - 1] - p) ** 2).sum() < _EQ:
        return pts, npts
    if npts == len(pts):
        pts = np.concatenate((pts, np.empty((len(pts), 3))))
    pts[npts] = p
    return pts, npts + 1


@njit(cache=True)
def _straight(links, left, right, sp, ep):  # noqa: ANN001, ANN202
    """findStraightPath's funnel through the portals `links` (path order) from sp to ep: (K, 3) points."""
    m = len(links)
    pts = np.empty((m + 2, 3))
    npts = 1
    pts[0] = sp
    apex = sp.copy()
    pl, pr = sp.copy(), sp.copy()
    ai, li_, ri = 0, 0, 0
    i = 0
    while i < m + 1:
        if i < m:
            lft, rgt = left[links[i]], right[links[i]]
            if i == 0 and _seg_t(apex, lft, rgt)[0] < _EPS * _EPS:
                i += 1
                continue
        else:
            lft, rgt = ep, ep
        restart = False
        if _tri_area2d(apex, pr, rgt) <= 0.0:
            if ((apex - pr) ** 2).sum() < _EQ or _tri_area2d(apex, pl, rgt) > 0.0:
                pr = rgt.copy()
                ri = i
            else:
                apex = pl.copy()
                ai = li_
                pts, npts = _append(pts, npts, apex)
                pl, pr = apex.copy(), apex.copy()
                li_, ri = ai, ai
                i = ai + 1
                restart = True
        if not restart and _tri_area2d(apex, pl, lft) >= 0.0:
            if ((apex - pl) ** 2).sum() < _EQ or _tri_area2d(apex, pr, lft) < 0.0:
                pl = lft.copy()
                li_ = i
            else:
                apex = pr.copy()
                ai = ri
                pts, npts = _append(pts, npts, apex)
                pl, pr = apex.copy(), apex.copy()
                li_, ri = ai, ai
                i = ai + 1
                restart = True
        if not restart:
            i += 1
    if npts == 1:  # start and end coincide: habitat still returns both
        pts[1] = ep
        npts = 2
    else:
        pts, npts = _append(pts, npts, ep)
    return pts[:npts]


@njit(cache=True)
def _chain(link_src, parent_link, end):  # noqa: ANN001, ANN202
    """The links from the start polygon to `end`, in path order."""
    m = 0
    q = end
    while parent_link[q] >= 0:
        m += 1
        q = link_src[parent_link[q]]
    out = np.empty(m, np.int64)
    q = end
    for i in range(m - 1, -1, -1):
        out[i] = parent_link[q]
        q = link_src[out[i]]
    return out


@njit(cache=True)
def _snap_goals(goals, g_verts, g_nv, walk, bmin, bmax, tris, tri_start, climb, ext, buckets):  # noqa: ANN001, ANN202
    """Each goal's nearest polygon (-1: none in the pick box) and snapped point, as findNearestPoly gives."""
    k = len(goals)
    snapped = np.empty((k, 3))
    polys = np.empty(k, np.int64)
    for j in range(k):
        polys[j], _ = _nearest(
            g_verts, g_nv, walk, bmin, bmax, tris, tri_start, climb, goals[j], ext, snapped[j], buckets
        )
    return polys, snapped


@njit(cache=True)
def _multi(
    a,
    polys,
    snapped,
    g_verts,
    g_nv,
    walk,
    island,
    bmin,
    bmax,
    tris,
    tri_start,
    climb,
    ext,
    link_start,
    link_src,
    link_to,
    left,
    right,
    parent_link,
    node_pos,
    cost,
    total,
    state,
    buckets,
    heap_k,
    heap_v,
):  # noqa: ANN001, ANN202 - fmt: skip
    """habitat's MultiGoalShortestPath to goals already snapped (`_snap_goals`): snap the start, try goals
    nearest first, skip a goal once its straight-line distance alone is no shorter than the best path;
    inf when none is reachable."""
    sa = np.empty(3)
    pa, _ = _nearest(g_verts, g_nv, walk, bmin, bmax, tris, tri_start, climb, a, ext, sa, buckets)
    best = np.inf
    if pa < 0:
        return best
    k = len(polys)
    gap = np.empty(k)
    for j in range(k):
        gap[j] = _dist(snapped[j], sa) if polys[j] >= 0 else np.inf
    n = len(g_nv)
    for j in np.argsort(gap, kind="mergesort"):
        pb = polys[j]
        if pb < 0 or gap[j] >= best or island[pb] != island[pa]:
            continue
        sb = snapped[j]
        if not _astar(link_start, link_src, link_to, left, right, n, pa, pb, sa, sb, parent_link, node_pos, cost,
                      total, state, heap_k, heap_v):  # fmt: skip
            continue
        pts = _straight(_chain(link_src, parent_link, pb), left, right, sa, sb)
        length = 0.0
        for i in range(len(pts) - 1):
            length += _dist(pts[i], pts[i + 1])
        best = min(best, length)
    return best


@njit(cache=True)
def _query(
    a,
    goals,
    g_verts,
    g_nv,
    walk,
    island,
    bmin,
    bmax,
    tris,
    tri_start,
    climb,
    ext,
    link_start,
    link_src,
    link_to,
    left,
    right,
    parent_link,
    node_pos,
    cost,
    total,
    state,
    buckets,
    heap_k,
    heap_v,
):  # noqa: ANN001, ANN202 - fmt: skip
    """A one-off multi-goal query: `_snap_goals` and `_multi` in one call (one dispatch from Python)."""
    polys, snapped = _snap_goals(goals, g_verts, g_nv, walk, bmin, bmax, tris, tri_start, climb, ext, buckets)
    return _multi(
        a, polys, snapped, g_verts, g_nv, walk, island, bmin, bmax, tris, tri_start, climb, ext,
        link_start, link_src, link_to, left, right, parent_link, node_pos, cost, total, state, buckets, heap_k, heap_v,
    )  # fmt: skip


@njit(cache=True)
def _move_along(g_verts, g_nv, link_start, link_edge, link_to, tris, tri_start, start_poly, sp, ep):  # noqa: ANN001, ANN202
    """Detour's moveAlongSurface, then the surface height (habitat's try_step): a breadth-first walk over
    the polygons within reach of the segment sp -> ep; the end point if a visited polygon holds it, else
    the nearest point (x/z) on a wall edge of the visited polygons, so a blocked move slides along the wall."""
    n = len(g_nv)
    seen = np.zeros(n, np.bool_)
    queue = np.empty(n, np.int64)
    head, tail = 0, 1
    queue[0] = start_poly
    seen[start_poly] = True
    search = 0.5 * (sp + ep)
    rad = 0.5 * math.sqrt((sp[0] - ep[0]) ** 2 + (sp[1] - ep[1]) ** 2 + (sp[2] - ep[2]) ** 2) + 0.001
    best_pos = sp.copy()
    best_d = np.inf
    best_poly = start_poly
    while head < tail:
        cur = queue[head]
        head += 1
        nv = g_nv[cur]
        verts = g_verts[cur]
        if _inside(ep, verts, nv):
            best_poly = cur
            best_pos = ep.copy()
            break
        j = nv - 1
        for i in range(nv):
            wall = True
            for li in range(link_start[cur], link_start[cur + 1]):
                if link_edge[li] != j:
                    continue
                wall = False
                nb = link_to[li]
                if seen[nb]:
                    continue
                if _seg_t(search, verts[j], verts[i])[0] > rad * rad:
                    continue
                seen[nb] = True
                queue[tail] = nb
                tail += 1
            if wall:
                d, t = _seg_t(ep, verts[j], verts[i])
                if d < best_d:
                    best_d = d
                    best_poly = cur
                    for k in range(3):
                        best_pos[k] = verts[j, k] + (verts[i, k] - verts[j, k]) * t
            j = i
    h = _height(best_pos, tris, tri_start[best_poly], tri_start[best_poly + 1])
    if not np.isnan(h):
        best_pos[1] = h
    return best_pos


@njit(cache=True)
def _clip(p0, p1, verts, nv):  # noqa: ANN001, ANN202 - dtIntersectSegmentPoly2D
    """(tmin, tmax, exit edge or -1, whether the segment meets the polygon): the segment p0 -> p1 clipped to a
    convex polygon in x/z; the exit edge j runs from verts[j] to verts[j + 1]."""
    tmin, tmax, seg_max = 0.0, 1.0, -1
    dx, dz = p1[0] - p0[0], p1[2] - p0[2]
    j = nv - 1
    for i in range(nv):
        ex, ez = verts[i, 0] - verts[j, 0], verts[i, 2] - verts[j, 2]
        n = ez * (p0[0] - verts[j, 0]) - ex * (p0[2] - verts[j, 2])
        d = dz * ex - dx * ez
        if abs(d) < 1e-8:
            if n < 0:
                return tmin, tmax, seg_max, False
        else:
            t = n / d
            if d < 0:
                if t > tmin:
                    tmin = t
                    if tmin > tmax:
                        return tmin, tmax, seg_max, False
            elif t < tmax:
                tmax, seg_max = t, j
                if tmax < tmin:
                    return tmin, tmax, seg_max, False
        j = i
    return tmin, tmax, seg_max, True


@njit(cache=True)
def _move_straight(g_verts, g_nv, link_start, link_edge, link_to, left, right, tris, tri_start, start_poly, sp, ep):  # noqa: ANN001, ANN202
    """habitat's try_step_no_sliding: the move goes straight along sp -> ep through the polygons (a Detour
    raycast) and stops where it first meets a wall, at the contact; then the surface height there."""
    cur = start_poly
    t_end = t_in = 0.0  # t_in: where the move entered the current polygon
    for _ in range(len(g_nv)):
        _, tmax, edge, ok = _clip(sp, ep, g_verts[cur], g_nv[cur])
        if not ok:  # rounding at a shared edge: stop where the move entered this polygon
            t_end = t_in
            break
        if edge < 0:  # the end lies in this polygon
            t_end = 1.0
            break
        hx, hz = sp[0] + (ep[0] - sp[0]) * tmax, sp[2] + (ep[2] - sp[2]) * tmax
        nxt = -1
        for li in range(link_start[cur], link_start[cur + 1]):
            if link_edge[li] != edge:
                continue
            # a link across a tile border covers part of the edge only: the hit must lie on its portal
            lx, lz, rx, rz = left[li, 0], left[li, 2], right[li, 0], right[li, 2]
            seg = (rx - lx) ** 2 + (rz - lz) ** 2
            s_on = ((hx - lx) * (rx - lx) + (hz - lz) * (rz - lz)) / seg if seg > 0 else 0.0
            if -1e-4 <= s_on <= 1.0 + 1e-4:
                nxt = link_to[li]
                break
        if nxt < 0:  # a wall: stop at the contact
            t_end = tmax
            break
        cur, t_in, t_end = nxt, tmax, tmax
    out = sp + (ep - sp) * t_end
    h = _height(out, tris, tri_start[cur], tri_start[cur + 1])
    out[1] = sp[1] if np.isnan(h) else h
    return out


# ----------------------------------------------------------------------------------------------
# the finder
# ----------------------------------------------------------------------------------------------


class PathFinder:
    """Habitat's PathFinder queries on one navmesh: snap, is_navigable, find_path, geodesic_distance. Its
    queries share scratch arrays (so they allocate nothing): one thread per PathFinder, as env workers are
    processes."""

    def __init__(self, mesh: NavMesh) -> None:
        self.g = poly_graph(mesh)
        n = self.g.count
        self._parent = np.empty(n, np.int64)
        self._pos = np.empty((n, 3))
        self._cost = np.empty(n)
        self._total = np.empty(n)
        self._state = np.empty(n, np.int64)
        self._ext = np.asarray(POLY_PICK_EXTENT, np.float64)
        self._buckets = _buckets(self.g.bmin, self.g.bmax, self.g.walkable)
        self._heap_k = np.empty(len(self.g.link_src) + n + 16)
        self._heap_v = np.empty(len(self.g.link_src) + n + 16, np.int64)
        g = self.g
        self._snap_args = (
            g.verts, g.nv, g.walkable, g.bmin, g.bmax, g.tris, g.tri_start, g.climb, self._ext, self._buckets,
        )  # fmt: skip
        self._multi_args = (
            g.verts, g.nv, g.walkable, g.island, g.bmin, g.bmax, g.tris, g.tri_start, g.climb, self._ext,
            g.link_start, g.link_src, g.link_to, g.link_left, g.link_right,
            self._parent, self._pos, self._cost, self._total, self._state, self._buckets, self._heap_k, self._heap_v,
        )  # fmt: skip

    def nearest(self, xyz) -> tuple[int, np.ndarray, bool]:
        """(polygon or -1, the snapped point, whether the point is over that polygon)."""
        g = self.g
        out = np.zeros(3)
        p = np.asarray(xyz, np.float64).reshape(3)
        poly, over = _nearest(
            g.verts, g.nv, g.walkable, g.bmin, g.bmax, g.tris, g.tri_start, g.climb, p, self._ext, out, self._buckets
        )
        return int(poly), out, bool(over)

    def snap_point(self, xyz) -> np.ndarray:
        """The nearest navmesh point (habitat's snap_point); nan when no polygon lies within the pick box."""
        poly, out, _ = self.nearest(xyz)
        return out if poly >= 0 else np.full(3, np.nan)

    def is_navigable(self, xyz, max_y_delta: float = MAX_Y_DELTA) -> bool:
        """habitat's is_navigable: the snapped point lies within 1 cm of the point in x/z (over a walkable
        polygon, or on its rim, where a move stopped by a wall ends) and within `max_y_delta` of it in y."""
        p = np.asarray(xyz, np.float64).reshape(3)
        poly, out, _ = self.nearest(p)
        return poly >= 0 and on_polygon(p, out) and abs(out[1] - p[1]) <= max_y_delta

    def try_step(self, start, end) -> np.ndarray:
        """Where a move from start toward end ends on the navmesh, sliding along walls (habitat's try_step):
        the start itself when it is on no polygon."""
        p = np.asarray(start, np.float64).reshape(3)
        poly, snapped, _ = self.nearest(p)
        if poly < 0:
            return p.copy()
        g = self.g
        return _move_along(
            g.verts, g.nv, g.link_start, g.link_edge, g.link_to, g.tris, g.tri_start, poly, snapped,
            np.asarray(end, np.float64).reshape(3),
        )  # fmt: skip

    def try_step_no_sliding(self, start, end) -> np.ndarray:
        """Where a move from start toward end ends when it may not slide (habitat's try_step_no_sliding): along
        the move's own line, at the first wall it meets; the start itself when it is on no polygon."""
        p = np.asarray(start, np.float64).reshape(3)
        poly, snapped, _ = self.nearest(p)
        if poly < 0:
            return p.copy()
        g = self.g
        return _move_straight(
            g.verts, g.nv, g.link_start, g.link_edge, g.link_to, g.link_left, g.link_right, g.tris, g.tri_start,
            poly, snapped, np.asarray(end, np.float64).reshape(3),
        )  # fmt: skip

    def find_path(self, a, b) -> np.ndarray:
        """The straight path (K, 3) from a to b as habitat returns it; (0, 3) when there is none."""
        pa, sa, _ = self.nearest(a)
        pb, sb, _ = self.nearest(b)
        return self._path(pa, sa, pb, sb)

    def _path(self, pa: int, sa: np.ndarray, pb: int, sb: np.ndarray) -> np.ndarray:
        g = self.g
        if pa < 0 or pb < 0 or g.island[pa] != g.island[pb]:
            return np.zeros((0, 3))
        ok = _astar(
            g.link_start, g.link_src, g.link_to, g.link_left, g.link_right, g.count, pa, pb, sa, sb,
            self._parent, self._pos, self._cost, self._total, self._state, self._heap_k, self._heap_v,
        )  # fmt: skip
        if not ok:
            return np.zeros((0, 3))
        return _straight(_chain(g.link_src, self._parent, pb), g.link_left, g.link_right, sa, sb)

    def geodesic_distance(self, a, goals) -> float:
        """Length of the shortest straight path from a to the nearest of `goals` ((3,) or (K, 3)); inf when none
        is reachable. Goals are tried nearest first and skipped once their straight-line distance alone is
        no shorter than the best path (habitat's MultiGoalShortestPath)."""
        a = np.asarray(a, np.float64).reshape(3)
        return float(_query(a, np.asarray(goals, np.float64).reshape(-1, 3), *self._multi_args))

    def distance_to(self, goals) -> GoalDistance:
        """The geodesic distance to the nearest of `goals` as a function of the start, with the goals
        snapped once (habitat's MultiGoalShortestPath caches its requested ends the same way): a metric
        that asks every step pays for the start's snap and the A*s only."""
        g = np.ascontiguousarray(np.asarray(goals, np.float64).reshape(-1, 3))
        polys, snapped = _snap_goals(g, *self._snap_args)
        return GoalDistance(self, polys, snapped)


class GoalDistance:
    """Geodesic distance (m) from a point to the nearest of a fixed goal set on one navmesh: callable."""

    def __init__(self, finder: PathFinder, polys: np.ndarray, snapped: np.ndarray) -> None:
        self.finder, self.polys, self.snapped = finder, polys, snapped

    def __call__(self, xyz) -> float:
        a = np.asarray(xyz, np.float64).reshape(3)
        return float(_multi(a, self.polys, self.snapped, *self.finder._multi_args))


_FINDERS = LRU(16)


def path_finder(path: str) -> PathFinder:
    """The PathFinder of a navmesh file, cached in-process by path, size and modification time: a query
    per step stats the file, it does not read it again."""
    from pathlib import Path

    from ovon.sim.navmesh.format import navmesh_file_bytes, parse_navmesh

    p = Path(path)
    st = p.stat() if p.is_file() else None
    key = (str(p.resolve()), st.st_size, st.st_mtime_ns) if st else (str(p), None, None)
    return _FINDERS.get(key, lambda: PathFinder(parse_navmesh(navmesh_file_bytes(p), str(p))))


def navmesh_surface(nav) -> PathFinder | None:  # noqa: ANN001 - a SceneNav
    """The PathFinder of a scene read from a habitat navmesh (its steps and geodesics follow the polygons),
    None for a scene whose navigability was computed from its triangles."""
    return path_finder(nav.source) if nav.from_navmesh else None
