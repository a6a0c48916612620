"""Reading glTF 2.0 (`.glb`, or `.gltf` with `.bin` / data-URI buffers) into triangle primitives.

Hand-rolled on purpose: raw accessors, node transforms applied exactly as glTF defines them and
nothing else (no implicit axis conversion: the up axis is decided by `upaxis`), float32 positions kept
bit-exact. Every structural problem of a broken file (truncated chunks, accessors reaching past their
buffer, indices past the vertex count, NaN positions, Git LFS pointers) is a `SceneFileError` naming
the file and what is wrong.
"""

from __future__ import annotations

import base64
import json
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ovon.scenes.hm3dsem.errors import SceneFileError, read_bytes
from ovon.scenes.hm3dsem.glb_write import VERTEX_ID_ATTR
from ovon.scenes.hm3dsem.textures import TextureError, decode_image

_COMP = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_NCOMP = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_BASIS_EXTENSIONS = ("KHR_texture_basisu", "GOOGLE_texture_basis", "KHR_texture_ktx", "EXT_texture_webp")


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
    """Container level: GLB header and chunks, or a `.gltf` JSON document."""
    data = read_bytes(path)
    if data[:4] != b"glTF":
        if path.suffix.lower() == ".gltf" or data[:1] in (b"{", b" ", b"\n", b"\t", b"\r"):
            try:
                doc = json.loads(data.decode("utf-8"))
            except (UnicodeDecodeError, json.JSONDecodeError) as e:
                raise SceneFileError(path, f"is not valid glTF JSON ({e})") from None
            if not isinstance(doc, dict):
                raise SceneFileError(path, "is not a glTF document (top level is not an object)")
            return _Glb(doc, b"", path)
        what = "empty" if not data else f"starts with {data[:4]!r}"
        raise SceneFileError(path, f"is not a GLB file ({what}, expected the magic b'glTF')",
                             "is it a complete .glb? re-download or re-export it")
    if len(data) < 20:
        raise SceneFileError(path, f"is truncated: {len(data)} bytes, a GLB header alone needs 20")
    _, version, total = struct.unpack_from("<4sII", data, 0)
    if version != 2:
        raise SceneFileError(path, f"is glTF version {version}; only glTF 2.0 is supported")
    if total > len(data):
        raise SceneFileError(path, f"is truncated: the header declares {total:,} bytes but the file has "
                                   f"{len(data):,}", "re-download or re-export it")
    off = 12
    doc: dict | None = None
    binchunk = b""
    while off + 8 <= len(data):
        length, ctype = struct.unpack_from("<I4s", data, off)
        if off + 8 + length > len(data):
            raise SceneFileError(path, f"is truncated: chunk {ctype!r} at byte {off} declares {length:,} bytes, "
                                       f"only {len(data) - off - 8:,} follow", "re-download or re-export it")
        chunk = data[off + 8 : off + 8 + length]
        if ctype == b"JSON":
            try:
                doc = json.loads(chunk.decode("utf-8"))
            except (UnicodeDecodeError, json.JSONDecodeError) as e:
                raise SceneFileError(path, f"has a corrupt JSON chunk ({e})") from None
        elif ctype == b"BIN\x00":
            binchunk = chunk
        off += 8 + length
    if not isinstance(doc, dict):
        raise SceneFileError(path, "has no JSON chunk (not a valid GLB)")
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
            raise FileNotFoundError(f"{g.path}: external buffer {ext} is missing (a .gltf needs its .bin beside it)")
        data = read_bytes(ext)
    need = int(buf.get("byteLength", 0))
    if len(data) < need:
        src = "the BIN chunk" if uri is None else "a data URI" if uri.startswith("data:") else str(g.path.parent / uri)
        raise SceneFileError(g.path, f"buffer {index} declares {need:,} bytes but {src} holds {len(data):,} "
                                     "(truncated or corrupt)", "re-download or re-export it")
    cache[index] = data
    return data


def _view_bytes(g: _Glb, view_index: int, cache: dict[int, bytes]) -> tuple[bytes, int]:
    v = g.doc["bufferViews"][view_index]
    buf = _buffer_bytes(g, v["buffer"], cache)
    start = int(v.get("byteOffset", 0))
    length = int(v["byteLength"])
    if start < 0 or start + length > len(buf):
        raise SceneFileError(g.path, f"bufferView {view_index} spans bytes {start:,}..{start + length:,} of buffer "
                                     f"{v['buffer']}, which has {len(buf):,} (truncated or corrupt)")
    return buf[start : start + length], int(v.get("byteStride", 0))


def _accessor(g: _Glb, index: int, cache: dict[int, bytes]) -> np.ndarray:
    a = g.doc["accessors"][index]
    if a.get("componentType") not in _COMP or a.get("type") not in _NCOMP:
        raise SceneFileError(g.path, f"accessor {index} has componentType {a.get('componentType')} / type "
                                     f"{a.get('type')!r}, which glTF 2.0 does not define")
    dtype = np.dtype(_COMP[a["componentType"]])
    n = _NCOMP[a["type"]]
    count = int(a["count"])
    elem = dtype.itemsize * n
    if count < 0:
        raise SceneFileError(g.path, f"accessor {index} has a negative count {count}")
    if "bufferView" in a:
        raw, stride = _view_bytes(g, a["bufferView"], cache)
        off = int(a.get("byteOffset", 0))
        step = stride if stride else elem
        need = off + (step * (count - 1) + elem if count else 0)
        if need > len(raw):
            raise SceneFileError(g.path, f"accessor {index} needs {need:,} bytes of bufferView {a['bufferView']} "
                                         f"({count:,} x {a['type']}), which has {len(raw):,} (truncated or corrupt)")
        if stride and stride != elem:
            rows = np.frombuffer(raw, dtype=np.uint8, count=stride * (count - 1) + elem if count else 0, offset=off)
            rows = np.lib.stride_tricks.as_strided(rows, shape=(count, elem), strides=(stride, 1))
            out = np.ascontiguousarray(rows).view(dtype).reshape(count, n)
        else:
            out = np.frombuffer(raw, dtype=dtype, count=count * n, offset=off).reshape(count, n)
    else:
        if count * elem > 1 << 31:
            raise SceneFileError(g.path, f"accessor {index} declares {count:,} elements without data (corrupt)")
        out = np.zeros((count, n), dtype=dtype)
    if "sparse" in a:
        sp = a["sparse"]
        k = int(sp["count"])
        iraw, _ = _view_bytes(g, sp["indices"]["bufferView"], cache)
        idt = np.dtype(_COMP[sp["indices"]["componentType"]])
        ioff = int(sp["indices"].get("byteOffset", 0))
        vraw, _ = _view_bytes(g, sp["values"]["bufferView"], cache)
        voff = int(sp["values"].get("byteOffset", 0))
        if ioff + k * idt.itemsize > len(iraw) or voff + k * elem > len(vraw):
            raise SceneFileError(g.path, f"sparse accessor {index} reaches past its bufferViews (corrupt)")
        idx = np.frombuffer(iraw, dtype=idt, count=k, offset=ioff).astype(np.int64)
        if k and (idx.min() < 0 or idx.max() >= count):
            raise SceneFileError(g.path, f"sparse accessor {index} indexes element {int(idx.max())} of {count}")
        vals = np.frombuffer(vraw, dtype=dtype, count=k * n, offset=voff)
        out = out.copy()
        out[idx] = vals.reshape(-1, n)
    return out


def _normalized_float(arr: np.ndarray, normalized: bool) -> np.ndarray:
    if arr.dtype == np.float32 or not normalized:
        return arr.astype(np.float32, copy=False)
    info = np.iinfo(arr.dtype)
    return np.maximum(arr.astype(np.float32) / info.max, -1.0)


def _image(g: _Glb, image_index: int, cache: dict[int, bytes]) -> np.ndarray | str:
    """Decoded texture (H, W, 3), or a string saying why it could not be decoded."""
    if image_index in g.images:
        return g.images[image_index]
    img = g.doc["images"][image_index]
    mime = img.get("mimeType", "")
    try:
        if "bufferView" in img:
            data, _ = _view_bytes(g, img["bufferView"], cache)
        elif img.get("uri", "").startswith("data:"):
            head, payload = img["uri"].split(",", 1)
            mime = mime or head[5:].split(";")[0]
            data = base64.b64decode(payload)
        else:
            ext = g.path.parent / img.get("uri", "")
            if not ext.is_file():
                raise TextureError(f"texture image {ext} is missing")
            data = read_bytes(ext)
            mime = mime or ("image/ktx2" if ext.suffix in (".ktx2", ".basis") else "")
        result: np.ndarray | str = decode_image(data, mime)
    except (TextureError, SceneFileError) as e:
        result = str(e)
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


def _node_order(doc: dict) -> list[tuple[int, np.ndarray]]:
    """(node index, world matrix) of every node reachable from the default scene, parents first."""
    nodes = doc.get("nodes", [])
    scenes = doc.get("scenes")
    if scenes:
        roots = scenes[doc.get("scene", 0)].get("nodes", [])
    else:
        children = {c for n in nodes for c in n.get("children", [])}
        roots = [i for i in range(len(nodes)) if i not in children]
    stack: list[tuple[int, np.ndarray, int]] = [(r, np.eye(4), 0) for r in reversed(roots)]
    order: list[tuple[int, np.ndarray]] = []
    while stack:
        ni, parent, depth = stack.pop()
        if depth > 256:
            raise ValueError("node hierarchy deeper than 256 levels (a cycle?)")
        world = parent @ _node_matrix(nodes[ni])
        order.append((ni, world))
        for c in reversed(nodes[ni].get("children", [])):
            stack.append((c, world, depth + 1))
    if not nodes and doc.get("meshes"):
        order = [(-1, np.eye(4))]
    return order


def _triangles(idx: np.ndarray, mode: int) -> np.ndarray:
    if mode == 4:
        return idx[: len(idx) // 3 * 3].reshape(-1, 3)
    if mode == 5:  # strip
        k = np.arange(max(len(idx) - 2, 0))
        return np.stack([idx[k], idx[k + 1 + (k % 2)], idx[k + 2 - (k % 2)]], axis=1)
    k = np.arange(1, max(len(idx) - 1, 1))  # fan
    return np.stack([np.full_like(k, idx[0] if len(idx) else 0), idx[k], idx[k + 1]], axis=1)


def _texture_of(g: _Glb, prim: dict, p: _Primitive, cache: dict[int, bytes]) -> None:
    doc = g.doc
    attrs = prim["attributes"]
    mat = doc["materials"][prim["material"]]
    pbr = mat.get("pbrMetallicRoughness", {})
    bcf = pbr.get("baseColorFactor", [1, 1, 1, 1])
    p.base_color = tuple(int(round(255 * min(max(float(c), 0.0), 1.0))) for c in bcf[:3])  # type: ignore[assignment]
    tex_ref = pbr.get("baseColorTexture")
    if tex_ref is None:
        return
    tex = doc["textures"][tex_ref["index"]]
    src = None
    for name in _BASIS_EXTENSIONS:  # a compressed image named by an extension wins over a fallback
        src = tex.get("extensions", {}).get(name, {}).get("source", src)
    src = tex.get("source") if src is None else src
    uv_attr = f"TEXCOORD_{tex_ref.get('texCoord', 0)}"
    if src is None or uv_attr not in attrs:
        p.texture_problem = "texture without image or UVs"
        return
    img = _image(g, src, cache)
    if isinstance(img, str):
        fallback = tex.get("source")
        if fallback is not None and fallback != src:
            img = _image(g, fallback, cache)
    if isinstance(img, str):
        p.texture_problem = img
        return
    acc = doc["accessors"][attrs[uv_attr]]
    uv = _normalized_float(_accessor(g, attrs[uv_attr], cache), acc.get("normalized", False))[:, :2].copy()
    if len(uv) != len(p.positions):
        raise SceneFileError(g.path, f"{uv_attr} has {len(uv)} entries for {len(p.positions)} vertices")
    uv[:, 1] = 1.0 - uv[:, 1]
    p.uvs, p.texture = uv, img


def _read_primitive(g: _Glb, prim: dict, world: np.ndarray, where: str, cache: dict[int, bytes],
                    notes: list[str]) -> _Primitive | None:
    doc = g.doc
    mode = prim.get("mode", 4)
    attrs = prim["attributes"]
    if "POSITION" not in attrs:
        return None
    pos_acc = doc["accessors"][attrs["POSITION"]]
    pos = _normalized_float(_accessor(g, attrs["POSITION"], cache), pos_acc.get("normalized", False))
    if mode not in (4, 5, 6):
        notes.append(f"skipped a primitive with mode {mode} (points/lines)")
        return None
    if pos.shape[1] != 3:
        raise SceneFileError(g.path, f"{where}: POSITION is {pos_acc.get('type')}, expected VEC3")
    bad = ~np.isfinite(pos).all(axis=1)
    if bad.any():
        raise SceneFileError(g.path, f"{where}: {int(bad.sum()):,} of {len(pos):,} vertex positions are NaN or "
                                     f"infinite (first: vertex {int(np.flatnonzero(bad)[0])})",
                             "repair or re-export the mesh")
    if "indices" in prim:
        idx = _accessor(g, prim["indices"], cache).reshape(-1).astype(np.int64)
        if len(idx) and (idx.max() >= len(pos) or idx.min() < 0):
            raise SceneFileError(g.path, f"{where}: triangle index {int(idx.max())} is out of range: the primitive "
                                         f"has {len(pos):,} vertices", "the file is corrupt; re-export it")
    else:
        idx = np.arange(len(pos), dtype=np.int64)
    tris = _triangles(idx, mode)
    if not np.allclose(world, np.eye(4)):
        pos = (pos.astype(np.float64) @ world[:3, :3].T + world[:3, 3]).astype(np.float32)
        if np.linalg.det(world[:3, :3]) < 0:
            tris = tris[:, [0, 2, 1]]
    p = _Primitive(positions=pos, indices=tris)
    a_idx = attrs.get("COLOR_0")
    if a_idx is not None:
        acc = doc["accessors"][a_idx]
        col = _accessor(g, a_idx, cache)
        if len(col) != len(pos):
            raise SceneFileError(g.path, f"{where}: COLOR_0 has {len(col)} entries for {len(pos)} vertices")
        if col.dtype == np.uint8:
            p.colors = col[:, :3].copy()
        else:
            f = _normalized_float(col, acc.get("normalized", True))
            p.colors = np.clip(np.rint(np.nan_to_num(f[:, :3]) * 255.0), 0, 255).astype(np.uint8)
    if VERTEX_ID_ATTR in attrs:
        p.vertex_ids = _accessor(g, attrs[VERTEX_ID_ATTR], cache).reshape(-1).astype(np.int64)
    if prim.get("material") is not None:
        _texture_of(g, prim, p, cache)
    return p


def read_primitives(path: Path) -> tuple[list[_Primitive], list[str], dict]:
    """All triangle primitives of a glTF/GLB in world coordinates (node transforms applied), the notes
    on what was skipped, and the glTF document (node names etc.)."""
    g = _read_glb_file(path)
    doc = g.doc
    cache: dict[int, bytes] = {}
    notes: list[str] = []
    prims: list[_Primitive] = []
    try:
        for ni, world in _node_order(doc):
            mesh_index = doc["nodes"][ni].get("mesh") if ni >= 0 else 0
            if mesh_index is None:
                continue
            for k, prim in enumerate(doc["meshes"][mesh_index]["primitives"]):
                p = _read_primitive(g, prim, world, f"mesh {mesh_index} primitive {k}", cache, notes)
                if p is not None:
                    prims.append(p)
    except (SceneFileError, FileNotFoundError):
        raise
    except (KeyError, IndexError, TypeError, ValueError, AttributeError, struct.error, OverflowError) as e:
        what = f"missing key {e}" if isinstance(e, KeyError) else f"{type(e).__name__}: {e}"
        raise SceneFileError(path, f"is a corrupt glTF document ({what})", "re-download or re-export it") from None
    return prims, notes, doc
