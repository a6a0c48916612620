"""Geometry of loaded meshes: floor heights from horizontal faces, yaw-aligned oriented boxes."""

from __future__ import annotations

import numpy as np

from ovon.scenes.model import Mesh

FLOOR_SEPARATION = 1.5  # metres between two detected floors of a real scan


def face_normals_areas(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    v = vertices.astype(np.float64)
    a, b, c = v[faces[:, 0]], v[faces[:, 1]], v[faces[:, 2]]
    cr = np.cross(b - a, c - a)
    norm = np.linalg.norm(cr, axis=1)
    n = cr / np.maximum(norm, 1e-12)[:, None]
    return n, 0.5 * norm


def detect_floors(mesh: Mesh, bin_size: float = 0.1, min_area: float = 2.0) -> list[float]:
    """Floor heights (ascending; empty when there is no upward horizontal face) from large upward-facing
    horizontal triangles: an area-weighted height histogram, peaks taken greedily by area, each at least
    FLOOR_SEPARATION from the ones already taken. A peak at the very top of the mesh with nothing above
    most of it is a roof, not a floor (unless no peak remains: an open scan)."""
    if mesh.num_faces == 0:
        return []
    n, area = face_normals_areas(mesh.vertices, mesh.faces)
    up = n[:, 1] > 0.9
    if not up.any():
        return []  # no floor at all (a wrong up axis?): never a made-up height
    y = mesh.vertices[mesh.faces[up]].astype(np.float64)[:, :, 1].mean(axis=1)
    w = area[up]
    chosen = height_peaks(y, w, bin_size, min_area, FLOOR_SEPARATION)
    faces_up = mesh.faces[up]
    top = float(mesh.vertices[:, 1].max())
    kept = [
        h for h in chosen if top - h > 0.5 or _covered_fraction(mesh, faces_up[np.abs(y - h) <= bin_size], h) >= 0.5
    ]
    return sorted(kept or [min(chosen)])


def height_peaks(
    y: np.ndarray, w: np.ndarray, bin_size: float = 0.1, min_area: float = 2.0, separation: float = FLOOR_SEPARATION
) -> list[float]:
    """Heights of the big horizontal areas among surfaces at heights `y` with areas `w` (not sorted,
    largest first): an area-weighted histogram, peaks taken greedily by area (at least `min_area` and
    15% of the largest), each more than `separation` from the ones already taken; the largest single
    surface when no peak qualifies."""
    lo = np.floor(y.min() / bin_size) * bin_size
    bins = np.floor((y - lo) / bin_size).astype(np.int64)
    hist = np.bincount(bins, weights=w)
    # smooth over neighbouring bins so a floor split across two bins still counts as one
    sm = hist + np.concatenate([[0], hist[:-1]]) + np.concatenate([hist[1:], [0]])
    order = np.argsort(-sm, kind="stable")
    threshold = max(min_area, 0.15 * float(sm.max()))
    chosen: list[float] = []
    for b in order:
        if sm[b] < threshold:
            break
        sel = np.abs(bins - b) <= 1
        ys, ws = y[sel], w[sel]
        srt = np.argsort(ys)
        cum = np.cumsum(ws[srt])
        h = float(ys[srt][np.searchsorted(cum, cum[-1] / 2.0)])  # area-weighted median
        if all(abs(h - c) > separation for c in chosen):
            chosen.append(h)
    return chosen or [float(y[np.argmax(w)])]


def _covered_fraction(mesh: Mesh, faces: np.ndarray, h: float, cell: float = 0.5, samples: int = 50_000) -> float:
    """Share of the area of `faces` (a floor candidate at height h) with mesh surface more than 1 m above
    it, from area-uniform surface samples binned on an xz grid (deterministic)."""
    rng = np.random.default_rng(0)

    def sample(f: np.ndarray, k: int) -> np.ndarray:
        v = mesh.vertices.astype(np.float64)
        a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
        ar = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
        if ar.sum() <= 0:
            return np.zeros((0, 3))
        idx = rng.choice(len(f), size=k, p=ar / ar.sum())
        r1, r2 = rng.random(k), rng.random(k)
        flip = r1 + r2 > 1
        r1[flip], r2[flip] = 1 - r1[flip], 1 - r2[flip]
        return a[idx] + r1[:, None] * (b[idx] - a[idx]) + r2[:, None] * (c[idx] - a[idx])

    everywhere = sample(mesh.faces, samples)
    floor = sample(faces, 2000)
    if len(floor) == 0:
        return 0.0
    above = everywhere[everywhere[:, 1] > h + 1.0]
    if len(above) == 0:
        return 0.0
    key = lambda p: (np.floor(p[:, 0] / cell).astype(np.int64) << 32) + np.floor(p[:, 2] / cell).astype(np.int64)  # noqa: E731
    return float(np.isin(key(floor), np.unique(key(above))).mean())


def _hull_2d(pts: np.ndarray) -> np.ndarray:
    """Convex hull (Andrew's monotone chain), counter-clockwise, no repeated end point."""
    pts = np.unique(pts, axis=0)
    if len(pts) <= 2:
        return pts

    def half(points: np.ndarray) -> list[np.ndarray]:
        out: list[np.ndarray] = []
        for p in points:
            while len(out) >= 2:
                o, a = out[-2], out[-1]
                if (a[0] - o[0]) * (p[1] - o[1]) - (a[1] - o[1]) * (p[0] - o[0]) <= 0:
                    out.pop()
                else:
                    break
            out.append(p)
        return out

    lower = half(pts)
    upper = half(pts[::-1])
    return np.array(lower[:-1] + upper[:-1])


def yaw_obb(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Yaw-aligned oriented box of points: minimum-area rectangle of the x/z footprint (rotating
    calipers over hull edges) with the y extent. Returns (center, half_extents, rotation local->world)."""
    pts = np.asarray(points, dtype=np.float64)
    xz = pts[:, [0, 2]]
    try:
        from scipy.spatial import ConvexHull, QhullError

        try:
            hull = xz[ConvexHull(xz).vertices]
        except (QhullError, ValueError):  # flat or too few points
            hull = _hull_2d(xz)
    except ImportError:
        hull = _hull_2d(xz)
    best = (np.inf, 1.0, 0.0)
    if len(hull) >= 3:
        edges = np.roll(hull, -1, axis=0) - hull
        lens = np.linalg.norm(edges, axis=1)
        for (ex, ez), ln in zip(edges, lens):
            if ln < 1e-12:
                continue
            dx, dz = ex / ln, ez / ln
            a = hull @ np.array([dx, dz])
            b = hull @ np.array([-dz, dx])
            area = (a.max() - a.min()) * (b.max() - b.min())
            if area < best[0] - 1e-12:
                best = (area, dx, dz)
    _, dx, dz = best
    # canonical: the box's local x axis within [0, 90) degrees of world x
    ang = np.arctan2(dz, dx) % (np.pi / 2.0)
    dx, dz = float(np.cos(ang)), float(np.sin(ang))
    rot = np.array([[dx, 0.0, -dz], [0.0, 1.0, 0.0], [dz, 0.0, dx]])
    local = pts @ rot  # world -> local (rot is orthonormal)
    lo, hi = local.min(axis=0), local.max(axis=0)
    center = rot @ ((lo + hi) / 2.0)
    return center, (hi - lo) / 2.0, rot


def _faces_by_instance(face_instance: np.ndarray) -> dict[int, np.ndarray]:
    order = np.argsort(face_instance, kind="stable")
    ids, starts = np.unique(face_instance[order], return_index=True)
    bounds = list(starts[1:]) + [len(order)]
    return {int(i): order[s:e] for i, s, e in zip(ids, starts, bounds)}
