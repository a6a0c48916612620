"""The one grid line-of-sight kernel (closed supercover DDA), shared by navigability, geodesic path
shortcuts, the experts' explored maps and the modular agent's maps.

A segment from the centre of cell (r0, c0) to the centre of (r1, c1) is clear when every cell whose
*closed* square it meets, endpoints excluded, is transparent. "Closed" means a segment passing exactly
through a grid corner is blocked by either of the two cells that only touch it there (no seeing or
walking through diagonal gaps between two wall cells). Integer arithmetic: no floating-point tolerance.
"""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True, nogil=True)
def los_clear(transparent: np.ndarray, r0: int, c0: int, r1: int, c1: int) -> bool:
    """Closed-supercover line of sight from cell (r0, c0) to (r1, c1), endpoints excluded (in bounds)."""
    dr = r1 - r0
    dc = c1 - c0
    ny = abs(dr)
    nx = abs(dc)
    sy = 1 if dr > 0 else -1
    sx = 1 if dc > 0 else -1
    r = r0
    c = c0
    iy = 0
    ix = 0
    while ix < nx or iy < ny:
        d = (1 + 2 * ix) * ny - (1 + 2 * iy) * nx
        if d == 0:
            # through a grid corner: the two side cells touch the segment there
            if not transparent[r + sy, c] or not transparent[r, c + sx]:
                return False
            r += sy
            c += sx
            iy += 1
            ix += 1
        elif d < 0:
            c += sx
            ix += 1
        else:
            r += sy
            iy += 1
        if r == r1 and c == c1:
            return True
        if not transparent[r, c]:
            return False
    return True


@nb.njit(cache=True, nogil=True)
def los_between(mask: np.ndarray, r0: int, c0: int, r1: int, c1: int) -> bool:
    """`los_clear` with both endpoints required in bounds and in `mask` (a walk along free cells)."""
    rows, cols = mask.shape
    if r0 < 0 or c0 < 0 or r1 < 0 or c1 < 0 or r0 >= rows or r1 >= rows or c0 >= cols or c1 >= cols:
        return False
    if not mask[r0, c0] or not mask[r1, c1]:
        return False
    return los_clear(mask, r0, c0, r1, c1)
