"""CPU ray-casting renderer on embree (embreex): one primary ray per pixel centre, shaded in numba.

Rays come from `camera.ray_directions`, the same pixel centres and projection the GL backend
rasterises, so both backends agree pixel for pixel. z-depth = t * cos(angle to the optical axis) with
unit rays. Rays start on the near plane (z = `camera.NEAR`), like GL's near clipping, so a camera
inside a wall sees what GL sees; hits beyond `camera.FAR` are dropped like GL's far clipping.
"""

from __future__ import annotations

import numba
import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

from ovon.config.sim import CameraConfig
from ovon.scenes.model import Mesh, Scene
from ovon.sim.render import camera as cam
from ovon.sim.render.texture import (
    SemanticSource,
    VisualSource,
    same_geometry,
    sample_bilinear,
    sample_nearest_id,
    semantic_source,
    visual_source,
)
from ovon.sim.types import Frame

_MODES = {"face": 0, "vertex": 1, "texture": 2}
_DEPTH_ONLY = 3
_NEAR = np.float32(cam.NEAR)
_FAR = np.float32(cam.FAR)


def _bvh(mesh: Mesh) -> rtcore_scene.EmbreeScene:
    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(
        scene=scene,
        vertices=np.ascontiguousarray(mesh.vertices, dtype=np.float32),
        indices=np.ascontiguousarray(mesh.faces, dtype=np.int32),
    )
    return scene


class EmbreeRenderer:
    """Renderer protocol on embree; geometry/BVH built once, ray directions precomputed once."""

    def __init__(self, scene: Scene, camera: CameraConfig) -> None:
        self.width = int(camera.width)
        self.height = int(camera.height)
        self.hfov_deg = float(camera.hfov_deg)
        mesh = scene.mesh
        self._faces = np.ascontiguousarray(mesh.faces, dtype=np.int32)
        self._vis: VisualSource = visual_source(mesh)
        self.rgb = bool(camera.rgb)  # False: depth and ids only (no colour lookups)
        self._mode = _MODES[self._vis.mode] if self.rgb else _DEPTH_ONLY
        # Unused inputs are passed as tiny dummies so numba compiles one specialisation.
        self._face_rgb = _or(self._vis.face_rgb, np.zeros((1, 3), np.uint8))
        self._vert_rgb = _or(self._vis.vertex_rgb, np.zeros((1, 3), np.uint8))
        self._uvs = _or(self._vis.uvs, np.zeros((1, 2), np.float32))
        self._tex = _or(self._vis.texture, np.zeros((1, 1, 3), np.uint8))
        self._scene = _bvh(mesh)

        sem_mesh = scene.semantic_source
        self._sem: SemanticSource = semantic_source(sem_mesh, scene.semantic_colors)
        self._separate_sem = not same_geometry(mesh, scene.semantic_mesh)
        self._sem_scene = _bvh(sem_mesh) if self._separate_sem else None
        self._sem_faces = np.ascontiguousarray(sem_mesh.faces, dtype=np.int32)
        self._sem_is_tex = self._sem.mode == "texture"
        self._face_ids = _or(self._sem.face_ids, np.zeros(1, np.int32))
        self._sem_uvs = _or(self._sem.uvs, np.zeros((1, 2), np.float32))
        self._id_tex = _or(self._sem.id_texture, np.zeros((1, 1), np.int32))

        dirs, zfac = cam.ray_directions(self.width, self.height, self.hfov_deg)
        self._dirs_cam = dirs.astype(np.float32)
        self._zfac = zfac.astype(np.float32)
        self._near_t = (cam.NEAR / zfac).astype(np.float32)[:, None]  # ray length to the near plane
        n = self.width * self.height
        self._dirs = np.empty((n, 3), np.float32)
        self._origins = np.empty((n, 3), np.float32)

    def render(self, eye: np.ndarray, yaw: float, pitch: float) -> Frame:
        """Cast one ray per pixel centre; colour, depth and ids from the hit triangles."""
        rot = cam.rotation(yaw, pitch).T.astype(np.float32)
        np.matmul(self._dirs_cam, rot, out=self._dirs)
        np.multiply(self._dirs, self._near_t, out=self._origins)
        self._origins += np.asarray(eye, dtype=np.float32)
        hit = self._scene.run(self._origins, self._dirs, output=1)
        n = self.width * self.height
        rgb = np.empty((n if self.rgb else 1, 3), np.uint8)
        depth = np.empty(n, np.float32)
        sem = np.empty(n, np.int32)
        _shade(
            hit["primID"], hit["u"], hit["v"], hit["tfar"], self._zfac, self._mode, self._faces,
            self._vis.shade, self._face_rgb, self._vert_rgb, self._uvs, self._tex, rgb, depth,
        )  # fmt: skip
        if self._sem_scene is not None:
            hit = self._sem_scene.run(self._origins, self._dirs, output=1)
        _ids(
            hit["primID"], hit["u"], hit["v"], hit["tfar"], self._zfac, self._sem_is_tex,
            self._sem_faces, self._face_ids, self._sem_uvs, self._id_tex, sem,
        )  # fmt: skip
        shape = (self.height, self.width)
        rgb_out = rgb.reshape(*shape, 3) if self.rgb else None
        return Frame(rgb=rgb_out, depth=depth.reshape(shape), semantic=sem.reshape(shape))

    def close(self) -> None:
        self._scene = None  # type: ignore[assignment]
        self._sem_scene = None


def _or(a: np.ndarray | None, default: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a) if a is not None else default


@numba.njit(cache=True, nogil=True)
def _shade(prim, bu, bv, tfar, zfac, mode, faces, shade, face_rgb, vert_rgb, uvs, tex, rgb, depth):  # noqa: ANN001
    """Per-pixel colour (base * face shade, rounded like GL's unorm8 conversion) and z-depth."""
    col = np.empty(3, np.float32)
    for k in range(prim.shape[0]):
        f = prim[k]
        z = tfar[k] * zfac[k] + _NEAR
        if f < 0 or z > _FAR:
            depth[k] = 0.0
            if mode == _DEPTH_ONLY:
                continue
            rgb[k, 0] = 0
            rgb[k, 1] = 0
            rgb[k, 2] = 0
            continue
        depth[k] = z
        if mode == _DEPTH_ONLY:
            continue
        u = bu[k]
        v = bv[k]
        w = 1.0 - u - v
        if mode == 0:
            for c in range(3):
                col[c] = face_rgb[f, c] / 255.0
        elif mode == 1:
            a, b, d = faces[f, 0], faces[f, 1], faces[f, 2]
            for c in range(3):
                col[c] = (w * vert_rgb[a, c] + u * vert_rgb[b, c] + v * vert_rgb[d, c]) / 255.0
        else:
            a, b, d = faces[f, 0], faces[f, 1], faces[f, 2]
            tu = w * uvs[a, 0] + u * uvs[b, 0] + v * uvs[d, 0]
            tv = w * uvs[a, 1] + u * uvs[b, 1] + v * uvs[d, 1]
            sample_bilinear(tex, tu, tv, col)
        s = shade[f]
        for c in range(3):
            x = col[c] * s * 255.0 + 0.5
            rgb[k, c] = np.uint8(min(max(x, 0.0), 255.0))


@numba.njit(cache=True, nogil=True)
def _ids(prim, bu, bv, tfar, zfac, is_tex, faces, face_ids, uvs, id_tex, out):  # noqa: ANN001
    """Per-pixel instance id from per-face ids or a nearest-sampled id texture (0 = none)."""
    for k in range(prim.shape[0]):
        f = prim[k]
        z = tfar[k] * zfac[k] + _NEAR
        if f < 0 or z > _FAR:
            out[k] = 0
        elif not is_tex:
            out[k] = face_ids[f]
        else:
            u = bu[k]
            v = bv[k]
            w = 1.0 - u - v
            a, b, d = faces[f, 0], faces[f, 1], faces[f, 2]
            tu = w * uvs[a, 0] + u * uvs[b, 0] + v * uvs[d, 0]
            tv = w * uvs[a, 1] + u * uvs[b, 1] + v * uvs[d, 1]
            out[k] = sample_nearest_id(id_tex, tu, tv)
