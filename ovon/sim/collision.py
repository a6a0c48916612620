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
