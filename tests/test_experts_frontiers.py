"""Frontiers and pockets: incremental updates equal a brute-force recomputation; pockets in m^2."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage

from ovon.experts import FrontierExpert, FrontierExpertConfig
from ovon.experts.gridsim import grid_from_arrays, rollout, room_grid
from ovon.maps.frontiers import FrontierMap
from ovon.maps.visibility import ExploredMap
from ovon.sim.types import AgentState


def brute_force(navigable, seen, cell_area, pocket_area):
    """Explored (seen + pockets) and frontier mask recomputed from scratch."""
    unexplored = navigable & ~seen
    lab, n = ndimage.label(unexplored)
    sizes = np.bincount(lab.ravel(), minlength=n + 1)
    small = np.flatnonzero(sizes * cell_area < pocket_area)
    small = small[small > 0]
    explored = seen | np.isin(lab, small)
    un = navigable & ~explored
    pad = np.pad(un, 1)
    near = pad[:-2, 1:-1] | pad[2:, 1:-1] | pad[1:-1, :-2] | pad[1:-1, 2:]
    return explored, explored & navigable & near


@pytest.mark.parametrize("seed", range(6))
def test_incremental_frontiers_match_brute_force(seed):
    rng = np.random.default_rng(seed)
    cs = 0.1
    free, nav = room_grid(120, 140, rng, room_m=3.0, cell_size=cs)
    em = ExploredMap(free, nav, cs, 42.0, 3.0)
    fm = FrontierMap(nav, em.explored, cs, 1.5)
    fm.reset()
    seen = em.explored.copy()  # initial pockets (small islands) only
    pts = np.argwhere(nav)
    for _ in range(40):
        r, c = pts[rng.integers(len(pts))]
        yaw = float(rng.uniform(-math.pi, math.pi))
        em.update(int(r), int(c), yaw)
        seen |= em.explored  # what visibility revealed (+ what was filled)
        fm.update(em.new_r, em.new_c)
        exp_explored, exp_frontier = brute_force(nav, seen, cs * cs, 1.5)
        assert np.array_equal(em.explored, exp_explored)
        assert np.array_equal(fm.frontier_mask(), exp_frontier)
        got = {(int(a), int(b)) for a, b in zip(fm.frontier_rows, fm.frontier_cols)}
        assert got == set(zip(*map(lambda v: v.tolist(), np.nonzero(exp_frontier))))


@pytest.mark.parametrize("cs", [0.05, 0.1])
@pytest.mark.parametrize("area,filled", [(1.0, True), (2.0, False)])
def test_pocket_threshold_in_square_metres(cs, area, filled):
    """A 1.0 m^2 unexplored pocket is filled, a 2.0 m^2 one is not, at both cell sizes."""
    n = int(round(8.0 / cs))
    nav = np.ones((n, n), dtype=bool)
    h = int(round(1.0 / cs))
    w = int(round(area / 1.0 / cs))
    r0, c0 = n // 3, n // 3
    explored = np.ones_like(nav)
    explored[r0 - 1 : r0 + h + 1, c0 - 1 : c0 + w + 1] = False  # pocket + a ring explored "now"
    fm = FrontierMap(nav, explored, cs, 1.5)
    fm.reset()
    ring = np.zeros_like(nav)
    ring[r0 - 1 : r0 + h + 1, c0 - 1 : c0 + w + 1] = True
    ring[r0 : r0 + h, c0 : c0 + w] = False
    explored |= ring
    rr, cc = np.nonzero(ring)
    fm.update(rr.astype(np.int32), cc.astype(np.int32))
    assert explored[r0 : r0 + h, c0 : c0 + w].all() == filled
    assert abs(h * w * cs * cs - area) < 1e-9
    assert (fm.n_frontier_cells == 0) == filled


@pytest.mark.parametrize("cs", [0.05, 0.1])
def test_small_islands_count_as_explored_at_reset(cs):
    n = int(round(8.0 / cs))
    nav = np.zeros((n, n), dtype=bool)
    one = int(round(1.0 / cs))
    nav[5 : 5 + one, 5 : 5 + one] = True  # 1 m^2 island: pocket
    r2 = 5 + one + 5
    nav[r2 : r2 + one, 5 : 5 + 2 * one] = True  # 2 m^2 island: not a pocket
    explored = np.zeros_like(nav)
    fm = FrontierMap(nav, explored, cs, 1.5)
    fm.reset()
    assert explored[5 : 5 + one, 5 : 5 + one].all()
    assert explored.sum() == one * one


def test_waypoint_is_the_middle_of_a_straight_frontier():
    nav = np.ones((40, 60), dtype=bool)
    explored = np.zeros_like(nav)
    explored[20:, 10:51] = True  # explored block; its top row borders unexplored cells
    explored[20:, :10] = False
    fm = FrontierMap(nav, explored, 0.1, 0.01)
    fm.reset()
    rr, cc = np.nonzero(explored)
    fm.update(rr.astype(np.int32), cc.astype(np.int32))
    fr = fm.frontiers()
    assert len(fr) == 1
    # frontier cells: row 20 cols 10..50, col 10 and col 50 down the sides (bordering unexplored)
    assert fr.rows[0] == 20 and abs(int(fr.cols[0]) - 30) <= 1


def _two_grids():
    rng = np.random.default_rng(3)
    fa, na = room_grid(100, 100, rng, room_m=2.5, cell_size=0.1)
    fb, nb_ = room_grid(90, 130, rng, room_m=2.5, cell_size=0.1)
    return grid_from_arrays(fa, na, 0.1), grid_from_arrays(fb, nb_, 0.1)


def test_state_fully_reset_between_episodes():
    """Upstream never cleared its frontier list between episodes."""
    ga, gb = _two_grids()
    ex = FrontierExpert(FrontierExpertConfig(beeline_distance_m=0.0))
    pa = np.argwhere(ga.navigable)
    start = AgentState(ga.cell_to_world(*pa[len(pa) // 2]), 0.0)
    far = ga.cell_to_world(*pa[-1])
    rollout(ex, ga, start, [(far, 0.0)], max_steps=60)
    assert ex.explored.sum() > 0 and ex.frontier_map.n_frontier_cells > 0
    pb = np.argwhere(gb.navigable)
    sb = AgentState(gb.cell_to_world(*pb[len(pb) // 2]), 0.0)
    ex.reset(gb, [(gb.cell_to_world(*pb[-1]), 0.0)], sb)
    fresh = FrontierExpert(FrontierExpertConfig(beeline_distance_m=0.0))
    fresh.reset(gb, [(gb.cell_to_world(*pb[-1]), 0.0)], sb)
    assert ex.explored.shape == gb.navigable.shape
    assert np.array_equal(ex.explored, fresh.explored)
    assert ex.frontier_map.n_frontier_cells == 0 and ex.target is None
    # same grid again: identical to a fresh expert, step for step
    ex.reset(ga, [(far, 0.0)], start)
    fresh.reset(ga, [(far, 0.0)], start)
    assert np.array_equal(ex.explored, fresh.explored) and ex.frontier_map.n_frontier_cells == 0
    s1, a1, _ = rollout(ex, ga, start, [(far, 0.0)], max_steps=40)
    s2, a2, _ = rollout(fresh, ga, start, [(far, 0.0)], max_steps=40)
    assert a1 == a2
