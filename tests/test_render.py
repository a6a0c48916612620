"""Render backends: analytic depth, camera conventions, textures, and GL vs embree agreement."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ovon.config.sim import CameraConfig
from ovon.scenes.model import Mesh, Scene
from ovon.sim.render import camera as cam
from ovon.sim.render import gl_available, make_renderer
from ovon.sim.render.texture import colors_to_ids

HAS_GL = gl_available()
needs_gl = pytest.mark.skipif(not HAS_GL, reason="no headless EGL context (moderngl/EGL unavailable)")
BACKENDS = [pytest.param("gl", marks=needs_gl), "embree"]

FLOOR, CEIL, WALL_N, WALL_S, WALL_E, WALL_W = 1, 2, 3, 4, 5, 6


class MeshBuilder:
    """Accumulates triangles with per-face colour and id (tests only)."""

    def __init__(self) -> None:
        self.v: list[np.ndarray] = []
        self.f: list[np.ndarray] = []
        self.col: list[np.ndarray] = []
        self.ids: list[np.ndarray] = []
        self.n = 0

    def quad(self, corners, inst: int, color=(200, 200, 200)) -> MeshBuilder:  # noqa: ANN001
        self.v.append(np.asarray(corners, np.float32))
        self.f.append(np.array([[0, 1, 2], [0, 2, 3]], np.int32) + self.n)
        self.col.append(np.tile(np.asarray(color, np.uint8), (2, 1)))
        self.ids.append(np.full(2, inst, np.int32))
        self.n += 4
        return self

    def box(self, lo, hi, inst: int, color=(120, 60, 30)) -> MeshBuilder:  # noqa: ANN001
        (x0, y0, z0), (x1, y1, z1) = lo, hi
        self.quad([(x0, y0, z0), (x1, y0, z0), (x1, y0, z1), (x0, y0, z1)], inst, color)
        self.quad([(x0, y1, z0), (x1, y1, z0), (x1, y1, z1), (x0, y1, z1)], inst, color)
        self.quad([(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0)], inst, color)
        self.quad([(x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)], inst, color)
        self.quad([(x0, y0, z0), (x0, y0, z1), (x0, y1, z1), (x0, y1, z0)], inst, color)
        self.quad([(x1, y0, z0), (x1, y0, z1), (x1, y1, z1), (x1, y1, z0)], inst, color)
        return self

    def mesh(self) -> Mesh:
        return Mesh(
            vertices=np.concatenate(self.v),
            faces=np.concatenate(self.f),
            face_colors=np.concatenate(self.col),
            face_instance=np.concatenate(self.ids),
        )


def room(half: float = 3.0, height: float = 2.5) -> MeshBuilder:
    """Box room x, z in [-half, half], floor y = 0, ceiling y = height, each surface its own id."""
    h, t = half, height
    b = MeshBuilder()
    b.quad([(-h, 0, -h), (h, 0, -h), (h, 0, h), (-h, 0, h)], FLOOR, (150, 120, 90))
    b.quad([(-h, t, -h), (h, t, -h), (h, t, h), (-h, t, h)], CEIL, (240, 240, 240))
    b.quad([(-h, 0, -h), (h, 0, -h), (h, t, -h), (-h, t, -h)], WALL_N, (200, 50, 50))
    b.quad([(-h, 0, h), (h, 0, h), (h, t, h), (-h, t, h)], WALL_S, (50, 200, 50))
    b.quad([(h, 0, -h), (h, 0, h), (h, t, h), (h, t, -h)], WALL_E, (50, 50, 200))
    b.quad([(-h, 0, -h), (-h, 0, h), (-h, t, h), (-h, t, -h)], WALL_W, (200, 200, 50))
    return b


def furnished() -> Scene:
    b = room()
    b.box((-0.5, 0.0, -2.0), (0.5, 0.8, -1.2), 10, (160, 40, 160))  # table ahead (-z)
    b.box((-2.5, 0.0, -0.4), (-1.8, 1.8, 0.4), 11, (40, 160, 160))  # cabinet left (-x)
    b.box((1.2, 0.0, 1.0), (2.0, 0.5, 2.0), 12, (90, 90, 90))  # bed behind-right
    b.box((0.8, 0.8, -2.6), (1.1, 1.4, -2.3), 13, (250, 150, 0))  # small object
    return Scene(scene_id="test-room", mesh=b.mesh(), source="test")


def camera(width: int = 160, height: int = 120, hfov: float = 79.0) -> CameraConfig:
    return CameraConfig(width=width, height=height, hfov_deg=hfov)


@pytest.fixture(scope="module")
def scene() -> Scene:
    return furnished()


@pytest.mark.parametrize("backend", BACKENDS)
def test_wall_z_depth(backend: str) -> None:
    """2 m in front of a wall, facing it: z-depth is 2.0 everywhere (not the ray length)."""
    sc = Scene(scene_id="wall", mesh=room().mesh())
    r = make_renderer(sc, camera(), backend)
    f = r.render(np.array([0.0, 1.25, -1.0]), 0.0, 0.0)  # wall at z = -3
    r.close()
    assert (f.semantic == WALL_N).all()
    np.testing.assert_allclose(f.depth, 2.0, atol=1e-3)


@pytest.mark.parametrize("backend", BACKENDS)
def test_floor_depth_rows(backend: str) -> None:
    """Looking down 30 deg at the floor: analytic z-depth per row."""
    w, h, hfov = 64, 48, 60.0
    sc = Scene(scene_id="floor", mesh=room(half=50.0, height=10.0).mesh())
    r = make_renderer(sc, camera(w, h, hfov), backend)
    eye_h, pitch = 1.0, math.radians(-30.0)
    f = r.render(np.array([0.0, eye_h, 0.0]), 0.3, pitch)
    r.close()
    fl = cam.focal_length(w, h, hfov)
    yn = (h / 2.0 - (np.arange(h) + 0.5)) / fl  # camera-frame y / (-z) per row
    # camera-frame ray (x, yn, -1) in world: its y component = yn cos(p) + sin(p) (per unit of -z)
    down = -(yn * math.cos(pitch) + math.sin(pitch))
    expected = eye_h / down
    rows = f.semantic == FLOOR
    assert rows[h // 2 :].all()
    got = np.where(rows, f.depth, np.nan)
    np.testing.assert_allclose(got[h // 2 :], np.broadcast_to(expected[h // 2 :, None], (h - h // 2, w)), atol=1e-3)


@pytest.mark.parametrize("backend", BACKENDS)
def test_pitch_up_down(backend: str, scene: Scene) -> None:
    r = make_renderer(scene, camera(), backend)
    eye = np.array([0.0, 1.3, 0.0])
    up = r.render(eye, 0.0, math.radians(60)).semantic
    down = r.render(eye, 0.0, math.radians(-60)).semantic
    level = r.render(eye, 0.0, 0.0).semantic
    r.close()
    assert (up == CEIL).mean() > 0.3 and (up == FLOOR).sum() == 0
    assert (down == FLOOR).mean() > 0.3 and (down == CEIL).sum() == 0
    assert (up[0] == CEIL).all() and (level[0] == CEIL).all()  # row 0 is the top of the image
    assert (level[-1] == FLOOR).mean() > 0.3 and not (level[-1] == CEIL).any()


@pytest.mark.parametrize("backend", BACKENDS)
def test_yaw_convention(backend: str, scene: Scene) -> None:
    """Yaw 0 looks along -z (table); +90 deg turns left and looks along -x (cabinet)."""
    r = make_renderer(scene, camera(), backend)
    eye = np.array([0.0, 1.3, 0.0])
    f0 = r.render(eye, 0.0, math.radians(-20)).semantic
    f90 = r.render(eye, math.radians(90), 0.0).semantic
    fm90 = r.render(eye, math.radians(-90), 0.0).semantic
    r.close()
    assert (f0 == 10).sum() > 100 and (f0 == 11).sum() == 0
    assert (f90 == 11).sum() > 100 and (f90 == 10).sum() == 0
    assert (f90 == WALL_W).any() and not (fm90 == WALL_W).any() and (fm90 == WALL_E).any()
    # the table (x in [-0.5, 0.5]) is centred at yaw 0; the small object (x > 0) is right of centre
    cols = np.nonzero((f0 == 13).any(axis=0))[0]
    assert cols.min() > f0.shape[1] // 2


@needs_gl
@pytest.mark.parametrize("size", [(160, 120), (360, 640), (224, 224), (33, 17)])  # odd: row alignment
def test_gl_embree_agree(scene: Scene, size: tuple[int, int]) -> None:
    cfg = camera(*size, hfov=42.0 if size[0] < size[1] else 79.0)
    g = make_renderer(scene, cfg, "gl")
    e = make_renderer(scene, cfg, "embree")
    rng = np.random.default_rng(0)
    for _ in range(6):
        eye = np.array([rng.uniform(-1.5, 1.5), rng.uniform(0.4, 1.8), rng.uniform(-1.0, 2.0)])
        yaw, pitch = rng.uniform(-math.pi, math.pi), rng.choice([-0.52, 0.0, 0.52])
        fg, fe = g.render(eye, yaw, pitch), e.render(eye, yaw, pitch)
        assert fg.rgb.shape == (size[1], size[0], 3) and fe.semantic.shape == (size[1], size[0])
        assert (fg.semantic == fe.semantic).mean() >= 0.995
        both = (fg.depth > 0) & (fe.depth > 0) & (fg.semantic == fe.semantic)
        assert both.mean() > 0.9
        assert np.abs(fg.depth[both] - fe.depth[both]).max() < 1e-3
        diff = np.abs(fg.rgb.astype(int) - fe.rgb.astype(int))[both]
        assert np.mean(diff <= 1) > 0.99
    g.close()
    e.close()


def _textured_quad_scene(semantic: bool, separate: bool = True) -> Scene:
    """A 2 x 2 m quad on the wall z = -2 (x, y in [-1, 1]) with glTF UVs (0, 0) top-left."""
    verts = np.array([[-1, -1, -2], [1, -1, -2], [1, 1, -2], [-1, 1, -2]], np.float32)
    uvs = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32)
    faces = np.array([[0, 1, 2], [0, 2, 3]], np.int32)
    # row 0 = top: top-left red, top-right green, bottom-left blue, bottom-right white
    tex = np.array([[[255, 0, 0], [0, 255, 0]], [[0, 0, 255], [255, 255, 255]]], np.uint8)
    vis = Mesh(vertices=verts, faces=faces, uvs=uvs, texture=tex)
    colors = {7: (255, 0, 0), 8: (0, 255, 0), 9: (0, 0, 255)}  # white is unknown -> 0
    if not semantic:
        return Scene(scene_id="tex", mesh=vis)
    if not separate:  # ids from the visual texture's colours: one pass, one interpolated uv for both lookups
        return Scene(scene_id="tex", mesh=vis, semantic_colors=colors)
    # the other diagonal: different triangles, so the backends take their second-pass path
    sem = Mesh(vertices=verts, faces=np.array([[0, 1, 3], [1, 2, 3]], np.int32), uvs=uvs, texture=tex)
    return Scene(scene_id="tex", mesh=vis, semantic_mesh=sem, semantic_colors=colors)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("separate", [True, False], ids=["semantic-mesh", "visual-texture-ids"])
def test_texture_quadrants(backend: str, separate: bool) -> None:
    sc = _textured_quad_scene(semantic=True, separate=separate)
    r = make_renderer(sc, camera(100, 100, 90.0), backend)
    f = r.render(np.zeros(3), 0.0, 0.0)  # the quad fills the middle half of the image
    r.close()
    shade = cam.face_shade(sc.mesh.vertices, sc.mesh.faces)[0]
    q = {"tl": (30, 30), "tr": (30, 69), "bl": (69, 30), "br": (69, 69)}  # (row, col), inside texel centres
    expect = {"tl": (255, 0, 0), "tr": (0, 255, 0), "bl": (0, 0, 255), "br": (255, 255, 255)}
    ids = {"tl": 7, "tr": 8, "bl": 9, "br": 0}
    # sample near the texel centres (quad spans pixels 25..74): bilinear gives the pure colour there
    q = {"tl": (37, 37), "tr": (37, 62), "bl": (62, 37), "br": (62, 62)}
    for k, (row, col) in q.items():
        want = np.round(np.array(expect[k]) * shade)
        assert np.abs(f.rgb[row, col].astype(int) - want).max() <= 2, (k, f.rgb[row, col], want)
        assert f.semantic[row, col] == ids[k], k
    # nearest sampling of ids: whole quadrants, sharp edges
    assert (f.semantic[26:49, 26:49] == 7).all() and (f.semantic[51:74, 51:74] == 0).all()
    assert f.semantic[0, 0] == 0 and f.depth[0, 0] == 0.0
    np.testing.assert_allclose(f.depth[50, 50], 2.0, atol=1e-3)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("shared", [True, False], ids=["same-triangles", "other-triangles"])
def test_separate_semantic_mesh(backend: str, shared: bool, scene: Scene) -> None:
    """A semantic mesh with ids from face colours gives the same ids as per-face instance ids, whether
    it shares the visual triangles (single pass) or not (second pass / second BVH)."""
    vis = scene.mesh
    ids = vis.face_instance
    palette = {int(i): (int(i) * 40 % 256, int(i) * 7 % 256, 3) for i in np.unique(ids)}
    faces = vis.faces if shared else vis.faces[:, ::-1].copy()  # reversed winding: other triangles
    sem = Mesh(vertices=vis.vertices, faces=faces, face_colors=np.array([palette[int(i)] for i in ids], np.uint8))
    vis2 = Mesh(vertices=vis.vertices, faces=vis.faces, face_colors=vis.face_colors)
    split = Scene(scene_id="split", mesh=vis2, semantic_mesh=sem, semantic_colors=palette)
    a, b = make_renderer(scene, camera(), backend), make_renderer(split, camera(), backend)
    for yaw in (0.0, 1.5, 3.0, -1.5):
        fa, fb = a.render(np.array([0.2, 1.2, 0.1]), yaw, -0.3), b.render(np.array([0.2, 1.2, 0.1]), yaw, -0.3)
        assert (fa.semantic == fb.semantic).mean() > 0.999 and len(np.unique(fb.semantic)) >= 3
        np.testing.assert_array_equal(fa.depth, fb.depth)
        np.testing.assert_array_equal(fa.rgb, fb.rgb)
    a.close()
    b.close()


def test_colors_to_ids() -> None:
    cols = np.array([[[1, 2, 3], [4, 5, 6]], [[9, 9, 9], [1, 2, 3]]], np.uint8)
    ids = colors_to_ids(cols, {5: (1, 2, 3), 6: (4, 5, 6)})
    assert ids.tolist() == [[5, 6], [0, 5]]
    assert colors_to_ids(cols, {}).sum() == 0


@pytest.mark.parametrize("backend", BACKENDS)
def test_vertex_colors(backend: str) -> None:
    sc = Scene(scene_id="wall", mesh=room().mesh())
    mesh = sc.mesh
    mesh.face_colors = None
    mesh.vertex_colors = np.full((len(mesh.vertices), 3), 100, np.uint8)
    r = make_renderer(sc, camera(32, 24), backend)
    f = r.render(np.array([0.0, 1.25, -1.0]), 0.0, 0.0)
    r.close()
    want = round(100 * float(cam.face_shade(mesh.vertices, mesh.faces)[4]))
    assert np.abs(f.rgb.astype(int) - want).max() <= 1


@pytest.mark.parametrize("size", [(160, 120), (360, 640)])
def test_auto_backend_and_shapes(scene: Scene, size: tuple[int, int]) -> None:
    r = make_renderer(scene, camera(*size), "auto")
    f = r.render(np.array([0.0, 1.3, 0.0]), 0.0, 0.0)
    r.close()
    w, h = size
    assert f.rgb.shape == (h, w, 3) and f.rgb.dtype == np.uint8
    assert f.depth.shape == (h, w) and f.depth.dtype == np.float32
    assert f.semantic.shape == (h, w) and f.semantic.dtype == np.int32
    assert (f.depth > 0).all()  # closed room: every pixel hits


def test_unknown_backend(scene: Scene) -> None:
    with pytest.raises(ValueError):
        make_renderer(scene, camera(), "vulkan")


def test_camera_helpers() -> None:
    assert cam.vfov_deg(100, 100, 90.0) == pytest.approx(90.0)
    np.testing.assert_allclose(cam.forward(0.0, 0.0), [0, 0, -1], atol=1e-12)
    np.testing.assert_allclose(cam.forward(math.pi / 2, 0.0), [-1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(cam.forward(0.0, math.pi / 2), [0, 1, 0], atol=1e-12)
    d, z = cam.ray_directions(4, 2, 90.0)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0)
    assert d[0, 1] > 0 and d[0, 0] < 0 and d[-1, 1] < 0 and d[-1, 0] > 0  # row 0 top, col 0 left
    np.testing.assert_allclose(z, -d[:, 2])


def test_constant_id_texture_needs_no_lookup() -> None:
    """A textured mesh whose colours map to one id (or with no annotations) gets per-face ids, not a texture."""
    from ovon.sim.render.texture import semantic_source

    vis = _textured_quad_scene(semantic=False).mesh
    src = semantic_source(vis, {})
    assert src.mode == "face" and (src.face_ids == 0).all()
    src = semantic_source(vis, {7: tuple(int(c) for c in vis.texture[0, 0])})  # colours -> {7 (top-left), 0}
    assert src.mode == "texture"
    one = Mesh(vertices=vis.vertices, faces=vis.faces, uvs=vis.uvs, texture=np.full((2, 2, 3), 9, np.uint8))
    src = semantic_source(one, {5: (9, 9, 9)})
    assert src.mode == "face" and (src.face_ids == 5).all()
