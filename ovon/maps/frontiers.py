"""Frontiers of an explored map, updated incrementally.

One implementation for the privileged frontier expert (the true navigability, fixed per episode) and the
modular agents (their own navigability from depth + odometry, which changes as obstacles are observed:
`update_navigability` accounts for cells whose flag the caller changed in place).

* Frontier cell: explored, navigable, 4-adjacent to an unexplored navigable cell.
* Pocket: a 4-connected component of unexplored navigable cells whose area (cells * cell_size**2, in m^2)
  is below `pocket_area_m2`; pockets count as explored (upstream squared the area wrongly).
* Frontier: an 8-connected component of frontier cells. Its waypoint is the middle of the component's
  longest hop path: BFS from any cell to the farthest cell A, BFS from A to the farthest cell B, and the
  cell halfway along the B -> A BFS path. For an open boundary curve this is its midpoint along the curve.

Why incremental: a full-map label costs about 1 ms at 400x400; here a step only looks at the newly explored
cells (pocket flood fills stop as soon as a component reaches the threshold area) and frontier cells are
kept in an O(1) add/remove list, so grouping them costs O(number of frontier cells), done only when the
expert chooses a target.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np
from scipy import ndimage


@nb.njit(cache=True, nogil=True)
def _is_frontier(navigable: np.ndarray, explored: np.ndarray, r: int, c: int) -> bool:
    if not (explored[r, c] and navigable[r, c]):
        return False
    rows, cols = navigable.shape
    if r > 0 and navigable[r - 1, c] and not explored[r - 1, c]:
        return True
    if r + 1 < rows and navigable[r + 1, c] and not explored[r + 1, c]:
        return True
    if c > 0 and navigable[r, c - 1] and not explored[r, c - 1]:
        return True
    if c + 1 < cols and navigable[r, c + 1] and not explored[r, c + 1]:
        return True
    return False


@nb.njit(cache=True, nogil=True)
def _refresh_cell(navigable, explored, fpos, fr, fc, nf, r, c) -> int:
    """Recompute the frontier flag of one cell; keep the (fr, fc, fpos) list consistent. Returns nf."""
    f = _is_frontier(navigable, explored, r, c)
    i = fpos[r, c]
    if f and i < 0:
        fr[nf] = r
        fc[nf] = c
        fpos[r, c] = nf
        nf += 1
    elif not f and i >= 0:
        last = nf - 1
        lr = fr[last]
        lc = fc[last]
        fr[i] = lr
        fc[i] = lc
        fpos[lr, lc] = i
        fpos[r, c] = -1
        nf = last
    return nf


@nb.njit(cache=True, nogil=True)
def _update(
    navigable: np.ndarray,
    explored: np.ndarray,
    new_r: np.ndarray,
    new_c: np.ndarray,
    n_new: int,
    cell_area: float,
    pocket_area: float,
    stamp: np.ndarray,
    stamp_next: int,
    queue_r: np.ndarray,
    queue_c: np.ndarray,
    fpos: np.ndarray,
    fr: np.ndarray,
    fc: np.ndarray,
    nf: int,
) -> tuple[int, int, int]:
    """Fill pockets next to the newly explored cells, then refresh frontier flags around every change.

    Each bounded BFS gets its own stamp id; ids >= `base` belong to this update. A BFS that reaches a cell
    stamped by an earlier BFS of this update has joined a component that BFS found large (small ones are
    filled, hence explored, at once), so it is large too.
    Returns (number of frontier cells, number of pocket cells filled, next stamp id)."""
    rows, cols = navigable.shape
    base = stamp_next
    filled = 0  # queue holds [filled pocket cells ... | current BFS]
    for k in range(n_new):
        r0 = new_r[k]
        c0 = new_c[k]
        for d in range(5):  # the 4 neighbours, then the cell itself (a cell that just became navigable)
            sr = r0 + (d == 1) - (d == 0)
            sc = c0 + (d == 3) - (d == 2)
            if sr < 0 or sr >= rows or sc < 0 or sc >= cols:
                continue
            if not navigable[sr, sc] or explored[sr, sc] or stamp[sr, sc] >= base:
                continue
            cur = stamp_next
            stamp_next += 1
            tail = filled
            queue_r[tail] = sr
            queue_c[tail] = sc
            tail += 1
            stamp[sr, sc] = cur
            head = filled
            large = (tail - filled) * cell_area >= pocket_area
            while head < tail and not large:
                r = queue_r[head]
                c = queue_c[head]
                head += 1
                for e in range(4):
                    nr = r + (e == 1) - (e == 0)
                    nc = c + (e == 3) - (e == 2)
                    if nr < 0 or nr >= rows or nc < 0 or nc >= cols:
                        continue
                    if not navigable[nr, nc] or explored[nr, nc]:
                        continue
                    s = stamp[nr, nc]
                    if s == cur:
                        continue
                    if s >= base:
                        large = True
                        break
                    stamp[nr, nc] = cur
                    queue_r[tail] = nr
                    queue_c[tail] = nc
                    tail += 1
                    if (tail - filled) * cell_area >= pocket_area:
                        large = True
                        break
            if not large:
                for q in range(filled, tail):
                    explored[queue_r[q], queue_c[q]] = True
                filled = tail
    # refresh frontier flags of the changed cells and their 4-neighbours
    for k in range(n_new + filled):
        if k < n_new:
            r0 = new_r[k]
            c0 = new_c[k]
        else:
            r0 = queue_r[k - n_new]
            c0 = queue_c[k - n_new]
        nf = _refresh_cell(navigable, explored, fpos, fr, fc, nf, r0, c0)
        for d in range(4):
            nr = r0 + (d == 1) - (d == 0)
            nc = c0 + (d == 3) - (d == 2)
            if 0 <= nr < rows and 0 <= nc < cols:
                nf = _refresh_cell(navigable, explored, fpos, fr, fc, nf, nr, nc)
    return nf, filled, stamp_next


@nb.njit(cache=True, nogil=True)
def _bfs8(fr, fc, fpos, start, comp, cid, hop, parent, members) -> tuple[int, int]:
    """8-connected BFS over frontier cells from list index `start`; returns (count, last index).

    Fills `members[:count]` with the visited list indices, `hop` and `parent` for them; `comp` marks
    visited ones with `cid` (callers pass a fresh id per BFS)."""
    rows, cols = fpos.shape
    members[0] = start
    comp[start] = cid
    hop[start] = 0
    parent[start] = -1
    head = 0
    tail = 1
    last = start
    while head < tail:
        i = members[head]
        head += 1
        last = i
        r = fr[i]
        c = fc[i]
        for dr in range(-1, 2):
            for dc in range(-1, 2):
                if dr == 0 and dc == 0:
                    continue
                nr = r + dr
                nc = c + dc
                if nr < 0 or nr >= rows or nc < 0 or nc >= cols:
                    continue
                j = fpos[nr, nc]
                if j < 0 or comp[j] == cid:
                    continue
                comp[j] = cid
                hop[j] = hop[i] + 1
                parent[j] = i
                members[tail] = j
                tail += 1
    return tail, last


@nb.njit(cache=True, nogil=True)
def _components(fr, fc, nf, fpos, min_cells):
    """Group frontier cells into 8-connected components; waypoint = middle of the longest BFS path.

    Returns (label per list index (-1 = component too small), waypoint rows, waypoint cols, sizes)."""
    label = np.full(nf, -1, dtype=np.int32)
    comp = np.full(nf, -1, dtype=np.int32)  # BFS ids: 3 per component
    hop = np.zeros(nf, dtype=np.int32)
    parent = np.full(nf, -1, dtype=np.int32)
    members = np.empty(max(nf, 1), dtype=np.int32)
    wr = np.empty(nf, dtype=np.int32)
    wc = np.empty(nf, dtype=np.int32)
    sizes = np.empty(nf, dtype=np.int32)
    seen = np.zeros(nf, dtype=np.bool_)
    ncomp = 0
    bid = 0
    for s in range(nf):
        if seen[s]:
            continue
        n, a = _bfs8(fr, fc, fpos, s, comp, bid, hop, parent, members)
        bid += 1
        for k in range(n):
            seen[members[k]] = True
        if n < min_cells:
            continue
        n2, b = _bfs8(fr, fc, fpos, a, comp, bid, hop, parent, members)
        bid += 1
        half = hop[b] // 2
        m = b
        for _ in range(half):
            m = parent[m]
        for k in range(n2):
            label[members[k]] = ncomp
        wr[ncomp] = fr[m]
        wc[ncomp] = fc[m]
        sizes[ncomp] = n2
        ncomp += 1
    return label, wr[:ncomp].copy(), wc[:ncomp].copy(), sizes[:ncomp].copy()


@dataclass
class Frontiers:
    """Frontiers at one moment: waypoint cell and size (cells) per frontier."""

    rows: np.ndarray  # (K,) waypoint rows
    cols: np.ndarray  # (K,) waypoint cols
    sizes: np.ndarray  # (K,) cells per frontier

    def __len__(self) -> int:
        return int(self.rows.shape[0])


class FrontierMap:
    """Pockets and frontier cells of one grid, kept in step with an `ExploredMap`'s `explored` array."""

    def __init__(
        self,
        navigable: np.ndarray,
        explored: np.ndarray,
        cell_size: float,
        pocket_area_m2: float,
        min_frontier_cells: int = 1,
        islands: bool = True,
    ) -> None:
        """`islands`: label the navigable map's islands once (a fixed map: the expert keeps to its island and
        small islands count as explored at reset); a growing map has no meaningful islands."""
        self.navigable = np.ascontiguousarray(navigable, dtype=np.bool_)
        self.explored = explored  # shared with the ExploredMap, modified in place (pocket filling)
        self.cell_size = float(cell_size)
        self.cell_area = self.cell_size**2
        self.pocket_area_m2 = float(pocket_area_m2)
        self.min_frontier_cells = int(min_frontier_cells)
        shape = self.navigable.shape
        n = shape[0] * shape[1]
        self.fpos = np.full(shape, -1, dtype=np.int32)
        self._fr = np.empty(n, dtype=np.int32)
        self._fc = np.empty(n, dtype=np.int32)
        self.n_frontier_cells = 0
        self._stamp = np.zeros(shape, dtype=np.int32)
        self._stamp_next = 1
        self._queue_r = np.empty(n + 1, dtype=np.int32)
        self._queue_c = np.empty(n + 1, dtype=np.int32)
        self.islands: np.ndarray | None = None
        self.island_cells = np.zeros(0, dtype=np.int64)
        if islands:
            # components of the navigable map: the initial unexplored components (labelled once per grid)
            labels, k = ndimage.label(self.navigable)
            self.islands = labels.astype(np.int32) - 1  # -1 off the navigable map, 4-connected islands
            self.island_cells = np.bincount(labels.ravel(), minlength=k + 1)[1:]
        self.pockets_filled = 0

    @property
    def frontier_rows(self) -> np.ndarray:
        return self._fr[: self.n_frontier_cells]

    @property
    def frontier_cols(self) -> np.ndarray:
        return self._fc[: self.n_frontier_cells]

    def reset(self) -> None:
        """Forget everything (call after the ExploredMap's reset); fills the initial pockets."""
        nf = self.n_frontier_cells
        self.fpos[self._fr[:nf], self._fc[:nf]] = -1
        self.n_frontier_cells = 0
        self._stamp[:] = 0
        self._stamp_next = 1
        small = np.flatnonzero(self.island_cells * self.cell_area < self.pocket_area_m2)
        if small.size and self.islands is not None:
            mask = np.isin(self.islands, small)
            self.explored |= mask
            self.pockets_filled = int(mask.sum())
        else:
            self.pockets_filled = 0

    def update(self, new_r: np.ndarray, new_c: np.ndarray) -> int:
        """Account for newly explored cells; return the number of pocket cells filled."""
        return self._apply(new_r, new_c)

    def update_navigability(self, changed_r: np.ndarray, changed_c: np.ndarray) -> int:
        """Account for cells whose `navigable` flag the caller changed in place (e.g. a new obstacle split
        an unexplored area into a pocket); return the number of pocket cells filled.

        The same pass as for newly explored cells: pocket searches start next to (and at) every changed
        cell and the frontier flags of the changed cells and their neighbours are recomputed."""
        return self._apply(changed_r, changed_c)

    def _apply(self, new_r: np.ndarray, new_c: np.ndarray) -> int:
        n = int(new_r.shape[0])
        if n == 0:
            return 0
        if self._stamp_next > 2_000_000_000:
            self._stamp[:] = 0
            self._stamp_next = 1
        nf, filled, self._stamp_next = _update(
            self.navigable,
            self.explored,
            new_r,
            new_c,
            n,
            self.cell_area,
            self.pocket_area_m2,
            self._stamp,
            self._stamp_next,
            self._queue_r,
            self._queue_c,
            self.fpos,
            self._fr,
            self._fc,
            self.n_frontier_cells,
        )
        self.n_frontier_cells = int(nf)
        self.pockets_filled += int(filled)
        return int(filled)

    def frontiers(self, min_cells: int | None = None) -> Frontiers:
        """Group the current frontier cells (8-connected) and pick each frontier's waypoint."""
        m = self.min_frontier_cells if min_cells is None else int(min_cells)
        nf = self.n_frontier_cells
        if nf == 0:
            e = np.empty(0, dtype=np.int32)
            return Frontiers(e, e.copy(), e.copy())
        _, wr, wc, sizes = _components(self._fr, self._fc, nf, self.fpos, m)
        return Frontiers(wr, wc, sizes)

    def any_frontier_near(self, row: int, col: int, radius_cells: int) -> bool:
        """Whether a frontier cell lies in the square window of `radius_cells` around (row, col)."""
        r0 = max(0, row - radius_cells)
        c0 = max(0, col - radius_cells)
        win = self.fpos[r0 : row + radius_cells + 1, c0 : col + radius_cells + 1]
        return bool((win >= 0).any())

    def frontier_mask(self) -> np.ndarray:
        return self.fpos >= 0
