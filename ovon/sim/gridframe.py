"""The xz frame and the floor bands of navigability grids, shared by grids computed from a mesh
(`ovon.sim.navgrid`) and grids read from a habitat navmesh (`ovon.sim.navmesh.raster`), so both put
cell centres and floors in the same places."""

from __future__ import annotations

import numpy as np


def hint_bands(hints: list[float], sep: float) -> list[tuple[float, float, float]]:
    """(nominal height, lo, hi) per given floor height: from `sep` below the lowest floor up to 2 * sep
    above each, cut half a separation below the next floor."""
    fh = sorted(float(h) for h in hints)
    bands: list[tuple[float, float, float]] = []
    for i, h in enumerate(fh):
        lo = h - sep if i == 0 else max(h - sep / 2.0, bands[-1][2])
        hi = h + 2.0 * sep
        if i + 1 < len(fh):
            hi = min(hi, fh[i + 1] - sep / 2.0)
        bands.append((h, lo, hi))
    return bands


def grid_frame(V: np.ndarray, cs: float) -> tuple[np.ndarray, int, int]:
    """Origin so that cell centres are multiples of cs, with one empty cell of padding on each side."""
    lo = V[:, [0, 2]].min(axis=0)
    hi = V[:, [0, 2]].max(axis=0)
    first = np.floor(lo / cs) - 1  # index (in multiples of cs) of the first cell centre
    last = np.ceil(hi / cs) + 1
    origin = (first - 0.5) * cs
    cols, rows = (last - first + 1).astype(int)
    return origin, int(rows), int(cols)
