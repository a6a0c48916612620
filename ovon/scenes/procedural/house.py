"""Seeded procedural houses: `generate_house(seed) -> Scene`, deterministic for a seed and config.

Algorithm:
1. Layout (layout.py): a footprint sized for 4-12 rooms is split recursively (longest side, random
   fraction, sides 2.5-7 m), optionally after carving a 1.3-1.9 m hallway strip; rooms get types
   (ground floor: living room + kitchen, then bedrooms, bathrooms, ... weighted by size). Doorways: a
   random spanning tree over rooms sharing a wall long enough for a door, plus a few extra ones. Walls
   are boxes centred on cell edges, cut at doors with lintels above; every room gets a floor and a
   ceiling slab. With a seeded probability a smaller second storey sits at `floor_to_floor` (no stairs).
2. Furnishing (furnish.py): per room, floor objects by room affinity x frequency (against walls facing
   inward, or free standing), each accepted only when it stays inside the room, overlaps nothing, keeps
   1 m in front of every doorway clear, leaves either no gap or >= 0.5 m to walls and other obstacles
   (no slits that turn into dead-end pockets), and keeps the room's free space in one piece on 5 cm
   grids at clearances 0.17 and 0.22 m; then wall objects (flush, not over doors), small objects on
   `is_surface` tops, and ceiling objects hanging above head height.
3. Mesh (shapes.py): one builder per shape family; parts are transformed and concatenated once, with
   per-face colour (category colour x part shade; orientation shading only if `bake_shading`) and per-face instance id.
4. Looks (looks.py, `looks="category"`): each category's faces are split along its pattern's planes and
   two-toned (base colour / accent), so siblings of a family look different and synonyms alike.

Instance ids: structural parts come first (walls, floors, ceilings: raw labels "wall", "floor",
"ceiling", category None), then objects; ids start at 1 and are contiguous.
"""

from __future__ import annotations

import hashlib

import numpy as np

from ..model import Mesh, ObjectInstance, Region, Scene
from ..vocabulary import Vocabulary, load_vocabulary
from .config import HouseConfig
from .furnish import Furnisher, rotation
from .layout import make_layout
from .looks import apply_look, look_of
from .shapes import box_mesh, build_shape

_ALNUM = "0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz"

_FLOOR_COLORS = {
    "bathroom": (205, 205, 200), "kitchen": (190, 185, 175), "laundry room": (200, 198, 190),
    "garage": (140, 140, 138), "gym": (90, 90, 95),
}  # fmt: skip
_WOOD = (150, 111, 72)
_WALL = (236, 232, 224)
_CEILING = (246, 246, 244)


def scene_tag(seed: int) -> str:
    """HM3D-style 11-character alphanumeric tag derived from the seed."""
    digest = hashlib.sha256(f"ovon-house-{seed}".encode()).digest()
    return "".join(_ALNUM[b % len(_ALNUM)] for b in digest[:11])


def semantic_color(instance_id: int, used: set[tuple[int, int, int]]) -> tuple[int, int, int]:
    """Distinct, non-black RGB per id (hash of the id; rehashed on a clash)."""
    k = 0
    while True:
        d = hashlib.blake2b(f"{instance_id}:{k}".encode(), digest_size=3).digest()
        c = (d[0], d[1], d[2])
        if c != (0, 0, 0) and c not in used:
            used.add(c)
            return c
        k += 1


def _shade_by_normal(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Orientation shading: tops bright, sides a little darker, bottoms darkest."""
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    n /= np.linalg.norm(n, axis=1, keepdims=True) + 1e-12
    return 0.82 + 0.18 * n[:, 1] - 0.06 * np.abs(n[:, 0])


def generate_house(seed: int, vocab: Vocabulary | None = None, cfg: HouseConfig | None = None) -> Scene:
    """Build the house for `seed` (same seed + config -> identical arrays)."""
    if not 0 <= int(seed) < 2**32:  # the generator's seed is 32 bits: a larger one would repeat a smaller one's house
        raise ValueError(f"house seed {seed} is outside [0, 2**32); fix: pass a seed in that range")
    vocab = vocab if vocab is not None else load_vocabulary()
    cfg = cfg if cfg is not None else HouseConfig()
    root = np.random.SeedSequence([int(seed) & 0xFFFFFFFF, 0x0F0F])
    lay_rng, furn_rng, col_rng = (np.random.default_rng(s) for s in root.spawn(3))
    layout = make_layout(lay_rng, cfg)
    placed = Furnisher(vocab, cfg).furnish(furn_rng, layout)
    rooms = {r.id: r for r in layout.rooms}

    verts: list[np.ndarray] = []
    faces: list[np.ndarray] = []
    cols: list[np.ndarray] = []
    ids: list[np.ndarray] = []
    objects: list[ObjectInstance] = []
    used: set[tuple[int, int, int]] = set()
    nv = 0

    def add(v: np.ndarray, f: np.ndarray, col: np.ndarray, iid: int) -> None:
        nonlocal nv
        verts.append(v)
        faces.append(f + nv)
        cols.append(col)
        ids.append(np.full(len(f), iid, dtype=np.int32))
        nv += len(v)

    # structure
    for box in layout.boxes:
        iid = len(objects) + 1
        v, f = box_mesh(box.lo, box.hi)
        room = rooms[box.region]
        if box.kind == "wall":
            base = np.array(_WALL) * col_rng.uniform(0.95, 1.02)
        elif box.kind == "floor":
            base = np.array(_FLOOR_COLORS.get(room.name, _WOOD)) * col_rng.uniform(0.92, 1.05)
        else:
            base = np.array(_CEILING, dtype=np.float64)
        add(v, f, np.tile(base, (len(f), 1)), iid)
        c = (box.lo + box.hi) / 2
        objects.append(
            ObjectInstance(
                id=iid, raw_label=box.kind, category=None, aabb_min=box.lo.copy(), aabb_max=box.hi.copy(),
                obb_center=c, obb_half_extents=(box.hi - box.lo) / 2, obb_rotation=np.eye(3),
                region_id=room.id, region_name=room.name, floor=box.floor, color=semantic_color(iid, used),
            )
        )  # fmt: skip

    # objects
    for p in placed:
        iid = len(objects) + 1
        pm = build_shape(p.category.family, p.size, cfg.cylinder_segments)
        if cfg.looks == "category":
            local, f, col = apply_look(pm.vertices, pm.faces, pm.shade, p.size, p.color, look_of(p.category, vocab))
        else:
            local, f, col = pm.vertices, pm.faces, p.color[None, :] * pm.shade[:, None]
        R = rotation(p.yaw)
        v = local @ R.T + p.pos
        add(v, f, col, iid)
        half = np.array(p.size) / 2
        objects.append(
            ObjectInstance(
                id=iid, raw_label=p.raw_label, category=p.category.name, aabb_min=v.min(axis=0),
                aabb_max=v.max(axis=0), obb_center=p.pos + np.array([0.0, half[1], 0.0]), obb_half_extents=half,
                obb_rotation=R, region_id=p.room.id, region_name=p.room.name, floor=p.room.floor,
                color=semantic_color(iid, used),
            )
        )  # fmt: skip

    V = np.concatenate(verts).astype(np.float32)
    F = np.concatenate(faces).astype(np.int32)
    C = np.concatenate(cols)
    if cfg.bake_shading:
        C = C * _shade_by_normal(np.concatenate(verts), F)[:, None]
    mesh = Mesh(
        vertices=V,
        faces=F,
        face_colors=np.clip(np.rint(C), 0, 255).astype(np.uint8),
        face_instance=np.concatenate(ids).astype(np.int32),
    )
    t = cfg.wall_thickness
    regions = [Region(r.id, r.name, r.floor, r.interior(t)) for r in layout.rooms]
    return Scene(
        scene_id=f"{int(seed):05d}-{scene_tag(int(seed))}",
        mesh=mesh,
        objects=objects,
        regions=regions,
        floor_heights=sorted(layout.floor_heights),
        semantic_colors={o.id: o.color for o in objects},
        source=f"procedural:{int(seed)}",
    )
