"""Writing scenes in the HM3DSem layout: a small glTF 2.0 (GLB) encoder and `write_scene`.

Why hand-rolled: positions stay float32 bit-exact and face order is kept, so a written scene loads back
identical (tests compare arrays exactly); third-party readers (trimesh, pygltflib) read the files too.
"""

from __future__ import annotations

import io
import json
import struct
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from ovon.atomic import atomic_write_bytes
from ovon.scenes.hm3dsem.errors import SceneLoadWarning
from ovon.scenes.hm3dsem.files import _short_id
from ovon.scenes.hm3dsem.semantic_txt import SemanticEntry, format_semantic_txt
from ovon.scenes.hm3dsem.sidecar import sidecar_doc
from ovon.scenes.model import Scene

VERTEX_ID_ATTR = "_VERTEX_ID"  # our own glTF attribute: index of the vertex in the original mesh

_GL_FLOAT, _GL_UBYTE, _GL_UINT, _GL_USHORT, _GL_BYTE, _GL_SHORT = 5126, 5121, 5125, 5123, 5120, 5122
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963


class _GlbBuilder:
    """Accumulates one binary buffer and the accessors/bufferViews pointing into it."""

    def __init__(self) -> None:
        self.chunks: list[bytes] = []
        self.offset = 0
        self.views: list[dict] = []
        self.accessors: list[dict] = []

    def _view(self, data: bytes, target: int | None) -> int:
        pad = (-self.offset) % 4
        if pad:
            self.chunks.append(b"\x00" * pad)
            self.offset += pad
        view: dict[str, Any] = {"buffer": 0, "byteOffset": self.offset, "byteLength": len(data)}
        if target is not None:
            view["target"] = target
        self.chunks.append(data)
        self.offset += len(data)
        self.views.append(view)
        return len(self.views) - 1

    def accessor(self, arr: np.ndarray, gltype: str, comp: int, target: int | None, **extra: Any) -> int:
        view = self._view(np.ascontiguousarray(arr).tobytes(), target)
        acc: dict[str, Any] = {
            "bufferView": view,
            "componentType": comp,
            "count": int(arr.shape[0]),
            "type": gltype,
            **extra,
        }
        self.accessors.append(acc)
        return len(self.accessors) - 1

    def image(self, png: bytes) -> int:
        return self._view(png, None)

    def blob(self) -> bytes:
        data = b"".join(self.chunks)
        return data + b"\x00" * ((-len(data)) % 4)


def _png_bytes(texture: np.ndarray) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(texture[..., :3].astype(np.uint8))).save(buf, format="PNG")
    return buf.getvalue()


def encode_glb(
    vertices: np.ndarray,
    faces: np.ndarray,
    vertex_rgb: np.ndarray | None = None,
    uvs: np.ndarray | None = None,
    texture: np.ndarray | None = None,
    vertex_ids: np.ndarray | None = None,
    unlit: bool = False,
) -> bytes:
    """One-primitive GLB. `uvs` follow the Mesh convention (v = 1 at the image top) and are flipped
    to glTF's (v = 0 at the top) here."""
    b = _GlbBuilder()
    pos = np.ascontiguousarray(vertices, dtype=np.float32)
    attrs: dict[str, int] = {}
    mn = pos.min(axis=0) if len(pos) else np.zeros(3, np.float32)
    mx = pos.max(axis=0) if len(pos) else np.zeros(3, np.float32)
    attrs["POSITION"] = b.accessor(
        pos, "VEC3", _GL_FLOAT, _ARRAY_BUFFER, min=[float(v) for v in mn], max=[float(v) for v in mx]
    )
    if vertex_rgb is not None:
        rgba = np.full((len(pos), 4), 255, dtype=np.uint8)
        rgba[:, :3] = vertex_rgb
        attrs["COLOR_0"] = b.accessor(rgba, "VEC4", _GL_UBYTE, _ARRAY_BUFFER, normalized=True)
    if uvs is not None:
        uv = np.asarray(uvs, dtype=np.float32).copy()
        uv[:, 1] = 1.0 - uv[:, 1]
        attrs["TEXCOORD_0"] = b.accessor(uv, "VEC2", _GL_FLOAT, _ARRAY_BUFFER)
    if vertex_ids is not None:
        attrs[VERTEX_ID_ATTR] = b.accessor(vertex_ids.astype(np.float32), "SCALAR", _GL_FLOAT, _ARRAY_BUFFER)
    idx = b.accessor(np.asarray(faces, dtype=np.uint32).reshape(-1), "SCALAR", _GL_UINT, _ELEMENT_ARRAY_BUFFER)
    material: dict[str, Any] = {
        "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1], "metallicFactor": 0.0, "roughnessFactor": 1.0},
        "doubleSided": True,
    }
    doc: dict[str, Any] = {"asset": {"version": "2.0", "generator": "ovon.scenes.hm3dsem"}}
    if texture is not None and uvs is not None:
        view = b.image(_png_bytes(texture))
        doc["images"] = [{"bufferView": view, "mimeType": "image/png"}]
        doc["samplers"] = [{"magFilter": 9728, "minFilter": 9728}]  # NEAREST: exact texel colours
        doc["textures"] = [{"source": 0, "sampler": 0}]
        material["pbrMetallicRoughness"]["baseColorTexture"] = {"index": 0}
    if unlit:
        material["extensions"] = {"KHR_materials_unlit": {}}
        doc["extensionsUsed"] = ["KHR_materials_unlit"]
    doc.update(
        {
            "scene": 0,
            "scenes": [{"nodes": [0]}],
            "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [{"attributes": attrs, "indices": idx, "material": 0, "mode": 4}]}],
            "materials": [material],
            "accessors": b.accessors,
            "bufferViews": b.views,
        }
    )
    blob = b.blob()
    doc["buffers"] = [{"byteLength": len(blob)}]
    js = json.dumps(doc, separators=(",", ":")).encode()
    js += b" " * ((-len(js)) % 4)
    total = 12 + 8 + len(js) + 8 + len(blob)
    return b"".join(
        [
            struct.pack("<4sII", b"glTF", 2, total),
            struct.pack("<I4s", len(js), b"JSON"),
            js,
            struct.pack("<I4s", len(blob), b"BIN\x00"),
            blob,
        ]
    )


def _per_face_layout(num_vertices: int, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Corner-duplicated layout: written vertex k comes from original vertex `src[k]`. Vertices no face
    uses are appended at the end so the original vertex array can be rebuilt exactly."""
    corners = faces.reshape(-1).astype(np.int64)
    unused = np.setdiff1d(np.arange(num_vertices), corners, assume_unique=False)
    src = np.concatenate([corners, unused])
    new_faces = np.arange(len(corners), dtype=np.int64).reshape(-1, 3)
    return src, new_faces


def _id_color(iid: int, used: set[tuple[int, int, int]]) -> tuple[int, int, int]:
    rng = np.random.default_rng(1_000_003 + iid)
    while True:
        c = tuple(int(v) for v in rng.integers(16, 256, size=3))
        if c not in used:
            return c  # type: ignore[return-value]


def semantic_palette(scene: Scene) -> dict[int, tuple[int, int, int]]:
    """Unique non-black colour per instance: the scene's own when usable, else one derived from the id."""
    used: set[tuple[int, int, int]] = set()
    out: dict[int, tuple[int, int, int]] = {}
    for o in sorted(scene.objects, key=lambda o: o.id):
        c = scene.semantic_colors.get(o.id) or tuple(int(v) for v in o.color)
        c = tuple(int(v) for v in c)
        if c == (0, 0, 0) or c in used:
            c = _id_color(o.id, used)
        used.add(c)  # type: ignore[arg-type]
        out[o.id] = c  # type: ignore[assignment]
    return out


def write_scene(scene: Scene, folder: str | Path, meta: dict | None = None) -> Path:
    """Write `scene` into `folder` in the HM3DSem layout plus the `<id>.ovon.json` sidecar.

    `meta` (JSON-serialisable) is stored as the sidecar's "meta" entry (e.g. the generator's seed).
    Returns the folder. Every file is written atomically; the sidecar is written last, so a folder
    whose four files all exist is complete.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    stem = _short_id(scene.scene_id)
    mesh = scene.mesh
    verts = np.asarray(mesh.vertices, dtype=np.float32)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    palette = semantic_palette(scene)

    # visual mesh
    has_tex = mesh.texture is not None and mesh.uvs is not None
    if mesh.face_colors is not None:
        src, new_faces = _per_face_layout(len(verts), faces)
        rgb = np.zeros((len(src), 3), dtype=np.uint8)
        rgb[: faces.size] = np.repeat(np.asarray(mesh.face_colors, dtype=np.uint8)[:, :3], 3, axis=0)
        if mesh.vertex_colors is not None:
            warnings.warn(
                f"{scene.scene_id}: mesh has both face and vertex colours; only face colours are written",
                SceneLoadWarning,
                stacklevel=2,
            )
        visual = encode_glb(
            verts[src],
            new_faces,
            vertex_rgb=rgb,
            uvs=None if not has_tex else np.asarray(mesh.uvs)[src],
            texture=mesh.texture if has_tex else None,
            vertex_ids=src,
        )
        mode = "face"
    else:
        visual = encode_glb(
            verts,
            faces,
            vertex_rgb=None if mesh.vertex_colors is None else np.asarray(mesh.vertex_colors)[:, :3],
            uvs=mesh.uvs if has_tex else None,
            texture=mesh.texture if has_tex else None,
        )
        mode = "vertex" if mesh.vertex_colors is not None else ("texture" if has_tex else "none")

    # semantic mesh: same geometry as the visual one, flat instance colours per face
    sem_src = scene.semantic_source
    s_verts = np.asarray(sem_src.vertices, dtype=np.float32)
    s_faces = np.asarray(sem_src.faces, dtype=np.int64)
    fi = sem_src.face_instance
    fi = np.zeros(len(s_faces), dtype=np.int64) if fi is None else np.asarray(fi, dtype=np.int64)
    lut_ids = np.array(sorted(palette), dtype=np.int64)
    lut_rgb = np.array([palette[i] for i in lut_ids], dtype=np.uint8).reshape(-1, 3)
    face_rgb = np.zeros((len(s_faces), 3), dtype=np.uint8)
    if len(lut_ids):
        pos = np.clip(np.searchsorted(lut_ids, fi), 0, len(lut_ids) - 1)
        known = lut_ids[pos] == fi
        face_rgb[known] = lut_rgb[pos[known]]
        unknown = (~known) & (fi != 0)
    else:
        unknown = fi != 0
    if unknown.any():
        warnings.warn(
            f"{scene.scene_id}: {int(unknown.sum())} faces carry instance ids with no object "
            f"({sorted(set(fi[unknown].tolist()))[:10]}); written as id 0 (black)",
            SceneLoadWarning,
            stacklevel=2,
        )
    src, new_faces = _per_face_layout(len(s_verts), s_faces)
    rgb = np.zeros((len(src), 3), dtype=np.uint8)
    rgb[: s_faces.size] = np.repeat(face_rgb, 3, axis=0)
    semantic = encode_glb(s_verts[src], new_faces, vertex_rgb=rgb, vertex_ids=src, unlit=True)

    entries = [
        SemanticEntry(o.id, palette[o.id], o.raw_label, int(o.region_id))
        for o in sorted(scene.objects, key=lambda o: o.id)
    ]
    atomic_write_bytes(folder / f"{stem}.glb", visual)
    atomic_write_bytes(folder / f"{stem}.semantic.glb", semantic)
    atomic_write_bytes(folder / f"{stem}.semantic.txt", format_semantic_txt(entries).encode())
    side_doc = sidecar_doc(scene, mode)
    if meta is not None:
        side_doc["meta"] = meta
    side = json.dumps(side_doc, indent=1)
    atomic_write_bytes(folder / f"{stem}.ovon.json", side.encode())
    return folder
