"""Navigability grids on hand-built meshes with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from ovon.config.sim import AgentConfig, NavConfig
from ovon.sim.navgrid import build_navigation, clear_cache
from tests.meshes import empty_floor, room_boxes, scene_from_boxes, wall_x_with_gap

R = AgentConfig().radius
CS = NavConfig().cell_size


def _island_at(g, x, z) -> int:
    return g.island_of(np.array([x, 0.0, z]))


def test_box_room_area_and_one_island():
    nav = build_navigation(scene_from_boxes(room_boxes(0, 0, 5, 4), floor_heights=[0.0]))
    assert len(nav.floors) == 1
    g = nav.floors[0]
    area = g.navigable.sum() * CS * CS
    expected = (5 - 2 * R) * (4 - 2 * R)
    assert abs(area - expected) < (2 * (5 + 4)) * CS  # one cell around the perimeter
    assert g.num_islands == 1
    assert abs(g.island_area[0] - area) < 1e-9
    assert g.island_radius[0] == pytest.approx(np.hypot(5 - 2 * R, 4 - 2 * R) / 2, abs=2 * CS)
    # walls are not free, the interior is; outside the house has no floor
    assert g.free[g.world_to_cell([2.5, 0, 2.0])] and not g.free[g.world_to_cell([0.0, 0, 2.0])]
    assert not g.is_navigable([-1.0, 0, 2.0]) and not g.is_navigable([100.0, 0, 100.0])
    assert g.is_navigable([R + 0.05, 0, 2.0]) and not g.is_navigable([R - 0.05, 0, 2.0])
    assert g.height == 0.0 and g.heights[g.world_to_cell([2.5, 0, 2.0])] == pytest.approx(0.0)


def test_roof_is_not_a_floor_without_hints():
    nav = build_navigation(scene_from_boxes(room_boxes(0, 0, 5, 4)))  # no floor_heights
    assert len(nav.floors) == 1 and nav.floors[0].height == pytest.approx(0.0)


@pytest.mark.parametrize("width,islands", [(0.30, 2), (0.40, 2), (0.45, 2), (0.50, 1), (0.90, 1)])
def test_doorway_width(width, islands):
    boxes = room_boxes(0, 0, 10, 4) + wall_x_with_gap(5.0, 0, 4, 1.5, 1.5 + width)
    g = build_navigation(scene_from_boxes(boxes, floor_heights=[0.0])).floors[0]
    assert g.num_islands == islands
    same = _island_at(g, 2.0, 2.0) == _island_at(g, 8.0, 2.0)
    assert same == (islands == 1)


@pytest.mark.parametrize("step,connected", [(0.15, False), (0.05, True), (0.10, True)])
def test_step_height(step, connected):
    boxes = room_boxes(0, 0, 6, 4) + [((3.0, 0.0, 0.0), (6.0, step, 4.0))]
    g = build_navigation(scene_from_boxes(boxes, floor_heights=[0.0])).floors[0]
    a, b = _island_at(g, 1.5, 2.0), _island_at(g, 4.5, 2.0)
    assert a >= 0 and b >= 0
    assert (a == b) == connected
    assert g.heights[g.world_to_cell([4.5, 0, 2.0])] == pytest.approx(step, abs=1e-5)


def test_low_ceiling_blocks_floor_under_it():
    # a slab 1.0..1.2 m over x 2..3: under it no clearance; its top (1.3 m to the ceiling) is no floor either
    boxes = room_boxes(0, 0, 5, 4) + [((2.0, 1.0, 1.0), (3.0, 1.2, 3.0))]
    g = build_navigation(scene_from_boxes(boxes, floor_heights=[0.0])).floors[0]
    r, c = g.world_to_cell(np.array([[2.5, 0, 2.0], [2.1, 0, 1.1], [2.9, 0, 2.9]]))
    assert not g.navigable[r, c].any() and not g.free[r, c].any()
    assert g.num_islands == 1
    assert g.is_navigable([1.0, 0, 2.0]) and g.is_navigable([4.0, 0, 2.0])


def test_table_top_is_a_separate_island():
    # a 1 m high table top with head room above it: the floor under it is blocked; its top is an island
    boxes = room_boxes(0, 0, 5, 4, wall_height=3.0) + [((2.0, 0.95, 1.0), (3.0, 1.0, 3.0))]
    g = build_navigation(scene_from_boxes(boxes, floor_heights=[0.0])).floors[0]
    main = _island_at(g, 1.0, 2.0)
    top = _island_at(g, 2.5, 2.0)
    assert main >= 0 and top >= 0 and top != main
    assert g.heights[g.world_to_cell([2.5, 0, 2.0])] == pytest.approx(1.0, abs=1e-5)


def test_two_stacked_floors():
    boxes = room_boxes(0, 0, 5, 4) + room_boxes(0, 0, 5, 4, floor_y=3.0)
    for hints in ([0.0, 3.0], []):
        nav = build_navigation(scene_from_boxes(boxes, floor_heights=hints))
        assert [round(g.height, 3) for g in nav.floors] == [0.0, 3.0]
        for g in nav.floors:
            assert g.num_islands == 1
            assert g.island_area[0] == pytest.approx((5 - 2 * R) * (4 - 2 * R), abs=18 * CS)
        assert nav.floor_index([2.5, 0.0, 2.0]) == 0
        assert nav.floor_index([2.5, 1.2, 2.0]) == 0
        assert nav.floor_index([2.5, 3.0, 2.0]) == 1
        assert nav.floor_index([2.5, 4.0, 2.0]) == 1
        assert nav.grid_for([2.5, 3.0, 2.0]) is nav.floors[1]
        assert nav.floors[1].heights[nav.floors[1].world_to_cell([2.5, 3, 2])] == pytest.approx(3.0)


def test_world_cell_roundtrip_and_vectorised():
    g = build_navigation(scene_from_boxes(empty_floor(5, 4), floor_heights=[0.0])).floors[0]
    pts = np.array([[1.01, 0, 2.02], [3.33, 0, 0.51]])
    rows, cols = g.world_to_cell(pts)
    for p, r, c in zip(pts, rows, cols):
        assert (r, c) == g.world_to_cell(p)
        q = g.cell_to_world(r, c)
        assert abs(q[0] - p[0]) <= CS / 2 + 1e-9 and abs(q[2] - p[2]) <= CS / 2 + 1e-9
    assert g.in_bounds(rows, cols).all()
    assert not g.in_bounds(-1, 0)


def test_snap_and_random_point_respects_min_island_radius():
    big = room_boxes(0, 0, 5, 4)
    small = room_boxes(8, 0, 9.5, 1.5)
    g = build_navigation(scene_from_boxes(big + small, floor_heights=[0.0])).floors[0]
    assert g.num_islands == 2
    small_id = _island_at(g, 8.75, 0.75)
    assert small_id >= 0 and g.island_radius[small_id] < 1.5
    rng = np.random.default_rng(0)
    picked = {g.island_of(g.random_point(rng, min_island_radius=1.5)) for _ in range(300)}
    assert small_id not in picked and len(picked) == 1
    picked_all = [g.island_of(g.random_point(rng)) for _ in range(300)]
    assert small_id in picked_all and all(g.is_navigable(g.random_point(rng)) for _ in range(50))
    with pytest.raises(ValueError):
        g.random_point(rng, min_island_radius=100.0)
    # a point inside a wall snaps to a navigable cell next to it; a navigable point to its own cell
    s = g.snap([0.0, 0.0, 2.0])
    assert g.is_navigable(s) and abs(s[0] - R) < 2 * CS and abs(s[2] - 2.0) < CS
    p = np.array([2.51, 0.0, 2.02])
    assert np.allclose(g.snap(p), g.cell_to_world(*g.world_to_cell(p)))


def test_line_of_sight():
    boxes = room_boxes(0, 0, 10, 4) + wall_x_with_gap(5.0, 0, 4, 3.0, 4.0)
    g = build_navigation(scene_from_boxes(boxes, floor_heights=[0.0])).floors[0]
    a = g.world_to_cell([2.0, 0, 1.0])
    b = g.world_to_cell([8.0, 0, 1.0])
    c = g.world_to_cell([2.0, 0, 3.5])
    d = g.world_to_cell([8.0, 0, 3.5])
    assert not g.line_of_sight(a, b)
    assert g.line_of_sight(c, d) and g.line_of_sight(a, c) and g.line_of_sight(a, a)
    assert not g.line_of_sight(a, (-5, 3))
    assert g.line_of_sight(a, b, mask=np.ones_like(g.navigable))


def test_cache_returns_same_object_and_disk_cache(tmp_path):
    scene = scene_from_boxes(empty_floor(3, 3), floor_heights=[0.0])
    a = build_navigation(scene)
    assert build_navigation(scene) is a
    assert build_navigation(scene, AgentConfig(radius=0.3)) is not a
    assert not list(tmp_path.iterdir())  # no folder given: nothing on disk
    clear_cache()
    b = build_navigation(scene, cache_dir=tmp_path)
    assert [p.name for p in tmp_path.iterdir()] == [f"nav_{b.key}.npz"]  # no temp file left behind
    clear_cache()
    c = build_navigation(scene, cache_dir=tmp_path)
    assert c is not b
    assert np.array_equal(c.floors[0].navigable, a.floors[0].navigable)
    assert np.array_equal(c.floors[0].islands, a.floors[0].islands)


def _torn(path):  # what kill -9 during a non-atomic write leaves: half a zip
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


def _other_keys(path):  # a readable npz that is not a grid cache (another version's layout)
    np.savez(path.open("wb"), something=np.zeros(3))


@pytest.mark.parametrize(
    "damage",
    [_torn, lambda p: p.write_bytes(b""), lambda p: p.write_bytes(b"PK\x03\x04junk"), _other_keys],
    ids=["torn", "empty", "garbage", "other-keys"],
)
def test_a_corrupt_cache_file_is_a_miss_rebuilt_and_replaced(tmp_path, damage):
    scene = scene_from_boxes(room_boxes(0, 0, 4, 3), floor_heights=[0.0])
    clear_cache()
    good = build_navigation(scene, cache_dir=tmp_path)
    path = tmp_path / f"nav_{good.key}.npz"
    damage(path)
    clear_cache()
    again = build_navigation(scene, cache_dir=tmp_path)  # BadZipFile / EOFError / KeyError: all a miss
    assert np.array_equal(again.floors[0].navigable, good.floors[0].navigable)
    with np.load(path) as z:  # the bad file was replaced by a good one
        assert int(z["n"]) == 1 and np.array_equal(z["free0"], good.floors[0].free)
    clear_cache()
    assert np.array_equal(build_navigation(scene, cache_dir=tmp_path).floors[0].islands, good.floors[0].islands)


def test_two_processes_building_the_same_scene_at_once_both_succeed(tmp_path):
    """Both compute, write and re-read the same cache file at the same moments (a start barrier, then
    rounds that clear the in-process cache): unique temp names + rename, so no one reads a torn file."""
    import json
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    go = tmp_path / "go"
    script = (
        "import sys, time, zlib\n"
        "from pathlib import Path\n"
        "from ovon.sim.navgrid import build_navigation, clear_cache\n"
        "from tests.meshes import room_boxes, scene_from_boxes\n"
        "scene = scene_from_boxes(room_boxes(0, 0, 6, 5), floor_heights=[0.0])\n"
        "while not Path(sys.argv[1]).exists(): time.sleep(0.01)\n"
        "sums = set()\n"
        "for _ in range(12):\n"
        "    clear_cache()\n"
        "    sums.add(zlib.crc32(build_navigation(scene, cache_dir=sys.argv[2]).floors[0].navigable.tobytes()))\n"
        "print(sorted(sums))\n"
    )
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", script, str(go), str(tmp_path / "nav")],
            cwd=root,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for _ in range(2)
    ]
    go.touch()
    outs = [p.communicate(timeout=300) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], [e[-2000:] for _, e in outs]
    assert outs[0][0] == outs[1][0] and len(json.loads(outs[0][0])) == 1  # one answer, the same in both
    assert [p.suffix for p in (tmp_path / "nav").iterdir()] == [".npz"]  # one file, no temp files left


def test_ten_cm_gap_is_not_a_connection():
    """A doorway 10 cm wider than the agent (0.44 m): the agent's centre has a 10 cm strip, which a
    0.25 m / 30 deg agent cannot drive (its heading can be 15 deg off the strip): not connected, and the
    strip is reported as `narrow`."""
    from ovon.sim.navgrid import min_drivable_width

    assert min_drivable_width(AgentConfig()) == pytest.approx(2 * 0.25 * np.sin(np.radians(15)))
    boxes = room_boxes(0, 0, 8, 4) + wall_x_with_gap(4.0, 0, 4, 1.5, 1.5 + 2 * R + 0.10)
    g = build_navigation(scene_from_boxes(boxes, floor_heights=[0.0])).floors[0]
    assert g.num_islands == 2 and _island_at(g, 2.0, 2.0) != _island_at(g, 6.0, 2.0)
    assert g.narrow[g.world_to_cell([4.0, 0.0, 1.5 + R + 0.05])]
    wide = room_boxes(0, 0, 8, 4) + wall_x_with_gap(4.0, 0, 4, 1.5, 2.2)
    assert build_navigation(scene_from_boxes(wide, floor_heights=[0.0])).floors[0].num_islands == 1


def test_table_top_and_box_interior_are_no_start_islands():
    boxes = room_boxes(0, 0, 8, 6, wall_height=3.0)
    boxes += [((1.0, 0.95, 1.0), (3.0, 1.0, 2.5))]  # a table top with head room: an elevated island
    # a closed box (a cupboard the agent fits in) whose interior is a small island at floor level
    boxes += [
        ((5.0, 0.0, 1.0), (7.0, 3.0, 1.1)),
        ((5.0, 0.0, 2.9), (7.0, 3.0, 3.0)),
        ((5.0, 0.0, 1.1), (5.1, 3.0, 2.9)),
        ((6.9, 0.0, 1.1), (7.0, 3.0, 2.9)),
    ]
    g = build_navigation(scene_from_boxes(boxes, floor_heights=[0.0])).floors[0]
    top, inside, main = _island_at(g, 2.0, 1.75), _island_at(g, 6.0, 2.0), _island_at(g, 4.0, 4.5)
    assert len({top, inside, main}) == 3 and min(top, inside, main) >= 0
    assert g.elevated()[top] and not g.elevated()[inside] and not g.elevated()[main]
    assert set(g.start_islands(1.5).tolist()) == {main}
    rng = np.random.default_rng(0)
    assert {g.island_of(g.random_point(rng)) for _ in range(300)} <= {main, inside}  # never the table top
