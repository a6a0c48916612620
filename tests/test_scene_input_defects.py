"""Bad scene input gets one clear line before any work starts (audit defects D5-D9, D13, D15): label
tables (ids past int32, shared colours, BOM, bytes that are not UTF-8), meshes in mm / cm, glTF node
transforms and index types, a pre-flight of every scene of a generation, and warnings that name the file.
"""

from __future__ import annotations

import json
import shutil
import struct
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from ovon.cli.main import main
from ovon.scenes.hm3dsem import SceneFileError, SceneLoadWarning, encode_glb, load_scene, parse_semantic_txt

FIXTURE = Path(__file__).parent / "fixtures" / "hm3dsem" / "00001-FixtureScn01"
HEADER = "HM3D Semantic Annotations\n"
# the fixture's semantic.txt: couch 9A9CAA, dining table 1F77B4, two floors
TABLE = '1,9A9CAA,"couch",0\n2,1F77B4,"dining table",1\n3,FF7F0E,"floor",0\n4,2CA02C,"floor",1\n'
QUAD = np.array([[0, 0, 0], [4, 0, 0], [4, 0, 4], [0, 0, 4]], np.float32)  # a 4 m floor quad
QUAD_FACES = np.array([[0, 2, 1], [0, 3, 2]])


def preflight_scene(path: Path) -> dict:
    """`ovon.scenes.hm3dsem.load.preflight_scene`, imported when called (each test fails on its own when
    it is missing)."""
    from ovon.scenes.hm3dsem.load import preflight_scene as check

    return check(path)


def _fixture(tmp_path: Path, table: bytes | None = None) -> Path:
    dst = tmp_path / FIXTURE.name
    shutil.copytree(FIXTURE, dst)
    if table is not None:
        (dst / "FixtureScn01.semantic.txt").write_bytes(table)
    return dst


def _one_line(exc: BaseException, *needles: str) -> None:
    msg = str(exc)
    assert "\n" not in msg, msg
    for n in needles:
        assert n in msg, (n, msg)


def _cli_error(argv: list[str], capsys: pytest.CaptureFixture[str], *needles: str) -> None:
    """The command exits 2 with one `ovon: error:` line holding the needles (no internal error)."""
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err and err[-1].startswith("ovon: error: "), err
    for n in needles:
        assert n in err[-1], (n, err[-1])


def _edited_glb(path: Path, edit: Callable[[dict], None], vertices: np.ndarray = QUAD) -> Path:
    """A GLB of the quad whose JSON document `edit` changed in place."""
    from ovon.scenes.hm3dsem import _read_glb_file

    src = path.with_name("src_" + path.name)
    src.write_bytes(encode_glb(vertices, QUAD_FACES))
    g = _read_glb_file(src)
    edit(g.doc)
    js = json.dumps(g.doc).encode()
    js += b" " * (-len(js) % 4)
    path.write_bytes(
        struct.pack("<4sII", b"glTF", 2, 28 + len(js) + len(g.bin))
        + struct.pack("<I4s", len(js), b"JSON")
        + js
        + struct.pack("<I4s", len(g.bin), b"BIN\x00")
        + g.bin
    )
    src.unlink()
    return path


# ------------------------------------------------------------------------------- D5-D7 semantic.txt


def test_d5_instance_id_beyond_int32_names_file_line_and_value(tmp_path: Path, capsys) -> None:
    folder = _fixture(tmp_path, (HEADER + '3000000000,9A9CAA,"couch",0\n2,1F77B4,"dining table",1\n').encode())
    with pytest.raises(SceneFileError) as e:
        load_scene(folder)
    _one_line(e.value, "FixtureScn01.semantic.txt:2", "3000000000", "fix:")
    _cli_error(["scenes", "inspect", str(folder)], capsys, "FixtureScn01.semantic.txt:2", "3000000000")
    (folder / "FixtureScn01.semantic.txt").write_text(HEADER + '1,9A9CAA,"couch",4294967296\n')
    with pytest.raises(SceneFileError) as e:
        parse_semantic_txt(folder / "FixtureScn01.semantic.txt")
    _one_line(e.value, "semantic.txt:2", "region id 4294967296")
    (folder / "FixtureScn01.semantic.txt").write_text(HEADER + '2147483647,9A9CAA,"couch",-1\n')
    assert parse_semantic_txt(folder / "FixtureScn01.semantic.txt")[0].id == 2**31 - 1  # the largest id is fine


def test_d6_two_instances_with_one_colour_load_as_habitat_reads_them(tmp_path: Path) -> None:
    """habitat-sim's HM3D loader keeps the first line of a colour (a std::map insert): the later instance gets
    no faces. ovon does the same and says so, instead of refusing a label table habitat reads, or (as it
    once did) silently giving the faces to the later instance."""
    plain = {o.id: o for o in load_scene(_fixture(tmp_path / "a")).objects}
    folder = _fixture(tmp_path / "b", (HEADER + '1,9A9CAA,"couch",0\n2,9a9caa,"dining table",1\n').encode())
    with pytest.warns(SceneLoadWarning) as said:
        scene = load_scene(folder)
    line = next(str(w.message) for w in said if "share a colour" in str(w.message))
    assert "FixtureScn01.semantic.txt" in line and "instance 2 ('dining table', colour 9A9CAA) with instance 1" in line
    objects = {o.id: o for o in scene.objects}
    assert 2 not in objects and objects[1].raw_label == "couch"
    np.testing.assert_array_equal(objects[1].aabb_min, plain[1].aabb_min)
    np.testing.assert_array_equal(objects[1].aabb_max, plain[1].aabb_max)


def test_d7_byte_order_mark_is_accepted(tmp_path: Path) -> None:
    plain = {o.raw_label for o in load_scene(_fixture(tmp_path / "a")).objects}
    folder = _fixture(tmp_path / "b", b"\xef\xbb\xbf" + (HEADER + TABLE).encode())
    with warnings.catch_warnings():
        warnings.simplefilter("error", SceneLoadWarning)
        assert {o.raw_label for o in load_scene(folder).objects} == plain == {"couch", "dining table", "floor"}


def test_d7_label_bytes_not_utf8_warn_naming_file_and_line(tmp_path: Path) -> None:
    txt = tmp_path / "x.semantic.txt"
    txt.write_bytes((HEADER + '1,9A9CAA,"couch",0\n').encode() + b'2,1F77B4,"caf\xe9 table",1\n')
    with pytest.warns(SceneLoadWarning, match=r"x\.semantic\.txt: line\(s\) 3 hold bytes that are not UTF-8.*fix"):
        entries = parse_semantic_txt(txt)
    assert [e.raw_label for e in entries] == ["couch", "caf\ufffd table"]
    txt.write_bytes((HEADER + TABLE).encode("utf-16"))
    with pytest.raises(SceneFileError) as e:
        parse_semantic_txt(txt)
    _one_line(e.value, "x.semantic.txt", "UTF-16", "re-save it as UTF-8")


# ------------------------------------------------------------------------------------- D8 mm / cm


def test_d8_mesh_in_millimetres_is_refused_before_the_grid(tmp_path: Path, capsys) -> None:
    from ovon.scenes.hm3dsem.load import MAX_SCENE_SPAN_M

    mm = tmp_path / "mm.glb"
    mm.write_bytes(encode_glb(QUAD * 1000, QUAD_FACES))
    with pytest.raises(SceneFileError) as e:
        load_scene(mm)
    _one_line(
        e.value,
        "mm.glb",
        "4,000 x 4,000 m",
        f"max {MAX_SCENE_SPAN_M:g} m",
        "millimetres",
        "4.0 x 4.0 m",
        "scale the mesh to metres",
    )
    _cli_error(["scenes", "inspect", str(mm), "--nav"], capsys, "mm.glb", "millimetres")
    _cli_error(["sim", "view", str(mm), "--out", str(tmp_path / "v.png")], capsys, "mm.glb", "millimetres")
    ok = tmp_path / "m.glb"
    ok.write_bytes(encode_glb(QUAD, QUAD_FACES))
    assert load_scene(ok).mesh.num_faces == 2


def test_d8_stray_vertices_are_told_apart_from_units(tmp_path: Path) -> None:
    n = 40  # a 4 m floor of many triangles plus one far triangle
    xs = np.linspace(0, 4, n)
    grid = np.array([[x, 0, z] for z in xs for x in xs], np.float32)
    faces = [[r * n + c, (r + 1) * n + c, r * n + c + 1] for r in range(n - 1) for c in range(n - 1)]
    far = np.array([[9000, 0, 0], [9001, 0, 0], [9000, 0, 1]], np.float32)
    path = tmp_path / "stray.glb"
    path.write_bytes(
        encode_glb(np.concatenate([grid, far]), np.array(faces + [[len(grid), len(grid) + 2, len(grid) + 1]]))
    )
    with pytest.raises(SceneFileError) as e:
        load_scene(path)
    _one_line(e.value, "stray.glb", "3 stray vertices", "delete the stray geometry")


def test_d8_grid_frame_refuses_a_grid_beyond_its_cell_cap() -> None:
    from ovon.sim.gridframe import MAX_GRID_CELLS, grid_frame

    with pytest.raises(ValueError) as e:
        grid_frame(QUAD.astype(np.float64) * 1000, 0.05)
    _one_line(e.value, "4,000 x 4,000 m", f"max {MAX_GRID_CELLS:,}", "sim.nav.cell_size")
    origin, rows, cols = grid_frame(QUAD.astype(np.float64), 0.05)
    assert (rows, cols) == (83, 83) and np.allclose(origin, [-0.075, -0.075])


# ------------------------------------------------------------------------------------- D9 glTF


@pytest.mark.parametrize(
    ("name", "edit", "needles"),
    [
        ("nan_scale", lambda d: d["nodes"][0].update(scale=[1, float("nan"), 1]), ("node 0", "scale", "finite")),
        (
            "nan_matrix",
            lambda d: d["nodes"][0].update(matrix=[1, 0, 0, 0] * 3 + [float("inf"), 0, 0, 1]),
            ("node 0", "matrix", "finite"),
        ),
        (
            "zero_matrix",
            lambda d: d["nodes"][0].update(matrix=[0] * 16),
            ("every node with a mesh", "node 0", "singular"),
        ),
        (
            "zero_scales",
            lambda d: (
                d["nodes"][0].update(scale=[1, 0, 1])
                or d["nodes"].append({"mesh": 0, "scale": [0, 0, 0], "name": "flat"})
                or d["scenes"][0]["nodes"].append(1)
            ),
            ("every node with a mesh", "singular"),
        ),
        ("bad_rotation", lambda d: d["nodes"][0].update(rotation=[0, 0, 0, 3]), ("node 0", "unit quaternion")),
        (
            "float_indices",
            lambda d: d["accessors"][1].update(componentType=5126),
            ("mesh 0 primitive 0", "componentType 5126 (float)", "5125 (unsigned int)"),
        ),
    ],
)
def test_d9_gltf_node_transforms_and_index_types(tmp_path: Path, name: str, edit: Callable, needles: tuple) -> None:
    path = _edited_glb(tmp_path / f"{name}.glb", edit)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no numpy RuntimeWarning on the way
        with pytest.raises(SceneFileError) as e:
            load_scene(path)
        _one_line(e.value, f"{name}.glb", *needles)
        with pytest.raises(SceneFileError) as e:  # the pre-flight finds it without reading vertex data
            preflight_scene(path)
        _one_line(e.value, f"{name}.glb", *needles)


def test_d9_transform_overflowing_float32_is_refused(tmp_path: Path) -> None:
    path = _edited_glb(tmp_path / "huge.glb", lambda d: d["nodes"][0].update(scale=[1e38] * 3))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(SceneFileError) as e:
            load_scene(path)
    _one_line(e.value, "huge.glb", "mesh 0 primitive 0", "overflow to infinity")


def test_d9_a_zero_scale_node_is_hidden_not_an_error(tmp_path: Path) -> None:
    """Exporters hide a node by scaling it to 0 (valid glTF): its mesh is skipped with a note, and the
    scene loads as without it; only a scene whose every mesh node is singular is refused (test above)."""

    def hide(d: dict) -> None:
        d["nodes"].append({"mesh": 0, "scale": [0, 0, 0], "translation": [50, 0, 50], "name": "hidden"})
        d["scenes"][0]["nodes"].append(1)

    plain = load_scene(_edited_glb(tmp_path / "plain.glb", lambda d: None))
    path = _edited_glb(tmp_path / "hidden.glb", hide)
    with pytest.warns(
        UserWarning,
        match=r"skipped 1 node\(s\) with a singular \(zero-scale: hidden\) transform: "
        r"node 1 \('hidden'\)",
    ):
        scene = load_scene(path)
    np.testing.assert_array_equal(scene.mesh.vertices, plain.mesh.vertices)
    np.testing.assert_array_equal(scene.mesh.faces, plain.mesh.faces)
    assert preflight_scene(path)["visual"] == path


def test_d9_mm_to_m_node_scale_is_not_singular(tmp_path: Path) -> None:
    path = _edited_glb(tmp_path / "scaled.glb", lambda d: d["nodes"][0].update(scale=[0.001] * 3), vertices=QUAD * 1000)
    scene = load_scene(path)
    np.testing.assert_allclose(scene.mesh.bounds()[1], [4, 0, 4], atol=1e-5)
    assert preflight_scene(path)["visual"] == path


# ----------------------------------------------------------------------------------- D13 pre-flight


def test_d13_generation_checks_every_scene_before_any_work(tmp_path: Path) -> None:
    from ovon.dataset.generate import generate
    from tests.conftest import tiny_generation_config

    root = tmp_path / "scenes"
    shutil.copytree(FIXTURE, root / "train" / FIXTURE.name)
    bad = root / "val" / "00002-FixtureScn01"
    shutil.copytree(FIXTURE, bad)
    data = (bad / "FixtureScn01.glb").read_bytes()
    (bad / "FixtureScn01.glb").write_bytes(data[:-40])
    out = tmp_path / "out"
    with pytest.raises(SceneFileError) as e:
        generate(root, out, tiny_generation_config(), progress=False)
    _one_line(e.value, "val/00002-FixtureScn01/FixtureScn01.glb", "truncated")
    assert not (out / ".cache").exists()  # no scene was processed, no cache written


@pytest.mark.parametrize("cut", [0, 10, 30, 200, 2000, -40])
def test_d13_preflight_finds_what_loading_finds_in_a_truncated_glb(tmp_path: Path, cut: int) -> None:
    folder = _fixture(tmp_path)
    visual = folder / "FixtureScn01.glb"
    visual.write_bytes(visual.read_bytes()[:cut])
    with pytest.raises(SceneFileError) as loading:
        load_scene(folder)
    with pytest.raises(SceneFileError) as e:
        preflight_scene(folder)
    assert str(e.value) == str(loading.value)
    _one_line(e.value, "FixtureScn01.glb")


def test_d13_preflight_of_a_gltf_without_its_bin(tmp_path: Path) -> None:
    from tests.meshes import mesh_from_boxes, room_boxes, write_gltf_bin

    write_gltf_bin(mesh_from_boxes(room_boxes(0.0, 0.0, 4.0, 3.0)), tmp_path / "room.gltf")
    assert preflight_scene(tmp_path / "room.gltf")["visual"] == tmp_path / "room.gltf"
    (tmp_path / "room.bin").write_bytes(b"\0" * 10)
    with pytest.raises(SceneFileError, match=r"room\.gltf: buffer 0 declares .* holds 10"):
        preflight_scene(tmp_path / "room.gltf")
    (tmp_path / "room.bin").unlink()
    with pytest.raises(FileNotFoundError, match=r"room\.bin is missing"):
        preflight_scene(tmp_path / "room.gltf")


def test_d13_preflight_finds_units_from_bounds_and_trusts_vertices(tmp_path: Path) -> None:
    folder = tmp_path / "00003-mm"
    folder.mkdir()
    (folder / "mm.glb").write_bytes(encode_glb(QUAD * 1000, QUAD_FACES))
    with pytest.raises(SceneFileError, match="millimetres"):
        preflight_scene(folder)
    # stale POSITION bounds that claim 4 km: the vertices decide, no false refusal
    path = _edited_glb(folder / "mm.glb", lambda d: d["accessors"][0].update(max=[4000.0, 0.0, 4000.0]))
    assert preflight_scene(path)["visual"] == path
    (folder / "mm.semantic.txt").write_text(HEADER + TABLE)
    with pytest.raises(FileNotFoundError, match=r"mm\.semantic\.glb is missing"):
        preflight_scene(folder)


# -------------------------------------------------------------------------------- D15 warning names


def test_d15_warnings_name_the_mesh_file(tmp_path: Path, monkeypatch, capsys) -> None:
    from tests.meshes import mesh_from_boxes, room_boxes, to_z_up, write_glb

    write_glb(to_z_up(mesh_from_boxes(room_boxes(0.0, 0.0, 4.0, 3.0))), tmp_path / "zup.glb")
    monkeypatch.chdir(tmp_path)
    assert main(["scenes", "inspect", "zup.glb"]) == 0
    err = capsys.readouterr().err
    assert "ovon: warning: zup.glb: most flat area faces the z axis" in err, err
    folder = _fixture(tmp_path, (HEADER + TABLE.replace("2,1F77B4", "2,123456")).encode())
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        load_scene(folder)
    said = [str(w.message) for w in caught if issubclass(w.category, SceneLoadWarning)]
    sem, txt = folder / "FixtureScn01.semantic.glb", folder / "FixtureScn01.semantic.txt"
    assert any(m.startswith(f"{sem}: 12 semantic faces have colours missing") for m in said), said
    assert any(m.startswith(f"{txt}: 1 annotated instances have no faces") for m in said), said
