"""Any mesh file -> triangle primitives: glTF through our own reader, PLY and OBJ through trimesh.

Why trimesh for PLY/OBJ: both formats have many dialects (ASCII/binary PLY, OBJ with MTL materials and
texture images) and trimesh reads them all without changing the vertices (`process=False`). Vertex
colours and textures (OBJ `map_Kd`, PLY texture UVs) carry over; UVs stay in the file's convention
(v = 0 at the image bottom), which is the Mesh convention.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ovon.scenes.hm3dsem.errors import SceneFileError, lfs_pointer_error
from ovon.scenes.hm3dsem.glb_read import _Primitive, read_primitives

FORMATS = {".glb": "glTF binary", ".gltf": "glTF", ".ply": "PLY", ".obj": "OBJ"}


def read_mesh_primitives(path: Path) -> tuple[list[_Primitive], list[str]]:
    """Triangle primitives of a `.glb`/`.gltf`/`.ply`/`.obj` file (world coordinates) and loader notes."""
    suffix = path.suffix.lower()
    if suffix in (".glb", ".gltf"):
        prims, notes, _doc = read_primitives(path)
        return prims, notes
    if suffix not in FORMATS:
        raise SceneFileError(path, f"unsupported mesh format {suffix!r}", f"use one of {sorted(FORMATS)}")
    return _read_trimesh(path, FORMATS[suffix])


def _read_trimesh(path: Path, fmt: str) -> tuple[list[_Primitive], list[str]]:
    with open(path, "rb") as f:
        head = f.read(200)
    err = lfs_pointer_error(path, head)
    if err is not None:
        raise err
    if not head.strip():
        raise SceneFileError(path, f"is empty (not a {fmt} mesh)")
    import trimesh

    try:
        loaded = trimesh.load(str(path), process=False, maintain_order=True)
    except Exception as e:  # trimesh raises many types for broken files
        raise SceneFileError(
            path,
            f"could not be read as {fmt} ({type(e).__name__}: {str(e)[:120]})",
            "is the file complete? re-export it",
        ) from None
    geoms = list(loaded.dump()) if isinstance(loaded, trimesh.Scene) else [loaded]
    notes: list[str] = []
    prims = []
    for g in geoms:
        if not isinstance(g, trimesh.Trimesh) or len(g.faces) == 0:
            notes.append(f"skipped a {type(g).__name__} without triangles")
            continue
        prims.append(_primitive(path, g))
    return prims, notes


def _primitive(path: Path, g) -> _Primitive:  # noqa: ANN001 (trimesh.Trimesh)
    pos = np.asarray(g.vertices, dtype=np.float32)
    faces = np.asarray(g.faces, dtype=np.int64)
    bad = ~np.isfinite(pos).all(axis=1)
    if bad.any():
        raise SceneFileError(
            path,
            f"{int(bad.sum()):,} of {len(pos):,} vertex positions are NaN or infinite",
            "repair or re-export the mesh",
        )
    if len(faces) and (faces.min() < 0 or faces.max() >= len(pos)):
        raise SceneFileError(path, f"face index {int(faces.max())} is out of range: the mesh has {len(pos):,} vertices")
    p = _Primitive(positions=pos, indices=faces)
    vis = g.visual
    if getattr(vis, "kind", None) == "texture":
        uv = getattr(vis, "uv", None)
        mat = getattr(vis, "material", None)
        img = getattr(mat, "image", None) or getattr(mat, "baseColorTexture", None)
        if uv is not None and img is not None and len(uv) == len(pos):
            p.uvs = np.asarray(uv, dtype=np.float32)[:, :2].copy()
            p.texture = np.asarray(img.convert("RGB"), dtype=np.uint8).copy()
        else:
            p.texture_problem = "texture image or UVs missing"
        diffuse = getattr(mat, "diffuse", None)
        if diffuse is not None:
            p.base_color = tuple(int(c) for c in np.asarray(diffuse)[:3])  # type: ignore[assignment]
    elif getattr(vis, "kind", None) == "vertex":
        p.colors = np.asarray(vis.vertex_colors, dtype=np.uint8)[:, :3].copy()
    elif getattr(vis, "kind", None) == "face":
        fc = np.asarray(vis.face_colors, dtype=np.uint8)[:, :3]
        # per-face colour -> corner-duplicated vertices so it survives as vertex colours
        p.positions = pos[faces.reshape(-1)]
        p.indices = np.arange(len(faces) * 3, dtype=np.int64).reshape(-1, 3)
        p.colors = np.repeat(fc, 3, axis=0)
    return p
