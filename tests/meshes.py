"""Hand-built box meshes with known navigability, shared by the simulator tests.

Boxes have outward winding (top faces point up), like a procedural house. Coordinates: Habitat frame,
y up, metres; a box is given by its min and max corners.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ovon.scenes.model import Mesh, Scene

Box = tuple[Sequence[float], Sequence[float]]

# unit cube corners and outward-wound triangles (checked: every face normal points outwards)
_CORNERS = np.array(
    [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], dtype=np.float64
)
# fmt: off
_FACES = np.array(
    [
        [0, 3, 2], [0, 2, 1],  # z = 0 (normal -z)
        [4, 5, 6], [4, 6, 7],  # z = 1 (+z)
        [0, 4, 7], [0, 7, 3],  # x = 0 (-x)
        [1, 2, 6], [1, 6, 5],  # x = 1 (+x)
        [0, 1, 5], [0, 5, 4],  # y = 0 (-y)
        [3, 7, 6], [3, 6, 2],  # y = 1 (+y)
    ],
    dtype=np.int64,
)
# fmt: on


def box(lo: Sequence[float], hi: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (8, 3) and faces (12, 3) of an axis-aligned box."""
    lo_a = np.asarray(lo, dtype=np.float64)
    hi_a = np.asarray(hi, dtype=np.float64)
    return lo_a + _CORNERS * (hi_a - lo_a), _FACES.copy()


def mesh_from_boxes(boxes: Sequence[Box]) -> Mesh:
    verts, faces, off = [], [], 0
    for lo, hi in boxes:
        v, f = box(lo, hi)
        verts.append(v)
        faces.append(f + off)
        off += len(v)
    return Mesh(vertices=np.concatenate(verts).astype(np.float32), faces=np.concatenate(faces).astype(np.int32))


def scene_from_boxes(boxes: Sequence[Box], floor_heights: Sequence[float] = (), scene_id: str = "test") -> Scene:
    return Scene(scene_id=scene_id, mesh=mesh_from_boxes(boxes), floor_heights=list(floor_heights))


def room_boxes(
    x0: float,
    z0: float,
    x1: float,
    z1: float,
    floor_y: float = 0.0,
    wall_height: float = 2.5,
    wall_t: float = 0.1,
    slab_t: float = 0.1,
    ceiling: bool = True,
) -> list[Box]:
    """Floor slab (top at floor_y), four walls outside [x0, x1] x [z0, z1], optional ceiling slab.

    The free interior is exactly [x0, x1] x [z0, z1].
    """
    y0, y1 = floor_y, floor_y + wall_height
    out: list[Box] = [((x0 - wall_t, y0 - slab_t, z0 - wall_t), (x1 + wall_t, y0, z1 + wall_t))]
    out += [
        ((x0 - wall_t, y0, z0 - wall_t), (x0, y1, z1 + wall_t)),
        ((x1, y0, z0 - wall_t), (x1 + wall_t, y1, z1 + wall_t)),
        ((x0, y0, z0 - wall_t), (x1, y1, z0)),
        ((x0, y0, z1), (x1, y1, z1 + wall_t)),
    ]
    if ceiling:
        out.append(((x0 - wall_t, y1, z0 - wall_t), (x1 + wall_t, y1 + slab_t, z1 + wall_t)))
    return out


def wall_x_with_gap(
    x: float,
    z0: float,
    z1: float,
    gap_z0: float,
    gap_z1: float,
    floor_y: float = 0.0,
    height: float = 2.5,
    t: float = 0.1,
) -> list[Box]:
    """A wall centred on x spanning z0..z1 with a doorway (full height) from gap_z0 to gap_z1."""
    out: list[Box] = []
    if gap_z0 > z0:
        out.append(((x - t / 2, floor_y, z0), (x + t / 2, floor_y + height, gap_z0)))
    if gap_z1 < z1:
        out.append(((x - t / 2, floor_y, gap_z1), (x + t / 2, floor_y + height, z1)))
    return out


def empty_floor(size_x: float, size_z: float, floor_y: float = 0.0) -> list[Box]:
    """A walled room of the given interior size starting at the origin, with ceiling."""
    return room_boxes(0.0, 0.0, size_x, size_z, floor_y=floor_y)


def grid_house(seed: int = 0, rooms: int = 4, room_size: float = 5.0, furniture: int = 80) -> list[Box]:
    """A rooms x rooms house of square rooms joined by 0.9 m doorways, with random box furniture
    (0.3-1.2 m high, so some tops are walkable islands). A stand-in for a procedural house."""
    rng = np.random.default_rng(seed)
    size = rooms * room_size
    boxes = room_boxes(0.0, 0.0, size, size)
    for i in range(1, rooms):
        x = room_size * i
        for j in range(rooms):
            z0 = room_size * j
            g0, g1 = z0 + 2.0, z0 + 2.9
            boxes += wall_x_with_gap(x, z0, z0 + room_size, g0, g1)
            boxes += [
                ((z0, 0.0, x - 0.05), (g0, 2.5, x + 0.05)),
                ((g1, 0.0, x - 0.05), (z0 + room_size, 2.5, x + 0.05)),
            ]
    for _ in range(furniture):
        cx, cz = rng.uniform(0.5, size - 0.5, 2)
        w, d = rng.uniform(0.3, 1.5, 2)
        h = rng.uniform(0.3, 1.2)
        boxes.append(((cx - w / 2, 0.0, cz - d / 2), (cx + w / 2, h, cz + d / 2)))
    return boxes


# ------------------------------------------------------------------------------- mesh files on disk


def to_z_up(mesh: Mesh) -> Mesh:
    """The same mesh in a z-up frame (what habitat's `up: [0, 0, 1]` assets use): (x, y, z) -> (x, -z, y)."""
    v = mesh.vertices.astype(np.float64)
    return Mesh(vertices=np.stack([v[:, 0], -v[:, 2], v[:, 1]], axis=1).astype(np.float32), faces=mesh.faces.copy())


def write_glb(mesh: Mesh, path) -> None:  # noqa: ANN001
    from ovon.scenes.hm3dsem import encode_glb

    path.write_bytes(encode_glb(mesh.vertices, mesh.faces, vertex_rgb=mesh.vertex_colors))


def write_gltf_bin(mesh: Mesh, path) -> None:  # noqa: ANN001
    """`<name>.gltf` (JSON) + `<name>.bin` (the buffer as an external file)."""
    import json
    import struct

    from ovon.scenes.hm3dsem import encode_glb

    glb = encode_glb(mesh.vertices, mesh.faces)
    jlen = struct.unpack_from("<I", glb, 12)[0]
    doc = json.loads(glb[20 : 20 + jlen])
    blen = struct.unpack_from("<I", glb, 20 + jlen)[0]
    binary = glb[28 + jlen : 28 + jlen + blen]
    doc["buffers"][0]["uri"] = path.with_suffix(".bin").name
    path.write_text(json.dumps(doc))
    path.with_suffix(".bin").write_bytes(binary)


def write_trimesh(mesh: Mesh, path) -> None:  # noqa: ANN001
    """PLY or OBJ (by suffix) through trimesh, with vertex colours when the mesh has them."""
    import trimesh

    tm = trimesh.Trimesh(vertices=mesh.vertices, faces=mesh.faces, process=False, vertex_colors=mesh.vertex_colors)
    tm.export(path)
