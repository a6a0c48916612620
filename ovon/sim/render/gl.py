"""Headless OpenGL renderer (moderngl on EGL; llvmpipe on CPU machines).

Geometry is de-indexed once (3 vertices per face) so flat colours, shading and instance ids are plain
per-vertex attributes, and uploaded once. One framebuffer holds colour (RGBA8), linear z-depth (R32F,
written from view space for precision rather than un-projected from the depth buffer), instance ids
(R32I) and a depth buffer. A separate semantic mesh with other triangles (real scans) is drawn in a
second pass into its own framebuffer; one with the same triangles shares the single pass. The
projection flips y, so the bottom-up GL read-back comes out with row 0 at the top.
"""

from __future__ import annotations

import os

import numpy as np

from ovon.config.sim import CameraConfig
from ovon.scenes.model import Mesh, Scene
from ovon.sim.render import camera as cam
from ovon.sim.render.texture import (
    SemanticSource,
    VisualSource,
    same_geometry,
    semantic_source,
    visual_source,
)
from ovon.sim.types import Frame

_CTX = None  # one shared context per process (creating one costs ~0.3 s)
_CTX_PID = -1


def gl_context():  # noqa: ANN201  (moderngl.Context; import is lazy)
    """The process's shared standalone EGL context, created on first use (and again after a fork)."""
    global _CTX, _CTX_PID
    if _CTX is None or _CTX_PID != os.getpid():
        # llvmpipe reads this at start-up; 0 (render on the calling thread) measured fastest on 2 cores
        os.environ.setdefault("LP_NUM_THREADS", "0")
        import moderngl

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
#ifdef SEM_TEX
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
#ifdef SEM_TEX
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
in vec2 v_suv;
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
#if defined(SEM_FACE) || defined(SEM_TEX)
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


class GLRenderer:
    """Renderer protocol on moderngl; one draw call per pass, buffers reused across frames."""

    def __init__(self, scene: Scene, camera: CameraConfig) -> None:
        self.width = int(camera.width)
        self.height = int(camera.height)
        self.hfov_deg = float(camera.hfov_deg)
        self.ctx = gl_context()
        ctx = self.ctx
        self._res: list = []  # GL objects to release on close
        self._proj = cam.projection_matrix(self.width, self.height, self.hfov_deg)
        size = (self.width, self.height)

        # Without RGB (camera.rgb = False: no consumer reads it) the colour attribute, texture lookup,
        # attachment and read-back are all skipped; depth and ids stay one pass.
        self.rgb = bool(getattr(camera, "rgb", True))
        vis = visual_source(scene.mesh) if self.rgb else None
        sem = semantic_source(scene.semantic_source, scene.semantic_colors)
        self._separate = not same_geometry(scene.mesh, scene.semantic_mesh)
        sem_define = "SEM_TEX" if sem.mode == "texture" else "SEM_FACE"
        vis_defines = ["VISUAL"] + ([] if vis is None else ["VIS_TEX" if vis.mode == "texture" else "VIS_COL"])
        if not self._separate:
            vis_defines.append(sem_define)  # same triangles: ids in the same single pass
        self._vis_prog, self._vis_vao, self._vis_tex = self._build(scene.mesh, vis_defines, vis, sem)

        self._zlin = self._keep(ctx.renderbuffer(size, components=1, dtype="f4"))
        self._ids = self._keep(ctx.renderbuffer(size, components=1, dtype="i4"))
        attach = [self._zlin] + ([] if self._separate else [self._ids])
        if self.rgb:
            self._color = self._keep(ctx.renderbuffer(size, components=4, dtype="f1"))
            attach.insert(0, self._color)
        self._fbo = self._keep(
            ctx.framebuffer(color_attachments=attach, depth_attachment=self._keep(ctx.depth_renderbuffer(size)))
        )
        if self._separate:
            sem_mesh = scene.semantic_source
            self._sem_prog, self._sem_vao, self._sem_tex = self._build(sem_mesh, [sem_define], None, sem)
            self._sem_fbo = self._keep(
                ctx.framebuffer(
                    color_attachments=[self._ids], depth_attachment=self._keep(ctx.depth_renderbuffer(size))
                )
            )

    def _keep(self, obj):  # noqa: ANN001, ANN202
        self._res.append(obj)
        return obj

    def _build(self, mesh: Mesh, defines: list[str], vis: VisualSource | None, sem: SemanticSource):  # noqa: ANN202
        """Compile the program variant and upload the de-indexed mesh with its attributes."""
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
                import moderngl

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
            content.append((sem.uvs[corners].astype("f4"), "2f", "in_suv"))
            h, w = sem.id_texture.shape
            tex = self._keep(ctx.texture((w, h), 1, sem.id_texture.astype("i4").tobytes(), dtype="i4"))
            import moderngl

            tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            textures.append(("u_ids", tex))
        vao_content = []
        for data, fmt, name in content:
            buf = self._keep(ctx.buffer(np.ascontiguousarray(data).tobytes()))
            vao_content.append((buf, fmt, name))
        vao = self._keep(ctx.vertex_array(prog, vao_content))
        for unit, (name, _tex) in enumerate(textures):
            prog[name].value = unit
        return prog, vao, [t for _, t in textures]

    def render(self, eye: np.ndarray, yaw: float, pitch: float) -> Frame:
        """Draw the visual mesh (and the semantic mesh when separate) and read the attachments back."""
        ctx = self.ctx
        view = cam.view_matrix(eye, yaw, pitch)
        mvp = (self._proj @ view).astype("f4").T.tobytes()  # GL wants column-major
        view_b = view.astype("f4").T.tobytes()
        ctx.disable(ctx.CULL_FACE)
        ctx.enable(ctx.DEPTH_TEST)

        self._fbo.use()
        self._fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        self._vis_prog["u_mvp"].write(mvp)
        self._vis_prog["u_view"].write(view_b)
        for unit, tex in enumerate(self._vis_tex):
            tex.use(unit)
        self._vis_vao.render()
        if self._separate:
            self._sem_fbo.use()
            self._sem_fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
            self._sem_prog["u_mvp"].write(mvp)
            self._sem_prog["u_view"].write(view_b)
            for unit, tex in enumerate(self._sem_tex):
                tex.use(unit)
            self._sem_vao.render()

        h, w = self.height, self.width
        rgb = None
        first = 0
        if self.rgb:
            rgb = np.empty((h, w, 3), np.uint8)
            self._fbo.read_into(rgb, components=3, attachment=0, dtype="f1")
            first = 1
        depth = np.empty((h, w), np.float32)
        sem = np.empty((h, w), np.int32)
        self._fbo.read_into(depth, components=1, attachment=first, dtype="f4")
        sem_fbo = self._sem_fbo if self._separate else self._fbo
        sem_fbo.read_into(sem, components=1, attachment=0 if self._separate else first + 1, dtype="i4")
        return Frame(rgb=rgb, depth=depth, semantic=sem)

    def close(self) -> None:
        for obj in reversed(self._res):
            obj.release()
        self._res.clear()
