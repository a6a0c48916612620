"""Headless OpenGL renderer (moderngl on EGL; llvmpipe on CPU machines).

Geometry is de-indexed once (3 vertices per face) so flat colours, shading and instance ids are plain
per-vertex attributes, and uploaded once. One framebuffer holds colour (RGBA8), linear z-depth (R32F,
written from view space for precision rather than un-projected from the depth buffer), instance ids
(R32I) and a depth buffer. A separate semantic mesh with other triangles (real scans) is drawn in a
second pass into its own framebuffer; one with the same triangles shares the single pass. The
projection flips y, so the bottom-up GL read-back comes out with row 0 at the top.

llvmpipe pays for every triangle it rasterises, visible or not, so each pass draws only the mesh chunks
that can be visible (`cull.py`: frustum and depth-buffer occlusion tests, survivors in the original face
order, depth ties checked): frames are bitwise those of drawing everything (`camera.cull = False`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import cv2
import moderngl
import numpy as np

from ovon.config.sim import CameraConfig
from ovon.scenes.model import Mesh, Scene
from ovon.sim.render import camera as cam
from ovon.sim.render.cull import (
    Chunks,
    build_chunks,
    faces_in,
    frustum_mask,
    nearest_chunks,
    occlusion_mask,
    visible_faces,
)
from ovon.sim.render.texture import (
    SemanticSource,
    VisualSource,
    same_geometry,
    semantic_source,
    visual_source,
)
from ovon.sim.types import Frame

GUESS_FACES = 4096  # nearest frustum faces in a first guess (besides a recent view's); fewer in view: no occlusion test
RECENT_VIEWS = 8  # visible sets kept per pass: one per env sharing the renderer (several envs per process)
SAME_VIEWER = 1.5  # a recent view this close (metres + |forward difference|) seeds the guess; a 30 deg turn is 0.52
ADD_RATIO = 2  # missing chunks with at most 1/ADD_RATIO of the needed faces are added on top (tie-checked)
GUESS_GROWTH = 1.0  # missing faces above this many times the needed ones drawn: grow the guess (depth only)
SEMANTIC_GUESS_MARGIN_M = 0.05  # semantic chunks this far behind the visual depth are left out of the guess

_CTX = None  # one shared context per process (creating one costs ~0.3 s)
_CTX_PID = -1


def gl_context() -> moderngl.Context:
    """The process's shared standalone EGL context, created on first use (and again after a fork)."""
    global _CTX, _CTX_PID
    if _CTX is None or _CTX_PID != os.getpid():
        # llvmpipe reads this at start-up; 0 (render on the calling thread) measured fastest on 2 cores
        os.environ.setdefault("LP_NUM_THREADS", "0")
        _CTX = moderngl.create_standalone_context(backend="egl")
        _CTX_PID = os.getpid()
    return _CTX


_VERT = """
#version 330
uniform mat4 u_mvp;
uniform mat4 u_view;
in vec3 in_pos;
#ifdef VIS_TEX
in vec2 in_uv;
in float in_shade;
out vec2 v_uv;
out float v_shade;
#endif
#ifdef VIS_COL
in vec3 in_col;
out vec3 v_col;
#endif
#ifdef SEM_FACE
in int in_id;
flat out int v_id;
#endif
#if defined(SEM_TEX) && !defined(SEM_UV_IS_UV)
in vec2 in_suv;
out vec2 v_suv;
#endif
out float v_z;
void main() {
    gl_Position = u_mvp * vec4(in_pos, 1.0);
    v_z = -(u_view * vec4(in_pos, 1.0)).z;
#ifdef VIS_TEX
    v_uv = in_uv;
    v_shade = in_shade;
#endif
#ifdef VIS_COL
    v_col = in_col;
#endif
#ifdef SEM_FACE
    v_id = in_id;
#endif
#if defined(SEM_TEX) && !defined(SEM_UV_IS_UV)
    v_suv = in_suv;
#endif
}
"""

_FRAG = """
#version 330
in float v_z;
#ifdef VIS_TEX
uniform sampler2D u_tex;
in vec2 v_uv;
in float v_shade;
#endif
#ifdef VIS_COL
in vec3 v_col;
#endif
#ifdef SEM_FACE
flat in int v_id;
#endif
#ifdef SEM_TEX
uniform isampler2D u_ids;
#ifdef SEM_UV_IS_UV
#define v_suv v_uv
#else
in vec2 v_suv;
#endif
#endif
#if defined(VISUAL) && (defined(VIS_TEX) || defined(VIS_COL))
layout(location = 0) out vec4 f_color;
layout(location = 1) out float f_depth;
#define ID_LOC 2
#elif defined(VISUAL)
layout(location = 0) out float f_depth;
#define ID_LOC 1
#else
#define ID_LOC 0
#endif
#if defined(SEM_FACE) || defined(SEM_TEX) || defined(SEM_CONST)
layout(location = ID_LOC) out int f_id;
#endif
void main() {
#ifdef VIS_TEX
    f_color = vec4(texture(u_tex, v_uv).rgb * v_shade, 1.0);
#endif
#ifdef VIS_COL
    f_color = vec4(v_col, 1.0);
#endif
#ifdef VISUAL
    f_depth = v_z;
#endif
    gl_FragDepth = v_z * INV_FAR;  // linear depth test: uniform ~6 um steps instead of 1/z ones
#ifdef SEM_FACE
    f_id = v_id;
#endif
#ifdef SEM_CONST
    f_id = SEM_CONST;  // one id on every face: no per-vertex attribute (a flat varying costs ~30% per face)
#endif
#ifdef SEM_TEX
    ivec2 size = textureSize(u_ids, 0);
    vec2 w = fract(v_suv);
    ivec2 ij = min(ivec2(w * vec2(size)), size - 1);
    f_id = texelFetch(u_ids, ij, 0).r;
#endif
}
"""


def _src(defines: list[str], body: str) -> str:
    head, rest = body.strip().split("\n", 1)
    defines = [*defines, f"INV_FAR {1.0 / cam.FAR!r}"]
    return head + "\n" + "".join(f"#define {d}\n" for d in defines) + rest


@dataclass
class _Pass:
    """One draw pass: its program, geometry (de-indexed, original face order), textures and culling state."""

    prog: object  # moderngl.Program
    vao: object  # draws every face, in order
    vao_subset: object | None  # draws the faces listed in `ibo` (culling)
    ibo: object | None
    textures: list
    chunks: Chunks | None
    num_faces: int
    recent: list  # [(eye, forward, visible chunks (N,) bool)] of recent views, most recent last (first guesses)
    fbo: object = None  # its framebuffer (cleared before each full draw)
    zfbo: object = None  # the same depth buffer alone: depth-only draws and read-backs
    zbuf: np.ndarray | None = None  # (H, W) float32 read-back of the depth buffer


class GLRenderer:
    """Renderer protocol on moderngl; buffers reused across frames, chunks culled per frame (`cull.py`)."""

    def __init__(self, scene: Scene, camera: CameraConfig) -> None:
        self.width = int(camera.width)
        self.height = int(camera.height)
        self.hfov_deg = float(camera.hfov_deg)
        self.cull = bool(camera.cull)
        self.ctx = gl_context()
        ctx = self.ctx
        self._res: list = []  # GL objects to release on close
        self.faces_drawn = 0  # faces rasterised by the last render (all passes and draws): what culling saves
        self._ties = self.ctx.query(samples=True)  # counts fragments that tie with the drawn depth
        self._proj = cam.projection_matrix(self.width, self.height, self.hfov_deg)
        self._focal = cam.focal_length(self.width, self.height, self.hfov_deg)
        size = (self.width, self.height)

        # Without RGB (camera.rgb = False: no consumer reads it) the colour attribute, texture lookup,
        # attachment and read-back are all skipped; depth and ids stay one pass.
        self.rgb = bool(camera.rgb)
        vis = visual_source(scene.mesh) if self.rgb else None
        sem = semantic_source(scene.semantic_source, scene.semantic_colors)
        self._separate = not same_geometry(scene.mesh, scene.semantic_mesh)
        if sem.mode == "texture":
            sem_define = "SEM_TEX"
        elif len(sem.face_ids) and (sem.face_ids == sem.face_ids[0]).all():
            sem_define = f"SEM_CONST {int(sem.face_ids[0])}"
        else:
            sem_define = "SEM_FACE"
        vis_defines = ["VISUAL"] + ([] if vis is None else ["VIS_TEX" if vis.mode == "texture" else "VIS_COL"])
        if not self._separate:
            vis_defines.append(sem_define)  # same triangles: ids in the same single pass
            if sem.mode == "texture" and vis is not None and vis.mode == "texture" and _same(sem.uvs, vis.uvs):
                vis_defines.append("SEM_UV_IS_UV")  # one interpolated uv for both lookups (cheaper setup)
        self._vis = self._build(scene.mesh, vis_defines, vis, sem)

        self._zlin = self._keep(ctx.renderbuffer(size, components=1, dtype="f4"))
        self._ids = self._keep(ctx.renderbuffer(size, components=1, dtype="i4"))
        attach = [self._zlin] + ([] if self._separate else [self._ids])
        if self.rgb:
            self._color = self._keep(ctx.renderbuffer(size, components=4, dtype="f1"))
            self._rgba = np.empty((self.height, self.width, 4), np.uint8)
            attach.insert(0, self._color)
        self._fbo = self._attach(self._vis, attach)
        self._sem: _Pass | None = None
        if self._separate:
            self._sem = self._build(scene.semantic_source, [sem_define], None, sem)
            self._sem_fbo = self._attach(self._sem, [self._ids])

    def _attach(self, p: _Pass, colors: list) -> object:
        """Framebuffer of pass `p` with these colour attachments and its own depth buffer (also alone)."""
        depth = self._keep(self.ctx.depth_renderbuffer((self.width, self.height)))
        p.fbo = self._keep(self.ctx.framebuffer(color_attachments=colors, depth_attachment=depth))
        p.zfbo = self._keep(self.ctx.framebuffer(depth_attachment=depth))
        p.zbuf = np.empty((self.height, self.width), np.float32)
        return p.fbo

    def _keep(self, obj):  # noqa: ANN001, ANN202
        self._res.append(obj)
        return obj

    def _build(self, mesh: Mesh, defines: list[str], vis: VisualSource | None, sem: SemanticSource) -> _Pass:
        """Compile the program variant, upload the de-indexed mesh with its attributes, chunk it for culling."""
        ctx = self.ctx
        prog = self._keep(ctx.program(vertex_shader=_src(defines, _VERT), fragment_shader=_src(defines, _FRAG)))
        corners = mesh.faces.reshape(-1)
        content = [(mesh.vertices[corners].astype("f4"), "3f", "in_pos")]
        textures = []
        if vis is not None:
            if vis.mode == "texture":
                shade = np.repeat(vis.shade, 3).astype("f4")
                content += [(vis.uvs[corners], "2f", "in_uv"), (shade, "f", "in_shade")]
                h, w = vis.texture.shape[:2]
                tex = self._keep(ctx.texture((w, h), 3, vis.texture.tobytes(), alignment=1))
                tex.repeat_x = tex.repeat_y = True
                tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
                textures.append(("u_tex", tex))
            else:
                if vis.mode == "vertex":
                    base = vis.vertex_rgb[corners].astype("f4")
                else:
                    base = np.repeat(vis.face_rgb, 3, axis=0).astype("f4")
                col = base / np.float32(255.0) * np.repeat(vis.shade, 3)[:, None]
                content.append((col.astype("f4"), "3f", "in_col"))
        if "SEM_FACE" in defines:
            content.append((np.repeat(sem.face_ids.astype("i4"), 3), "i", "in_id"))
        if "SEM_TEX" in defines:
            if "SEM_UV_IS_UV" not in defines:
                content.append((sem.uvs[corners].astype("f4"), "2f", "in_suv"))
            h, w = sem.id_texture.shape
            tex = self._keep(ctx.texture((w, h), 1, sem.id_texture.astype("i4").tobytes(), dtype="i4"))
            tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            textures.append(("u_ids", tex))
        vao_content = []
        for data, fmt, name in content:
            buf = self._keep(ctx.buffer(np.ascontiguousarray(data).tobytes()))
            vao_content.append((buf, fmt, name))
        vao = self._keep(ctx.vertex_array(prog, vao_content))
        for unit, (name, _tex) in enumerate(textures):
            prog[name].value = unit
        chunks, vao_subset, ibo = None, None, None
        if self.cull:
            chunks = build_chunks(mesh.vertices, mesh.faces)
            ibo = self._keep(ctx.buffer(reserve=max(12 * mesh.num_faces, 4), dynamic=True))
            vao_subset = self._keep(ctx.vertex_array(prog, vao_content, index_buffer=ibo, index_element_size=4))
        return _Pass(prog, vao, vao_subset, ibo, [t for _, t in textures], chunks, mesh.num_faces, [])

    def render(self, eye: np.ndarray, yaw: float, pitch: float) -> Frame:
        """Draw the visual mesh (and the semantic mesh when separate) and read the attachments back."""
        ctx = self.ctx
        view = cam.view_matrix(eye, yaw, pitch)
        clip = self._proj @ view
        mvp = clip.astype("f4").T.tobytes()  # GL wants column-major
        view_b = view.astype("f4").T.tobytes()
        ctx.disable(ctx.CULL_FACE)
        ctx.enable(ctx.DEPTH_TEST)
        h, w = self.height, self.width
        self.faces_drawn = 0
        self._render_pass(self._vis, mvp, view_b, eye, clip, view, None)
        first = 1 if self.rgb else 0
        depth = np.empty((h, w), np.float32)
        self._fbo.read_into(depth, components=1, attachment=first, dtype="f4")
        if self._sem is not None:
            self._render_pass(self._sem, mvp, view_b, eye, clip, view, depth)
        rgb = None
        if self.rgb:
            # reading RGBA is a copy, reading RGB a per-pixel conversion in Mesa (10x slower); cv2 drops alpha
            self._fbo.read_into(self._rgba, components=4, attachment=0, dtype="f1")
            rgb = cv2.cvtColor(self._rgba, cv2.COLOR_RGBA2RGB)
        sem = np.empty((h, w), np.int32)
        sem_fbo = self._sem_fbo if self._separate else self._fbo
        sem_fbo.read_into(sem, components=1, attachment=0 if self._separate else first + 1, dtype="i4")
        return Frame(rgb=rgb, depth=depth, semantic=sem)

    def _render_pass(self, p: _Pass, mvp: bytes, view_b: bytes, eye, clip, view, guess_depth) -> None:  # noqa: ANN001
        """Draw pass `p` exactly as if every face were drawn, drawing only chunks that can be visible.

        A first guess is drawn -- the chunks visible from the nearest recent view plus the nearest ones in the
        frustum (for a separate semantic mesh: those the visual depth does not hide) -- and every frustum chunk
        that its depth does not hide is `needed` (see `cull.py`). If the guess missed a few, they are added on
        top when none of their fragments ties with the drawn depth, else the needed chunks are drawn afresh. A
        guess that left much of the view open (a cold start, a turn) first grows, depth only, by the nearest
        missing chunks with a doubling budget: its depth then hides far rooms seen through the holes, which
        would otherwise all be needed."""
        p.prog["u_mvp"].write(mvp)
        p.prog["u_view"].write(view_b)
        for unit, tex in enumerate(p.textures):
            tex.use(unit)
        if p.chunks is None:
            self._draw(p, None)
            return
        ch = p.chunks
        infrustum = frustum_mask(ch, clip)
        if faces_in(ch, infrustum) <= GUESS_FACES:  # few faces: culling more would cost more than it saves
            self._draw(p, infrustum)
            return
        seen = _recent_view(p.recent, eye, view)
        known = infrustum & p.recent[seen][2] if seen is not None else np.zeros_like(infrustum)
        if guess_depth is None:
            guess = known | nearest_chunks(ch, infrustum & ~known, eye, GUESS_FACES)
        else:
            hidden_margin = SEMANTIC_GUESS_MARGIN_M
            guess = known | occlusion_mask(ch, infrustum, guess_depth, view, self._focal, cam.NEAR, hidden_margin)
        self._draw(p, guess)
        drawn, depth_only, budget = guess, False, GUESS_FACES
        while True:
            needed = self._needed(p, infrustum, view)
            missing = needed & ~drawn
            if not missing.any() and not depth_only:
                break  # the guess was complete: its frame is final
            few = faces_in(ch, missing) * ADD_RATIO <= faces_in(ch, needed)
            if not depth_only and few and self._add_without_ties(p, missing):
                needed = self._needed(p, needed, view)
                break
            if not missing.any() or faces_in(ch, missing) <= GUESS_GROWTH * faces_in(ch, needed & drawn):
                self._draw(p, needed)
                needed = self._needed(p, needed, view)  # tighter: against the final depth (next frame's guess)
                break
            budget *= 2
            grow = nearest_chunks(ch, missing, eye, budget)
            self._draw(p, grow, depth_only=True)
            drawn, depth_only = drawn | grow, True
        _remember_view(p.recent, seen, eye, view, needed)

    def _add_without_ties(self, p: _Pass, mask: np.ndarray) -> bool:
        """Draw the chunks in `mask` on top of the frame, unless one of their fragments has exactly the depth
        already drawn at its pixel (a tie, which only the original face order may resolve): then draw nothing
        and return False. Without ties, the frame equals drawing both sets in the original order."""
        faces = visible_faces(p.chunks, mask)
        idx = _corner_indices(faces)
        p.ibo.write(idx)
        self.faces_drawn += 2 * len(faces)
        ctx = self.ctx
        p.zfbo.depth_mask = False
        p.zfbo.use()
        ctx.depth_func = "=="
        with self._ties:
            p.vao_subset.render(vertices=len(idx))
        ctx.depth_func = "<"
        p.zfbo.depth_mask = True
        if self._ties.samples:
            return False
        p.fbo.use()
        p.vao_subset.render(vertices=len(idx))
        return True

    def _needed(self, p: _Pass, candidates: np.ndarray, view: np.ndarray) -> np.ndarray:
        """Candidates not hidden behind the depth buffer of pass `p` (which holds z / FAR, cleared to 1)."""
        p.zfbo.read_into(p.zbuf, components=1, attachment=-1, dtype="f4")
        return occlusion_mask(p.chunks, candidates, p.zbuf, view, self._focal, cam.NEAR, scale=cam.FAR, hole_at=1.0)

    def _draw(self, p: _Pass, mask: np.ndarray | None, depth_only: bool = False) -> None:
        """Draw the faces of the chunks in `mask` (all faces when None), in mesh order: after clearing the pass's
        framebuffer, or (`depth_only`) into its depth buffer alone, on top of what is there (the depth buffer
        keeps the nearest depth whatever the order, so such draws may come in any order)."""
        if depth_only:
            p.zfbo.use()
        else:
            p.fbo.use()
            p.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        if mask is None or p.chunks is None:
            p.vao.render()
            self.faces_drawn += p.num_faces
            return
        faces = visible_faces(p.chunks, mask)
        self.faces_drawn += len(faces)
        if len(faces) == p.chunks.num_faces:
            p.vao.render()
        elif len(faces):
            idx = _corner_indices(faces)
            p.ibo.write(idx)
            p.vao_subset.render(vertices=len(idx))

    def close(self) -> None:
        for obj in reversed(self._res):
            obj.release()
        self._res.clear()


def _recent_view(recent: list, eye: np.ndarray, view: np.ndarray) -> int | None:
    """Index of the recent view nearest to this one (eye distance + forward-vector distance), if any is
    within SAME_VIEWER: envs sharing a renderer (one world per process) each keep finding their own."""
    if not recent:
        return None
    fwd = -view[2, :3]
    d = [np.linalg.norm(eye - e) + np.linalg.norm(fwd - f) for e, f, _ in recent]
    j = int(np.argmin(d))
    return j if d[j] <= SAME_VIEWER else None


def _remember_view(recent: list, seen: int | None, eye: np.ndarray, view: np.ndarray, visible: np.ndarray) -> None:
    if seen is not None:
        del recent[seen]
    recent.append((np.array(eye, dtype=np.float64), -view[2, :3].copy(), visible))
    del recent[:-RECENT_VIEWS]


def _same(a: np.ndarray | None, b: np.ndarray | None) -> bool:
    return a is not None and b is not None and a.shape == b.shape and bool(np.array_equal(a, b))


def _corner_indices(faces: np.ndarray) -> np.ndarray:
    """Vertex ids of the de-indexed buffer (3 per face) for `faces`, in order."""
    idx = np.empty((len(faces), 3), np.int32)
    base = faces * 3
    idx[:, 0] = base
    idx[:, 1] = base + 1
    idx[:, 2] = base + 2
    return idx.reshape(-1)
