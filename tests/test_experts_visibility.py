"""Visibility of the frontier expert's explored map against an exact, slow reference.

The reference decides line of sight with exact rational arithmetic: a cell blocks the view when its
closed square meets the segment between the two cell centres (see ovon/maps/visibility.py).
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from ovon.maps.visibility import ExploredMap, cone_params


def _segment_meets_square(r0: int, c0: int, r1: int, c1: int, r: int, c: int) -> bool:
    """Closed square of cell (r, c) meets the segment between the centres of (r0, c0) and (r1, c1)."""
    lo, hi = Fraction(0), Fraction(1)
    for p0, p1, k in ((r0, r1, r), (c0, c1, c)):
        a = Fraction(2 * p0 + 1)
        d = Fraction(2 * (p1 - p0))
        s0, s1 = Fraction(2 * k), Fraction(2 * k + 2)
        if d == 0:
            if not (s0 <= a <= s1):
                return False
            continue
        t0, t1 = (s0 - a) / d, (s1 - a) / d
        if t0 > t1:
            t0, t1 = t1, t0
        lo, hi = max(lo, t0), min(hi, t1)
        if lo > hi:
            return False
    return True


def reference_visible(transparent, r0, c0, yaw, fov_deg, range_cells):
    fr, fc, cos_half = cone_params(yaw, fov_deg)
    rows, cols = transparent.shape
    out = set()
    for r in range(rows):
        for c in range(cols):
            dr, dc = r - r0, c - c0
            d2 = float(dr * dr + dc * dc)
            if d2 == 0:
                out.add((r, c))
                continue
            if d2 > range_cells * range_cells or dr * fr + dc * fc < cos_half * math.sqrt(d2):
                continue
            blocked = False
            for rr in range(min(r0, r), max(r0, r) + 1):
                for cc in range(min(c0, c), max(c0, c) + 1):
                    if (rr, cc) in ((r0, c0), (r, c)) or transparent[rr, cc]:
                        continue
                    if _segment_meets_square(r0, c0, r, c, rr, cc):
                        blocked = True
                        break
                if blocked:
                    break
            if not blocked:
                out.add((r, c))
    return out


def _cells(mask):
    return {(int(r), int(c)) for r, c in zip(*np.nonzero(mask))}


@settings(max_examples=150, deadline=None)
@given(
    rows=st.integers(3, 18),
    cols=st.integers(3, 18),
    density=st.floats(0.0, 0.5),
    seed=st.integers(0, 2**31 - 1),
    yaw=st.floats(-math.pi, math.pi),
    fov=st.floats(10.0, 170.0),
    range_cells=st.floats(1.0, 14.0),
)
def test_visibility_matches_exact_reference(rows, cols, density, seed, yaw, fov, range_cells):
    rng = np.random.default_rng(seed)
    transparent = rng.random((rows, cols)) >= density
    r0, c0 = int(rng.integers(rows)), int(rng.integers(cols))
    em = ExploredMap(transparent, transparent, 1.0, fov, range_cells)
    n = em.update(r0, c0, yaw)
    expect = reference_visible(transparent, r0, c0, yaw, fov, range_cells)
    assert _cells(em.explored) == expect
    assert n == len(expect)
    assert {(int(r), int(c)) for r, c in zip(em.new_r, em.new_c)} == expect


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), yaw1=st.floats(-math.pi, math.pi), yaw2=st.floats(-math.pi, math.pi))
def test_incremental_updates_are_the_union(seed, yaw1, yaw2):
    rng = np.random.default_rng(seed)
    transparent = rng.random((16, 16)) >= 0.25
    (ra, ca), (rb, cb) = rng.integers(16, size=(2, 2))
    em = ExploredMap(transparent, transparent, 0.1, 60.0, 1.0)
    em.update(int(ra), int(ca), yaw1)
    first = _cells(em.explored)
    n = em.update(int(rb), int(cb), yaw2)
    second = reference_visible(transparent, int(rb), int(cb), yaw2, 60.0, 10.0)
    assert _cells(em.explored) == first | second
    assert n == len(second - first)


def test_obstacle_free_cone_reveals_whole_sector():
    """Upstream's shadow cutting revealed nothing in an empty cone; the sector must be all there."""
    cs, rng_m, fov = 0.05, 3.0, 42.0
    free = np.ones((200, 200), dtype=bool)
    for yaw in np.linspace(-math.pi, math.pi, 13):
        em = ExploredMap(free, free, cs, fov, rng_m)
        n = em.update(100, 100, float(yaw))
        sector = math.pi * (rng_m / cs) ** 2 * fov / 360.0
        assert abs(n - sector) / sector < 0.03, (yaw, n, sector)
        assert n == em.explored.sum()


def test_wall_blocks_and_pitch_free():
    """A wall across the view hides everything behind it; cells in front stay visible."""
    free = np.ones((80, 80), dtype=bool)
    free[20, :] = False  # wall 20 rows "ahead" (yaw 0 looks toward decreasing rows)
    em = ExploredMap(free, free, 0.1, 90.0, 6.0)
    em.update(40, 40, 0.0)
    assert em.explored[21:40, 40].all()
    assert em.explored[20, 40]  # the wall face itself is seen
    assert not em.explored[:20].any()


def test_update_touches_only_the_cone_box():
    free = np.ones((1000, 1000), dtype=bool)
    em = ExploredMap(free, free, 0.05, 42.0, 3.0)
    em.update(500, 500, 0.7)
    r, c = np.nonzero(em.explored)
    assert np.hypot(r - 500, c - 500).max() <= 60.0 + 1e-9
    assert em.update(500, 500, 0.7) == 0  # nothing new from the same pose
