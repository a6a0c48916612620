"""GL chunk culling is exact: culled and unculled frames are bitwise identical (rgb, depth, ids)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from ovon.config.sim import CameraConfig
from ovon.scenes.model import Mesh, Scene
from ovon.sim.render import cull, gl_available, make_renderer
from tests.test_render import MeshBuilder, room

pytestmark = pytest.mark.skipif(not gl_available(), reason="no headless EGL context (moderngl/EGL unavailable)")


@pytest.fixture
def fine_chunks(monkeypatch: pytest.MonkeyPatch) -> None:
    """Tiny chunks and a tiny first guess, so that small test scenes exercise every culling path (frustum,
    occlusion, the growing guess, second draws)."""
    import ovon.sim.render.gl as gl

    monkeypatch.setattr(cull, "CHUNK_FACES", 4)
    monkeypatch.setattr(cull, "CHUNK_EXTENT_M", 0.3)
    monkeypatch.setattr(gl, "GUESS_FACES", 8)


def edge_scene(textured: bool = False) -> Scene:
    """A 8 x 8 m room with rings of small boxes that cross the frustum edges as the camera turns, boxes
    sunk into the floor and each other (depth ties along the seams) and decals exactly on the walls, drawn
    before and after the wall (ties that only the original draw order resolves)."""
    b = MeshBuilder()
    h, t = 4.0, 2.6
    b.quad([(-1, 0.5, -h), (1, 0.5, -h), (1, 1.8, -h), (-1, 1.8, -h)], 30, (10, 200, 10))  # decal before its wall
    walls = room(half=h, height=t)
    for corners, col, ids in zip(walls.v, walls.col, walls.ids, strict=True):
        b.quad(corners, int(ids[0]), tuple(int(c) for c in col[0]))
    b.quad([(h, 0.3, -1), (h, 0.3, 1), (h, 2.0, 1), (h, 2.0, -1)], 31, (200, 10, 200))  # decal after its wall
    rng = np.random.default_rng(3)
    inst = 40
    for radius in (0.7, 1.6, 3.2):
        for k in range(20):
            a = 2 * math.pi * (k + 0.5 * (radius > 1)) / 20
            cx, cz = radius * math.sin(a), radius * math.cos(a)
            y0 = float(rng.choice([-0.05, 0.0, 0.6, 1.2, 2.3]))  # sunk into the floor, floating, into the ceiling
            s = float(rng.uniform(0.08, 0.3))
            b.box(
                (cx - s, y0, cz - s),
                (cx + s, y0 + 2 * s, cz + s),
                inst,
                tuple(int(v) for v in rng.integers(30, 250, 3)),
            )
            inst += 1
    b.box((-0.3, 0.0, -2.0), (0.3, 1.0, -1.4), inst, (90, 90, 200))  # two boxes sharing a face
    b.box((-0.3, 1.0, -2.0), (0.3, 1.6, -1.4), inst + 1, (200, 90, 90))
    mesh = b.mesh()
    if textured:
        v = mesh.vertices
        mesh.uvs = np.stack([v[:, 0] * 0.37 + v[:, 2] * 0.11, v[:, 1] * 0.29 - v[:, 2] * 0.05], 1).astype(np.float32)
        mesh.texture = rng.integers(0, 255, (16, 16, 3), dtype=np.uint8)
        mesh.face_colors = None
    return Scene(scene_id="edges", mesh=mesh, floor_heights=[0.0])


def poses(rng: np.random.Generator, n: int, half: float = 3.6) -> list[tuple[np.ndarray, float, float]]:
    out = []
    for _ in range(n):
        eye = np.array([rng.uniform(-half, half), rng.uniform(0.2, 2.4), rng.uniform(-half, half)])
        out.append((eye, float(rng.uniform(-math.pi, math.pi)), math.radians(float(rng.choice([-60, -30, 0, 30, 60])))))
    return out


def sweep(eye: np.ndarray, steps: int = 24) -> list[tuple[np.ndarray, float, float]]:
    """A full turn in small steps at each pitch: objects enter and leave through every frustum edge."""
    return [(eye, 2 * math.pi * k / steps, math.radians(p)) for p in (-60, -20, 0, 25, 60) for k in range(steps)]


def walk(start: np.ndarray, n: int, rng: np.random.Generator) -> list[tuple[np.ndarray, float, float]]:
    """Agent-like steps (0.25 m forward, 30 deg turns, look up/down): the last frame's visible set is reused."""
    eye, yaw, pitch, out = start.astype(float), 0.0, 0.0, []
    for _ in range(n):
        a = rng.integers(5)
        if a == 0:
            eye = eye + 0.25 * np.array([-math.sin(yaw), 0.0, -math.cos(yaw)])
        elif a in (1, 2):
            yaw += math.radians(30 if a == 1 else -30)
        else:
            pitch = float(np.clip(pitch + math.radians(30 if a == 3 else -30), -1.05, 1.05))
        out.append((eye.copy(), yaw, pitch))
    return out


def assert_identical(scene: Scene, cfg: CameraConfig, pose_list: list) -> tuple[int, int]:
    """Render every pose culled and unculled; frames must match bit for bit. Returns faces drawn (culled,
    unculled) summed over the poses."""
    a = make_renderer(scene, replace(cfg, cull=True), "gl")
    b = make_renderer(scene, replace(cfg, cull=False), "gl")
    drawn = [0, 0]
    for k, (eye, yaw, pitch) in enumerate(pose_list):
        fa, fb = a.render(eye, yaw, pitch), b.render(eye, yaw, pitch)
        where = f"pose {k}: eye {eye.round(3).tolist()} yaw {yaw:.3f} pitch {pitch:.3f}"
        np.testing.assert_array_equal(fa.depth, fb.depth, err_msg=where)
        np.testing.assert_array_equal(fa.semantic, fb.semantic, err_msg=where)
        if cfg.rgb:
            np.testing.assert_array_equal(fa.rgb, fb.rgb, err_msg=where)
        else:
            assert fa.rgb is None and fb.rgb is None
        drawn[0] += a.faces_drawn
        drawn[1] += b.faces_drawn
    a.close()
    b.close()
    return drawn[0], drawn[1]


@pytest.mark.parametrize("rgb", [True, False])
@pytest.mark.parametrize("size", [(160, 120, 42.0), (72, 128, 42.0), (33, 17, 79.0)])
def test_edge_scene_identical(fine_chunks: None, size: tuple[int, int, float], rgb: bool) -> None:
    scene = edge_scene()
    cfg = CameraConfig(width=size[0], height=size[1], hfov_deg=size[2], rgb=rgb)
    rng = np.random.default_rng(0)
    two = zip(walk(np.array([0.0, 1.31, 2.0]), 30, rng), walk(np.array([1.0, 1.31, -2.0]), 30, rng), strict=True)
    interleaved = [p for pair in two for p in pair]  # two envs sharing one renderer (one world per process)
    ps = poses(rng, 40) + sweep(np.array([0.05, 1.31, 0.1]), 12) + walk(np.array([0.0, 1.31, 2.0]), 40, rng)
    culled, full = assert_identical(scene, cfg, ps + interleaved)
    assert culled < 0.7 * full  # culling did cull


def test_camera_inside_chunks(fine_chunks: None) -> None:
    """Eyes inside chunk boxes, on their corners and just outside: boxes straddling the near plane."""
    scene = edge_scene()
    ch = cull.build_chunks(scene.mesh.vertices, scene.mesh.faces)
    rng = np.random.default_rng(1)
    ps = []
    for i in rng.choice(len(ch), 30, replace=False):
        for eye in ((ch.lo[i] + ch.hi[i]) / 2, ch.lo[i], ch.hi[i] + 0.005):
            eye = np.clip(eye, [-3.9, 0.05, -3.9], [3.9, 2.5, 3.9])
            ps.append((eye, float(rng.uniform(-math.pi, math.pi)), math.radians(float(rng.choice([-60, 0, 60])))))
    assert_identical(scene, CameraConfig(width=64, height=48, hfov_deg=79.0), ps)


@pytest.mark.parametrize("annotated", [True, False], ids=["face-ids", "bare-scan"])
def test_textured_identical(fine_chunks: None, annotated: bool) -> None:
    """Textured meshes, with per-face ids or none (a bare scan: one id everywhere, no id attribute)."""
    scene = edge_scene(textured=True)
    if not annotated:
        scene.mesh.face_instance = None
    cfg = CameraConfig(width=96, height=72, hfov_deg=60.0)
    assert_identical(scene, cfg, poses(np.random.default_rng(2), 40))
    if not annotated:
        f = make_renderer(scene, cfg, "gl").render(np.array([0.0, 1.3, 0.0]), 0.3, 0.0)
        assert (f.semantic == 0).all() and (f.depth > 0).all()


def test_separate_semantic_mesh_identical(fine_chunks: None) -> None:
    """The second (semantic) pass is culled on its own depth: still exact."""
    vis = edge_scene().mesh
    ids = vis.face_instance
    palette = {int(i): (int(i) * 37 % 256, int(i) * 11 % 256, 7) for i in np.unique(ids)}
    sem = Mesh(vertices=vis.vertices, faces=vis.faces[:, ::-1].copy(),
               face_colors=np.array([palette[int(i)] for i in ids], np.uint8))  # fmt: skip
    split = Scene(scene_id="split", mesh=Mesh(vis.vertices, vis.faces, face_colors=vis.face_colors),
                  semantic_mesh=sem, semantic_colors=palette)  # fmt: skip
    rng = np.random.default_rng(4)
    assert_identical(
        split,
        CameraConfig(width=80, height=60, hfov_deg=79.0),
        poses(rng, 30) + walk(np.zeros(3) + [0, 1.3, 0], 30, rng),
    )


def test_procedural_house_identical() -> None:
    """The real thing with the default chunking: random poses and an agent-like walk in a generated house."""
    from ovon.scenes.procedural import generate_house

    scene = generate_house(0)
    lo, hi = scene.mesh.bounds()
    rng = np.random.default_rng(5)
    ps = []
    for _ in range(40):
        eye = np.array([rng.uniform(lo[0], hi[0]), scene.floor_heights[0] + 1.31, rng.uniform(lo[2], hi[2])])
        ps.append((eye, float(rng.uniform(-math.pi, math.pi)), math.radians(float(rng.choice([-30, 0, 30])))))
    ps += walk(ps[0][0], 40, rng)
    culled, full = assert_identical(scene, CameraConfig(width=160, height=120), ps)
    assert culled < 0.5 * full


def test_build_chunks_partition() -> None:
    scene = edge_scene()
    v, f = scene.mesh.vertices, scene.mesh.faces
    ch = cull.build_chunks(v, f, max_faces=5, max_extent=0.4)
    assert sorted(ch.perm.tolist()) == list(range(len(f)))  # every face exactly once
    assert ch.count.max() <= 5 and ch.count.min() >= 1
    tri = v[f].astype(np.float64)
    for i in range(len(ch)):
        faces = ch.perm[ch.start[i] : ch.start[i + 1]]
        assert (np.diff(faces) > 0).all()  # ascending: the original draw order inside a chunk
        assert (tri[faces].min(axis=(0, 1)) >= ch.lo[i]).all() and (tri[faces].max(axis=(0, 1)) <= ch.hi[i]).all()
        if len(faces) > 1:
            assert (ch.hi[i] - ch.lo[i]).max() <= 0.4 + 1e-9
    with pytest.raises(ValueError, match="max_faces"):
        cull.build_chunks(v, f, max_faces=0)


def test_visible_faces_sorted() -> None:
    scene = edge_scene()
    ch = cull.build_chunks(scene.mesh.vertices, scene.mesh.faces, max_faces=3, max_extent=0.5)
    mask = np.random.default_rng(0).random(len(ch)) < 0.5
    got = cull.visible_faces(ch, mask)
    want = np.sort(np.concatenate([ch.perm[ch.start[i] : ch.start[i + 1]] for i in np.flatnonzero(mask)]))
    np.testing.assert_array_equal(got, want)


def test_occlusion_keeps_boxes_in_front() -> None:
    """A box in front of a wall stays; the same box behind it goes; one straddling the near plane stays."""
    lo = np.array([[-0.2, -0.2, -1.2], [-0.2, -0.2, -3.2], [-0.2, -0.2, -0.005]])
    hi = lo + 0.4
    ch = cull.Chunks(np.arange(3, dtype=np.int32), np.arange(4), lo, hi, 3)
    depth = np.full((48, 64), 2.0, np.float32)  # a wall 2 m ahead fills the view
    view = np.eye(4)  # camera at the origin looking along -z
    keep = cull.occlusion_mask(ch, np.ones(3, bool), depth, view, focal=40.0, near=0.01)
    assert keep.tolist() == [True, False, True]
    depth[20:28, 28:36] = 0.0  # a hole (nothing drawn) behind the second box: it may be visible through it
    keep = cull.occlusion_mask(ch, np.ones(3, bool), depth, view, focal=40.0, near=0.01)
    assert keep.tolist() == [True, True, True]
