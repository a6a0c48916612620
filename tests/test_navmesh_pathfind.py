"""Polygon shortest paths on habitat navmeshes: habitat's own golden geodesics, and known geometry."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from ovon.sim.navmesh import read_navmesh
from ovon.sim.navmesh.pathfind import PathFinder
from tests.navmesh_files import grid_polys, make_navmesh, make_tile, rect

FIX = Path(__file__).parent / "fixtures" / "habitat"


def test_habitat_golden_geodesics_are_reproduced_exactly():
    pf = PathFinder(read_navmesh(FIX / "van-gogh-room.navmesh"))
    gold = json.loads((FIX / "test-sim-geodesic-distance-test-golden.json").read_text())
    cases = [(c["start"], c["end"], c["expected"]) for c in gold["single_end"]]
    cases += [(c["start"], c["ends"], c["expected"]) for c in gold["multi_end"]]
    assert len(cases) == 20
    for start, ends, expected in cases:
        ours = pf.geodesic_distance(start, ends)
        assert math.isfinite(ours) == math.isfinite(float(expected))
        if math.isfinite(ours):
            assert ours == pytest.approx(float(expected), rel=1e-5)  # float32 files: habitat's own rounding


def test_open_floor_paths_are_straight_and_corners_are_cut_exactly():
    strip = PathFinder(make_navmesh([make_tile(grid_polys(0, 0, 4, 0.5, 0.5))]))  # one row of squares
    assert strip.geodesic_distance([0.3, 0.0, 0.1], [3.7, 0.0, 0.4]) == pytest.approx(math.hypot(3.4, 0.3), abs=1e-5)
    # on a grid of small squares Detour's corridor (A* over portal midpoints) can miss the straight line and
    # the funnel then bends at a vertex, as in habitat: never shorter than the straight line, barely longer
    pf = PathFinder(make_navmesh([make_tile(grid_polys(0, 0, 4, 4, 0.5))]))
    d, e = pf.geodesic_distance([0.3, 0.0, 0.2], [3.7, 0.0, 3.1]), math.hypot(3.4, 2.9)
    assert e - 1e-6 <= d <= 1.005 * e
    # an L: the bar x in [0, 4], z in [0, 1] and the leg x in [3, 4], z in [1, 4]; from (0.5, 0.5) to (3.5, 3.5)
    # the shortest path bends once, at the inner corner (3, 1)
    polys = [rect(0, 0, 3, 1), rect(3, 0, 4, 1), rect(3, 1, 4, 4)]
    pf = PathFinder(make_navmesh([make_tile(polys)]))
    want = math.hypot(2.5, 0.5) + math.hypot(0.5, 2.5)
    assert pf.geodesic_distance([0.5, 0.0, 0.5], [3.5, 0.0, 3.5]) == pytest.approx(want, abs=1e-5)
    pts = pf.find_path([0.5, 0.0, 0.5], [3.5, 0.0, 3.5])
    assert len(pts) == 3 and np.allclose(pts[1], [3.0, 0.0, 1.0], atol=1e-5)
    # several goals: the nearest by path, not by straight line
    assert pf.geodesic_distance([0.5, 0.0, 0.5], [[3.5, 0.0, 3.5], [2.5, 0.0, 0.5]]) == pytest.approx(2.0, abs=1e-5)


def test_paths_cross_tile_borders_and_islands_are_unreachable():
    left = make_tile(grid_polys(0, 0, 2, 2, 1.0), tx=0, tile_size=2.0)
    right = make_tile(grid_polys(2, 0, 4, 2, 1.0), tx=1, tile_size=2.0)
    far = make_tile([rect(10, 0, 11, 1)], tx=5, tile_size=2.0)
    pf = PathFinder(make_navmesh([left, right, far], tile_size=2.0))
    assert pf.geodesic_distance([0.5, 0.0, 0.5], [3.5, 0.0, 1.5]) == pytest.approx(math.hypot(3.0, 1.0), abs=1e-5)
    assert pf.geodesic_distance([0.5, 0.0, 0.5], [10.5, 0.0, 0.5]) == math.inf


def test_navigability_follows_the_polygons():
    pf = PathFinder(make_navmesh([make_tile([rect(0, 0, 2, 1), rect(2, 0, 3, 3)], bump=0.05)]))
    assert pf.is_navigable([0.01, 0.0, 0.01]) and pf.is_navigable([2.99, 0.0, 2.99])  # a polygon's very corner
    assert not pf.is_navigable([1.0, 0.0, 2.0])  # beside the L, inside its bounding box
    assert not pf.is_navigable([1.0, 0.8, 0.5])  # over the floor but farther above it than 0.5 m
    snapped = pf.snap_point([1.0, 0.0, 2.0])
    assert snapped[2] == pytest.approx(1.0) and 0 <= snapped[1] <= 0.05
    assert np.isnan(pf.snap_point([50.0, 0.0, 50.0])).all()  # outside the pick box of every polygon


def test_a_scene_read_from_a_navmesh_answers_with_habitats_geodesic_by_default():
    from ovon.sim.geodesic import geodesic_distance
    from ovon.sim.navmesh import load_navmesh
    from ovon.sim.navmesh.agreement import HABITAT_AGENT, geodesic_agreement

    sn = load_navmesh(FIX / "van-gogh-room.navmesh", HABITAT_AGENT)
    case = json.loads((FIX / "test-sim-geodesic-distance-test-golden.json").read_text())["single_end"][0]
    assert geodesic_distance(sn, case["start"], case["end"]) == pytest.approx(case["expected"], rel=1e-5)
    assert geodesic_distance(sn, case["start"], case["end"], how="field") != pytest.approx(case["expected"], rel=1e-5)
    gold = json.loads((FIX / "test-sim-geodesic-distance-test-golden.json").read_text())
    row = geodesic_agreement(sn, gold, "navmesh")
    assert row["reachability_agrees"] == row["pairs"] == 20 and row["max_rel_error"] < 1e-5
    assert {"median_rel_error", "p95_rel_error"} <= row.keys()
    built = dataclasses.replace(sn, source="mesh")  # a scene built from triangles has no polygons to ask
    with pytest.raises(ValueError, match="'navmesh' needs a scene read from a habitat navmesh"):
        geodesic_distance(built, case["start"], case["end"], how="navmesh")


def test_steps_follow_the_polygons_as_habitats_do():
    from ovon.sim.agent import MOVE_FORWARD, Kinematics
    from ovon.sim.navmesh import load_navmesh
    from ovon.sim.navmesh.agreement import HABITAT_AGENT, trajectory_agreement
    from ovon.sim.types import AgentState

    sn = load_navmesh(FIX / "van-gogh-room.navmesh", HABITAT_AGENT)
    traj = json.loads((FIX / "habitat-sim_trajectory_data.json").read_text())
    on_polys, on_grid = (trajectory_agreement(sn, traj, how=h) for h in ("navmesh", "grid"))
    assert on_polys["steps"] == 57 and on_polys["max_xz_error_m"] < 1e-5  # habitat's, sliding included
    assert on_grid["mean_xz_error_m"] > 100 * on_polys["mean_xz_error_m"]
    # a move into the L's outer wall slides along it; a free move goes the whole way and does not collide
    pf = PathFinder(make_navmesh([make_tile([rect(0, 0, 3, 1), rect(3, 0, 4, 1), rect(3, 1, 4, 4)])]))
    end = pf.try_step([1.0, 0.0, 0.5], [1.2, 0.0, 1.5])
    assert end == pytest.approx([1.2, 0.0, 1.0], abs=1e-6)
    assert pf.try_step([3.5, 0.0, 0.5], [3.5, 0.0, 2.0]) == pytest.approx([3.5, 0.0, 2.0], abs=1e-6)
    kin = Kinematics(sn.floors[0], HABITAT_AGENT.__class__(forward_step=0.25, allow_sliding=True), surface=pf)
    step = kin.step(AgentState(np.array([3.5, 0.0, 0.1]), 0.0), MOVE_FORWARD)  # yaw 0: along -z, into the wall
    assert step.collided and step.state.position == pytest.approx([3.5, 0.0, 0.0], abs=1e-6)
    step = kin.step(AgentState(np.array([3.5, 0.0, 2.0]), 0.0), MOVE_FORWARD)
    assert not step.collided and step.state.position == pytest.approx([3.5, 0.0, 1.75], abs=1e-6)


def test_the_distance_to_goals_is_habitats_on_a_navmesh_scene_and_the_fields_elsewhere():
    from ovon.sim.geodesic import distance_field, distance_to_goals
    from ovon.sim.navmesh import load_navmesh
    from ovon.sim.navmesh.agreement import HABITAT_AGENT

    sn = load_navmesh(FIX / "van-gogh-room.navmesh", HABITAT_AGENT)
    gold = json.loads((FIX / "test-sim-geodesic-distance-test-golden.json").read_text())["single_end"]
    ends = np.array([c["end"] for c in gold[:6]])
    pf = PathFinder(read_navmesh(FIX / "van-gogh-room.navmesh"))
    field = distance_field(sn.grid_for(ends[0]), ends)
    measure = distance_to_goals(sn, field, ends)
    for c in gold:  # goals snapped once answer as the one-shot multi-goal query does, every start
        assert measure(c["start"]) == pf.geodesic_distance(c["start"], ends)
    reachable = [c for c in gold if math.isfinite(measure(c["start"]))]
    assert reachable and any(measure(c["start"]) != field.distance(c["start"]) for c in reachable)
    built = dataclasses.replace(sn, source="mesh")
    assert distance_to_goals(built, field, ends) == field.distance  # a scene from triangles: the grid's field
    far = pf.distance_to(np.array([[100.0, 0.0, 100.0]]))  # a goal outside every pick box reaches nothing
    assert far(gold[0]["start"]) == math.inf


def test_a_point_habitat_calls_navigable_is_navigable_and_a_valid_start_on_a_navmesh_scene():
    """The grid is a cache of the polygons: where its rasterisation left a cell blocked under a walkable
    polygon (next to the polygon's border), the scene still calls the point navigable and lets an episode
    start there, as habitat does."""
    from ovon.sim.navmesh import load_navmesh
    from ovon.sim.navmesh.agreement import HABITAT_AGENT

    sn = load_navmesh(FIX / "van-gogh-room.navmesh", HABITAT_AGENT)
    pf = PathFinder(read_navmesh(FIX / "van-gogh-room.navmesh"))
    rng = np.random.default_rng(0)
    lo, hi = pf.g.bmin.min(axis=0), pf.g.bmax.max(axis=0)
    on_polys = [p for p in (pf.snap_point(rng.uniform(lo, hi)) for _ in range(4000)) if np.isfinite(p).all()]
    blocked = [p for p in on_polys if pf.is_navigable(p) and not sn.grid_for(p).is_navigable(p)]
    assert blocked, "expected some polygon points in cells the grid leaves blocked"
    for p in blocked[:20]:
        assert sn.is_navigable(p) and sn.start_problem(p) is None
    p = blocked[0]
    assert "m from its floor's surface" in sn.start_problem(p + np.array([0.0, 0.6, 0.0]))
    off = np.array([hi[0] + 3.0, lo[1], hi[2] + 3.0])  # beyond the 2 m pick box
    assert not sn.is_navigable(off)
    assert np.isnan(sn.snap(off)).all()  # habitat's snap_point: nothing within the pick box
    q = p + np.array([0.0, 0.3, 0.0])
    assert sn.snap(q) == pytest.approx(pf.snap_point(q)) and sn.is_navigable(sn.snap(q))
    assert "not on a walkable polygon of the navmesh" in sn.start_problem(off)
    built = dataclasses.replace(sn, source="mesh")  # a scene from triangles asks its grid
    assert not built.is_navigable(p) and "not on the navigable map" in built.start_problem(p)
    from ovon.sim.navmesh.agreement import navigability_agreement

    row = navigability_agreement(sn, points=1500)  # what benchmarks/navmesh_agreement.py reports
    assert row["points"] > 500 and 0 < row["grid_blocked"] < 0.05
    assert row["scene_refuses"] == row["start_refused"] == 0.0


def test_steps_without_sliding_stop_at_the_wall_along_their_own_line():
    """habitat-sim's own PathFinderTest.tryStepNoSliding, on van-gogh-room: from random navigable points, ten
    steps each; every end is navigable and lies along the step (within 1 degree). On an L of squares the
    contact point is exact, and the Kinematics of a navmesh scene use it when sliding is off."""
    from ovon.sim.agent import MOVE_FORWARD, Kinematics
    from ovon.sim.navmesh import load_navmesh
    from ovon.sim.navmesh.agreement import HABITAT_AGENT
    from ovon.sim.types import AgentState

    pf = PathFinder(read_navmesh(FIX / "van-gogh-room.navmesh"))
    rng = np.random.default_rng(0)
    lo, hi = pf.g.bmin.min(axis=0), pf.g.bmax.max(axis=0)
    steps = stopped = 0
    while steps < 800:
        pos = pf.snap_point(rng.uniform(lo, hi))
        if not np.isfinite(pos).all():
            continue
        a = rng.uniform(-math.pi, math.pi)
        d = np.array([math.cos(a), 0.0, math.sin(a)]) * 0.25
        for _ in range(10):
            end = pf.try_step_no_sliding(pos, pos + d)
            steps += 1
            assert pf.is_navigable(end)
            m = (end - pos)[[0, 2]]
            if m @ m < 1e-5:
                stopped += 1
                break
            cos = float(m @ d[[0, 2]]) / (np.linalg.norm(m) * 0.25)
            assert math.degrees(math.acos(min(1.0, cos))) < 1.0
            pos = end
    assert stopped > 20  # walls were met
    pf = PathFinder(make_navmesh([make_tile([rect(0, 0, 3, 1), rect(3, 0, 4, 1), rect(3, 1, 4, 4)])]))
    assert pf.try_step_no_sliding([1.0, 0.0, 0.5], [1.2, 0.0, 1.5]) == pytest.approx([1.1, 0.0, 1.0], abs=1e-9)
    assert pf.try_step_no_sliding([2.5, 0.0, 0.5], [3.5, 0.0, 0.7]) == pytest.approx([3.5, 0.0, 0.7], abs=1e-9)
    sn = load_navmesh(FIX / "van-gogh-room.navmesh", HABITAT_AGENT)
    cfg = HABITAT_AGENT.__class__(forward_step=0.25, allow_sliding=False)
    kin = Kinematics(sn.floors[0], cfg, surface=pf)
    step = kin.step(AgentState(np.array([1.0, 0.0, 0.9]), math.atan2(-0.2, -1.0)), MOVE_FORWARD)  # +z, a bit +x
    assert step.collided and step.state.position == pytest.approx([1.02, 0.0, 1.0], abs=1e-9)  # stops at the wall
