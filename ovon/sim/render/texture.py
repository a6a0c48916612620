"""Mesh colour/id preparation and numba texture sampling shared by both render backends.

UV convention (glTF, as a glTF loader hands UVs over): (0, 0) is the top-left of the texture image and
v grows downwards, so texel row j (row 0 = top of the image array) covers v in [j/H, (j+1)/H). Wrapping
is REPEAT (the glTF default). Visual textures are sampled bilinearly with texel centres at
((i + 0.5)/W, (j + 0.5)/H) and no mipmaps; semantic textures are sampled nearest. GL uploads the image
rows in memory order (row 0 at t = 0), which is exactly this convention, so both backends agree.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from ovon.scenes.model import Mesh
from ovon.sim.render.camera import face_shade

DEFAULT_GREY = 180  # colour of meshes that carry none


@dataclass
class VisualSource:
    """Colour description of the visual mesh, in exactly one of three modes."""

    mode: str  # "face" | "vertex" | "texture"
    shade: np.ndarray  # (M,) float32 per-face shading factor
    face_rgb: np.ndarray | None = None  # (M, 3) uint8
    vertex_rgb: np.ndarray | None = None  # (N, 3) uint8
    uvs: np.ndarray | None = None  # (N, 2) float32
    texture: np.ndarray | None = None  # (H, W, 3) uint8, C-contiguous


@dataclass
class SemanticSource:
    """Instance-id description of the semantic mesh: per-face ids or a nearest-sampled id texture."""

    mode: str  # "face" | "texture"
    face_ids: np.ndarray | None = None  # (M,) int32
    uvs: np.ndarray | None = None  # (N, 2) float32
    id_texture: np.ndarray | None = None  # (H, W) int32


def visual_source(mesh: Mesh) -> VisualSource:
    """Pick the colour mode of a visual mesh (texture > vertex colours > face colours > grey)."""
    shade = face_shade(mesh.vertices, mesh.faces)
    if mesh.uvs is not None and mesh.texture is not None:
        tex = np.ascontiguousarray(_rgb(mesh.texture))
        return VisualSource("texture", shade, uvs=mesh.uvs.astype(np.float32), texture=tex)
    if mesh.vertex_colors is not None:
        return VisualSource("vertex", shade, vertex_rgb=_rgb(mesh.vertex_colors))
    if mesh.face_colors is not None:
        return VisualSource("face", shade, face_rgb=_rgb(mesh.face_colors))
    grey = np.full((mesh.num_faces, 3), DEFAULT_GREY, dtype=np.uint8)
    return VisualSource("face", shade, face_rgb=grey)


def semantic_source(mesh: Mesh, semantic_colors: dict[int, tuple[int, int, int]]) -> SemanticSource:
    """Ids from `face_instance`, else from colours via `semantic_colors` (unknown colour -> 0)."""
    if mesh.face_instance is not None:
        return SemanticSource("face", face_ids=mesh.face_instance.astype(np.int32))
    if mesh.uvs is not None and mesh.texture is not None:
        ids = colors_to_ids(_rgb(mesh.texture), semantic_colors) if semantic_colors else None
        if ids is None or (ids == ids.flat[0]).all():  # one id everywhere (e.g. no annotations): no lookups
            value = 0 if ids is None else int(ids.flat[0])
            return SemanticSource("face", face_ids=np.full(mesh.num_faces, value, dtype=np.int32))
        return SemanticSource("texture", uvs=mesh.uvs.astype(np.float32), id_texture=ids)
    if mesh.face_colors is not None:
        return SemanticSource("face", face_ids=colors_to_ids(_rgb(mesh.face_colors), semantic_colors))
    if mesh.vertex_colors is not None:  # per-face id from the first vertex's colour
        vc = _rgb(mesh.vertex_colors)[mesh.faces[:, 0]]
        return SemanticSource("face", face_ids=colors_to_ids(vc, semantic_colors))
    return SemanticSource("face", face_ids=np.zeros(mesh.num_faces, dtype=np.int32))


def same_geometry(a: Mesh, b: Mesh | None) -> bool:
    """True when `b` is None or has exactly `a`'s triangles, so one ray cast / draw serves both."""
    if b is None or a is b:
        return True
    if a.vertices.shape != b.vertices.shape or a.faces.shape != b.faces.shape:
        return False
    return bool(np.array_equal(a.faces, b.faces) and np.array_equal(a.vertices, b.vertices))


def colors_to_ids(rgb: np.ndarray, semantic_colors: dict[int, tuple[int, int, int]]) -> np.ndarray:
    """Map (..., 3) uint8 colours to int32 ids through {id: (r, g, b)}; unknown colours give 0."""
    key = _pack(rgb)
    if not semantic_colors:
        return np.zeros(key.shape, dtype=np.int32)
    ids = np.array(list(semantic_colors.keys()), dtype=np.int32)
    cols = _pack(np.array([semantic_colors[int(i)] for i in ids], dtype=np.uint8))
    order = np.argsort(cols, kind="stable")
    cols, ids = cols[order], ids[order]
    pos = np.clip(np.searchsorted(cols, key), 0, len(cols) - 1)
    return np.where(cols[pos] == key, ids[pos], 0).astype(np.int32)


def _pack(rgb: np.ndarray) -> np.ndarray:
    rgb = rgb.astype(np.int64)
    return (rgb[..., 0] << 16) | (rgb[..., 1] << 8) | rgb[..., 2]


def _rgb(a: np.ndarray) -> np.ndarray:
    """Drop alpha and make uint8."""
    return np.asarray(a)[..., :3].astype(np.uint8, copy=False)


@numba.njit(cache=True, nogil=True, inline="always")
def sample_bilinear(tex: np.ndarray, u: float, v: float, out: np.ndarray) -> None:
    """Bilinear REPEAT sample of an (H, W, 3) uint8 texture into `out` (3,) float32 in [0, 1]."""
    h, w = tex.shape[0], tex.shape[1]
    x = u * w - 0.5
    y = v * h - 0.5
    x0 = np.floor(x)
    y0 = np.floor(y)
    fx = x - x0
    fy = y - y0
    i0 = int(x0) % w
    j0 = int(y0) % h
    i1 = (i0 + 1) % w
    j1 = (j0 + 1) % h
    for c in range(3):
        top = tex[j0, i0, c] * (1.0 - fx) + tex[j0, i1, c] * fx
        bot = tex[j1, i0, c] * (1.0 - fx) + tex[j1, i1, c] * fx
        out[c] = (top * (1.0 - fy) + bot * fy) / 255.0


@numba.njit(cache=True, nogil=True, inline="always")
def sample_nearest_id(tex: np.ndarray, u: float, v: float) -> int:
    """Nearest REPEAT sample of an (H, W) int32 id texture."""
    h, w = tex.shape[0], tex.shape[1]
    uf = u - np.floor(u)
    vf = v - np.floor(v)
    i = min(int(uf * w), w - 1)
    j = min(int(vf * h), h - 1)
    return tex[j, i]
