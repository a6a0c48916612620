"""Build byte-faithful habitat navmesh files from convex polygons, for the navmesh tests.

Polygons are lists of (x, y, z) vertices (3-6, convex). Tiles are laid out on Detour's grid from
`origin` with square tiles of `tile_size`; a polygon edge on its tile's border becomes a portal
(`EXT_LINK | side`), an edge shared with another polygon of the tile an internal neighbour. Detail
meshes are fans; with `bump` a detail vertex is added above (or below) each polygon's centroid, so the
surface the detail mesh describes differs from the polygon's own plane.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ovon.sim.navmesh import NavMesh, NavMeshSettings, NavMeshTile
from ovon.sim.navmesh.format import EXT_LINK, FLAG_WALK, detail_array, poly_array

Poly = Sequence[Sequence[float]]


def _side(a: np.ndarray, b: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> int | None:
    """Detour side (0 +x, 2 +z, 4 -x, 6 -z) of an edge lying on the tile border, else None."""
    eps = 1e-5
    if abs(a[0] - hi[0]) < eps and abs(b[0] - hi[0]) < eps:
        return 0
    if abs(a[2] - hi[1]) < eps and abs(b[2] - hi[1]) < eps:
        return 2
    if abs(a[0] - lo[0]) < eps and abs(b[0] - lo[0]) < eps:
        return 4
    if abs(a[2] - lo[1]) < eps and abs(b[2] - lo[1]) < eps:
        return 6
    return None


def make_tile(
    polys: list[Poly],
    tx: int = 0,
    ty: int = 0,
    origin=(0.0, 0.0, 0.0),
    tile_size: float = 1e3,  # noqa: ANN001
    flags: Sequence[int] | None = None,
    bump: float = 0.0,
    radius: float = 0.1,
    climb: float = 0.2,
    portals: bool = True,
) -> NavMeshTile:
    keyed: dict[tuple[float, float, float], int] = {}
    verts: list[tuple[float, float, float]] = []
    pidx: list[list[int]] = []
    for poly in polys:
        ids = []
        for v in poly:
            k = tuple(round(float(c), 5) for c in v)
            if k not in keyed:
                keyed[k] = len(verts)
                verts.append(k)
            ids.append(keyed[k])
        pidx.append(ids)
    V = np.asarray(verts, np.float32).reshape(-1, 3)
    lo = np.array([origin[0] + tx * tile_size, origin[2] + ty * tile_size])
    hi = lo + tile_size
    edges: dict[tuple[int, int], int] = {}
    for k, ids in enumerate(pidx):
        for j in range(len(ids)):
            edges[(ids[j], ids[(j + 1) % len(ids)])] = k
    P = poly_array(len(polys))
    D = detail_array(len(polys))
    dverts: list[np.ndarray] = []
    dtris: list[list[int]] = []
    links = 0
    for k, ids in enumerate(pidx):
        n = len(ids)
        P[k]["verts"][:n] = ids
        P[k]["vert_count"] = n
        P[k]["flags"] = FLAG_WALK if flags is None else flags[k]
        for j in range(n):
            a, b = ids[j], ids[(j + 1) % n]
            other = edges.get((b, a))
            if other is not None:
                P[k]["neis"][j] = other + 1
                links += 1
            elif portals and (s := _side(V[a], V[b], lo, hi)) is not None:
                P[k]["neis"][j] = EXT_LINK | s
                links += 2
        D[k]["tri_base"] = len(dtris)
        if bump:
            c = V[ids].mean(axis=0) + np.array([0.0, bump, 0.0], np.float32)
            D[k]["vert_base"] = len(dverts)
            D[k]["vert_count"] = 1
            dverts.append(c)
            for j in range(n):
                dtris.append([j, (j + 1) % n, n, 0])
            D[k]["tri_count"] = n
        else:
            D[k]["vert_base"] = len(dverts)
            for j in range(1, n - 1):
                dtris.append([0, j, j + 1, 0])
            D[k]["tri_count"] = n - 2
    bmin = tuple(float(x) for x in V.min(axis=0)) if len(V) else (0.0, 0.0, 0.0)
    bmax = tuple(float(x) for x in V.max(axis=0)) if len(V) else (0.0, 0.0, 0.0)
    return NavMeshTile(x=tx, y=ty, layer=0, verts=V, polys=P, detail_meshes=D,
                       detail_verts=np.asarray(dverts, np.float32).reshape(-1, 3),
                       detail_tris=np.asarray(dtris, np.uint8).reshape(-1, 4), walkable_radius=radius,
                       walkable_climb=climb, bmin=bmin, bmax=bmax, max_link_count=links)  # fmt: skip


def make_navmesh(
    tiles: list[NavMeshTile],
    version: int = 2,
    settings: NavMeshSettings | None = None,
    origin=(0.0, 0.0, 0.0),
    tile_size: float = 1e3,
) -> NavMesh:  # noqa: ANN001
    return NavMesh(origin=tuple(origin), tile_width=tile_size, tile_height=tile_size, max_tiles=max(1, len(tiles)),
                   max_polys=max([len(t.polys) for t in tiles] + [1]), tiles=tiles,
                   settings=(settings or NavMeshSettings()) if version >= 2 else None, version=version)  # fmt: skip


def rect(x0: float, z0: float, x1: float, z1: float, y: float = 0.0) -> Poly:
    """Axis-aligned rectangle, wound as Recast winds polygons (clockwise seen from above, y up)."""
    return [(x0, y, z0), (x0, y, z1), (x1, y, z1), (x1, y, z0)]


def grid_polys(x0: float, z0: float, x1: float, z1: float, step: float, y: float = 0.0) -> list[Poly]:
    """The rectangle cut into square polygons of `step` (neighbours share whole edges)."""
    xs = np.round(np.arange(x0, x1 + 1e-9, step), 6)
    zs = np.round(np.arange(z0, z1 + 1e-9, step), 6)
    return [rect(xs[i], zs[j], xs[i + 1], zs[j + 1], y) for i in range(len(xs) - 1) for j in range(len(zs) - 1)]


def cells_to_polys(mask: np.ndarray, origin: Sequence[float], cs: float, heights: np.ndarray) -> list[Poly]:
    """One square polygon per True cell of a grid (row grows with z, col with x)."""
    out = []
    for r, c in zip(*np.nonzero(mask), strict=True):
        x0, z0 = origin[0] + c * cs, origin[1] + r * cs
        out.append(rect(x0, z0, x0 + cs, z0 + cs, float(heights[r, c])))
    return out
