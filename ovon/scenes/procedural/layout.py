"""Room layout of a procedural house: recursive rectangle splitting, room types, doorways, walls, slabs.

Walls are centred on the cell edges of the split, so a room's walkable interior is its cell shrunk by
half a wall thickness on every side. Doorways connect rooms along shared edges: a random spanning tree
of the adjacency graph (so every room is reachable) plus a few extra doors.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .config import HouseConfig

_EPS = 1e-6


@dataclass
class Room:
    id: int
    name: str
    floor: int
    cell: tuple[float, float, float, float]  # (xmin, zmin, xmax, zmax) on wall centre lines
    floor_y: float
    is_hall: bool = False
    doors: list[RoomDoor] = field(default_factory=list)

    def interior(self, t: float) -> tuple[float, float, float, float]:
        x0, z0, x1, z1 = self.cell
        return (x0 + t / 2, z0 + t / 2, x1 - t / 2, z1 - t / 2)

    @property
    def area(self) -> float:
        x0, z0, x1, z1 = self.cell
        return (x1 - x0) * (z1 - z0)


@dataclass
class Door:
    a: int  # room ids
    b: int
    axis: str  # "x": the wall is the line x = line (runs along z); "z": the line z = line
    line: float
    center: float  # coordinate along the wall
    width: float
    floor: int


@dataclass
class RoomDoor:
    """A door seen from one room: which side of its interior, and where along it."""

    side: str  # "x0" | "x1" | "z0" | "z1"
    center: float
    width: float


@dataclass
class WallBox:
    lo: np.ndarray  # (3,)
    hi: np.ndarray
    region: int
    floor: int
    kind: str  # "wall" | "floor" | "ceiling"


@dataclass
class Layout:
    rooms: list[Room]
    doors: list[Door]
    boxes: list[WallBox]
    floor_heights: list[float]


def _split_rects(
    rng: np.random.Generator, cfg: HouseConfig, n: int, rect: tuple[float, float, float, float], hallway: bool
) -> list[tuple[tuple[float, float, float, float], bool]]:
    """Split a footprint into about n rooms (a hallway strip first when asked and it fits)."""
    out: list[tuple[tuple[float, float, float, float], bool]] = []
    x0, z0, x1, z1 = rect
    rects = [rect]
    ms = cfg.min_room_side
    if hallway:
        hw = float(rng.uniform(*cfg.hallway_width))
        along_x = (x1 - x0) >= (z1 - z0)
        lo, hi = (z0, z1) if along_x else (x0, x1)
        a0, a1 = (x0, x1) if along_x else (z0, z1)
        length = a1 - a0
        hl = min(length, cfg.hallway_max_length * float(rng.uniform(0.8, 1.0)))
        if 0.0 < length - hl < ms:
            hl = length - ms
        if hi - lo >= 2 * ms + hw and hl >= 0.5 * length:
            c = float(rng.uniform(lo + ms, hi - ms - hw))
            e = a0 + hl
            if along_x:
                out.append(((x0, c, e, c + hw), True))
                rects = [(x0, z0, e, c), (x0, c + hw, e, z1)]
                if e < x1 - 1e-9:
                    rects.append((e, z0, x1, z1))
            else:
                out.append(((c, z0, c + hw, e), True))
                rects = [(x0, z0, c, e), (c + hw, z0, x1, e)]
                if e < z1 - 1e-9:
                    rects.append((x0, e, x1, z1))

    def long_side(r: tuple[float, float, float, float]) -> float:
        return max(r[2] - r[0], r[3] - r[1])

    def split(r: tuple[float, float, float, float]) -> list[tuple[float, float, float, float]]:
        rx0, rz0, rx1, rz1 = r
        along_x = (rx1 - rx0) >= (rz1 - rz0)
        length = (rx1 - rx0) if along_x else (rz1 - rz0)
        a = max(ms, cfg.split_fraction[0] * length)
        b = min(length - ms, cfg.split_fraction[1] * length)
        t = float(rng.uniform(a, b)) if b > a else length / 2
        if along_x:
            return [(rx0, rz0, rx0 + t, rz1), (rx0 + t, rz0, rx1, rz1)]
        return [(rx0, rz0, rx1, rz0 + t), (rx0, rz0 + t, rx1, rz1)]

    target = n - len(out)
    while len(rects) < target:
        cands = [i for i, r in enumerate(rects) if long_side(r) >= 2 * ms]
        if not cands:
            break
        areas = np.array([(rects[i][2] - rects[i][0]) * (rects[i][3] - rects[i][1]) for i in cands]) ** 2
        i = cands[int(rng.choice(len(cands), p=areas / areas.sum()))]
        r = rects.pop(i)
        rects.extend(split(r))
    changed = True
    while changed:  # no room longer than max_room_side
        changed = False
        for i, r in enumerate(rects):
            if long_side(r) > cfg.max_room_side and long_side(r) >= 2 * ms:
                rects.pop(i)
                rects.extend(split(r))
                changed = True
                break
    out.extend((r, False) for r in rects)
    return out


def _assign_types(
    rng: np.random.Generator, cfg: HouseConfig, rects: list, ground: bool, taken: list[str], need_private: bool
) -> list[str]:
    """Room types: the hallway strip is a hallway; ground floors get a living room and a kitchen; a floor
    that must hold the private rooms gets a bedroom and a bathroom (the smallest room); other rooms are
    drawn by weight, rare types (office, gym, ...) at most once per house."""
    names = ["" for _ in rects]
    order = sorted(range(len(rects)), key=lambda i: -_area(rects[i][0]))
    free = [i for i in order if not rects[i][1]]
    for i, (_, hall) in enumerate(rects):
        if hall:
            names[i] = "hallway"
    if ground and free:
        names[free.pop(0)] = "living room"
        if free:
            j = int(rng.integers(0, min(2, len(free))))
            names[free.pop(j)] = "kitchen"
    if need_private and free:
        names[free.pop()] = "bathroom"  # smallest
        if free:
            names[free.pop(int(rng.integers(0, len(free))))] = "bedroom"
    weights = dict(cfg.room_weights if ground else cfg.upper_room_weights)
    for i in free:
        r, _ = rects[i]
        area = _area(r)
        short = min(r[2] - r[0], r[3] - r[1])
        used = taken + names
        w = {k: v for k, v in weights.items() if k in cfg.repeatable_rooms or k not in used}
        if area > cfg.closet_max_area:
            w.pop("closet", None)
        if area < cfg.garage_min_area:
            w.pop("garage", None)
        if short > cfg.hallway_max_short_side:
            w.pop("hallway", None)
        if area < 9.0 and "bathroom" in w:
            w["bathroom"] *= 2.0
        if area > cfg.bathroom_max_area and "bathroom" in w:
            w["bathroom"] *= 0.1
        if used.count("bathroom") >= 2 and "bathroom" in w:
            w["bathroom"] *= 0.3
        if not w:
            w = {"bedroom": 1.0}
        keys = sorted(w)
        p = np.array([w[k] for k in keys], dtype=np.float64)
        names[i] = keys[int(rng.choice(len(keys), p=p / p.sum()))]
    return names


def _area(r: tuple[float, float, float, float]) -> float:
    return (r[2] - r[0]) * (r[3] - r[1])


def _adjacent(cfg: HouseConfig, a: Room, b: Room) -> tuple[str, float, float, float] | None:
    """Shared wall segment (axis, line, lo, hi) long enough for a door, else None."""
    ax0, az0, ax1, az1 = a.cell
    bx0, bz0, bx1, bz1 = b.cell
    need = cfg.door_width[1] + 2 * cfg.door_corner_margin
    for la, lb in ((ax1, bx0), (ax0, bx1)):
        if abs(la - lb) < _EPS:
            lo, hi = max(az0, bz0), min(az1, bz1)
            if hi - lo >= need:
                return ("x", la, lo, hi)
    for la, lb in ((az1, bz0), (az0, bz1)):
        if abs(la - lb) < _EPS:
            lo, hi = max(ax0, bx0), min(ax1, bx1)
            if hi - lo >= need:
                return ("z", la, lo, hi)
    return None


def _connect(rng: np.random.Generator, cfg: HouseConfig, rooms: list[Room], floor: int) -> list[Door] | None:
    """Random spanning tree of doorways (hallways/living rooms preferred) plus a few extra doors."""
    ids = [r.id for r in rooms]
    by_id = {r.id: r for r in rooms}
    edges = []
    for i, a in enumerate(rooms):
        for b in rooms[i + 1 :]:
            seg = _adjacent(cfg, a, b)
            if seg is not None:
                hub = a.name in ("hallway", "living room") or b.name in ("hallway", "living room")
                edges.append((float(rng.random()) - (0.6 if hub else 0.0), a.id, b.id, seg))
    edges.sort(key=lambda e: e[0])
    parent = {i: i for i in ids}

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    doors: list[Door] = []

    def make(a: int, b: int, seg: tuple[str, float, float, float]) -> Door:
        axis, line, lo, hi = seg
        w = float(rng.uniform(*cfg.door_width))
        m = cfg.door_corner_margin + w / 2
        c = float(rng.uniform(lo + m, hi - m))
        return Door(a, b, axis, line, c, w, floor)

    rest = []
    for _, a, b, seg in edges:
        ra, rb = find(a), find(b)
        if ra != rb:
            parent[ra] = rb
            doors.append(make(a, b, seg))
        else:
            rest.append((a, b, seg))
    if len({find(i) for i in ids}) > 1:
        return None
    private = ("bathroom", "closet")
    for a, b, seg in rest:
        if by_id[a].name in private or by_id[b].name in private:
            continue
        if rng.random() < cfg.extra_door_prob:
            doors.append(make(a, b, seg))
    return doors


def _room_doors(room: Room, doors: list[Door]) -> list[RoomDoor]:
    x0, z0, x1, z1 = room.cell
    out = []
    for d in doors:
        if room.id not in (d.a, d.b):
            continue
        if d.axis == "x":
            side = "x0" if abs(d.line - x0) < _EPS else "x1"
        else:
            side = "z0" if abs(d.line - z0) < _EPS else "z1"
        out.append(RoomDoor(side, d.center, d.width))
    return out


def _walls(cfg: HouseConfig, rooms: list[Room], doors: list[Door], floor: int, fy: float) -> list[WallBox]:
    """Wall boxes along every cell edge line, cut at doorways (with a lintel above each door)."""
    t, H = cfg.wall_thickness, cfg.wall_height
    lines: dict[tuple[str, float], list[tuple[float, float, int]]] = {}
    for r in rooms:
        x0, z0, x1, z1 = r.cell
        for axis, line, lo, hi in (("x", x0, z0, z1), ("x", x1, z0, z1), ("z", z0, x0, x1), ("z", z1, x0, x1)):
            key = (axis, round(line, 6))
            lines.setdefault(key, []).append((lo, hi, r.id))
    boxes: list[WallBox] = []
    for (axis, line), ivs in sorted(lines.items()):
        ivs.sort()
        merged: list[list[float]] = []
        owners: list[int] = []
        for lo, hi, rid in ivs:
            if merged and lo <= merged[-1][1] + _EPS:
                merged[-1][1] = max(merged[-1][1], hi)
            else:
                merged.append([lo, hi])
                owners.append(rid)
        cuts = sorted(
            (d.center - d.width / 2, d.center + d.width / 2)
            for d in doors
            if d.axis == axis and abs(d.line - line) < _EPS
        )
        for (lo, hi), rid in zip(merged, owners):
            pieces = []
            start, start_is_end = lo, True
            for c0, c1 in cuts:
                if c0 >= lo - _EPS and c1 <= hi + _EPS:
                    pieces.append((start, c0, start_is_end, False))
                    start, start_is_end = c1, False
            pieces.append((start, hi, start_is_end, True))
            for a, b, ext_a, ext_b in pieces:
                if axis == "x":  # only x-line walls are extended, so corners close without z-fighting
                    a -= t / 2 if ext_a else 0.0
                    b += t / 2 if ext_b else 0.0
                if b - a < 1e-4:
                    continue
                boxes.append(_wall_box(axis, line, a, b, fy, fy + H, t, rid, floor))
            for c0, c1 in cuts:
                if c0 >= lo - _EPS and c1 <= hi + _EPS:
                    boxes.append(_wall_box(axis, line, c0, c1, fy + cfg.door_height, fy + H, t, rid, floor))
    return boxes


def _wall_box(axis: str, line: float, a: float, b: float, y0: float, y1: float, t: float, rid: int,
              floor: int) -> WallBox:  # fmt: skip
    if axis == "x":
        lo, hi = (line - t / 2, y0, a), (line + t / 2, y1, b)
    else:
        lo, hi = (a, y0, line - t / 2), (b, y1, line + t / 2)
    return WallBox(np.array(lo, dtype=np.float64), np.array(hi, dtype=np.float64), rid, floor, "wall")


def make_layout(rng: np.random.Generator, cfg: HouseConfig) -> Layout:
    """Rooms, doors and structural boxes for one house (retries until the adjacency graph connects)."""
    for _ in range(cfg.layout_attempts):
        lay = _try_layout(rng, cfg)
        if lay is not None:
            return lay
    raise RuntimeError("could not build a connected layout; loosen HouseConfig room sizes")


def _try_layout(rng: np.random.Generator, cfg: HouseConfig) -> Layout | None:
    n_total = int(rng.integers(cfg.min_rooms, cfg.max_rooms + 1))
    two = n_total >= cfg.min_rooms_two_floors and rng.random() < cfg.second_floor_prob
    n_upper = int(rng.integers(cfg.min_upper_rooms, max(cfg.min_upper_rooms, n_total // 2) + 1)) if two else 0
    n_ground = n_total - n_upper
    area = n_ground * float(rng.uniform(*cfg.room_area))
    aspect = float(rng.uniform(*cfg.aspect))
    W = float(np.sqrt(area * aspect))
    D = area / W
    W = max(W, cfg.min_room_side)
    D = max(D, cfg.min_room_side)
    footprint = (-W / 2, -D / 2, W / 2, D / 2)
    rooms: list[Room] = []
    doors: list[Door] = []
    boxes: list[WallBox] = []
    heights = []
    for floor, n in enumerate([n_ground, n_upper] if two else [n_ground]):
        fy = floor * cfg.floor_to_floor
        heights.append(fy)
        rect = footprint
        if floor > 0:  # upper storey: part of the ground footprint, sized for its room count
            frac = min(1.0, n * float(np.mean(cfg.room_area)) / (W * D))
            x_len = max(2 * cfg.min_room_side, W * frac) if W * frac < W else W
            rect = (-W / 2, -D / 2, -W / 2 + min(W, x_len), D / 2)
        hall = n >= cfg.hallway_min_rooms and rng.random() < cfg.hallway_prob
        rects = _split_rects(rng, cfg, n, rect, hall)
        private = floor == 1 or not two or n >= cfg.private_ground_min_rooms
        names = _assign_types(rng, cfg, rects, floor == 0, [r.name for r in rooms], private)
        floor_rooms = [
            Room(len(rooms) + i, names[i], floor, tuple(float(v) for v in r), fy, is_hall=h)  # type: ignore[arg-type]
            for i, (r, h) in enumerate(rects)
        ]
        fdoors = _connect(rng, cfg, floor_rooms, floor)
        if fdoors is None:
            return None
        for r in floor_rooms:
            r.doors = _room_doors(r, fdoors)
        rooms.extend(floor_rooms)
        doors.extend(fdoors)
        boxes.extend(_walls(cfg, floor_rooms, fdoors, floor, fy))
        for r in floor_rooms:
            x0, z0, x1, z1 = r.cell
            boxes.append(WallBox(np.array([x0, fy - cfg.slab_thickness, z0]), np.array([x1, fy, z1]),
                                 r.id, floor, "floor"))  # fmt: skip
            yc = fy + cfg.wall_height
            boxes.append(WallBox(np.array([x0, yc, z0]), np.array([x1, yc + cfg.ceiling_thickness, z1]),
                                 r.id, floor, "ceiling"))  # fmt: skip
    if not (cfg.min_rooms <= len(rooms) <= cfg.max_rooms):
        return None
    return Layout(rooms, doors, boxes, heights)
