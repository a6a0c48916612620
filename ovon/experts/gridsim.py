"""A 2D kinematic simulation on a navigability grid, for expert tests, benchmarks and fast rollouts.

Why: the experts only need the grid and the true pose; rolling them out without rendering measures
their own cost and behaviour. `grid_from_arrays` wraps bool maps into a real `NavGrid`
and `room_grid` makes house-like maps of any size.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from ovon.config.sim import AgentConfig
from ovon.sim.agent import STOP, Kinematics
from ovon.sim.navgrid import NavGrid
from ovon.sim.types import AgentState


def grid_from_arrays(
    free: np.ndarray,
    navigable: np.ndarray,
    cell_size: float,
    origin: tuple[float, float] = (0.0, 0.0),
    height: float = 0.0,
) -> NavGrid:
    """A real `NavGrid` (one flat floor) from bool arrays, for tests, benchmarks and fast rollouts."""
    nav = np.ascontiguousarray(navigable, dtype=bool)
    free = np.ascontiguousarray(free, dtype=bool) | nav
    labels, n = ndimage.label(nav)
    islands = labels.astype(np.int32) - 1
    rr, cc = np.nonzero(nav)
    lab = labels[rr, cc] - 1
    cnt = np.bincount(lab, minlength=n).astype(np.float64)
    x = origin[0] + (cc + 0.5) * cell_size
    z = origin[1] + (rr + 0.5) * cell_size
    mx = np.bincount(lab, weights=x, minlength=n) / np.maximum(cnt, 1)
    mz = np.bincount(lab, weights=z, minlength=n) / np.maximum(cnt, 1)
    radius = np.zeros(n)
    np.maximum.at(radius, lab, np.hypot(x - mx[lab], z - mz[lab]))
    return NavGrid(
        floor=0,
        height=float(height),
        origin=np.asarray(origin, dtype=np.float64),
        cell_size=float(cell_size),
        navigable=nav,
        free=free,
        heights=np.where(free, np.float32(height), np.float32(np.nan)).astype(np.float32),
        islands=islands,
        island_area=cnt * cell_size * cell_size,
        island_radius=radius,
    )


def rollout(
    expert,
    grid: NavGrid,
    start: AgentState,
    viewpoints,
    max_steps: int = 500,
    agent: AgentConfig | None = None,
) -> tuple[list[AgentState], list[int], int]:
    """Run `expert` from `start` with the simulator's kinematics; (states, actions, collisions)."""
    kin = Kinematics(grid, agent or AgentConfig())
    state = start.copy()
    expert.reset(grid, viewpoints, state)
    states = [state]
    actions: list[int] = []
    collisions = 0
    for _ in range(max_steps):
        a = int(expert.act(state))
        actions.append(a)
        if a == STOP:
            break
        res = kin.step(state, a)
        state = res.state
        collisions += int(res.collided)
        states.append(state)
    return states, actions, collisions


def room_grid(
    rows: int,
    cols: int,
    rng: np.random.Generator,
    room_m: float = 4.0,
    cell_size: float = 0.05,
    door_m: float = 1.0,
    wall_m: float = 0.15,
    clutter: int = 3,
    erode_m: float = 0.17,
) -> tuple[np.ndarray, np.ndarray]:
    """House-like (free, navigable) maps: a grid of rooms with doors and some furniture blocks."""
    free = np.ones((rows, cols), dtype=bool)
    wall = max(1, int(round(wall_m / cell_size)))
    room = max(4 * wall, int(round(room_m / cell_size)))
    door = max(2, int(round(door_m / cell_size)))
    free[:wall] = free[-wall:] = False
    free[:, :wall] = free[:, -wall:] = False
    for r in range(room, rows - wall, room):
        free[r : r + wall] = False
    for c in range(room, cols - wall, room):
        free[:, c : c + wall] = False
    # doors: one per wall segment between neighbouring rooms (random position)
    for r in range(room, rows - wall, room):
        for c0 in range(0, cols, room):
            c1 = min(cols, c0 + room)
            if c1 - c0 > door + 2 * wall and rng.random() < 0.85:
                s = int(rng.integers(c0 + wall, c1 - door - wall + 1))
                free[r : r + wall, s : s + door] = True
    for c in range(room, cols - wall, room):
        for r0 in range(0, rows, room):
            r1 = min(rows, r0 + room)
            if r1 - r0 > door + 2 * wall and rng.random() < 0.85:
                s = int(rng.integers(r0 + wall, r1 - door - wall + 1))
                free[s : s + door, c : c + wall] = True
    # furniture
    n_rooms = max(1, (rows // room) * (cols // room))
    for _ in range(clutter * n_rooms):
        h = int(rng.integers(max(2, room // 10), max(3, room // 4)))
        w = int(rng.integers(max(2, room // 10), max(3, room // 4)))
        r = int(rng.integers(0, max(1, rows - h)))
        c = int(rng.integers(0, max(1, cols - w)))
        free[r : r + h, c : c + w] = False
    free[:wall] = free[-wall:] = False
    free[:, :wall] = free[:, -wall:] = False
    k = int(round(erode_m / cell_size))
    if k > 0:
        y, x = np.ogrid[-k : k + 1, -k : k + 1]
        nav = ndimage.binary_erosion(free, structure=(x * x + y * y) <= k * k, border_value=0)
    else:
        nav = free.copy()
    return free, nav
