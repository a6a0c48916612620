"""habitat navmesh files (written here byte for byte as habitat-sim writes them): the reader, habitat's
area and island definitions, the per-floor grids, bad files, and scenes that carry a navmesh."""

from __future__ import annotations

import json
import math
import struct
from dataclasses import astuple, replace
from pathlib import Path

import numpy as np
import pytest
import torch

from ovon.config.sim import AgentConfig, NavConfig, SimConfig
from ovon.sim.geodesic import geodesic_distance
from ovon.sim.navgrid import build_navigation
from ovon.sim.navmesh import (
    NavMeshError,
    NavMeshSettings,
    NavMeshWarning,
    compute_islands,
    load_navmesh,
    navmesh_summary,
    read_navmesh,
    write_navmesh,
)
from ovon.sim.navmesh.format import FLAG_DOOR, FLAG_WALK, navmesh_bytes
from tests.meshes import room_boxes, scene_from_boxes, write_glb
from tests.navmesh_files import cells_to_polys, grid_polys, make_navmesh, make_tile, rect

torch.set_num_threads(1)
AGENT = AgentConfig(radius=0.1)  # the radius the test navmeshes are baked for (no NavMeshWarning)
pytestmark = pytest.mark.filterwarnings("error::ovon.sim.navmesh.NavMeshWarning")


def write(tmp_path: Path, mesh, name: str = "t.navmesh") -> Path:  # noqa: ANN001
    return write_navmesh(mesh, tmp_path / name)


# ------------------------------------------------------------------------------------------- format


@pytest.mark.parametrize("version", [1, 2])
def test_byte_layout_and_round_trip(tmp_path, version):
    settings = NavMeshSettings(agent_radius=0.18, agent_height=0.88, cell_size=0.04)
    tile = make_tile(grid_polys(0, 0, 2, 1, 0.5), bump=0.1)
    path = write(tmp_path, make_navmesh([tile], version=version, settings=settings))
    data = path.read_bytes()
    # habitat's NavMeshSetHeader: 'MSET' little-endian, version, tile count, dtNavMeshParams (28 bytes)
    assert data[:4] == b"TESM" and struct.unpack_from("<ii", data, 4) == (version, 1)
    off = 40 + (56 if version == 2 else 0)  # NavMeshSettings: 13 floats + 4 bools, padded to 56
    ref, size = struct.unpack_from("<Ii", data, off)
    assert ref != 0 and off + 8 + size == len(data)
    body = data[off + 8 :]
    assert body[:4] == b"VAND" and struct.unpack_from("<i", body, 4)[0] == 7  # dtMeshHeader 'DNAV', version 7
    npoly, nvert, nlink, ndetail, ndv, ndt = struct.unpack_from("<6i", body, 24)
    # dtAlign4 blocks: header 100, verts 12, polys 32, links 12, detail meshes 12, detail verts 12, tris 4
    assert size == 100 + 12 * nvert + 32 * npoly + 12 * nlink + 12 * ndetail + 12 * ndv + 4 * ndt
    m = read_navmesh(path)
    assert m.version == version and len(m.tiles) == 1
    if version == 2:  # stored as float32
        assert astuple(m.settings) == pytest.approx(astuple(settings))
    else:
        assert m.settings is None
    t = m.tiles[0]
    np.testing.assert_array_equal(t.verts, tile.verts)
    np.testing.assert_array_equal(t.polys, tile.polys)
    np.testing.assert_array_equal(t.detail_verts, tile.detail_verts)
    np.testing.assert_array_equal(t.detail_tris, tile.detail_tris)
    assert navmesh_bytes(m) == data  # what we read is everything the file holds
    assert m.agent_radius() == pytest.approx(0.18 if version == 2 else 0.1)


def test_detail_mesh_area_and_heights(tmp_path):
    """Habitat's area is the 3D area of the detail triangles; the grid's heights follow them too."""
    bump = 0.2
    path = write(tmp_path, make_navmesh([make_tile([rect(0, 0, 2, 2)], bump=bump)]))
    isl = compute_islands(read_navmesh(path))
    # four triangles from the square's edges up to a centre raised by `bump`: base 2, slant height sqrt(1 + bump^2)
    assert isl.total_area == pytest.approx(4 * 0.5 * 2 * math.sqrt(1 + bump**2), rel=1e-6)
    g = load_navmesh(path, AGENT).floors[0]
    assert float(g.heights[g.world_to_cell([1.0, 0, 1.0])]) == pytest.approx(bump, abs=0.011)
    assert float(g.heights[g.world_to_cell([0.05, 0, 1.0])]) == pytest.approx(0.05 * bump, abs=0.011)


def _habitat_radius(polys) -> float:  # noqa: ANN001
    """habitat: max distance from the centroid of every polygon's vertices (counted per polygon)."""
    v = np.array([p for poly in polys for p in poly], dtype=np.float64)
    return float(np.linalg.norm(v - v.mean(axis=0), axis=1).max())


def test_islands_areas_radii_and_flags(tmp_path):
    a, b = grid_polys(0, 0, 4, 3, 1.0), grid_polys(5, 0, 8, 2, 1.0)
    door = [rect(9, 0, 10, 1)]  # a third, separate polygon without the WALK flag
    flags = [FLAG_WALK] * (len(a) + len(b)) + [FLAG_DOOR]
    path = write(tmp_path, make_navmesh([make_tile(a + b + door, flags=flags)]))
    isl = compute_islands(read_navmesh(path))
    assert isl.count == 3  # habitat starts an island at every unvisited polygon, walkable or not
    np.testing.assert_allclose(isl.area, [12.0, 6.0, 0.0])
    np.testing.assert_allclose(isl.radius, [_habitat_radius(a), _habitat_radius(b), _habitat_radius(door)], rtol=1e-6)
    s = navmesh_summary(path)
    assert s["navigable_area_m2"] == pytest.approx(18.0) and s["num_islands"] == 3
    sn = load_navmesh(path, AGENT)
    g = sn.floors[0]
    assert g.num_islands == 2 and not g.is_navigable([9.5, 0, 0.5])  # the non-walkable polygon is not rasterised
    assert math.isinf(geodesic_distance(sn, [1, 0, 1], [6, 0, 1]))
    assert geodesic_distance(sn, [0.5, 0, 0.5], [3.5, 0, 2.5]) == pytest.approx(math.hypot(3, 2), rel=0.01)


@pytest.mark.parametrize("version", [1, 2])
def test_multi_tile_portals_connect(tmp_path, version):
    """Two 2 m tiles; the polygons on their shared border link only through portals (Detour's ext links)."""
    t0 = make_tile(grid_polys(0, 0, 2, 2, 0.5), 0, 0, tile_size=2.0)
    t1 = make_tile(grid_polys(2, 0, 4, 2, 0.5), 1, 0, tile_size=2.0)
    path = write(tmp_path, make_navmesh([t0, t1], version=version, tile_size=2.0))
    m = read_navmesh(path)
    assert len(m.tiles) == 2 and compute_islands(m).count == 1
    sn = load_navmesh(path, AGENT)
    assert sn.floors[0].num_islands == 1
    assert geodesic_distance(sn, [0.3, 0, 1.0], [3.7, 0, 1.0], how="path") == pytest.approx(3.4, rel=0.005)
    # a border step higher than the tiles' walkable climb (0.2 m) is not a portal: two islands, both in
    # Detour's links and in the grid (the cells along the step are dropped)
    t2 = make_tile(grid_polys(2, 0, 4, 2, 0.5, y=0.5), 1, 0, tile_size=2.0)
    high = write(tmp_path, make_navmesh([t0, t2], version=version, tile_size=2.0), "step.navmesh")
    assert compute_islands(read_navmesh(high)).count == 2
    assert math.isinf(geodesic_distance(load_navmesh(high, AGENT), [1.0, 0, 1.0], [3.0, 0.5, 1.0]))
    # tiles two apart are not neighbours: their border edges face nothing
    t3 = make_tile(grid_polys(4, 0, 6, 2, 0.5), 2, 0, tile_size=2.0)
    apart = write(tmp_path, make_navmesh([t0, t3], version=version, tile_size=2.0), "apart.navmesh")
    assert compute_islands(read_navmesh(apart)).count == 2


def test_grid_is_not_eroded_again_and_floors_split(tmp_path):
    ground = grid_polys(0, 0, 4, 2, 1.0)
    upper = grid_polys(0, 0, 4, 2, 1.0, y=3.0)
    path = write(tmp_path, make_navmesh([make_tile(ground + upper)]))
    sn = load_navmesh(path, AGENT)
    assert [round(g.height, 2) for g in sn.floors] == [0.0, 3.0]
    g0 = sn.floors[0]
    # cell centres on the polygon are navigable right up to its edge: no second radius erosion
    assert g0.is_navigable([0.01, 0.0, 1.0]) and g0.is_navigable([3.99, 0.0, 1.0])
    assert g0.narrow.sum() == 0
    assert g0.navigable.sum() * g0.cell_size**2 == pytest.approx(8.0, rel=0.06)
    assert sn.floor_index([1, 3.0, 1]) == 1 and sn.floor_index([1, 0.0, 1]) == 0
    assert math.isinf(geodesic_distance(sn, [1, 0, 1], [1, 3, 1]))
    # the line-of-sight mask is the navigable area grown back by the radius the navmesh was eroded with
    assert g0.free[g0.world_to_cell([-0.07, 0, 1.0])] and not g0.free[g0.world_to_cell([-0.17, 0, 1.0])]
    assert g0.in_bounds(*g0.world_to_cell([-0.17, 0, 1.0]))
    # a scene's floor heights number the floors
    assert [g.floor for g in load_navmesh(path, AGENT, floor_heights=[0.0, 3.0]).floors] == [0, 1]


def test_radius_mismatch_warns(tmp_path):
    path = write(tmp_path, make_navmesh([make_tile([rect(0, 0, 1, 1)], radius=0.1)], version=1))
    with pytest.warns(NavMeshWarning, match="eroded for an agent radius of 0.100 m"):
        load_navmesh(path, AgentConfig(radius=0.3))


# ------------------------------------------------------------------------------------------ bad files


def _good(tmp_path: Path) -> bytes:
    return write(tmp_path, make_navmesh([make_tile(grid_polys(0, 0, 2, 2, 1.0), bump=0.1)])).read_bytes()


def _tile_offset(version: int = 2) -> int:
    return 40 + (56 if version == 2 else 0) + 8


def _corrupt(data: bytes, what: str) -> bytes:
    b = bytearray(data)
    t = _tile_offset()
    if what == "magic":
        b[:4] = b"glTF"
    elif what == "version":
        struct.pack_into("<i", b, 4, 3)
    elif what == "nan":
        struct.pack_into("<f", b, t + 100 + 4, float("nan"))  # y of vertex 0
    elif what == "missing vertex":
        struct.pack_into("<H", b, t + 100 + 12 * 9 + 4, 999)  # poly 0, its first vertex index
    elif what == "tile magic":
        b[t : t + 4] = b"XXXX"
    elif what == "detail index":
        nvert, npoly, nlink, ndetail, ndv = (struct.unpack_from("<i", b, t + o)[0] for o in (28, 24, 32, 36, 40))
        tris = t + 100 + 12 * nvert + 32 * npoly + 12 * nlink + 12 * ndetail + 12 * ndv
        b[tris] = 200
    return bytes(b)


@pytest.mark.parametrize(
    "what, message",
    [
        ("magic", "not a habitat-sim navmesh: magic 'glTF'"),
        ("version", "unsupported navmesh version 3"),
        ("nan", "vertex 0 is not finite"),
        ("missing vertex", "polygon 0 references vertex 999 but the tile has 9"),
        ("tile magic", "tile 0: tile magic"),
        ("detail index", "has a detail triangle on vertex 200"),
    ],
)
def test_bad_files_are_one_line(tmp_path, what, message):
    path = tmp_path / "bad.navmesh"
    path.write_bytes(_corrupt(_good(tmp_path), what))
    with pytest.raises(NavMeshError) as e:
        read_navmesh(path)
    assert message in str(e.value) and str(path) in str(e.value) and "\n" not in str(e.value)


@pytest.mark.parametrize("cut", [3, 20, 60, 100, 200, -1])
def test_truncated_files(tmp_path, cut):
    data = _good(tmp_path)
    path = tmp_path / "cut.navmesh"
    path.write_bytes(data[:cut])
    with pytest.raises(NavMeshError, match="too short|truncated"):
        read_navmesh(path)


def test_lfs_pointer_and_missing_file(tmp_path):
    lfs = tmp_path / "lfs.navmesh"
    lfs.write_text("version https://git-lfs.github.com/spec/v1\noid sha256:abc\nsize 28192\n")
    with pytest.raises(NavMeshError, match="Git LFS pointer.*28,192 bytes.*git lfs pull"):
        load_navmesh(lfs)
    with pytest.raises(NavMeshError, match="navmesh file does not exist"):
        read_navmesh(tmp_path / "nope.navmesh")


def test_cli_inspect_navmesh(tmp_path, capsys):
    from ovon.cli.main import main

    a, b = grid_polys(0, 0, 4, 3, 1.0), grid_polys(5, 0, 8, 2, 1.0)
    path = write(tmp_path, make_navmesh([make_tile(a + b)]))
    assert main(["scenes", "inspect", str(path), "--nav"]) == 0
    out = capsys.readouterr().out
    assert "18.000 m²" in out and "12.000" in out and "6.000" in out and "ovon grid floor 0" in out
    assert main(["scenes", "inspect", str(path), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["num_islands"] == 2 and doc["navigable_area_m2"] == pytest.approx(18.0)
    bad = tmp_path / "bad.navmesh"
    bad.write_bytes(b"TESM" + b"\0" * 8)
    assert main(["scenes", "inspect", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("ovon: error:") and "bad.navmesh" in err and "truncated" in err


# -------------------------------------------------------------------------------- scenes with a navmesh


def _room_scene():
    return scene_from_boxes(room_boxes(0, 0, 6, 4), floor_heights=[0.0], scene_id="room")


def _navmesh_of(scene, cs: float = 0.1):  # noqa: ANN001
    """A navmesh of the scene's own navigable area, one square polygon per cell, baked for radius 0.1."""
    g = build_navigation(scene, AGENT, NavConfig(cell_size=cs, source="mesh")).floors[0]
    return make_navmesh([make_tile(cells_to_polys(g.navigable, g.origin, cs, g.heights))]), g


def test_scene_uses_the_navmesh_beside_its_mesh(tmp_path):
    from ovon.scenes.hm3dsem import load_scene

    scene = _room_scene()
    write_glb(scene.mesh, tmp_path / "room.glb")
    mesh, g = _navmesh_of(scene)
    loaded = load_scene(tmp_path / "room.glb")
    assert loaded.navmesh == ""
    assert build_navigation(loaded, AGENT).source == "mesh"
    write_navmesh(mesh, tmp_path / "room.basis.navmesh")
    loaded = load_scene(tmp_path / "room.glb")
    assert loaded.navmesh == str(tmp_path / "room.basis.navmesh")
    sn = build_navigation(loaded, AGENT, NavConfig(cell_size=0.1))  # source auto: the navmesh
    assert sn.source == loaded.navmesh
    rr, cc = np.nonzero(g.navigable)  # the same cells, not eroded twice
    centres = np.stack([g.origin[0] + (cc + 0.5) * 0.1, np.zeros(len(rr)), g.origin[1] + (rr + 0.5) * 0.1], axis=1)
    r2, c2 = sn.floors[0].world_to_cell(centres)
    assert sn.floors[0].navigable[r2, c2].all() and sn.floors[0].navigable.sum() == len(rr)
    assert build_navigation(loaded, AGENT, NavConfig(cell_size=0.1, source="mesh")).source == "mesh"
    write_navmesh(mesh, tmp_path / "room.navmesh")  # <id>.navmesh is preferred to <id>.basis.navmesh
    assert load_scene(tmp_path / "room.glb").navmesh == str(tmp_path / "room.navmesh")


def test_navmesh_source_errors(tmp_path):
    scene = _room_scene()
    with pytest.raises(ValueError, match="sim.nav.source=navmesh but scene room has no habitat navmesh"):
        build_navigation(scene, AGENT, NavConfig(source="navmesh"))
    far = make_navmesh([make_tile(grid_polys(50, 50, 54, 53, 1.0))])
    scene.navmesh = str(write(tmp_path, far, "far.navmesh"))
    with pytest.raises(NavMeshError, match="lies outside the scene mesh"):
        build_navigation(scene, AGENT)
    from ovon.config.base import ConfigError, build

    with pytest.raises(ConfigError, match="nav.source.*'recast'.*'auto', 'navmesh', 'mesh'"):
        build(SimConfig, overrides=["nav.source=recast"])


def test_episode_and_expert_on_a_navmesh_scene(tmp_path):
    """Everything downstream of navigability runs unchanged: starts, goal fields, the env and the expert."""
    from ovon.config.sim import CameraConfig
    from ovon.config.task import TaskConfig
    from ovon.env import ObjectNavEnv
    from ovon.experts import ShortestPathExpert
    from ovon.experts.gridsim import rollout
    from ovon.sim.agent import MOVE_FORWARD, STOP
    from ovon.sim.navmesh.pathfind import path_finder
    from ovon.sim.world import build_world
    from ovon.task.episode import EpisodeSpec
    from ovon.task.setup import prepare_episode
    from tests.test_env_scene import objects_scene

    scene = objects_scene("couch-navmesh")
    mesh, _ = _navmesh_of(scene, cs=0.05)
    scene.navmesh = str(write(tmp_path, mesh, "couch.navmesh"))
    sim = SimConfig(agent=AGENT, camera=CameraConfig(width=32, height=24, hfov_deg=60.0))
    world = build_world(scene, sim)
    try:
        assert world.nav.source == scene.navmesh
        for seed in range(3):
            setup = prepare_episode(world, EpisodeSpec("nm", scene.scene_id, "couch"), np.random.default_rng(seed),
                                    TaskConfig(), 60.0)  # fmt: skip
            assert world.nav.is_navigable(setup.state.position)
            # the episode's distance-to-goal is habitat's DistanceToGoal: the polygons' multi-goal geodesic
            pts = np.stack([v.position for v in setup.viewpoints])
            setup.tracker.reset(setup.state.position)
            d0 = path_finder(world.nav.source).geodesic_distance(setup.state.position, pts)
            assert setup.tracker.d0 == d0 and math.isfinite(d0)
            assert setup.tracker.d0 != setup.goal_field.distance(setup.state.position)  # the grid's field differs
            goals = [(v.position, 0.0) for v in setup.viewpoints]
            states, actions, _ = rollout(ShortestPathExpert(), setup.grid, setup.state, goals, 300)
            assert actions[-1] == STOP
            assert setup.goal_field.distance(states[-1].position) < 0.25
    finally:
        world.close()
    env = ObjectNavEnv(scene=scene, goal="couch", sim=sim, task=TaskConfig(max_steps=5))
    try:
        env.reset(seed=0)
        obs, _, _, _, info = env.step(MOVE_FORWARD)
        assert obs["depth"].shape[:2] == (24, 32)
    finally:
        env.close()


def test_sliding_follows_a_diagonal_wall(tmp_path):
    """Sliding ends at the navigable point nearest to the target (habitat's moveAlongSurface), whatever the
    wall's direction: along a 45-degree wall the agent keeps moving along it."""
    from ovon.sim.agent import MOVE_FORWARD, Kinematics
    from ovon.sim.types import AgentState

    tri = [(0.0, 0.0, 0.0), (0.0, 0.0, 4.0), (4.0, 0.0, 4.0)]  # walkable where z >= x
    sn = load_navmesh(write(tmp_path, make_navmesh([make_tile([tri])])), AGENT, NavConfig(cell_size=0.02))
    cfg = replace(AGENT, allow_sliding=True)
    kin = Kinematics(sn.floors[0], cfg)  # the grid's own sliding (no polygon surface)
    s = AgentState(np.array([1.0, 0.0, 1.3]), math.radians(-90.0))  # yaw -90: heading +x, into the wall
    for _ in range(6):
        s = kin.step(s, MOVE_FORWARD).state
        assert sn.floors[0].is_navigable(s.position)  # on the grid it slides on
    # one free step to x = 1.25; the next ends at the wall point nearest to its target, (1.4, 1.4); then each
    # step pushes 0.25 m into the 45-degree wall and slides 0.25 * cos(45 deg), i.e. +0.125 in x and in z
    assert s.position[0] == pytest.approx(1.4 + 4 * 0.125, abs=0.03)
    assert s.position[2] - s.position[0] == pytest.approx(0.0, abs=0.03)


@pytest.mark.slow
def test_episode_generation_on_a_navmesh_scene(tmp_path):
    """`ovon dataset generate` on an HM3D-layout scene whose navmesh sits beside it: the episodes are
    generated on the navmesh's grids and validate."""
    from ovon.dataset.generate import generate
    from ovon.dataset.validate import validate_dataset
    from ovon.scenes.hm3dsem import load_scene, write_scene
    from ovon.scenes.procedural import HouseConfig, generate_house
    from tests.conftest import tiny_generation_config

    root = tmp_path / "ovon_world"
    scene = generate_house(80000, cfg=HouseConfig(min_rooms=4, max_rooms=5, second_floor_prob=0.0))
    folder = root / "val" / scene.scene_id
    write_scene(scene, folder)
    agent = AgentConfig()
    sn = build_navigation(scene, agent, NavConfig(source="mesh"))
    tiles = [make_tile(cells_to_polys(g.navigable, g.origin, g.cell_size, g.heights)) for g in sn.floors]
    stem = scene.scene_id.split("-", 1)[1]
    write_navmesh(make_navmesh(tiles, settings=NavMeshSettings(agent_radius=agent.radius)), folder / f"{stem}.navmesh")
    assert build_navigation(load_scene(folder), agent).source == str(folder / f"{stem}.navmesh")
    out = tmp_path / "episodes"
    generate(root, out, tiny_generation_config(), splits=("val_seen",), workers=1, progress=False)
    rep = validate_dataset(out, root)
    assert rep.ok, rep.errors[:5]
    assert rep.episodes > 5
