"""The xz frame, the floor bands and the step cut of navigability grids, shared by grids computed from a
mesh (`ovon.sim.navgrid`) and grids read from a habitat navmesh (`ovon.sim.navmesh.raster`), so both put
cell centres and floors in the same places and cut ledges alike."""

from __future__ import annotations

import numpy as np

# Most cells one navigation grid may have: a 500 m square (the loader's MAX_SCENE_SPAN_M, more than any
# building) at the default 0.05 m cell, with margin. Why a cap: the grid is sized from the mesh's extent
# with nothing else bounding it, and the rasteriser allocates several 8-byte arrays per cell, so a mesh in
# millimetres (a 4 m room spanning 4000 m: 6.4e9 cells, ~50 GB each) would fail deep inside numpy as "out
# of memory" instead of saying what is wrong. At this cap one such array is under 1 GB.
MAX_GRID_CELLS = 120_000_000


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
    """Origin so that cell centres are multiples of cs, with one empty cell of padding on each side.

    Raises ValueError, before anything is allocated, when the grid would exceed MAX_GRID_CELLS (a mesh
    in mm or cm, stray far-away vertices, or a tiny `sim.nav.cell_size` on a large scene)."""
    lo = V[:, [0, 2]].min(axis=0)
    hi = V[:, [0, 2]].max(axis=0)
    if not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        raise ValueError(
            "the scene's vertices are not all finite (NaN or infinite): no navigation grid can span "
            "them; fix: repair the mesh"
        )
    first = np.floor(lo / cs) - 1  # index (in multiples of cs) of the first cell centre
    last = np.ceil(hi / cs) + 1
    origin = (first - 0.5) * cs
    cols_f, rows_f = last - first + 1
    if float(cols_f) * float(rows_f) > MAX_GRID_CELLS:
        span = hi - lo
        raise ValueError(
            f"the scene spans {span[0]:,.0f} x {span[1]:,.0f} m (x by z): a navigation grid of {cs:g} m cells would "
            f"have {float(cols_f) * float(rows_f):,.0f} cells (max {MAX_GRID_CELLS:,}); are its units mm or cm? fix: "
            "scale the mesh to metres, or raise sim.nav.cell_size (e.g. --set sim.nav.cell_size=0.1)"
        )
    cols, rows = int(cols_f), int(rows_f)
    return origin, rows, cols


def step_cut(present: np.ndarray, h: np.ndarray, climb: float, labels: np.ndarray | None = None) -> np.ndarray:
    """Cells to drop: 8-neighbours both `present` whose heights `h` differ by more than `climb` (a ledge, as
    Recast's ledge filter cuts it) or, with `labels`, that lie on different labels (navmesh islands)."""
    cut = np.zeros_like(present)
    hh = np.where(present, h, 0.0)
    rows, cols = present.shape
    for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
        a = (slice(0, rows - dr), slice(max(0, -dc), cols - max(0, dc)))
        b = (slice(dr, None), slice(max(0, dc), cols - max(0, -dc)))
        bad = np.abs(hh[a] - hh[b]) > climb + 1e-5
        if labels is not None:
            bad = (labels[a] != labels[b]) | bad
        bad = present[a] & present[b] & bad
        cut[a] |= bad
        cut[b] |= bad
    return cut
