"""A binary min-heap on two flat arrays (keys, int values) for numba kernels: the Dijkstra of
`ovon.sim.geodesic` and the polygon A* of `ovon.sim.navmesh.pathfind` share it."""

from __future__ import annotations

from numba import njit


@njit(cache=True)
def heap_push(keys, vals, n, key, val):  # noqa: ANN001, ANN201
    """Push (key, val) onto the heap of size n (the arrays must have room); returns the new size."""
    k = n
    keys[k] = key
    vals[k] = val
    while k > 0:
        p = (k - 1) // 2
        if keys[p] <= keys[k]:
            break
        keys[p], keys[k] = keys[k], keys[p]
        vals[p], vals[k] = vals[k], vals[p]
        k = p
    return n + 1


@njit(cache=True)
def heap_pop(keys, vals, n):  # noqa: ANN001, ANN201
    """(smallest key, its value, new size) of a non-empty heap of size n."""
    key, val = keys[0], vals[0]
    n -= 1
    keys[0] = keys[n]
    vals[0] = vals[n]
    k = 0
    while True:
        c = 2 * k + 1
        if c >= n:
            break
        if c + 1 < n and keys[c + 1] < keys[c]:
            c += 1
        if keys[k] <= keys[c]:
            break
        keys[c], keys[k] = keys[k], keys[c]
        vals[c], vals[k] = vals[k], vals[c]
        k = c
    return key, val, n
