"""Any mesh through `load_scene` (glb, gltf + bin, ply, obj; z-up), up-axis configs and warnings, Basis
textures, and one-line errors for broken scene files (issue 11 items 1, 2, 5; issue 13 item 6)."""

from __future__ import annotations

import json
import shutil
import struct
import warnings
from pathlib import Path

import numpy as np
import pytest

from ovon.cli.main import main
from ovon.scenes.hm3dsem import SceneFileError, SceneLoadWarning, encode_glb, load_scene, write_scene
from tests.meshes import (
    mesh_from_boxes,
    room_boxes,
    to_z_up,
    write_glb,
    write_gltf_bin,
    write_trimesh,
)

FIXTURE = Path(__file__).parent / "fixtures" / "hm3dsem" / "00001-FixtureScn01"
KTX2 = Path(__file__).parent / "fixtures" / "basis" / "quadrants.ktx2"
ROOM = room_boxes(0.0, 0.0, 4.0, 3.0) + [((1.0, 0.0, 1.0), (1.8, 0.75, 1.6))]  # a room with a low box


def _room_mesh():
    m = mesh_from_boxes(ROOM)
    m.vertex_colors = np.tile(np.array([[200, 120, 40]], np.uint8), (len(m.vertices), 1))
    return m


def _quiet_load(path, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("error", SceneLoadWarning)  # an upright room must not warn
        return load_scene(path, **kw)


# ---------------------------------------------------------------------------------------- any mesh


@pytest.mark.parametrize("suffix", [".glb", ".gltf", ".ply", ".obj"])
def test_bare_mesh_formats_load_alike(tmp_path: Path, suffix: str) -> None:
    mesh = _room_mesh()
    path = tmp_path / f"room{suffix}"
    {".glb": write_glb, ".gltf": write_gltf_bin}.get(suffix, write_trimesh)(mesh, path)
    scene = _quiet_load(path)
    assert scene.scene_id == "room" and not scene.objects and scene.semantics_missing
    assert scene.floor_heights == pytest.approx([0.0], abs=1e-5)
    tri = np.sort(scene.mesh.vertices[scene.mesh.faces].reshape(-1, 9), axis=0)
    np.testing.assert_allclose(tri, np.sort(mesh.vertices[mesh.faces].reshape(-1, 9), axis=0), atol=1e-5)
    if suffix in (".glb", ".ply"):  # formats that carry vertex colours
        assert scene.mesh.vertex_colors is not None and (scene.mesh.vertex_colors[:, 0] == 200).all()
    from ovon.sim.navgrid import build_navigation

    g = build_navigation(scene).floors[0]
    assert g.navigable.sum() * g.cell_size**2 == pytest.approx((4 - 0.34) * (3 - 0.34) - 0.8 * 0.6, rel=0.15)
    with pytest.raises(ValueError, match="ObjectNav goals need semantic annotations.*room.semantic.txt"):
        scene.require_semantics()


def test_gltf_without_its_bin_names_the_file(tmp_path: Path) -> None:
    write_gltf_bin(_room_mesh(), tmp_path / "room.gltf")
    (tmp_path / "room.bin").unlink()
    with pytest.raises(FileNotFoundError, match=r"room\.bin is missing"):
        load_scene(tmp_path / "room.gltf")


def test_bare_mesh_commands(tmp_path: Path, capsys) -> None:
    write_glb(_room_mesh(), tmp_path / "room.glb")
    assert main(["scenes", "inspect", str(tmp_path / "room.glb"), "--nav"]) == 0
    out = capsys.readouterr().out
    assert "annotations" in out and "floor 0 navigable" in out
    assert main(["scenes", "inspect", str(tmp_path / "room.glb"), "--nav", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert "room.semantic.txt" in doc["annotations"] and doc["navigation"][0]["navigable_m2"] > 5
    png = tmp_path / "v.png"
    # a negative first number is a pose, not an option (issue 11 item 7)
    assert main(["sim", "view", str(tmp_path / "room.glb"), "--pose", "-0.0,0,1.5,90", "--out", str(png)]) == 0
    assert main(["sim", "view", str(tmp_path / "room.glb"), "--pose", "-3,0,2,90", "--out", str(png)]) == 0
    assert png.is_file()


def test_dataset_generation_says_which_scene_lacks_semantics(tmp_path: Path) -> None:
    from ovon.dataset.generate import generate
    from tests.conftest import tiny_generation_config

    (tmp_path / "w" / "val" / "00001-room").mkdir(parents=True)
    write_glb(_room_mesh(), tmp_path / "w" / "val" / "00001-room" / "room.glb")
    with pytest.raises(FileNotFoundError, match=r"00001-room has no semantic annotations.*ObjectNav episodes need"):
        generate(tmp_path / "w", tmp_path / "o", tiny_generation_config(), splits=("val_seen",), progress=False)


# ----------------------------------------------------------------------------------------- up axis


def test_z_up_mesh_warns_and_up_option_fixes_it(tmp_path: Path) -> None:
    write_glb(to_z_up(_room_mesh()), tmp_path / "zroom.glb")
    with pytest.warns(SceneLoadWarning, match="looks rotated.*--up z"):
        lying = load_scene(tmp_path / "zroom.glb")
    assert all(abs(h) < 100 for h in lying.floor_heights)  # never a made-up floor at -100 m
    upright = _quiet_load(tmp_path / "zroom.glb", up="z")
    assert upright.floor_heights == pytest.approx([0.0], abs=1e-5)
    np.testing.assert_allclose(upright.mesh.bounds()[1][1], 2.6, atol=1e-5)  # ceiling slab top, y up


def test_stage_and_scene_dataset_configs_give_the_up_axis(tmp_path: Path) -> None:
    folder = tmp_path / "stages"
    folder.mkdir()
    write_glb(to_z_up(_room_mesh()), folder / "zroom.glb")
    (folder / "zroom.stage_config.json").write_text(
        json.dumps({"render_asset": "zroom.glb", "up": [0, 0, 1], "front": [0, 1, 0]})
    )
    assert _quiet_load(folder / "zroom.glb").floor_heights == pytest.approx([0.0], abs=1e-5)
    (folder / "zroom.stage_config.json").unlink()
    (tmp_path / "d.scene_dataset_config.json").write_text(
        json.dumps({"stages": {"default_attributes": {"up": [0, 0, 1], "front": [0, 1, 0]}}})
    )
    assert _quiet_load(folder / "zroom.glb").floor_heights == pytest.approx([0.0], abs=1e-5)
    with pytest.raises(ValueError, match="--up 'q'"):
        load_scene(folder / "zroom.glb", up="q")


def test_mesh_without_horizontal_faces_has_no_floor(tmp_path: Path) -> None:
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)  # one vertical triangle
    (tmp_path / "wall.glb").write_bytes(encode_glb(v, np.array([[0, 1, 2]])))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneLoadWarning)
        scene = load_scene(tmp_path / "wall.glb")
    assert scene.floor_heights == []
    from ovon.scenes.inspect import summarize

    assert summarize(scene)["floors"] == []


# ---------------------------------------------------------------------------------------- textures


def _basis_glb(path: Path, ktx2: bytes) -> None:
    """A textured quad (4 x 4 m floor) whose texture is a KTX2/Basis image (KHR_texture_basisu)."""
    v = np.array([[0, 0, 0], [4, 0, 0], [4, 0, 4], [0, 0, 4]], np.float32)
    uv = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32)  # Mesh convention: v = 1 at the image top
    glb = encode_glb(v, np.array([[0, 2, 1], [0, 3, 2]]), uvs=uv, texture=np.zeros((2, 2, 3), np.uint8))
    jlen = struct.unpack_from("<I", glb, 12)[0]
    doc = json.loads(glb[20 : 20 + jlen])
    blob = bytearray(glb[28 + jlen :])
    view = doc["images"][0]["bufferView"]
    doc["bufferViews"][view]["byteOffset"] = len(blob)
    doc["bufferViews"][view]["byteLength"] = len(ktx2)
    blob += ktx2 + b"\0" * (-len(ktx2) % 4)
    doc["buffers"][0]["byteLength"] = len(blob)
    doc["images"][0]["mimeType"] = "image/ktx2"
    doc["textures"][0] = {"extensions": {"KHR_texture_basisu": {"source": 0}}, "sampler": 0}
    doc["extensionsUsed"] = ["KHR_texture_basisu"]
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    path.write_bytes(
        struct.pack("<4sII", b"glTF", 2, 28 + len(js) + len(blob))
        + struct.pack("<I4s", len(js), b"JSON")
        + js
        + struct.pack("<I4s", len(blob), b"BIN\x00")
        + bytes(blob)
    )


def test_basis_texture_is_decoded_and_rendered(tmp_path: Path) -> None:
    pytest.importorskip("opengl_basisu")
    _basis_glb(tmp_path / "floor.basis.glb", KTX2.read_bytes())
    scene = _quiet_load(tmp_path / "floor.basis.glb")
    tex = scene.mesh.texture
    assert tex is not None and tex.shape == (16, 16, 3)
    assert (np.abs(tex[2, 2].astype(int) - (255, 0, 0)) < 8).all() and (
        np.abs(tex[13, 13].astype(int) - (255, 255, 0)) < 8
    ).all()
    from ovon.config.sim import CameraConfig
    from ovon.sim.render import make_renderer

    r = make_renderer(scene, CameraConfig(width=32, height=32, hfov_deg=60.0, backend="embree"))
    frame = r.render(np.array([2.0, 3.0, 2.0]), 0.0, -np.pi / 2)  # straight down at the floor's centre
    rgb = frame.rgb.reshape(-1, 3).astype(int)
    assert frame.depth.min() > 0
    assert len({tuple(c // 64) for c in rgb}) >= 4  # the four quadrant colours, not flat grey


def test_undecodable_basis_falls_back_to_grey_with_a_warning(tmp_path: Path) -> None:
    _basis_glb(tmp_path / "floor.basis.glb", b"\xabKTX 20\xbb\r\n\x1a\n" + b"\0" * 40)  # a broken KTX2
    with pytest.warns(SceneLoadWarning, match="texture not decoded.*Basis/KTX2"):
        scene = load_scene(tmp_path / "floor.basis.glb")
    assert scene.mesh.texture is None and (scene.mesh.face_colors == 128).all()


# ------------------------------------------------------------------------------ broken scene files


def _fixture(tmp_path: Path) -> Path:
    dst = tmp_path / FIXTURE.name
    shutil.copytree(FIXTURE, dst)
    return dst


def _one_line(exc: BaseException, *needles: str) -> None:
    msg = str(exc)
    assert "\n" not in msg, msg
    for n in needles:
        assert n in msg, (n, msg)
    for bad in ("buffer is smaller than requested size", "Maximum allowed dimension exceeded"):
        assert bad not in msg
    assert not msg.startswith("'"), msg  # not a bare KeyError such as 'aabb_min'


def test_lfs_pointer_says_how_to_fetch(tmp_path: Path) -> None:
    p = tmp_path / "scan.glb"
    p.write_text("version https://git-lfs.github.com/spec/v1\noid sha256:" + "a" * 64 + "\nsize 123456789\n")
    with pytest.raises(SceneFileError) as e:
        load_scene(p)
    _one_line(e.value, "scan.glb", "Git LFS pointer", "123,456,789 bytes", "git lfs pull")
    q = tmp_path / "scan.ply"
    shutil.copy(p, q)
    with pytest.raises(SceneFileError, match="Git LFS pointer"):
        load_scene(q)


@pytest.mark.parametrize("cut", [10, 30, 200, -40])
def test_truncated_glb(tmp_path: Path, cut: int) -> None:
    data = (FIXTURE / "FixtureScn01.glb").read_bytes()
    p = tmp_path / "t.glb"
    p.write_bytes(data[:cut])
    with pytest.raises(SceneFileError) as e:
        load_scene(p)
    _one_line(e.value, "t.glb")
    assert "truncated" in str(e.value) or "corrupt" in str(e.value) or "not a GLB" in str(e.value)


def _edit_glb(src: Path, dst: Path, edit) -> None:  # noqa: ANN001
    from ovon.scenes.hm3dsem import _read_glb_file

    g = _read_glb_file(src)
    doc, blob = edit(g.doc, bytearray(g.bin))
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    dst.write_bytes(
        struct.pack("<4sII", b"glTF", 2, 28 + len(js) + len(blob))
        + struct.pack("<I4s", len(js), b"JSON")
        + js
        + struct.pack("<I4s", len(blob), b"BIN\x00")
        + bytes(blob)
    )


def test_corrupt_glb_contents(tmp_path: Path) -> None:
    src = tmp_path / "ok.glb"
    src.write_bytes(encode_glb(np.array([[0, 0, 0], [1, 0, 0], [0, 0, 1]], np.float32), np.array([[0, 2, 1]])))

    def bad_index(doc, blob):  # noqa: ANN001, ANN202
        acc = doc["accessors"][doc["meshes"][0]["primitives"][0]["indices"]]
        off = doc["bufferViews"][acc["bufferView"]]["byteOffset"]
        blob[off : off + 4] = struct.pack("<I", 99)
        return doc, blob

    def nan_vertex(doc, blob):  # noqa: ANN001, ANN202
        acc = doc["accessors"][doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]]
        off = doc["bufferViews"][acc["bufferView"]]["byteOffset"]
        blob[off : off + 4] = struct.pack("<f", float("nan"))
        return doc, blob

    def huge_count(doc, blob):  # noqa: ANN001, ANN202
        doc["accessors"][0]["count"] = 10**12
        return doc, blob

    def missing_key(doc, blob):  # noqa: ANN001, ANN202
        del doc["accessors"]
        return doc, blob

    for edit, needle in [
        (bad_index, "triangle index 99 is out of range"),
        (nan_vertex, "NaN or infinite"),
        (huge_count, "truncated or corrupt"),
        (missing_key, "corrupt glTF"),
    ]:
        dst = tmp_path / f"{edit.__name__}.glb"
        _edit_glb(src, dst, edit)
        with pytest.raises(SceneFileError) as e:
            load_scene(dst)
        _one_line(e.value, dst.name, needle)


def test_corrupt_ply_and_obj(tmp_path: Path) -> None:
    p = tmp_path / "bad.ply"
    p.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 100\nproperty float x\nend_header\n\x00")
    with pytest.raises(SceneFileError) as e:
        load_scene(p)
    _one_line(e.value, "bad.ply")
    o = tmp_path / "nan.obj"
    o.write_text("v 0 0 0\nv 1 0 nan\nv 0 0 1\nf 1 2 3\n")
    with pytest.raises(SceneFileError) as e:
        load_scene(o)
    _one_line(e.value, "nan.obj", "NaN")


def test_malformed_sidecar_and_semantic_txt(tmp_path: Path) -> None:
    from tests.test_hm3dsem import two_box_scene

    folder = write_scene(two_box_scene(), tmp_path / "s")
    side = folder / "TwoBoxes0042.ovon.json"
    doc = json.loads(side.read_text())
    del doc["objects"]["1"]["aabb_min"]
    side.write_text(json.dumps(doc))
    with pytest.raises(SceneFileError) as e:
        load_scene(folder)
    _one_line(e.value, "TwoBoxes0042.ovon.json", "object 1 lacks 'aabb_min'", "delete the sidecar")
    side.write_text(side.read_text()[:50])
    with pytest.raises(SceneFileError) as e:
        load_scene(folder)
    _one_line(e.value, "TwoBoxes0042.ovon.json", "not valid JSON")

    fx = _fixture(tmp_path)
    (fx / "FixtureScn01.semantic.txt").write_bytes(b"\x00\x01\x02binary")
    with pytest.raises(SceneFileError) as e:
        load_scene(fx)
    _one_line(e.value, "FixtureScn01.semantic.txt", "binary")


def test_cli_prints_one_line(tmp_path: Path, capsys) -> None:
    p = tmp_path / "t.glb"
    p.write_bytes((FIXTURE / "FixtureScn01.glb").read_bytes()[:300])
    assert main(["scenes", "inspect", str(p)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "t.glb" in err and "Traceback" not in err


def test_objectnav_env_on_a_bare_mesh_says_what_is_missing(tmp_path: Path) -> None:
    from ovon.scenes.hm3dsem import load_scene as load
    from ovon.task.episode import EpisodeSpec
    from ovon.task.goals import goal_instances

    write_glb(_room_mesh(), tmp_path / "room.glb")
    scene = load(tmp_path / "room.glb")
    with pytest.raises(ValueError, match=r"ObjectNav goals \('bed'\) need semantic annotations.*room.semantic.txt"):
        goal_instances(scene, EpisodeSpec("0", str(tmp_path / "room.glb"), "bed"))
