"""Reading glTF 2.0 (`.glb`, or `.gltf` with `.bin` / data-URI buffers) into triangle primitives.

Hand-rolled on purpose: raw accessors, node transforms applied exactly as glTF defines them and
nothing else (no implicit axis conversion: the up axis is decided by `upaxis`), float32 positions kept
bit-exact. Every structural problem of a broken file (truncated chunks, accessors reaching past their
buffer, indices past the vertex count or not of an integer type, NaN positions, node transforms that are
not finite or flatten the mesh, Git LFS pointers) is a `SceneFileError` naming the file and what is wrong.
"""

from __future__ import annotations

import base64
import json
import struct
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ovon.scenes.hm3dsem.errors import SceneFileError, lfs_pointer_error, read_bytes
from ovon.scenes.hm3dsem.glb_write import VERTEX_ID_ATTR
from ovon.scenes.hm3dsem.textures import TextureError, decode_image

_COMP = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_NCOMP = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
# glTF 2.0 allows only unsigned integer indices (3.7.2.1); a float accessor read as indices would be
# reinterpreted (rounded floats or garbage bits), never a triangle list the author meant
_INDEX_COMP = {5121: "unsigned byte", 5123: "unsigned short", 5125: "unsigned int"}
_COMP_NAME = {5120: "byte", 5122: "short", 5126: "float", **_INDEX_COMP}
# a node transform whose smallest singular value is below this fraction of its largest flattens the mesh
# to a plane, line or point (an all-zero matrix, a zero scale); unit changes (0.001 for mm) are uniform
# and stay far above it
_SINGULAR_RATIO = 1e-9
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
        return _Glb(_gltf_json(path, data), b"", path)
    doc, binchunk, _ = _glb_chunks(path, len(data), lambda off, n: data[off : off + n], True)
    return _Glb(doc, binchunk, path)


def _gltf_json(path: Path, data: bytes) -> dict:
    """The document of a `.gltf` (JSON) file, or the error for a file that is neither GLB nor glTF JSON."""
    if path.suffix.lower() == ".gltf" or data[:1] in (b"{", b" ", b"\n", b"\t", b"\r"):
        try:
            doc = json.loads(data.decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as e:
            raise SceneFileError(path, f"is not valid glTF JSON ({e})") from None
        if not isinstance(doc, dict):
            raise SceneFileError(path, "is not a glTF document (top level is not an object)")
        return doc
    what = "empty" if not data else f"starts with {data[:4]!r}"
    raise SceneFileError(
        path,
        f"is not a GLB file ({what}, expected the magic b'glTF')",
        "is it a complete .glb? re-download or re-export it",
    )


def _glb_chunks(path: Path, size: int, read_at: Callable[[int, int], bytes], want_bin: bool) -> tuple[dict, bytes, int]:
    """(JSON document, BIN chunk or b"" unless `want_bin`, BIN chunk length) of a GLB of `size` bytes read
    through `read_at(offset, n)`: every length the header and chunk headers declare is checked against the
    file's size, so a truncated file is caught without reading its (large) BIN chunk."""
    if size < 20:
        raise SceneFileError(path, f"is truncated: {size} bytes, a GLB header alone needs 20")
    _, version, total = struct.unpack("<4sII", read_at(0, 12))
    if version != 2:
        raise SceneFileError(path, f"is glTF version {version}; only glTF 2.0 is supported")
    if total > size:
        raise SceneFileError(
            path,
            f"is truncated: the header declares {total:,} bytes but the file has {size:,}",
            "re-download or re-export it",
        )
    off = 12
    doc: dict | None = None
    binchunk = b""
    binlen = 0
    while off + 8 <= size:
        length, ctype = struct.unpack("<I4s", read_at(off, 8))
        if off + 8 + length > size:
            raise SceneFileError(
                path,
                f"is truncated: chunk {ctype!r} at byte {off} declares {length:,} bytes, "
                f"only {size - off - 8:,} follow",
                "re-download or re-export it",
            )
        if ctype == b"JSON":
            try:
                doc = json.loads(read_at(off + 8, length).decode("utf-8"))
            except (UnicodeDecodeError, json.JSONDecodeError) as e:
                raise SceneFileError(path, f"has a corrupt JSON chunk ({e})") from None
        elif ctype == b"BIN\x00":
            binlen = length
            if want_bin:
                binchunk = read_at(off + 8, length)
        off += 8 + length
    if not isinstance(doc, dict):
        raise SceneFileError(path, "has no JSON chunk (not a valid GLB)")
    return doc, binchunk, binlen


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
        raise SceneFileError(
            g.path,
            f"buffer {index} declares {need:,} bytes but {src} holds {len(data):,} (truncated or corrupt)",
            "re-download or re-export it",
        )
    cache[index] = data
    return data


def _view_bytes(g: _Glb, view_index: int, cache: dict[int, bytes]) -> tuple[bytes, int]:
    v = g.doc["bufferViews"][view_index]
    buf = _buffer_bytes(g, v["buffer"], cache)
    start = int(v.get("byteOffset", 0))
    length = int(v["byteLength"])
    if start < 0 or start + length > len(buf):
        raise SceneFileError(
            g.path,
            f"bufferView {view_index} spans bytes {start:,}..{start + length:,} of buffer "
            f"{v['buffer']}, which has {len(buf):,} (truncated or corrupt)",
        )
    return buf[start : start + length], int(v.get("byteStride", 0))


def _accessor(g: _Glb, index: int, cache: dict[int, bytes]) -> np.ndarray:
    a = g.doc["accessors"][index]
    if a.get("componentType") not in _COMP or a.get("type") not in _NCOMP:
        raise SceneFileError(
            g.path,
            f"accessor {index} has componentType {a.get('componentType')} / type "
            f"{a.get('type')!r}, which glTF 2.0 does not define",
        )
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
            raise SceneFileError(
                g.path,
                f"accessor {index} needs {need:,} bytes of bufferView {a['bufferView']} "
                f"({count:,} x {a['type']}), which has {len(raw):,} (truncated or corrupt)",
            )
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
        ict = sp["indices"]["componentType"]
        if ict not in _INDEX_COMP:
            raise SceneFileError(
                g.path,
                f"sparse accessor {index} has indices of componentType {ict} "
                f"({_COMP_NAME.get(ict, 'unknown')}), expected one of {sorted(_INDEX_COMP)}",
                "fix: re-export the mesh",
            )
        iraw, _ = _view_bytes(g, sp["indices"]["bufferView"], cache)
        idt = np.dtype(_COMP[ict])
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


def _node_name(ni: int, node: dict) -> str:
    name = node.get("name")
    return f"node {ni}" + (f" ({name!r})" if isinstance(name, str) and name else "")


def _node_vector(path: Path, ni: int, node: dict, key: str, default: list[float]) -> np.ndarray:
    """A node's `matrix` / `translation` / `rotation` / `scale`: the right count of finite numbers, or a
    one-line error (NaN here would make every vertex NaN after the world transform)."""
    raw = node.get(key, default)
    try:
        v = np.asarray(raw, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        v = np.empty(0)
    if v.shape != (len(default),) or not np.isfinite(v).all():
        what = f"{len(default)} finite numbers"
        raise SceneFileError(
            path,
            f"{_node_name(ni, node)} has {key} {str(raw)[:80]}, expected {what}",
            "fix: repair the node transform or re-export the mesh",
        )
    return v


def _node_matrix(node: dict, path: Path = Path("?"), ni: int = -1) -> np.ndarray:
    """The node's local transform (4x4), checked: finite numbers, a unit rotation quaternion."""
    if "matrix" in node:
        ident = [1.0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]
        return _node_vector(path, ni, node, "matrix", ident).reshape(4, 4).T  # column-major in glTF
    t = _node_vector(path, ni, node, "translation", [0.0, 0.0, 0.0])
    q = _node_vector(path, ni, node, "rotation", [0.0, 0.0, 0.0, 1.0])
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > 1e-2:  # exporters round quaternions a little: renormalised below
        raise SceneFileError(
            path,
            f"{_node_name(ni, node)} has rotation {q.tolist()} of length {norm:.4g}, expected a unit quaternion",
            "fix: repair the node transform or re-export the mesh",
        )
    x, y, z, w = (float(v) for v in q / norm)
    s = _node_vector(path, ni, node, "scale", [1.0, 1.0, 1.0])
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


def _check_world(path: Path, ni: int, node: dict, world: np.ndarray) -> bool:
    """Whether the world transform of a node carrying a mesh draws it: False when it is singular (zero
    scale: exporters hide nodes that way, and glTF allows it), an error when it is not finite (overflow of
    huge scales)."""
    if not np.isfinite(world).all():
        raise SceneFileError(
            path,
            f"{_node_name(ni, node)}: its world transform (with its parents') is not finite",
            "fix: repair the node transforms or re-export the mesh",
        )
    sv = np.linalg.svd(world[:3, :3], compute_uv=False)
    return not (sv[0] == 0.0 or sv[-1] < _SINGULAR_RATIO * sv[0])


def _node_order(doc: dict, path: Path = Path("?"), notes: list[str] | None = None) -> list[tuple[int, np.ndarray]]:
    """(node index, world matrix) of every node reachable from the default scene whose mesh is drawn (and of
    the nodes without a mesh), parents first. A mesh node with a singular transform (zero scale: hidden) is
    left out with a note; when every mesh node is, the scene is refused: it would load with no floor and no
    walls instead of an error."""
    nodes = doc.get("nodes", [])
    scenes = doc.get("scenes")
    if scenes:
        roots = scenes[doc.get("scene", 0)].get("nodes", [])
    else:
        children = {c for n in nodes for c in n.get("children", [])}
        roots = [i for i in range(len(nodes)) if i not in children]
    stack: list[tuple[int, np.ndarray, int]] = [(r, np.eye(4), 0) for r in reversed(roots)]
    order: list[tuple[int, np.ndarray]] = []
    hidden: list[int] = []
    while stack:
        ni, parent, depth = stack.pop()
        if depth > 256:
            raise ValueError("node hierarchy deeper than 256 levels (a cycle?)")
        world = parent @ _node_matrix(nodes[ni], path, ni)
        if nodes[ni].get("mesh") is not None and not _check_world(path, ni, nodes[ni], world):
            hidden.append(ni)
        else:
            order.append((ni, world))
        for c in reversed(nodes[ni].get("children", [])):
            stack.append((c, world, depth + 1))
    if not nodes and doc.get("meshes"):
        order = [(-1, np.eye(4))]
    if hidden:
        if not any(ni < 0 or nodes[ni].get("mesh") is not None for ni, _ in order):
            ni = hidden[0]
            raise SceneFileError(
                path,
                f"every node with a mesh has a singular transform (with its parents'), e.g. "
                f"{_node_name(ni, nodes[ni])}: it flattens the scene to a plane, line or "
                "point",
                "fix: give the nodes invertible matrices / non-zero scales, or re-export the mesh",
            )
        if notes is not None:
            shown = ", ".join(_node_name(ni, nodes[ni]) for ni in hidden[:3]) + (", ..." if len(hidden) > 3 else "")
            notes.append(f"skipped {len(hidden)} node(s) with a singular (zero-scale: hidden) transform: {shown}")
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


def _check_index_type(path: Path, doc: dict, prim: dict, where: str) -> None:
    """Refuse triangle indices that glTF does not allow (see _INDEX_COMP)."""
    if "indices" not in prim:
        return
    iacc = doc["accessors"][prim["indices"]]
    ct = iacc.get("componentType")
    if ct not in _INDEX_COMP or iacc.get("type") != "SCALAR":
        allowed = ", ".join(f"{k} ({v})" for k, v in _INDEX_COMP.items())
        raise SceneFileError(
            path,
            f"{where}: its indices (accessor {prim['indices']}) are {iacc.get('type')} "
            f"of componentType {ct} ({_COMP_NAME.get(ct, 'unknown')}), expected SCALAR "
            f"of {allowed}",
            "fix: re-export the mesh",
        )


def _read_primitive(
    g: _Glb, prim: dict, world: np.ndarray, where: str, cache: dict[int, bytes], notes: list[str]
) -> _Primitive | None:
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
        raise SceneFileError(
            g.path,
            f"{where}: {int(bad.sum()):,} of {len(pos):,} vertex positions are NaN or "
            f"infinite (first: vertex {int(np.flatnonzero(bad)[0])})",
            "repair or re-export the mesh",
        )
    if "indices" in prim:
        _check_index_type(g.path, doc, prim, where)
        idx = _accessor(g, prim["indices"], cache).reshape(-1).astype(np.int64)
        if len(idx) and (idx.max() >= len(pos) or idx.min() < 0):
            raise SceneFileError(
                g.path,
                f"{where}: triangle index {int(idx.max())} is out of range: the primitive has {len(pos):,} vertices",
                "the file is corrupt; re-export it",
            )
    else:
        idx = np.arange(len(pos), dtype=np.int64)
    tris = _triangles(idx, mode)
    if not np.allclose(world, np.eye(4)):
        with np.errstate(over="ignore", invalid="ignore"):
            pos = (pos.astype(np.float64) @ world[:3, :3].T + world[:3, 3]).astype(np.float32)
        bad = ~np.isfinite(pos).all(axis=1)
        if bad.any():  # finite vertices and transform, yet beyond float32 once transformed (a huge scale)
            raise SceneFileError(
                g.path,
                f"{where}: {int(bad.sum()):,} of {len(pos):,} vertex positions overflow "
                "to infinity once its node transform is applied",
                "fix: repair the node transform or re-export the mesh",
            )
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
        for ni, world in _node_order(doc, path, notes):
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


# ------------------------------------------------------------------------------------- pre-flight


def _axis_aligned(m: np.ndarray) -> bool:
    """Each row has one non-zero entry: the map takes an axis-aligned box to an axis-aligned box."""
    a = np.abs(m)
    return bool((np.count_nonzero(a > 1e-12 * max(float(a.max()), 1e-300), axis=1) == 1).all())


def preflight_gltf(path: Path) -> tuple[np.ndarray, np.ndarray] | None:
    """Check a `.glb` / `.gltf` without reading its vertex data: container, buffer and bufferView lengths
    against the file(s), accessor extents, index component types and node transforms; a problem is the
    same `SceneFileError` (or FileNotFoundError) that loading the file would raise, found in milliseconds
    instead of after minutes of work on other scenes.

    Returns the world-frame bounds (lo, hi) of its triangles from the POSITION accessors' min / max when
    they are exact (every accessor has them and every node transform is axis-aligned), else None."""
    with open(path, "rb") as f:
        head = f.read(200)
        err = lfs_pointer_error(path, head)
        if err is not None:
            raise err
        if head[:4] != b"glTF":
            doc, binlen = _gltf_json(path, head + f.read()), 0
        else:

            def read_at(off: int, n: int) -> bytes:
                f.seek(off)
                return f.read(n)

            doc, _, binlen = _glb_chunks(path, path.stat().st_size, read_at, False)
    try:
        return _preflight_doc(path, doc, binlen)
    except (SceneFileError, FileNotFoundError):
        raise
    except (KeyError, IndexError, TypeError, ValueError, AttributeError, OverflowError) as e:
        what = f"missing key {e}" if isinstance(e, KeyError) else f"{type(e).__name__}: {e}"
        raise SceneFileError(path, f"is a corrupt glTF document ({what})", "re-download or re-export it") from None


def _preflight_doc(path: Path, doc: dict, binlen: int) -> tuple[np.ndarray, np.ndarray] | None:
    """The checks of `preflight_gltf` on a parsed document, limited to what `read_primitives` reads
    unconditionally (a broken texture image or an unused accessor is no error there, so none here)."""
    accessors, views = doc.get("accessors", []), doc.get("bufferViews", [])
    buf_have: dict[int, int] = {}

    def buffer_size(i: int) -> int:
        if i not in buf_have:
            buf = doc["buffers"][i]
            uri = buf.get("uri")
            if uri is None:
                have, src = binlen, "the BIN chunk"
            elif uri.startswith("data:"):
                have, src = len(base64.b64decode(uri.split(",", 1)[1])), "a data URI"
            else:
                ext = path.parent / uri
                if not ext.is_file():
                    raise FileNotFoundError(
                        f"{path}: external buffer {ext} is missing (a .gltf needs its .bin beside it)"
                    )
                have, src = ext.stat().st_size, str(ext)
            need = int(buf.get("byteLength", 0))
            if have < need:
                raise SceneFileError(
                    path,
                    f"buffer {i} declares {need:,} bytes but {src} holds {have:,} (truncated or corrupt)",
                    "re-download or re-export it",
                )
            buf_have[i] = have
        return buf_have[i]

    def check_accessor(i: int) -> None:
        a = accessors[i]
        if a.get("componentType") not in _COMP or a.get("type") not in _NCOMP:
            raise SceneFileError(
                path,
                f"accessor {i} has componentType {a.get('componentType')} / type "
                f"{a.get('type')!r}, which glTF 2.0 does not define",
            )
        if "bufferView" not in a:
            return
        vi = a["bufferView"]
        v = views[vi]
        have = buffer_size(v["buffer"])
        start, length = int(v.get("byteOffset", 0)), int(v["byteLength"])
        if start < 0 or start + length > have:
            raise SceneFileError(
                path,
                f"bufferView {vi} spans bytes {start:,}..{start + length:,} of buffer "
                f"{v['buffer']}, which has {have:,} (truncated or corrupt)",
            )
        elem = np.dtype(_COMP[a["componentType"]]).itemsize * _NCOMP[a["type"]]
        count = int(a["count"])
        step = int(v.get("byteStride", 0)) or elem
        need = int(a.get("byteOffset", 0)) + (step * (count - 1) + elem if count > 0 else 0)
        if need > length:
            raise SceneFileError(
                path,
                f"accessor {i} needs {need:,} bytes of bufferView {vi} ({count:,} x "
                f"{a['type']}), which has {length:,} (truncated or corrupt)",
            )

    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    exact = True
    for ni, world in _node_order(doc, path):
        mesh_index = doc["nodes"][ni].get("mesh") if ni >= 0 else 0
        if mesh_index is None:
            continue
        exact &= _axis_aligned(world[:3, :3])
        for k, prim in enumerate(doc["meshes"][mesh_index]["primitives"]):
            attrs = prim["attributes"]
            if "POSITION" not in attrs:
                continue
            check_accessor(attrs["POSITION"])
            if prim.get("mode", 4) not in (4, 5, 6):
                continue
            _check_index_type(path, doc, prim, f"mesh {mesh_index} primitive {k}")
            for i in [prim.get("indices"), attrs.get("COLOR_0"), attrs.get(VERTEX_ID_ATTR)]:
                if i is not None:
                    check_accessor(i)
            pa = accessors[attrs["POSITION"]]
            if "min" not in pa or "max" not in pa or pa.get("normalized") or pa.get("sparse"):
                exact = False
                continue
            box = np.array([pa["min"], pa["max"]], dtype=np.float64).reshape(2, 3)
            corners = np.array([[box[i, 0], box[j, 1], box[m, 2]] for i in (0, 1) for j in (0, 1) for m in (0, 1)])
            w = corners @ world[:3, :3].T + world[:3, 3]
            lo, hi = np.minimum(lo, w.min(axis=0)), np.maximum(hi, w.max(axis=0))
    if not exact or not np.isfinite(lo).all() or not np.isfinite(hi).all():
        return None
    return lo, hi
