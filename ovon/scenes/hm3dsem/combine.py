"""Primitives -> one `Mesh`: texture atlas of several materials, vertex or flat colours, and the
per-face instance ids of a semantic mesh (from vertex colours or a painted texture).

Approximation for real scans: their semantic mesh paints instance colours into a texture, so a face's
instance id is the texel at the face's centroid UV (nearest texel). A face can span several painted
regions; renderers sample the texture per pixel instead, and per-instance boxes computed from faces
inherit this approximation.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ovon.scenes.hm3dsem.errors import SceneFileError
from ovon.scenes.hm3dsem.glb_read import _Primitive
from ovon.scenes.model import Mesh

MAX_ATLAS_DIM = 8192  # atlas side cap (memory: 8192^2 RGB = 200 MB); bigger ones are downsampled (nearest)


def sample_texture_nearest(texture: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Texel colours at `uv` (Mesh convention, v = 1 at the top) with nearest lookup and repeat wrap."""
    h, w = texture.shape[:2]
    u = np.asarray(uv[:, 0], dtype=np.float64)
    v = np.asarray(uv[:, 1], dtype=np.float64)
    col = np.floor(np.mod(u, 1.0) * w).astype(np.int64) % w
    row = np.floor(np.mod(1.0 - v, 1.0) * h).astype(np.int64) % h
    return texture[row, col, :3]


def _merge_textures(prims: list[_Primitive]) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """One atlas (grid of pages) for several textured primitives; UVs remapped into it.

    Primitives without a texture get a small page of their base/vertex colour. UVs are wrapped
    into [0, 1) per vertex first (repeat wrap across a face is not preserved: noted). Atlases larger
    than MAX_ATLAS_DIM are downsampled by an integer factor with nearest sampling.
    """
    notes: list[str] = []
    pages: list[np.ndarray] = []
    for p in prims:
        if p.texture is not None:
            pages.append(p.texture)
        else:
            c = p.base_color if p.colors is None else tuple(int(v) for v in p.colors.mean(axis=0))
            pages.append(np.full((4, 4, 3), c, dtype=np.uint8))
    ch = max(pg.shape[0] for pg in pages)
    cw = max(pg.shape[1] for pg in pages)
    n = len(pages)
    cols = int(np.ceil(np.sqrt(n)))
    rows = int(np.ceil(n / cols))
    factor = 1
    while max(rows * ch, cols * cw) // factor > MAX_ATLAS_DIM:
        factor *= 2
    if factor > 1:
        notes.append(f"texture atlas downsampled {factor}x (nearest) to fit {MAX_ATLAS_DIM} texels")
        pages = [pg[::factor, ::factor] for pg in pages]
        ch = max(pg.shape[0] for pg in pages)
        cw = max(pg.shape[1] for pg in pages)
    atlas = np.zeros((rows * ch, cols * cw, 3), dtype=np.uint8)
    big_h, big_w = atlas.shape[:2]
    uvs_out: list[np.ndarray] = []
    wrapped = False
    for i, (p, pg) in enumerate(zip(prims, pages)):
        r, c = divmod(i, cols)
        h, w = pg.shape[:2]
        atlas[r * ch : r * ch + h, c * cw : c * cw + w] = pg
        if p.uvs is None or p.texture is None:
            uv = np.full((len(p.positions), 2), 0.5, dtype=np.float64)
        else:
            uv = p.uvs.astype(np.float64)
            if (uv < 0).any() or (uv > 1).any():
                wrapped = True
                uv = np.mod(uv, 1.0)
        u = (c * cw + uv[:, 0] * w) / big_w
        row = r * ch + (1.0 - uv[:, 1]) * h
        uvs_out.append(np.stack([u, 1.0 - row / big_h], axis=1).astype(np.float32))
    if wrapped:
        notes.append("UVs outside [0, 1] were wrapped per vertex when building the texture atlas")
    return atlas, np.concatenate(uvs_out), notes


def _combine(prims: list[_Primitive], kind: str, path: Path) -> tuple[Mesh, list[str]]:
    """Concatenate primitives into one Mesh (vertex colours, or a texture atlas, or flat colours)."""
    notes: list[str] = []
    if not prims:
        raise SceneFileError(path, f"the {kind} mesh has no triangles")
    if len(prims) == 1 and prims[0].vertex_ids is not None:
        p = prims[0]
        vid = p.vertex_ids
        n = int(vid.max()) + 1 if len(vid) else 0
        verts = np.zeros((n, 3), dtype=np.float32)
        verts[vid] = p.positions
        faces = vid[p.indices]
        mesh = Mesh(vertices=verts, faces=faces.astype(np.int32))
        if p.colors is not None:
            vc = np.zeros((n, 3), dtype=np.uint8)
            vc[vid] = p.colors
            mesh.vertex_colors = vc
            mesh.face_colors = p.colors[p.indices[:, 0]].copy()
        if p.texture is not None and p.uvs is not None:
            uv = np.zeros((n, 2), dtype=np.float32)
            uv[vid] = p.uvs
            mesh.uvs, mesh.texture = uv, p.texture
        return mesh, notes
    offsets = np.cumsum([0] + [len(p.positions) for p in prims])
    verts = np.concatenate([p.positions for p in prims]).astype(np.float32, copy=False)
    faces = np.concatenate([p.indices + o for p, o in zip(prims, offsets[:-1])]).astype(np.int32)
    mesh = Mesh(vertices=verts, faces=faces)
    problems = sorted({p.texture_problem for p in prims if p.texture_problem})
    if len(prims) == 1 and prims[0].texture is not None:
        mesh.texture, mesh.uvs = prims[0].texture, prims[0].uvs
    elif any(p.texture is not None for p in prims):
        atlas, uvs, tnotes = _merge_textures(prims)
        mesh.texture, mesh.uvs = atlas, uvs
        notes += tnotes
    elif any(p.colors is not None for p in prims):
        mesh.vertex_colors = np.concatenate(
            [p.colors if p.colors is not None else np.tile(p.base_color, (len(p.positions), 1)) for p in prims]
        ).astype(np.uint8)
    else:
        fc = []
        for p in prims:
            c = (128, 128, 128) if p.texture_problem else p.base_color
            fc.append(np.tile(np.asarray(c, dtype=np.uint8), (len(p.indices), 1)))
        mesh.face_colors = np.concatenate(fc)
    for prob in problems:
        notes.append(f"{kind} texture not decoded ({prob}): flat grey colours are used instead")
    return mesh, notes


def _decode_face_ids(
    face_rgb: np.ndarray, color_to_id: dict[tuple[int, int, int], int]
) -> tuple[np.ndarray, int, set[tuple[int, int, int]]]:
    """Instance id per face from its colour; black is 0; unknown colours become 0 and are counted."""
    key = (face_rgb[:, 0].astype(np.int64) << 16) | (face_rgb[:, 1].astype(np.int64) << 8) | face_rgb[:, 2]
    uniq, inv = np.unique(key, return_inverse=True)
    ids = np.zeros(len(uniq), dtype=np.int32)
    missing: set[tuple[int, int, int]] = set()
    for k, u in enumerate(uniq.tolist()):
        rgb = ((u >> 16) & 255, (u >> 8) & 255, u & 255)
        if rgb == (0, 0, 0):
            continue
        iid = color_to_id.get(rgb)
        if iid is None:
            missing.add(rgb)
        else:
            ids[k] = iid
    inv = inv.reshape(-1)
    fi = ids[inv]
    missing_keys = np.array([((u >> 16) & 255, (u >> 8) & 255, u & 255) in missing for u in uniq.tolist()], dtype=bool)
    unknown = int(missing_keys[inv].sum())
    return fi, unknown, missing


def _semantic_face_colors(sem_prims: list[_Primitive]) -> tuple[np.ndarray, str]:
    """Per-face semantic colour of each primitive: vertex colour of the first corner, or the texture
    sampled at the face's centroid UV (nearest texel: an approximation for painted textures)."""
    out: list[np.ndarray] = []
    how = "vertex colours"
    for p in sem_prims:
        if p.texture is not None and p.uvs is not None:
            uv = p.uvs[p.indices].mean(axis=1)
            out.append(sample_texture_nearest(p.texture, uv))
            how = "texture at face centroids (nearest texel, approximate)"
        elif p.colors is not None:
            out.append(p.colors[p.indices[:, 0]])
        else:
            out.append(np.zeros((len(p.indices), 3), dtype=np.uint8))
    return np.concatenate(out).astype(np.uint8), how
