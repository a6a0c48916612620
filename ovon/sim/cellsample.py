"""Triangles sampled at the cell centres of an xz grid: the one rasteriser behind grids computed from a
mesh (`ovon.sim.navgrid`) and grids read from a habitat navmesh (`ovon.sim.navmesh.raster`), so both
decide in the same way which cells a triangle covers, at what height, and which sample is a floor's surface.

A cell centre is sampled by a triangle when it lies in the triangle's xz projection (barycentric test
with a small tolerance, so a centre on a shared edge is sampled by both triangles); the sample is the
triangle's height there, what a vertical ray through the centre hits. Samples come back per cell (CSR:
`ptr`, then heights and triangle indices), sorted by height within a cell (ties in triangle order).
`band_surface` picks each cell's floor sample within a height band: navgrid the top of the lowest stack
of free candidates (and the lowest candidate), the navmesh the lowest sample.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

_EPS_BARY = 1e-7


@dataclass
class CellSamples:
    ptr: np.ndarray  # int64 (cells + 1,): the samples of cell r * cols + c are [ptr[cell], ptr[cell + 1])
    ys: np.ndarray  # float64 (samples,): height of each sample, ascending within a cell
    tri: np.ndarray  # int32 (samples,): the triangle (row of F) each sample lies on


@njit(cache=True)
def _edges(V, F, t):  # noqa: ANN001
    """First vertex of triangle t and its two edges from it."""
    a = F[t, 0]
    b = F[t, 1]
    c = F[t, 2]
    ax, ay, az = V[a, 0], V[a, 1], V[a, 2]
    return ax, ay, az, V[b, 0] - ax, V[b, 1] - ay, V[b, 2] - az, V[c, 0] - ax, V[c, 1] - ay, V[c, 2] - az


@njit(cache=True)
def _normal_y(e1x, e1y, e1z, e2x, e2y, e2z):  # noqa: ANN001
    """y component and length of the normal e1 x e2 (winding decides "up", as in Recast)."""
    nx = e1y * e2z - e1z * e2y
    ny = e1z * e2x - e1x * e2z
    nz = e1x * e2y - e1y * e2x
    return ny, math.sqrt(nx * nx + ny * ny + nz * nz)


@njit(cache=True)
def _sample_pass(V, F, ox, oz, cs, rows, cols, vertical_tol, area_tol, fill, counts, ptr, ys, tri):  # noqa: ANN001
    """Sample the triangles at cell centres: count per cell (fill=False) or write each sample."""
    for t in range(F.shape[0]):
        ax, ay, az, e1x, e1y, e1z, e2x, e2y, e2z = _edges(V, F, t)
        ny, nl = _normal_y(e1x, e1y, e1z, e2x, e2y, e2z)
        den = e1x * e2z - e1z * e2x  # = -ny, twice the signed xz area
        if nl < 1e-12 or abs(ny) < vertical_tol * nl or abs(den) < area_tol:
            continue  # degenerate or (nearly) vertical: a vertical ray never hits it
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
            for cc in range(c0, c1 + 1):
                px = ox + (cc + 0.5) * cs - ax
                w1 = (px * e2z - pz * e2x) / den
                w2 = (e1x * pz - e1z * px) / den
                if w1 < -_EPS_BARY or w2 < -_EPS_BARY or w1 + w2 > 1.0 + _EPS_BARY:
                    continue
                cell = r * cols + cc
                if fill:
                    k = ptr[cell] + counts[cell]
                    ys[k] = ay + w1 * e1y + w2 * e2y
                    tri[k] = t
                counts[cell] += 1


@njit(cache=True)
def _sort_cells(ptr, ys, tri):  # noqa: ANN001
    """Sort each cell's samples by height (stable insertion sort: a cell holds a handful)."""
    for cell in range(ptr.shape[0] - 1):
        s0 = ptr[cell]
        s1 = ptr[cell + 1]
        for i in range(s0 + 1, s1):
            y = ys[i]
            t = tri[i]
            j = i - 1
            while j >= s0 and ys[j] > y:
                ys[j + 1] = ys[j]
                tri[j + 1] = tri[j]
                j -= 1
            ys[j + 1] = y
            tri[j + 1] = t


def cell_samples(
    V: np.ndarray,
    F: np.ndarray,
    origin: np.ndarray,
    cs: float,
    rows: int,
    cols: int,
    vertical_tol: float = 0.0,
    area_tol: float = 0.0,
) -> CellSamples:
    """Every (cell centre, triangle) hit of the triangles `V[F]` on the grid with cell (0, 0)'s corner at
    `origin` (world x, z), sorted by height within a cell (ties in triangle order). Triangles are skipped
    when degenerate (normal shorter than 1e-12), when |normal_y| < `vertical_tol` * |normal| (nearly
    vertical) or when twice their xz area is below `area_tol`."""
    ncell = rows * cols
    counts = np.zeros(ncell, dtype=np.int64)
    ptr = np.zeros(ncell + 1, dtype=np.int64)
    ox, oz = float(origin[0]), float(origin[1])
    args = (V, F, ox, oz, float(cs), rows, cols, float(vertical_tol), float(area_tol))
    _sample_pass(*args, False, counts, ptr, np.empty(0), np.empty(0, dtype=np.int32))
    np.cumsum(counts, out=ptr[1:])
    ys = np.empty(int(ptr[-1]))
    tri = np.empty(int(ptr[-1]), dtype=np.int32)
    counts[:] = 0
    _sample_pass(*args, True, counts, ptr, ys, tri)
    _sort_cells(ptr, ys, tri)
    return CellSamples(ptr, ys, tri)


@njit(cache=True)
def _band_surface(ptr, ys, mask, lo, hi, climb, out):  # noqa: ANN001
    for cell in range(ptr.shape[0] - 1):
        for k in range(ptr[cell], ptr[cell + 1]):
            y = ys[k]
            if mask[k] and y >= lo and y < hi:
                if out[cell] < 0 or y <= ys[out[cell]] + climb + 1e-5:
                    out[cell] = k


def band_surface(s: CellSamples, mask: np.ndarray, lo: float, hi: float, climb: float = -math.inf) -> np.ndarray:
    """(cells,) index of each cell's surface sample among the `mask` samples with lo <= y < hi, -1 where
    none: the top of the lowest stack (each sample within `climb` + 1e-5 of the one below it, e.g. a floor
    and a low step box lying on it), or with `climb` = -inf the lowest sample (the first in triangle order
    on a tie)."""
    out = np.full(len(s.ptr) - 1, -1, dtype=np.int64)
    _band_surface(s.ptr, s.ys, mask, float(lo), float(hi), float(climb), out)
    return out


def pick(values: np.ndarray, k: np.ndarray, fill: float | int) -> np.ndarray:
    """values[k] where k >= 0, `fill` where k is -1 (`band_surface`'s "no sample")."""
    out = np.full(k.shape, fill, dtype=values.dtype)
    ok = k >= 0
    out[ok] = values[k[ok]]
    return out


@njit(cache=True)
def _upward(V, F, cos_slope, out):  # noqa: ANN001
    for t in range(F.shape[0]):
        _, _, _, e1x, e1y, e1z, e2x, e2y, e2z = _edges(V, F, t)
        ny, nl = _normal_y(e1x, e1y, e1z, e2x, e2y, e2z)
        out[t] = nl >= 1e-12 and ny / nl >= cos_slope


def upward(V: np.ndarray, F: np.ndarray, cos_slope: float) -> np.ndarray:
    """Per triangle: faces up with a slope whose cosine is at least `cos_slope` (False when degenerate)."""
    out = np.zeros(len(F), dtype=np.bool_)
    _upward(V, F, float(cos_slope), out)
    return out
