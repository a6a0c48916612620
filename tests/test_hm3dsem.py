"""HM3DSem folder I/O: exact round trip of our scenes, reading a real-format fixture (painted semantic
texture, no sidecar), and clear errors for broken folders."""

from __future__ import annotations

import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest

from ovon.scenes import hm3dsem
from ovon.scenes.hm3dsem import SceneLoadWarning, find_scene_files, list_scenes, load_scene, write_scene
from ovon.scenes.model import Mesh, ObjectInstance, Region, Scene
from ovon.scenes.vocabulary import load_vocabulary

FIXTURE = Path(__file__).parent / "fixtures" / "hm3dsem" / "00001-FixtureScn01"


def _box(lo, hi) -> tuple[np.ndarray, np.ndarray]:
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    v = np.array([[x, y, z] for y in (y0, y1) for z in (z0, z1) for x in (x0, x1)], dtype=np.float64)
    f = [[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4]]
    f += [[2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]]
    return v, np.array(f)


def two_box_scene() -> Scene:
    """Floor slab + two boxes, awkward float32 coordinates, random face colours, a rotated OBB."""
    vocab = load_vocabulary()
    parts = [
        (3, "floor", (-5.0, -0.1, -5.0), (5.0, 0.0, 5.0)),
        (1, "couch", (0.0, 0.0, 0.0), (2.0, 0.8, 1.0)),
        (7, "table", (3.0, 0.0, 3.0), (3.5, 0.7, 4.2)),
    ]
    verts, faces, fi, objs = [], [], [], []
    for iid, label, lo, hi in parts:
        v, f = _box(lo, hi)
        faces.append(f + sum(len(x) for x in verts))
        verts.append(v + 0.1234567)
        fi += [iid] * len(f)
        lo_, hi_ = np.array(lo) + 0.1234567, np.array(hi) + 0.1234567
        yaw = 0.3 if iid == 7 else 0.0
        rot = np.array([[np.cos(yaw), 0, np.sin(yaw)], [0, 1, 0], [-np.sin(yaw), 0, np.cos(yaw)]])
        objs.append(
            ObjectInstance(iid, label, vocab.clean(label), lo_, hi_, (lo_ + hi_) / 2, (hi_ - lo_) / 2, rot,
                           region_id=0, region_name="living room", floor=0, color=(10, 20, iid))
        )  # fmt: skip
    rng = np.random.default_rng(0)
    faces_a = np.concatenate(faces).astype(np.int32)
    mesh = Mesh(
        vertices=np.concatenate(verts).astype(np.float32),
        faces=faces_a,
        face_colors=rng.integers(0, 256, (len(faces_a), 3)).astype(np.uint8),
        face_instance=np.array(fi, dtype=np.int32),
    )
    regions = [Region(0, "living room", 0, (-5.0, -5.0, 5.0, 5.0)), Region(1, "kitchen", 1, None)]
    return Scene("00042-TwoBoxes0042", mesh, objs, regions, [0.0, 3.1], source="procedural:42")


def assert_same_scene(a: Scene, b: Scene) -> None:
    assert b.scene_id == a.scene_id
    assert b.mesh.vertices.dtype == np.float32
    assert np.array_equal(b.mesh.vertices, a.mesh.vertices)  # bit-exact float32
    assert np.array_equal(b.mesh.faces, a.mesh.faces)  # same order
    if a.mesh.face_colors is not None:
        assert np.array_equal(b.mesh.face_colors, a.mesh.face_colors)
    assert b.semantic_mesh is None
    assert np.array_equal(b.mesh.face_instance, a.mesh.face_instance)
    assert b.floor_heights == a.floor_heights
    assert b.regions == a.regions
    assert len(b.objects) == len(a.objects)
    for oa, ob in zip(sorted(a.objects, key=lambda o: o.id), b.objects):
        assert (ob.id, ob.raw_label, ob.category) == (oa.id, oa.raw_label, oa.category)
        assert (ob.region_id, ob.region_name, ob.floor) == (oa.region_id, oa.region_name, oa.floor)
        for field in ("aabb_min", "aabb_max", "obb_center", "obb_half_extents", "obb_rotation"):
            assert np.array_equal(np.asarray(getattr(ob, field), float), np.asarray(getattr(oa, field), float)), field
        assert b.semantic_colors[ob.id] == ob.color


def test_round_trip_hand_built(tmp_path: Path) -> None:
    scene = two_box_scene()
    folder = write_scene(scene, tmp_path / scene.scene_id)
    names = sorted(p.name for p in folder.iterdir())
    assert names == ["TwoBoxes0042.glb", "TwoBoxes0042.ovon.json", "TwoBoxes0042.semantic.glb",
                     "TwoBoxes0042.semantic.txt"]  # fmt: skip
    txt = (folder / "TwoBoxes0042.semantic.txt").read_text().splitlines()
    assert txt[0] == "HM3D Semantic Annotations"
    assert txt[1] == '1,0A1401,"couch",0'
    with warnings.catch_warnings():
        warnings.simplefilter("error", SceneLoadWarning)
        for p in [folder, folder / "TwoBoxes0042.semantic.txt", folder / "TwoBoxes0042.glb"]:
            loaded = load_scene(p)
            assert_same_scene(scene, loaded)
    assert loaded.source == "procedural:42"
    assert loaded.object_by_id(3).category is None  # structural label


def test_written_glb_is_standard(tmp_path: Path) -> None:
    """Third-party readers see the same triangles and colours."""
    import pygltflib
    import trimesh

    scene = two_box_scene()
    folder = write_scene(scene, tmp_path / scene.scene_id)
    g = pygltflib.GLTF2().load(str(folder / "TwoBoxes0042.semantic.glb"))
    assert g.meshes[0].primitives[0].attributes.COLOR_0 is not None
    tm = trimesh.load(folder / "TwoBoxes0042.glb", force="mesh", process=False)
    assert len(tm.faces) == scene.mesh.num_faces
    tri_ours = scene.mesh.vertices[scene.mesh.faces]
    assert np.array_equal(np.asarray(tm.vertices, np.float32)[tm.faces], tri_ours)


def test_rewrite_is_atomic_and_stable(tmp_path: Path) -> None:
    scene = two_box_scene()
    folder = write_scene(scene, tmp_path / "s")
    first = {p.name: p.read_bytes() for p in folder.iterdir()}
    write_scene(load_scene(folder), folder)
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == first  # no temp files left, same bytes


def test_round_trip_generated_house(tmp_path: Path) -> None:
    from ovon.scenes.procedural import generate_house

    scene = generate_house(3)
    folder = write_scene(scene, tmp_path / scene.scene_id)
    loaded = load_scene(folder)
    assert_same_scene(scene, loaded)
    assert loaded.categories == scene.categories


def test_fixture_real_format() -> None:
    """HM3DSem v0.2-style folder: painted semantic texture, separate semantic mesh, no sidecar."""
    vocab = load_vocabulary()
    scene = load_scene(FIXTURE)
    assert scene.scene_id == "00001-FixtureScn01"
    sem = scene.semantic_mesh
    assert sem is not None and sem.texture is not None and sem.texture.shape == (4, 4, 3) and sem.uvs is not None
    # 4 boxes of 12 faces in PARTS order: floor(3), couch(1), upper floor(4), table(2)
    assert sem.face_instance.tolist() == [3] * 12 + [1] * 12 + [4] * 12 + [2] * 12
    assert scene.mesh.texture is not None and scene.mesh.uvs is not None  # visual: atlas of its materials
    assert scene.mesh.num_faces == 48
    assert scene.semantic_colors[2] == (0x1F, 0x77, 0xB4)
    by = {o.id: o for o in scene.objects}
    assert by[1].raw_label == "couch" and by[1].category == vocab.clean("couch") is not None
    assert by[2].category == vocab.clean("dining table") is not None
    assert by[3].category is None and by[4].category is None
    assert by[1].name == "couch_1"
    # node translation of the visual table was applied: both meshes agree on the world box
    assert np.allclose(scene.mesh.bounds()[1], [3.0, 3.75, 3.0])
    np.testing.assert_allclose(by[2].aabb_min, [0.5, 3.0, 0.5], atol=1e-6)
    np.testing.assert_allclose(by[2].aabb_max, [1.5, 3.75, 1.1], atol=1e-6)
    np.testing.assert_allclose(by[2].obb_half_extents, [0.5, 0.375, 0.3], atol=1e-6)
    np.testing.assert_allclose(by[2].obb_center, [1.0, 3.375, 0.8], atol=1e-6)
    # floors from upward horizontal faces; objects on the highest floor at or below them
    np.testing.assert_allclose(scene.floor_heights, [0.0, 3.0], atol=1e-6)
    assert (by[1].floor, by[2].floor) == (0, 1)
    assert [(r.id, r.name, r.floor) for r in scene.regions] == [(0, "region_0", 0), (1, "region_1", 1)]
    assert by[2].region_name == "region_1"


def test_texture_sampling_nearest() -> None:
    tex = np.zeros((4, 4, 3), np.uint8)
    tex[0, 3] = 255  # top-right texel (Mesh convention: v = 1 at the top)
    got = hm3dsem.sample_texture_nearest(tex, np.array([[0.9, 0.9], [0.1, 0.1], [1.9, -0.1]]))
    assert got[:, 0].tolist() == [255, 0, 255]


def test_yaw_obb_rotated_rectangle() -> None:
    yaw = 0.4
    rot = np.array([[np.cos(yaw), 0, -np.sin(yaw)], [0, 1, 0], [np.sin(yaw), 0, np.cos(yaw)]])
    corners = np.array([[sx * 1.0, sy * 0.5, sz * 0.25] for sx in (-1, 1) for sy in (0, 1) for sz in (-1, 1)])
    pts = corners @ rot.T + [2.0, 0.0, -1.0]
    center, half, r = hm3dsem.yaw_obb(pts)
    np.testing.assert_allclose(sorted(half), sorted([1.0, 0.25, 0.25]), atol=1e-9)
    np.testing.assert_allclose(center, [2.0, 0.25, -1.0], atol=1e-9)
    assert np.allclose(r @ r.T, np.eye(3)) and np.isclose(np.linalg.det(r), 1.0)


def _copy_fixture(tmp_path: Path) -> Path:
    dst = tmp_path / FIXTURE.name
    shutil.copytree(FIXTURE, dst)
    return dst


def test_malformed_semantic_txt(tmp_path: Path) -> None:
    folder = _copy_fixture(tmp_path)
    txt = folder / "FixtureScn01.semantic.txt"
    lines = txt.read_text().splitlines()
    lines[2] = "2,1F77B4,dining table,1"  # label not quoted
    txt.write_text("\n".join(lines) + "\n")
    with pytest.raises(ValueError) as e:
        load_scene(folder)
    msg = str(e.value)
    assert str(txt) in msg and ":3:" in msg and 'id,HEXCOLOR,"raw label",region_id' in msg


def test_missing_files(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="nowhere"):
        load_scene(tmp_path / "nowhere")
    folder = _copy_fixture(tmp_path)
    (folder / "FixtureScn01.semantic.glb").unlink()
    with pytest.raises(FileNotFoundError, match=r"FixtureScn01\.semantic\.glb"):
        load_scene(folder)
    (folder / "FixtureScn01.semantic.txt").unlink()
    # both annotation files gone: a bare mesh, which loads without objects (issue 11: any mesh)
    bare = load_scene(folder)
    assert not bare.objects and "FixtureScn01.semantic.txt" in bare.semantics_missing
    with pytest.raises(ValueError, match="ObjectNav goals need semantic annotations"):
        bare.require_semantics()
    (folder / "FixtureScn01.glb").unlink()
    with pytest.raises(FileNotFoundError, match="expected <id>.glb"):
        load_scene(folder)


def test_unknown_semantic_colour_is_id_zero(tmp_path: Path) -> None:
    folder = _copy_fixture(tmp_path)
    txt = folder / "FixtureScn01.semantic.txt"
    txt.write_text("".join(line + "\n" for line in txt.read_text().splitlines() if not line.startswith("2,")))
    with pytest.warns(SceneLoadWarning, match="12 semantic faces have colours missing"):
        scene = load_scene(folder)
    assert (scene.semantic_mesh.face_instance == 0).sum() == 12
    assert 2 not in {o.id for o in scene.objects}


def test_basis_texture_falls_back_to_grey(tmp_path: Path) -> None:
    """A .basis.glb whose textures are KTX2: geometry loads, colours fall back to grey with a warning."""
    import json
    import struct

    folder = _copy_fixture(tmp_path)
    src = folder / "FixtureScn01.glb"
    g = hm3dsem._read_glb_file(src)
    for img in g.doc["images"]:
        img["mimeType"] = "image/ktx2"
    js = json.dumps(g.doc).encode()
    js += b" " * ((-len(js)) % 4)
    data = struct.pack("<4sII", b"glTF", 2, 28 + len(js) + len(g.bin)) + struct.pack("<I4s", len(js), b"JSON") + js
    data += struct.pack("<I4s", len(g.bin), b"BIN\x00") + g.bin
    (folder / "FixtureScn01.basis.glb").write_bytes(data)
    src.unlink()
    with pytest.warns(SceneLoadWarning, match="texture not decoded"):
        scene = load_scene(folder)
    assert scene.mesh.texture is None and scene.mesh.face_colors is not None
    assert (scene.mesh.face_colors[:12] == 204).all()  # floor material keeps its base colour
    assert (scene.mesh.face_colors[12:24] == 128).all()  # textured couch: grey


def test_find_and_list(tmp_path: Path) -> None:
    files = find_scene_files(FIXTURE / "FixtureScn01.semantic.glb")
    assert files["stem"] == "FixtureScn01" and files["sidecar"] is None
    root = tmp_path / "hm3d"
    shutil.copytree(FIXTURE, root / "val" / FIXTURE.name)
    write_scene(two_box_scene(), root / "train" / "00042-TwoBoxes0042")
    assert [p.name for p in list_scenes(root)] == ["00042-TwoBoxes0042", "00001-FixtureScn01"]
    assert [p.name for p in list_scenes(root, "val")] == ["00001-FixtureScn01"]
    with pytest.raises(FileNotFoundError, match="splits found"):
        list_scenes(root, "minival")
