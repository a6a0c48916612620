"""HM3DSem scene folders: write our scenes in that layout and read them (or real HM3D v0.2 scans) back.

A scene folder holds `<id>.glb` (visual mesh; HM3D also ships `<id>.basis.glb`), `<id>.semantic.glb`
(instance colours), `<id>.semantic.txt` (first line `HM3D Semantic Annotations`, then
`id,HEXCOLOR,"raw label",region_id` per instance) and, for scenes we wrote, a sidecar
`<id>.ovon.json` with what HM3DSem cannot carry (floor heights, named regions, oriented boxes).

Why one loader for both: procedural houses and real scans must go through the same code path, so a
bug in reading real scans shows up on the embedded world too.

GLB files are read and written with a small hand-rolled glTF 2.0 reader/writer (positions stay float32
bit-exact, face order is kept, node transforms are applied as glTF defines them and nothing else: HM3D
glbs are already in Habitat's y-up frame, no z-up conversion is applied).

Approximation for real scans: their semantic mesh paints instance colours into a texture, so a
face's instance id (`face_instance` of `scene.semantic_mesh`) is the texel at the face's centroid UV
(nearest texel). A face can span several painted regions; renderers should sample the texture per
pixel instead, and per-instance boxes computed from faces inherit this approximation.
"""

from __future__ import annotations

import base64
import io
import json
import re
import struct
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ovon.atomic import atomic_write_bytes
from ovon.scenes.model import Mesh, ObjectInstance, Region, Scene

SEMANTIC_HEADER = "HM3D Semantic Annotations"
SEMANTIC_LINE_FORMAT = 'id,HEXCOLOR,"raw label",region_id'
SIDECAR_FORMAT = "ovon-scene-sidecar"
SIDECAR_VERSION = 1
VERTEX_ID_ATTR = "_VERTEX_ID"  # our own glTF attribute: index of the vertex in the original mesh
MAX_ATLAS_DIM = 8192  # atlas side cap (memory: 8192^2 RGB = 200 MB); bigger ones are downsampled (nearest)
FLOOR_SEPARATION = 1.5  # metres between two detected floors of a real scan
FLOOR_TOLERANCE = 0.3  # an object belongs to the highest floor at or below its bottom + this

_LINE_RE = re.compile(r'^\s*(\d+)\s*,\s*#?([0-9A-Fa-f]{6})\s*,\s*"(.*)"\s*,\s*(-?\d+)\s*$')
_SUFFIXES = (".semantic.glb", ".semantic.txt", ".ovon.json", ".basis.glb", ".glb")


class SceneLoadWarning(UserWarning):
    """Something in a scene folder was read approximately or skipped; the message says what."""


# --------------------------------------------------------------------------------------------- files


def _short_id(scene_id: str) -> str:
    """File stem of a scene: the part after the dash of "00012-aB3dE5fG7hJ"."""
    return scene_id.split("-", 1)[1] if re.match(r"^\d+-.+", scene_id) else scene_id


def _stem_of(path: Path) -> str:
    name = path.name
    for suf in _SUFFIXES:
        if name.endswith(suf):
            return name[: -len(suf)]
    return path.stem


def find_scene_files(path: str | Path) -> dict[str, Any]:
    """Locate the files of one scene given its folder or any of its files.

    Returns {"folder", "scene_id", "stem", "visual", "semantic", "semantic_txt", "sidecar"}; optional
    entries are None when absent. The plain `.glb` is preferred over `.basis.glb` (Basis textures
    cannot be decoded here).
    """
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(
            f"scene path {p} does not exist (expected a scene folder holding <id>.glb, "
            "<id>.semantic.glb and <id>.semantic.txt, or one of those files)"
        )
    if p.is_dir():
        folder = p
        txts = sorted(q for q in folder.glob("*.semantic.txt") if not q.name.startswith("._"))
        glbs = sorted(
            q for q in folder.glob("*.glb") if not q.name.startswith("._") and not q.name.endswith(".semantic.glb")
        )
        candidates = [_stem_of(q) for q in txts] or [_stem_of(q) for q in glbs]
        if not candidates:
            raise FileNotFoundError(
                f"no scene in {folder}: expected <id>.glb (or <id>.basis.glb), <id>.semantic.glb and <id>.semantic.txt"
            )
        short = folder.name.split("-", 1)[-1]
        stem = short if short in candidates else candidates[0]
    else:
        folder = p.parent
        stem = _stem_of(p)

    def opt(suffix: str) -> Path | None:
        q = folder / f"{stem}{suffix}"
        return q if q.is_file() else None

    visual = opt(".glb") or opt(".basis.glb")
    if visual is None:
        raise FileNotFoundError(
            f"scene {stem} in {folder}: visual mesh {folder / (stem + '.glb')} (or {stem}.basis.glb) is missing"
        )
    scene_id = folder.name if folder.name.endswith(f"-{stem}") or folder.name == stem else stem
    return {
        "folder": folder,
        "scene_id": scene_id,
        "stem": stem,
        "visual": visual,
        "semantic": opt(".semantic.glb"),
        "semantic_txt": opt(".semantic.txt"),
        "sidecar": opt(".ovon.json"),
    }


def list_scenes(dataset_dir: str | Path, split: str | None = None) -> list[Path]:
    """Scene folders of a tree `DATASET_DIR/<split>/<NNNNN-id>/<id>.glb` (HM3D's `hm3d/` layout)."""
    root = Path(dataset_dir)
    if not root.is_dir():
        raise FileNotFoundError(f"dataset folder {root} does not exist (expected <dir>/<split>/<NNNNN-id>/)")
    if split is not None:
        split_dirs = [root / split]
        if not split_dirs[0].is_dir():
            have = sorted(d.name for d in root.iterdir() if d.is_dir())
            raise FileNotFoundError(f"split folder {split_dirs[0]} does not exist; splits found: {have}")
    else:
        split_dirs = sorted(d for d in root.iterdir() if d.is_dir() and not d.name.startswith("."))
    out: list[Path] = []
    for sd in split_dirs:
        for d in sorted(sd.iterdir()):
            if d.is_dir() and not d.name.startswith((".", "_")) and any(d.glob("*.glb")):
                out.append(d)
    return out


# ------------------------------------------------------------------------------------- semantic.txt


@dataclass
class SemanticEntry:
    id: int
    color: tuple[int, int, int]
    raw_label: str
    region_id: int


def _hex(c: tuple[int, int, int]) -> str:
    return "".join(f"{int(v):02X}" for v in c)


def format_semantic_txt(entries: list[SemanticEntry]) -> str:
    lines = [SEMANTIC_HEADER]
    for e in entries:
        label = e.raw_label.replace('"', "'").replace("\n", " ")
        lines.append(f'{e.id},{_hex(e.color)},"{label}",{e.region_id}')
    return "\n".join(lines) + "\n"


def parse_semantic_txt(path: Path) -> list[SemanticEntry]:
    """Parse an HM3DSem semantic.txt; a malformed line is an error naming the file and line."""
    text = Path(path).read_text(encoding="utf-8", errors="replace")
    entries: list[SemanticEntry] = []
    seen: dict[int, int] = {}
    for lineno, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        if lineno == 1 and line.strip().startswith("HM3D"):
            continue
        m = _LINE_RE.match(line)
        if m is None:
            raise ValueError(
                f'{path}:{lineno}: malformed line {line[:80]!r}; expected {SEMANTIC_LINE_FORMAT} e.g. 1,9A9CAA,"wall",0'
            )
        iid = int(m.group(1))
        if iid in seen:
            raise ValueError(f"{path}:{lineno}: instance id {iid} already defined on line {seen[iid]}")
        seen[iid] = lineno
        h = m.group(2)
        color = (int(h[0:2], 16), int(h[2:4], 16), int(h[4:6], 16))
        entries.append(SemanticEntry(iid, color, m.group(3), int(m.group(4))))
    return entries


# ----------------------------------------------------------------------------------------- GLB write

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


def _sidecar(scene: Scene, visual_mode: str, palette: dict[int, tuple[int, int, int]]) -> dict:
    def arr(a: Any) -> list:
        return np.asarray(a, dtype=np.float64).tolist()

    return {
        "format": SIDECAR_FORMAT,
        "version": SIDECAR_VERSION,
        "scene_id": scene.scene_id,
        "source": scene.source,
        "floor_heights": [float(h) for h in scene.floor_heights],
        "visual_colors": visual_mode,
        "regions": [
            {
                "id": int(r.id),
                "name": r.name,
                "floor": int(r.floor),
                "bounds": None if r.bounds is None else [float(v) for v in r.bounds],
            }
            for r in scene.regions
        ],
        "objects": {
            str(o.id): {
                "category": o.category,
                "aabb_min": arr(o.aabb_min),
                "aabb_max": arr(o.aabb_max),
                "obb_center": arr(o.obb_center),
                "obb_half_extents": arr(o.obb_half_extents),
                "obb_rotation": arr(o.obb_rotation),
                "region_name": o.region_name,
                "floor": int(o.floor),
            }
            for o in sorted(scene.objects, key=lambda o: o.id)
        },
    }


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
    side_doc = _sidecar(scene, mode, palette)
    if meta is not None:
        side_doc["meta"] = meta
    side = json.dumps(side_doc, indent=1)
    atomic_write_bytes(folder / f"{stem}.ovon.json", side.encode())
    return folder


# ------------------------------------------------------------------------------------------ GLB read

_COMP = {
    _GL_BYTE: np.int8,
    _GL_UBYTE: np.uint8,
    _GL_SHORT: np.int16,
    _GL_USHORT: np.uint16,
    _GL_UINT: np.uint32,
    _GL_FLOAT: np.float32,
}
_NCOMP = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}


@dataclass
class _Primitive:
    positions: np.ndarray  # (N, 3) float32, world frame
    indices: np.ndarray  # (M, 3) int64
    colors: np.ndarray | None = None  # (N, 3) uint8
    uvs: np.ndarray | None = None  # (N, 2) float32, Mesh convention (v = 1 at the image top)
    texture: np.ndarray | None = None  # (H, W, 3) uint8
    base_color: tuple[int, int, int] = (255, 255, 255)
    texture_problem: str = ""  # why a referenced texture could not be decoded
    vertex_ids: np.ndarray | None = None


@dataclass
class _Glb:
    doc: dict
    bin: bytes
    path: Path
    images: dict[int, np.ndarray | str] = field(default_factory=dict)  # decoded, or why not


def _read_glb_file(path: Path) -> _Glb:
    data = path.read_bytes()
    if data[:4] != b"glTF":
        if path.suffix == ".gltf" or data[:1] == b"{":
            return _Glb(json.loads(data), b"", path)
        raise ValueError(f"{path}: not a GLB file (bad magic {data[:4]!r})")
    _, version, _total = struct.unpack_from("<4sII", data, 0)
    if version != 2:
        raise ValueError(f"{path}: glTF version {version} is not supported (need 2)")
    off = 12
    doc: dict | None = None
    binchunk = b""
    while off + 8 <= len(data):
        length, ctype = struct.unpack_from("<I4s", data, off)
        chunk = data[off + 8 : off + 8 + length]
        if ctype == b"JSON":
            doc = json.loads(chunk.decode("utf-8"))
        elif ctype == b"BIN\x00":
            binchunk = chunk
        off += 8 + length
    if doc is None:
        raise ValueError(f"{path}: GLB has no JSON chunk")
    return _Glb(doc, binchunk, path)


def _buffer_bytes(g: _Glb, index: int, cache: dict[int, bytes]) -> bytes:
    if index in cache:
        return cache[index]
    buf = g.doc["buffers"][index]
    uri = buf.get("uri")
    if uri is None:
        data = g.bin
    elif uri.startswith("data:"):
        data = base64.b64decode(uri.split(",", 1)[1])
    else:
        ext = g.path.parent / uri
        if not ext.is_file():
            raise FileNotFoundError(f"{g.path}: external buffer {ext} is missing")
        data = ext.read_bytes()
    cache[index] = data
    return data


def _view_bytes(g: _Glb, view_index: int, cache: dict[int, bytes]) -> tuple[bytes, int, int]:
    v = g.doc["bufferViews"][view_index]
    buf = _buffer_bytes(g, v["buffer"], cache)
    start = v.get("byteOffset", 0)
    return buf[start : start + v["byteLength"]], int(v.get("byteStride", 0)), start


def _accessor(g: _Glb, index: int, cache: dict[int, bytes]) -> np.ndarray:
    a = g.doc["accessors"][index]
    dtype = np.dtype(_COMP[a["componentType"]])
    n = _NCOMP[a["type"]]
    count = a["count"]
    if "bufferView" in a:
        raw, stride, _ = _view_bytes(g, a["bufferView"], cache)
        off = a.get("byteOffset", 0)
        elem = dtype.itemsize * n
        if stride and stride != elem:
            rows = np.frombuffer(raw, dtype=np.uint8, count=stride * (count - 1) + elem, offset=off)
            rows = np.lib.stride_tricks.as_strided(rows, shape=(count, elem), strides=(stride, 1))
            out = np.ascontiguousarray(rows).view(dtype).reshape(count, n)
        else:
            out = np.frombuffer(raw, dtype=dtype, count=count * n, offset=off).reshape(count, n)
    else:
        out = np.zeros((count, n), dtype=dtype)
    if "sparse" in a:
        sp = a["sparse"]
        iraw, _, _ = _view_bytes(g, sp["indices"]["bufferView"], cache)
        idx = np.frombuffer(
            iraw,
            dtype=_COMP[sp["indices"]["componentType"]],
            count=sp["count"],
            offset=sp["indices"].get("byteOffset", 0),
        )
        vraw, _, _ = _view_bytes(g, sp["values"]["bufferView"], cache)
        vals = np.frombuffer(vraw, dtype=dtype, count=sp["count"] * n, offset=sp["values"].get("byteOffset", 0))
        out = out.copy()
        out[idx.astype(np.int64)] = vals.reshape(-1, n)
    return out


def _normalized_float(arr: np.ndarray, normalized: bool) -> np.ndarray:
    if arr.dtype == np.float32 or not normalized:
        return arr.astype(np.float32, copy=False)
    info = np.iinfo(arr.dtype)
    return np.maximum(arr.astype(np.float32) / info.max, -1.0)


def _image(g: _Glb, image_index: int, cache: dict[int, bytes]) -> np.ndarray | str:
    if image_index in g.images:
        return g.images[image_index]
    img = g.doc["images"][image_index]
    mime = img.get("mimeType", "")
    try:
        if "bufferView" in img:
            data, _, _ = _view_bytes(g, img["bufferView"], cache)
        elif img.get("uri", "").startswith("data:"):
            head, payload = img["uri"].split(",", 1)
            mime = mime or head[5:].split(";")[0]
            data = base64.b64decode(payload)
        else:
            ext = g.path.parent / img.get("uri", "")
            if not ext.is_file():
                raise FileNotFoundError(f"{g.path}: texture image {ext} is missing")
            data = ext.read_bytes()
            mime = mime or ("image/ktx2" if ext.suffix in (".ktx2", ".basis") else "")
        if mime in ("image/ktx2", "image/basis") or data[:12] == b"\xabKTX 20\xbb\r\n\x1a\n" or data[:2] == b"sB":
            result: np.ndarray | str = f"Basis/KTX2-compressed texture ({mime or 'unknown mime'})"
        else:
            from PIL import Image

            with Image.open(io.BytesIO(bytes(data))) as im:
                result = np.asarray(im.convert("RGB"), dtype=np.uint8).copy()
    except (OSError, ValueError) as e:
        result = f"undecodable texture: {e}"
    g.images[image_index] = result
    return result


def _node_matrix(node: dict) -> np.ndarray:
    if "matrix" in node:
        return np.asarray(node["matrix"], dtype=np.float64).reshape(4, 4).T  # column-major in glTF
    t = np.asarray(node.get("translation", [0, 0, 0]), dtype=np.float64)
    x, y, z, w = (float(v) for v in node.get("rotation", [0, 0, 0, 1]))
    s = np.asarray(node.get("scale", [1, 1, 1]), dtype=np.float64)
    r = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    m = np.eye(4)
    m[:3, :3] = r * s[None, :]
    m[:3, 3] = t
    return m


def _read_primitives(path: Path) -> tuple[list[_Primitive], list[str]]:
    """All triangle primitives of a glTF/GLB, in world coordinates (node transforms applied)."""
    g = _read_glb_file(path)
    doc = g.doc
    cache: dict[int, bytes] = {}
    notes: list[str] = []
    prims: list[_Primitive] = []
    nodes = doc.get("nodes", [])
    scenes = doc.get("scenes")
    if scenes:
        roots = scenes[doc.get("scene", 0)].get("nodes", [])
    else:
        children = {c for n in nodes for c in n.get("children", [])}
        roots = [i for i in range(len(nodes)) if i not in children]
    stack: list[tuple[int, np.ndarray]] = [(r, np.eye(4)) for r in reversed(roots)]
    order: list[tuple[int, np.ndarray]] = []
    while stack:
        ni, parent = stack.pop()
        world = parent @ _node_matrix(nodes[ni])
        order.append((ni, world))
        for c in reversed(nodes[ni].get("children", [])):
            stack.append((c, world))
    if not nodes and doc.get("meshes"):
        order = [(-1, np.eye(4))]
    for ni, world in order:
        mesh_index = nodes[ni].get("mesh") if ni >= 0 else 0
        if mesh_index is None:
            continue
        for prim in doc["meshes"][mesh_index]["primitives"]:
            mode = prim.get("mode", 4)
            attrs = prim["attributes"]
            if "POSITION" not in attrs:
                continue
            pos_acc = doc["accessors"][attrs["POSITION"]]
            pos = _normalized_float(_accessor(g, attrs["POSITION"], cache), pos_acc.get("normalized", False))
            if mode not in (4, 5, 6):
                notes.append(f"skipped a primitive with mode {mode} (points/lines)")
                continue
            if "indices" in prim:
                idx = _accessor(g, prim["indices"], cache).reshape(-1).astype(np.int64)
            else:
                idx = np.arange(len(pos), dtype=np.int64)
            if mode == 4:
                tris = idx[: len(idx) // 3 * 3].reshape(-1, 3)
            elif mode == 5:  # strip
                k = np.arange(len(idx) - 2)
                tris = np.stack([idx[k], idx[k + 1 + (k % 2)], idx[k + 2 - (k % 2)]], axis=1)
            else:  # fan
                k = np.arange(1, len(idx) - 1)
                tris = np.stack([np.full_like(k, idx[0]), idx[k], idx[k + 1]], axis=1)
            if not np.allclose(world, np.eye(4)):
                p64 = pos.astype(np.float64) @ world[:3, :3].T + world[:3, 3]
                pos = p64.astype(np.float32)
                if np.linalg.det(world[:3, :3]) < 0:
                    tris = tris[:, [0, 2, 1]]
            p = _Primitive(positions=pos, indices=tris)
            a_idx = attrs.get("COLOR_0")
            if a_idx is not None:
                acc = doc["accessors"][a_idx]
                col = _accessor(g, a_idx, cache)
                if col.dtype == np.uint8:
                    p.colors = col[:, :3].copy()
                else:
                    f = _normalized_float(col, acc.get("normalized", True))
                    p.colors = np.clip(np.rint(f[:, :3] * 255.0), 0, 255).astype(np.uint8)
            if VERTEX_ID_ATTR in attrs:
                p.vertex_ids = _accessor(g, attrs[VERTEX_ID_ATTR], cache).reshape(-1).astype(np.int64)
            mat_i = prim.get("material")
            if mat_i is not None:
                mat = doc["materials"][mat_i]
                pbr = mat.get("pbrMetallicRoughness", {})
                bcf = pbr.get("baseColorFactor", [1, 1, 1, 1])
                p.base_color = tuple(int(round(255 * float(c))) for c in bcf[:3])  # type: ignore[assignment]
                tex_ref = pbr.get("baseColorTexture")
                if tex_ref is not None:
                    tex = doc["textures"][tex_ref["index"]]
                    src = tex.get("source")
                    if src is None:
                        for ext in tex.get("extensions", {}).values():
                            if "source" in ext:
                                src = ext["source"]
                                break
                    uv_attr = f"TEXCOORD_{tex_ref.get('texCoord', 0)}"
                    if src is None or uv_attr not in attrs:
                        p.texture_problem = "texture without image or UVs"
                    else:
                        img = _image(g, src, cache)
                        if isinstance(img, str):
                            p.texture_problem = img
                        else:
                            acc = doc["accessors"][attrs[uv_attr]]
                            uv = _normalized_float(_accessor(g, attrs[uv_attr], cache), acc.get("normalized", False))
                            uv = uv[:, :2].copy()
                            uv[:, 1] = 1.0 - uv[:, 1]
                            p.uvs = uv
                            p.texture = img
            prims.append(p)
    return prims, notes


# ------------------------------------------------------------------------------ textures and meshes


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
        raise ValueError(f"{path}: the {kind} mesh has no triangles")
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


# --------------------------------------------------------------------------- geometry of real scans


def face_normals_areas(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    v = vertices.astype(np.float64)
    a, b, c = v[faces[:, 0]], v[faces[:, 1]], v[faces[:, 2]]
    cr = np.cross(b - a, c - a)
    norm = np.linalg.norm(cr, axis=1)
    n = cr / np.maximum(norm, 1e-12)[:, None]
    return n, 0.5 * norm


def detect_floors(mesh: Mesh, bin_size: float = 0.1, min_area: float = 2.0) -> list[float]:
    """Floor heights from large upward-facing horizontal triangles: an area-weighted height histogram,
    peaks taken greedily by area, each at least FLOOR_SEPARATION from the ones already taken."""
    if mesh.num_faces == 0:
        return [0.0]
    n, area = face_normals_areas(mesh.vertices, mesh.faces)
    up = n[:, 1] > 0.9
    if not up.any():
        return [float(mesh.vertices[:, 1].min())]
    y = mesh.vertices[mesh.faces[up]].astype(np.float64)[:, :, 1].mean(axis=1)
    w = area[up]
    lo = np.floor(y.min() / bin_size) * bin_size
    bins = np.floor((y - lo) / bin_size).astype(np.int64)
    hist = np.bincount(bins, weights=w)
    # smooth over neighbouring bins so a floor split across two bins still counts as one
    sm = hist + np.concatenate([[0], hist[:-1]]) + np.concatenate([hist[1:], [0]])
    order = np.argsort(-sm, kind="stable")
    threshold = max(min_area, 0.15 * float(sm.max()))
    chosen: list[float] = []
    for b in order:
        if sm[b] < threshold:
            break
        sel = np.abs(bins - b) <= 1
        ys, ws = y[sel], w[sel]
        srt = np.argsort(ys)
        cum = np.cumsum(ws[srt])
        h = float(ys[srt][np.searchsorted(cum, cum[-1] / 2.0)])  # area-weighted median
        if all(abs(h - c) > FLOOR_SEPARATION for c in chosen):
            chosen.append(h)
    if not chosen:
        chosen = [float(y[np.argmax(w)])]
    return sorted(chosen)


def _hull_2d(pts: np.ndarray) -> np.ndarray:
    """Convex hull (Andrew's monotone chain), counter-clockwise, no repeated end point."""
    pts = np.unique(pts, axis=0)
    if len(pts) <= 2:
        return pts

    def half(points: np.ndarray) -> list[np.ndarray]:
        out: list[np.ndarray] = []
        for p in points:
            while len(out) >= 2:
                o, a = out[-2], out[-1]
                if (a[0] - o[0]) * (p[1] - o[1]) - (a[1] - o[1]) * (p[0] - o[0]) <= 0:
                    out.pop()
                else:
                    break
            out.append(p)
        return out

    lower = half(pts)
    upper = half(pts[::-1])
    return np.array(lower[:-1] + upper[:-1])


def yaw_obb(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Yaw-aligned oriented box of points: minimum-area rectangle of the x/z footprint (rotating
    calipers over hull edges) with the y extent. Returns (center, half_extents, rotation local->world)."""
    pts = np.asarray(points, dtype=np.float64)
    xz = pts[:, [0, 2]]
    try:
        from scipy.spatial import ConvexHull, QhullError

        try:
            hull = xz[ConvexHull(xz).vertices]
        except (QhullError, ValueError):  # flat or too few points
            hull = _hull_2d(xz)
    except ImportError:
        hull = _hull_2d(xz)
    best = (np.inf, 1.0, 0.0)
    if len(hull) >= 3:
        edges = np.roll(hull, -1, axis=0) - hull
        lens = np.linalg.norm(edges, axis=1)
        for (ex, ez), ln in zip(edges, lens):
            if ln < 1e-12:
                continue
            dx, dz = ex / ln, ez / ln
            a = hull @ np.array([dx, dz])
            b = hull @ np.array([-dz, dx])
            area = (a.max() - a.min()) * (b.max() - b.min())
            if area < best[0] - 1e-12:
                best = (area, dx, dz)
    _, dx, dz = best
    # canonical: the box's local x axis within [0, 90) degrees of world x
    ang = np.arctan2(dz, dx) % (np.pi / 2.0)
    dx, dz = float(np.cos(ang)), float(np.sin(ang))
    rot = np.array([[dx, 0.0, -dz], [0.0, 1.0, 0.0], [dz, 0.0, dx]])
    local = pts @ rot  # world -> local (rot is orthonormal)
    lo, hi = local.min(axis=0), local.max(axis=0)
    center = rot @ ((lo + hi) / 2.0)
    return center, (hi - lo) / 2.0, rot


def _faces_by_instance(face_instance: np.ndarray) -> dict[int, np.ndarray]:
    order = np.argsort(face_instance, kind="stable")
    ids, starts = np.unique(face_instance[order], return_index=True)
    bounds = list(starts[1:]) + [len(order)]
    return {int(i): order[s:e] for i, s, e in zip(ids, starts, bounds)}


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


# ------------------------------------------------------------------------------------------ loading


def load_scene(path: str | Path, vocab: Any = None) -> Scene:
    """Load one scene folder (ours or a real HM3DSem v0.2 scan) given the folder or any of its files.

    `vocab` (default: the embedded vocabulary) cleans raw labels into categories. Warnings of class
    `SceneLoadWarning` report approximations (undecodable textures, unknown semantic colours).
    """
    files = find_scene_files(path)
    folder: Path = files["folder"]
    stem: str = files["stem"]
    if files["semantic_txt"] is None:
        raise FileNotFoundError(
            f"scene {stem}: {folder / (stem + '.semantic.txt')} is missing (HM3DSem annotations: first line "
            f"'{SEMANTIC_HEADER}', then {SEMANTIC_LINE_FORMAT} per instance)"
        )
    if files["semantic"] is None:
        raise FileNotFoundError(f"scene {stem}: semantic mesh {folder / (stem + '.semantic.glb')} is missing")
    if vocab is None:
        from ovon.scenes.vocabulary import load_vocabulary

        vocab = load_vocabulary()
    entries = parse_semantic_txt(files["semantic_txt"])
    side: dict | None = None
    if files["sidecar"] is not None:
        side = json.loads(files["sidecar"].read_text())
        if side.get("format") != SIDECAR_FORMAT:
            raise ValueError(f"{files['sidecar']}: not an ovon scene sidecar (format {side.get('format')!r})")

    notes: list[str] = []
    vis_prims, n1 = _read_primitives(files["visual"])
    mesh, n2 = _combine(vis_prims, "visual", files["visual"])
    notes += n1 + n2
    if side is not None and mesh.vertex_colors is not None:
        if side.get("visual_colors") == "face":
            mesh.vertex_colors = None
        elif side.get("visual_colors") == "vertex":
            mesh.face_colors = None

    sem_prims, n3 = _read_primitives(files["semantic"])
    notes += n3
    if not sem_prims:
        raise ValueError(f"{files['semantic']}: the semantic mesh has no triangles")
    color_to_id = {e.color: e.id for e in entries}
    face_rgb, _how = _semantic_face_colors(sem_prims)
    face_ids, unknown, missing = _decode_face_ids(face_rgb, color_to_id)
    if unknown:
        notes.append(
            f"{unknown} semantic faces have colours missing from {files['semantic_txt'].name} "
            f"({len(missing)} colours, e.g. {sorted(_hex(c) for c in missing)[:5]}); assigned id 0"
        )
    sem_mesh, n4 = _combine(sem_prims, "semantic", files["semantic"])
    notes += n4
    sem_mesh.face_instance = face_ids.astype(np.int32)
    same = (
        sem_mesh.texture is None  # painted textures stay a separate mesh: renderers sample them per pixel
        and sem_mesh.vertices.shape == mesh.vertices.shape
        and sem_mesh.faces.shape == mesh.faces.shape
        and np.array_equal(sem_mesh.faces, mesh.faces)
        and np.array_equal(sem_mesh.vertices, mesh.vertices)
    )
    semantic_mesh: Mesh | None
    if same:
        mesh.face_instance = sem_mesh.face_instance
        semantic_mesh = None
    else:
        semantic_mesh = Mesh(
            vertices=sem_mesh.vertices,
            faces=sem_mesh.faces,
            face_colors=None if sem_mesh.texture is not None else face_rgb,
            vertex_colors=sem_mesh.vertex_colors if sem_mesh.texture is None else None,
            uvs=sem_mesh.uvs,
            texture=sem_mesh.texture,
            face_instance=sem_mesh.face_instance,
        )

    geom = semantic_mesh if semantic_mesh is not None else mesh
    floors = [float(h) for h in side["floor_heights"]] if side and side.get("floor_heights") else None
    if floors is None:
        floors = detect_floors(mesh)
    scene = Scene(
        scene_id=(side or {}).get("scene_id") or files["scene_id"],
        mesh=mesh,
        floor_heights=floors,
        semantic_mesh=semantic_mesh,
        semantic_colors={e.id: e.color for e in entries},
        source=(side or {}).get("source") or str(folder),
    )
    side_objs: dict = (side or {}).get("objects", {})
    groups = _faces_by_instance(np.asarray(geom.face_instance))
    regions_side = {int(r["id"]): r for r in (side or {}).get("regions", [])}
    no_faces: list[int] = []
    mismatched: list[str] = []
    for e in entries:
        so = side_objs.get(str(e.id))
        category = vocab.clean(e.raw_label)
        if so is not None:
            if so.get("category") != category:
                mismatched.append(f"{e.raw_label!r}: {so.get('category')!r} -> {category!r}")
            obj = ObjectInstance(
                id=e.id,
                raw_label=e.raw_label,
                category=category,
                aabb_min=np.asarray(so["aabb_min"], dtype=np.float64),
                aabb_max=np.asarray(so["aabb_max"], dtype=np.float64),
                obb_center=np.asarray(so["obb_center"], dtype=np.float64),
                obb_half_extents=np.asarray(so["obb_half_extents"], dtype=np.float64),
                obb_rotation=np.asarray(so["obb_rotation"], dtype=np.float64),
                region_id=e.region_id,
                region_name=so.get("region_name", ""),
                floor=int(so.get("floor", 0)),
                color=e.color,
            )
        else:
            fidx = groups.get(e.id)
            if fidx is None or e.id == 0:
                no_faces.append(e.id)
                continue
            pts = geom.vertices[np.unique(geom.faces[fidx].reshape(-1))].astype(np.float64)
            center, half, rot = yaw_obb(pts)
            lo, hi = pts.min(axis=0), pts.max(axis=0)
            rname = regions_side.get(e.region_id, {}).get("name") or (
                f"region_{e.region_id}" if e.region_id >= 0 else ""
            )
            obj = ObjectInstance(
                id=e.id,
                raw_label=e.raw_label,
                category=category,
                aabb_min=lo,
                aabb_max=hi,
                obb_center=center,
                obb_half_extents=half,
                obb_rotation=rot,
                region_id=e.region_id,
                region_name=rname,
                floor=scene.floor_of_height(float(lo[1])),
                color=e.color,
            )
        scene.objects.append(obj)
    if no_faces:
        notes.append(f"{len(no_faces)} annotated instances have no faces and were skipped (ids {no_faces[:10]})")
    if mismatched:
        notes.append(
            f"{len(mismatched)} objects clean to a different category than the sidecar records "
            f"(vocabulary changed?), e.g. {mismatched[:3]}; the cleaned one is used"
        )
    if side is not None and "regions" in side:
        scene.regions = [
            Region(int(r["id"]), r["name"], int(r["floor"]), None if r["bounds"] is None else tuple(r["bounds"]))
            for r in side["regions"]
        ]
    else:
        scene.regions = _regions_from_objects(scene)
    for n in notes:
        warnings.warn(f"{folder}: {n}", SceneLoadWarning, stacklevel=2)
    return scene


def _regions_from_objects(scene: Scene) -> list[Region]:
    """Regions of a real scan: one per region_id, named "region_<id>", bounds = union of its objects'
    footprints, floor = the most common floor of its objects."""
    by: dict[int, list[ObjectInstance]] = {}
    for o in scene.objects:
        if o.region_id >= 0:
            by.setdefault(o.region_id, []).append(o)
    out = []
    for rid in sorted(by):
        objs = by[rid]
        lo = np.min([o.aabb_min for o in objs], axis=0)
        hi = np.max([o.aabb_max for o in objs], axis=0)
        floors = np.bincount([o.floor for o in objs])
        out.append(
            Region(
                rid, f"region_{rid}", int(np.argmax(floors)), (float(lo[0]), float(lo[2]), float(hi[0]), float(hi[2]))
            )
        )
    return out
