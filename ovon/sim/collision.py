"""The one collision test for straight moves on a navigability grid.

Shared by the simulator's kinematics and the privileged experts, so an expert never believes a forward
step is free when the simulator would block it (with two implementations, samples that land exactly on
a cell border flipped differently and the shortest-path expert ping-ponged against a corner)."""

from __future__ import annotations

import math

import numba as nb
import numpy as np


@nb.njit(cache=True, nogil=True)
def free_prefix(navigable: np.ndarray, ox: float, oz: float, cs: float, x: float, z: float, dx: float, dz: float):
    """Sample the segment (x, z) -> (x + dx, z + dz) every half cell; return (k, n): the number of leading
    samples on navigable cells and the number of samples. k == n means the whole move is free."""
    rows, cols = navigable.shape
    dist = math.sqrt(dx * dx + dz * dz)
    n = max(1, int(math.ceil(dist / max(cs * 0.5, 1e-3) - 1e-9)))
    for i in range(1, n + 1):
        px = x + dx * (i / n)
        pz = z + dz * (i / n)
        c = int(math.floor((px - ox) / cs))
        r = int(math.floor((pz - oz) / cs))
        if r < 0 or r >= rows or c < 0 or c >= cols or not navigable[r, c]:
            return i - 1, n
    return n, n


def forward_delta(yaw: float, step: float) -> tuple[float, float]:
    """World (dx, dz) of a forward move: yaw 0 looks along -z, positive yaw turns left."""
    return -math.sin(yaw) * step, -math.cos(yaw) * step


@nb.njit(cache=True, nogil=True)
def slide_point(navigable: np.ndarray, ox: float, oz: float, cs: float, x: float, z: float, dx: float, dz: float):
    """Where a blocked move (x, z) -> (x + dx, z + dz) ends when the agent slides, as Detour's
    moveAlongSurface (habitat's tryStep) does: the navigable point nearest to the target among the cells
    connected to the start inside the disk around the move's midpoint (radius: half the move + a cell).
    Along a wall that is the target projected onto the wall, whatever the wall's direction. Returns
    (x, z) of that point (kept 0.1 mm inside its cell); the start when its own cell is not navigable."""
    rows, cols = navigable.shape
    sr = int(math.floor((z - oz) / cs))
    sc = int(math.floor((x - ox) / cs))
    if sr < 0 or sr >= rows or sc < 0 or sc >= cols or not navigable[sr, sc]:
        return x, z
    tx = x + dx
    tz = z + dz
    mx = x + 0.5 * dx
    mz = z + 0.5 * dz
    rad = 0.5 * math.sqrt(dx * dx + dz * dz) + cs
    r0 = max(0, int(math.floor((mz - rad - oz) / cs)))
    r1 = min(rows - 1, int(math.floor((mz + rad - oz) / cs)))
    c0 = max(0, int(math.floor((mx - rad - ox) / cs)))
    c1 = min(cols - 1, int(math.floor((mx + rad - ox) / cs)))
    r0, r1, c0, c1 = min(r0, sr), max(r1, sr), min(c0, sc), max(c1, sc)
    h = r1 - r0 + 1
    w = c1 - c0 + 1
    seen = np.zeros((h, w), dtype=np.bool_)
    qr = np.empty(h * w, dtype=np.int64)
    qc = np.empty(h * w, dtype=np.int64)
    qr[0] = sr
    qc[0] = sc
    seen[sr - r0, sc - c0] = True
    head = 0
    tail = 1
    eps = 1e-4
    best_x = x
    best_z = z
    best = (x - tx) ** 2 + (z - tz) ** 2
    while head < tail:
        r = qr[head]
        c = qc[head]
        head += 1
        x0 = ox + c * cs
        z0 = oz + r * cs
        px = min(max(tx, x0 + eps), x0 + cs - eps)
        pz = min(max(tz, z0 + eps), z0 + cs - eps)
        d = (px - tx) ** 2 + (pz - tz) ** 2
        if d < best - 1e-12:
            best = d
            best_x = px
            best_z = pz
        for k in range(4):
            r2 = r + (1 if k == 0 else -1 if k == 1 else 0)
            c2 = c + (1 if k == 2 else -1 if k == 3 else 0)
            if r2 < r0 or r2 > r1 or c2 < c0 or c2 > c1 or seen[r2 - r0, c2 - c0] or not navigable[r2, c2]:
                continue
            # the cell square must reach into the search disk
            qx = min(max(mx, ox + c2 * cs), ox + (c2 + 1) * cs)
            qz = min(max(mz, oz + r2 * cs), oz + (r2 + 1) * cs)
            if (qx - mx) ** 2 + (qz - mz) ** 2 > rad * rad:
                continue
            seen[r2 - r0, c2 - c0] = True
            qr[tail] = r2
            qc[tail] = c2
            tail += 1
    return best_x, best_z
