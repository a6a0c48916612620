"""Read and write Recast/Detour navmesh files exactly as habitat-sim saves them (`<id>.navmesh`).

File layout (little-endian; habitat-sim `PathFinder::loadNavMesh` / `saveNavMesh`, Detour's
`dtCreateNavMeshData` / `dtNavMesh::addTile`):

* set header (40 bytes): magic 'MSET', version (1 or 2), tile count, `dtNavMeshParams` (origin xyz,
  tile width, tile height, max tiles, max polys);
* version 2 only: habitat's `NavMeshSettings` (13 floats + 4 bools, 56 bytes);
* per tile: tile ref (uint32; habitat builds Detour with 32-bit refs), data size, then the tile data:
  `dtMeshHeader` (100 bytes: magic 'DNAV', version 7, counts, walkable height/radius/climb, bounds),
  then vertices, polygons, links, detail sub-meshes, detail vertices, detail triangles, BV tree and
  off-mesh connections, each block padded to 4 bytes (`dtAlign4`). A tile with ref 0 or size 0 ends
  the list (as habitat's loader does).

Links and the BV tree are runtime data Detour rebuilds when it adds a tile: they are skipped on read
and written as zeros (links) or omitted (no BV tree) on write. Every count, index and coordinate is
checked on read, so a broken file is one line naming the file and what is wrong in it.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np

from ovon.atomic import atomic_write_bytes
from ovon.scenes.hm3dsem.errors import SceneFileError, lfs_pointer_error

SET_MAGIC = ord("M") << 24 | ord("S") << 16 | ord("E") << 8 | ord("T")
TILE_MAGIC = ord("D") << 24 | ord("N") << 16 | ord("A") << 8 | ord("V")
TILE_VERSION = 7  # DT_NAVMESH_VERSION
VERSIONS = (1, 2)  # NAVMESHSET_VERSION 1: no settings; 2: NavMeshSettings after the header
EXT_LINK = 0x8000  # dtPoly.neis: portal to a neighbouring tile; low byte = side (0 +x, 2 +z, 4 -x, 6 -z)
MAX_VERTS_PER_POLY = 6  # DT_VERTS_PER_POLYGON
POLY_GROUND, POLY_OFFMESH = 0, 1  # dtPolyTypes
FLAG_WALK, FLAG_DOOR, FLAG_DISABLED = 0x01, 0x02, 0x04  # habitat's PolyFlags

_SET = struct.Struct("<iii3fffii")  # NavMeshSetHeader (dtNavMeshParams inlined)
_SETTINGS = struct.Struct("<13f4?")  # habitat NavMeshSettings, 55 bytes + 1 of padding
_SETTINGS_SIZE = 56
_TILE_REF = struct.Struct("<Ii")  # NavMeshTileHeader: dtTileRef (32 bit), dataSize
_MESH = struct.Struct("<iiiiiIiiiiiiiiifff3f3ff")  # dtMeshHeader, 100 bytes
_POLY = np.dtype(
    [
        ("first_link", "<u4"),
        ("verts", "<u2", 6),
        ("neis", "<u2", 6),
        ("flags", "<u2"),
        ("vert_count", "u1"),
        ("area_type", "u1"),
    ]
)  # dtPoly, 32 bytes
_DETAIL = np.dtype(
    [("vert_base", "<u4"), ("tri_base", "<u4"), ("vert_count", "u1"), ("tri_count", "u1"), ("pad", "V2")]
)  # dtPolyDetail, 10 bytes + 2 of padding
_LINK_SIZE = 12  # dtLink with 32-bit refs
_BV_SIZE = 16  # dtBVNode
_OFFMESH = np.dtype(
    [("pos", "<f4", 6), ("rad", "<f4"), ("poly", "<u2"), ("flags", "u1"), ("side", "u1"), ("user_id", "<u4")]
)  # dtOffMeshConnection, 36 bytes


def _align4(n: int) -> int:
    return (n + 3) & ~3


class NavMeshError(SceneFileError):
    """A navmesh file cannot be used; the message names the file and what is wrong."""


@dataclass(frozen=True)
class NavMeshSettings:
    """habitat-sim's `NavMeshSettings` (what the navmesh was baked with), stored by version-2 files."""

    cell_size: float = 0.05
    cell_height: float = 0.2
    agent_height: float = 1.5
    agent_radius: float = 0.1
    agent_max_climb: float = 0.2
    agent_max_slope: float = 45.0
    region_min_size: float = 20.0
    region_merge_size: float = 20.0
    edge_max_len: float = 12.0
    edge_max_error: float = 1.3
    verts_per_poly: float = 6.0
    detail_sample_dist: float = 6.0
    detail_sample_max_error: float = 1.0
    filter_low_hanging_obstacles: bool = True
    filter_ledge_spans: bool = True
    filter_walkable_low_height_spans: bool = True
    include_static_objects: bool = False


@dataclass
class NavMeshTile:
    """One Detour tile: polygon mesh + detail mesh (what `dtMeshTile` points into)."""

    x: int
    y: int
    layer: int
    verts: np.ndarray  # (V, 3) float32 polygon vertices
    polys: np.ndarray  # (P,) structured `_POLY`: verts, neis, flags, vert_count, area_type
    detail_meshes: np.ndarray  # (D,) structured `_DETAIL`: vert_base, tri_base, vert_count, tri_count
    detail_verts: np.ndarray  # (DV, 3) float32, extra vertices of the detail meshes
    detail_tris: np.ndarray  # (DT, 4) uint8: three vertex indices + edge flags
    walkable_height: float = 1.5
    walkable_radius: float = 0.1
    walkable_climb: float = 0.2
    bmin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    bmax: tuple[float, float, float] = (0.0, 0.0, 0.0)
    user_id: int = 0
    max_link_count: int = 0
    offmesh: np.ndarray = field(default_factory=lambda: np.zeros(0, _OFFMESH))
    offmesh_base: int = -1  # index of the first off-mesh polygon; -1: the polygon count (none)
    bv_quant_factor: float = 0.0
    ref: int = 0  # dtTileRef the file stored (encodes the tile's slot and salt)

    @property
    def area(self) -> np.ndarray:
        return self.polys["area_type"] & 0x3F

    @property
    def kind(self) -> np.ndarray:
        return self.polys["area_type"] >> 6


@dataclass
class NavMesh:
    """A whole navmesh file: Detour's params, habitat's settings (None in version 1) and the tiles."""

    origin: tuple[float, float, float]
    tile_width: float
    tile_height: float
    max_tiles: int
    max_polys: int
    tiles: list[NavMeshTile]
    settings: NavMeshSettings | None = None
    version: int = 2
    path: str = ""

    def agent_radius(self) -> float:
        """The radius the walkable area was eroded by (settings, else the tiles' walkable radius)."""
        if self.settings is not None:
            return float(self.settings.agent_radius)
        return float(max((t.walkable_radius for t in self.tiles), default=0.0))

    def tile_order(self) -> list[int]:
        """Tiles in Detour's slot order (the order habitat iterates them: islands are numbered in it)."""
        poly_bits, mask = _bits(self.max_polys), (1 << _bits(self.max_tiles)) - 1

        def slot(i: int) -> tuple[int, int]:
            ref = self.tiles[i].ref
            return ((ref >> poly_bits) & mask, i) if ref else (1 << 40, i)

        return sorted(range(len(self.tiles)), key=slot)


# ------------------------------------------------------------------------------------------ reading


def read_navmesh(path: str | Path) -> NavMesh:
    """Parse a habitat-sim navmesh file; a broken file raises `NavMeshError` (one line)."""
    return parse_navmesh(navmesh_file_bytes(path), str(path))


def navmesh_file_bytes(path: str | Path) -> bytes:
    """The bytes of a navmesh file; a missing file or a Git LFS pointer is a `NavMeshError`."""
    p = Path(path)
    if not p.is_file():
        raise NavMeshError(
            p,
            "navmesh file does not exist" if not p.exists() else "is not a file",
            "pass the <id>.navmesh (or <id>.basis.navmesh) habitat-sim wrote",
        )
    data = p.read_bytes()
    lfs = lfs_pointer_error(p, data[:200])
    if lfs is not None:
        raise NavMeshError(p, lfs.problem, "fetch it with `git lfs pull` inside that repository, then retry")
    return data


def _fail(name: str, problem: str, fix: str = "") -> NavMeshError:
    return NavMeshError(name, problem, fix)


def parse_navmesh(data: bytes, name: str = "<bytes>") -> NavMesh:
    """Parse the bytes of a navmesh file (`name` is used in error messages)."""
    if len(data) < 4:
        raise _fail(
            name,
            f"too short to be a navmesh ({len(data)} bytes)",
            "expected a Recast/Detour navmesh saved by habitat-sim (it starts with 'TESM')",
        )
    magic = struct.unpack_from("<i", data)[0]
    if magic != SET_MAGIC:
        shown = data[:4].decode("latin-1").encode("unicode_escape").decode()
        raise _fail(
            name,
            f"not a habitat-sim navmesh: magic {shown!r} (expected 'TESM', 'MSET' little-endian)",
            "pass the <id>.navmesh file habitat-sim saves (PathFinder.save_nav_mesh)",
        )
    if len(data) < _SET.size:
        raise _fail(
            name,
            f"truncated: {len(data)} bytes, the header alone needs {_SET.size}",
            "the download or copy was cut short: fetch the file again",
        )
    _, version, num_tiles, ox, oy, oz, tw, th, max_tiles, max_polys = _SET.unpack_from(data)
    if version not in VERSIONS:
        raise _fail(
            name,
            f"unsupported navmesh version {version} (habitat-sim writes versions 1 and 2)",
            "re-save it with habitat-sim (PathFinder.load_nav_mesh + save_nav_mesh)",
        )
    params = (ox, oy, oz, tw, th)
    if not all(math.isfinite(v) for v in params):
        raise _fail(name, f"header has a non-finite origin or tile size {params}", "the file is corrupt")
    if num_tiles < 0 or max_tiles < 1 or max_polys < 1 or num_tiles > max_tiles:
        raise _fail(
            name, f"header says {num_tiles} tiles of at most {max_tiles} (max polys {max_polys})", "the file is corrupt"
        )
    off = _SET.size
    settings = None
    if version >= 2:
        if len(data) < off + _SETTINGS_SIZE:
            raise _fail(
                name,
                f"truncated: version 2 needs NavMeshSettings at byte {off}, the file has {len(data)} bytes",
                "fetch the file again",
            )
        vals = _SETTINGS.unpack_from(data, off)
        if not all(math.isfinite(v) for v in vals[:13]):
            raise _fail(name, f"NavMeshSettings hold non-finite values {vals[:13]}", "the file is corrupt")
        settings = NavMeshSettings(*vals)
        off += _SETTINGS_SIZE
    tiles: list[NavMeshTile] = []
    for i in range(num_tiles):
        if len(data) < off + _TILE_REF.size:
            raise _fail(
                name,
                f"truncated: tile {i} of {num_tiles} starts at byte {off}, the file has {len(data)} bytes",
                "fetch the file again",
            )
        ref, size = _TILE_REF.unpack_from(data, off)
        off += _TILE_REF.size
        if ref == 0 or size == 0:
            break  # habitat's loader stops at an empty tile record
        if size < 0 or off + size > len(data):
            raise _fail(
                name,
                f"truncated: tile {i} needs {size} bytes at byte {off}, the file has {len(data)} bytes",
                "fetch the file again",
            )
        tile = _parse_tile(data[off : off + size], name, i)
        tile.ref = int(ref)
        tiles.append(tile)
        off += size
    return NavMesh(
        origin=(ox, oy, oz),
        tile_width=tw,
        tile_height=th,
        max_tiles=max_tiles,
        max_polys=max_polys,
        tiles=tiles,
        settings=settings,
        version=version,
        path=name,
    )


def _parse_tile(buf: bytes, name: str, i: int) -> NavMeshTile:
    where = f"tile {i}"
    if len(buf) < _MESH.size:
        raise _fail(name, f"{where}: {len(buf)} bytes, its header alone needs {_MESH.size}", "the file is corrupt")
    h = _MESH.unpack_from(buf)
    (
        magic,
        version,
        tx,
        ty,
        layer,
        user_id,
        npoly,
        nvert,
        nlink,
        ndetail,
        ndvert,
        ndtri,
        nbv,
        noff,
        off_base,
        wh,
        wr,
        wc,
        b0,
        b1,
        b2,
        c0,
        c1,
        c2,
        quant,
    ) = h
    if magic != TILE_MAGIC:
        raise _fail(name, f"{where}: tile magic {buf[:4]!r} (expected b'VAND', Detour's 'DNAV')", "the file is corrupt")
    if version != TILE_VERSION:
        raise _fail(
            name,
            f"{where}: Detour tile version {version} (supported: {TILE_VERSION})",
            "re-save it with a current habitat-sim",
        )
    counts = {
        "polygons": npoly,
        "vertices": nvert,
        "links": nlink,
        "detail meshes": ndetail,
        "detail vertices": ndvert,
        "detail triangles": ndtri,
        "BV nodes": nbv,
        "off-mesh connections": noff,
    }
    bad = {k: v for k, v in counts.items() if v < 0}
    if bad:
        raise _fail(name, f"{where}: negative counts {bad}", "the file is corrupt")
    sizes = [
        _align4(12 * nvert),
        _align4(_POLY.itemsize * npoly),
        _align4(_LINK_SIZE * nlink),
        _align4(_DETAIL.itemsize * ndetail),
        _align4(12 * ndvert),
        _align4(4 * ndtri),
        _align4(_BV_SIZE * nbv),
        _align4(_OFFMESH.itemsize * noff),
    ]
    need = _align4(_MESH.size) + sum(sizes)
    if len(buf) < need:
        raise _fail(
            name,
            f"{where}: truncated tile data: {len(buf)} bytes, its counts ({npoly} polygons, {nvert} "
            f"vertices, ...) need {need}",
            "fetch the file again",
        )
    starts = np.cumsum([_align4(_MESH.size)] + sizes)
    verts = np.frombuffer(buf, "<f4", 3 * nvert, int(starts[0])).reshape(nvert, 3).astype(np.float32)
    polys = np.frombuffer(buf, _POLY, npoly, int(starts[1])).copy()
    detail = np.frombuffer(buf, _DETAIL, ndetail, int(starts[3])).copy()
    dverts = np.frombuffer(buf, "<f4", 3 * ndvert, int(starts[4])).reshape(ndvert, 3).astype(np.float32)
    dtris = np.frombuffer(buf, "u1", 4 * ndtri, int(starts[5])).reshape(ndtri, 4).copy()
    offmesh = np.frombuffer(buf, _OFFMESH, noff, int(starts[7])).copy()
    tile = NavMeshTile(
        x=tx,
        y=ty,
        layer=layer,
        verts=verts,
        polys=polys,
        detail_meshes=detail,
        detail_verts=dverts,
        detail_tris=dtris,
        walkable_height=wh,
        walkable_radius=wr,
        walkable_climb=wc,
        bmin=(b0, b1, b2),
        bmax=(c0, c1, c2),
        user_id=user_id,
        max_link_count=nlink,
        offmesh=offmesh,
        offmesh_base=off_base,
        bv_quant_factor=quant,
    )
    _check_tile(tile, name, where)
    return tile


def _check_tile(t: NavMeshTile, name: str, where: str) -> None:
    """Indices in range and coordinates finite: what Detour would otherwise read out of bounds."""
    for what, arr in (("vertex", t.verts), ("detail vertex", t.detail_verts)):
        bad = np.flatnonzero(~np.isfinite(arr).all(axis=1))
        if len(bad):
            raise _fail(
                name,
                f"{where}: {what} {int(bad[0])} is not finite ({arr[bad[0]].tolist()}; {len(bad)} such)",
                "the file is corrupt: rebuild the navmesh",
            )
    p = t.polys
    npoly, nvert = len(p), len(t.verts)
    if npoly == 0:
        return
    n = p["vert_count"].astype(np.int64)
    ground = (p["area_type"] >> 6) == POLY_GROUND
    bad = np.flatnonzero(np.where(ground, (n < 3) | (n > MAX_VERTS_PER_POLY), n != 2))
    if len(bad):
        k = int(bad[0])
        raise _fail(
            name,
            f"{where}: polygon {k} has {int(n[k])} vertices (a ground polygon has 3-6, an off-mesh link 2)",
            "the file is corrupt",
        )
    used = np.arange(MAX_VERTS_PER_POLY)[None, :] < n[:, None]
    vidx = np.where(used, p["verts"], 0)
    bad = np.flatnonzero((vidx >= nvert).any(axis=1))
    if len(bad):
        k = int(bad[0])
        raise _fail(
            name,
            f"{where}: polygon {k} references vertex {int(vidx[k].max())} but the tile has {nvert}",
            "the file is corrupt: rebuild the navmesh",
        )
    nei = np.where(used & ((p["neis"] & EXT_LINK) == 0), p["neis"], 0)
    bad = np.flatnonzero((nei > npoly).any(axis=1))
    if len(bad):
        k = int(bad[0])
        raise _fail(
            name,
            f"{where}: polygon {k} names neighbour {int(nei[k].max()) - 1} but the tile has {npoly}",
            "the file is corrupt",
        )
    g = np.flatnonzero(ground)
    if len(g) and int(g[-1]) >= len(t.detail_meshes):
        raise _fail(
            name,
            f"{where}: polygon {int(g[g >= len(t.detail_meshes)][0])} has no detail mesh "
            f"({len(t.detail_meshes)} for {npoly} polygons)",
            "the file is corrupt",
        )
    d = t.detail_meshes[g]
    vb, vc = d["vert_base"].astype(np.int64), d["vert_count"].astype(np.int64)
    tb, tc = d["tri_base"].astype(np.int64), d["tri_count"].astype(np.int64)
    bad = np.flatnonzero((vb + vc > len(t.detail_verts)) | (tb + tc > len(t.detail_tris)))
    if len(bad):
        i = int(bad[0])
        raise _fail(
            name,
            f"{where}: polygon {int(g[i])}'s detail mesh (vertices {int(vb[i])}+{int(vc[i])}, triangles "
            f"{int(tb[i])}+{int(tc[i])}) runs past the tile's {len(t.detail_verts)} detail vertices / "
            f"{len(t.detail_tris)} triangles",
            "the file is corrupt",
        )
    if tc.sum():
        owner = np.repeat(np.arange(len(g)), tc)
        rows = np.repeat(tb - np.cumsum(tc) + tc, tc) + np.arange(int(tc.sum()))
        top = t.detail_tris[rows, :3].max(axis=1).astype(np.int64)
        limit = n[g][owner] + vc[owner]
        bad = np.flatnonzero(top >= limit)
        if len(bad):
            i = int(bad[0])
            raise _fail(
                name,
                f"{where}: polygon {int(g[owner[i]])} has a detail triangle on vertex {int(top[i])} "
                f"of its {int(limit[i])}",
                "the file is corrupt",
            )


# ------------------------------------------------------------------------------------------ writing


def navmesh_bytes(mesh: NavMesh) -> bytes:
    """The file habitat-sim would write for `mesh` (links zeroed, no BV tree; version from `mesh.version`)."""
    if mesh.version not in VERSIONS:
        raise ValueError(f"navmesh version must be one of {VERSIONS}, got {mesh.version}")
    out = bytearray()
    ox, oy, oz = mesh.origin
    out += _SET.pack(
        SET_MAGIC,
        mesh.version,
        len(mesh.tiles),
        ox,
        oy,
        oz,
        mesh.tile_width,
        mesh.tile_height,
        mesh.max_tiles,
        mesh.max_polys,
    )
    if mesh.version >= 2:
        s = mesh.settings or NavMeshSettings()
        out += _SETTINGS.pack(*(getattr(s, f.name) for f in fields(s))) + b"\0" * (_SETTINGS_SIZE - _SETTINGS.size)
    for i, t in enumerate(mesh.tiles):
        body = _tile_bytes(t)
        pb, tb = _bits(mesh.max_polys), _bits(mesh.max_tiles)
        out += _TILE_REF.pack(t.ref or (1 << (pb + tb)) | (i << pb), len(body)) + body  # salt 1, slot i
    return bytes(out)


def _bits(n: int) -> int:
    """Detour's dtIlog2(dtNextPow2(n)): bits of a tile or polygon index in a reference."""
    return math.ceil(math.log2(n)) if n > 1 else 0


def _pad(b: bytes) -> bytes:
    return b + b"\0" * (_align4(len(b)) - len(b))


def _tile_bytes(t: NavMeshTile) -> bytes:
    npoly = len(t.polys)
    off_base = npoly if t.offmesh_base < 0 else t.offmesh_base
    head = _MESH.pack(
        TILE_MAGIC,
        TILE_VERSION,
        t.x,
        t.y,
        t.layer,
        t.user_id,
        npoly,
        len(t.verts),
        t.max_link_count,
        len(t.detail_meshes),
        len(t.detail_verts),
        len(t.detail_tris),
        0,
        len(t.offmesh),
        off_base,
        t.walkable_height,
        t.walkable_radius,
        t.walkable_climb,
        *t.bmin,
        *t.bmax,
        t.bv_quant_factor,
    )
    parts = [
        head,
        np.ascontiguousarray(t.verts, "<f4").tobytes(),
        np.ascontiguousarray(t.polys, _POLY).tobytes(),
        b"\0" * (_LINK_SIZE * t.max_link_count),
        np.ascontiguousarray(t.detail_meshes, _DETAIL).tobytes(),
        np.ascontiguousarray(t.detail_verts, "<f4").tobytes(),
        np.ascontiguousarray(t.detail_tris, "u1").tobytes(),
        np.ascontiguousarray(t.offmesh, _OFFMESH).tobytes(),
    ]
    return b"".join(_pad(p) for p in parts)


def write_navmesh(mesh: NavMesh, path: str | Path) -> Path:
    """Write `mesh` as a habitat-sim navmesh file (atomically)."""
    return atomic_write_bytes(path, navmesh_bytes(mesh))


def poly_array(n: int) -> np.ndarray:
    """An empty `dtPoly` array of n polygons (for building tiles)."""
    return np.zeros(n, _POLY)


def detail_array(n: int) -> np.ndarray:
    """An empty `dtPolyDetail` array of n sub-meshes (for building tiles)."""
    return np.zeros(n, _DETAIL)
