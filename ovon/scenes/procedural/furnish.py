"""Object placement: floor furniture, small objects on surfaces, wall and ceiling objects.

Why the checks: the simulator derives navigability from the mesh, so furniture must never close a
doorway or cut a room in two. Each room keeps 5 cm occupancy grids (footprints grown by the agent radius,
and by a larger margin); a placement is rejected when it touches a doorway's clear zone, overlaps another
object (footprint polygons plus height ranges), or splits a grid's free cells into several components.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ..vocabulary import Category, Vocabulary
from .config import HouseConfig
from .layout import Layout, Room
from .shapes import surface_top

# families that stand with their back against a wall; families that usually stand free
_WALL_FAMILIES = {
    "bed", "sofa", "wardrobe", "dresser", "cabinet", "shelf", "counter", "appliance", "stove", "toilet",
    "sink", "bathtub", "shower", "desk", "instrument", "fireplace", "radiator", "screen", "curtain",
    "towel", "window_frame", "wall_flat", "wall_box",
}  # fmt: skip
_FREE_FAMILIES = {"table", "round_table", "chair", "stool", "rug", "sphere", "cone", "clothes", "box", "fan"}
# at most one per room
_SINGLE_FAMILIES = {"bed", "toilet", "bathtub", "shower", "stove", "fireplace", "instrument", "sofa", "rug"}
_SIDE_YAW = {"z0": 0.0, "z1": math.pi, "x0": math.pi / 2, "x1": -math.pi / 2}


@dataclass
class Placed:
    """One placed object: bottom-centre position, yaw about +y, size (w, h, d) along local x, y, z."""

    category: Category
    raw_label: str
    size: tuple[float, float, float]
    pos: np.ndarray  # (3,) bottom centre, world
    yaw: float
    room: Room
    placement: str
    color: np.ndarray  # (3,) float base RGB
    support: int | None = None  # index (in the house list) of the object it rests on

    def __post_init__(self) -> None:
        self._fp = _corners(self.pos[0], self.pos[2], self.size[0] / 2, self.size[2] / 2, self.yaw)
        self._bb = (*self._fp.min(axis=0), *self._fp.max(axis=0))

    @property
    def y0(self) -> float:
        return float(self.pos[1])

    @property
    def y1(self) -> float:
        return float(self.pos[1] + self.size[1])

    def corners(self) -> np.ndarray:
        return self._fp


def rotation(yaw: float) -> np.ndarray:
    """Local -> world rotation about +y; columns are the box axes (local +z maps to (sin, 0, cos))."""
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _corners(px: float, pz: float, hw: float, hd: float, yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    lx = np.array([-hw, hw, hw, -hw])
    lz = np.array([-hd, -hd, hd, hd])
    return np.stack([px + c * lx + s * lz, pz - s * lx + c * lz], axis=1)


def polys_overlap(p: np.ndarray, q: np.ndarray, tol: float) -> bool:
    """Separating-axis test for two rectangles given as (4, 2) corner loops; touching or overlapping by
    <= tol is fine. Plain Python: numpy call overhead dominates for 4-point polygons."""
    P = p.tolist() if isinstance(p, np.ndarray) else p
    Q = q.tolist() if isinstance(q, np.ndarray) else q
    for poly in (P, Q):
        for k in (0, 1):  # a rectangle has two edge directions
            ex = poly[k + 1][0] - poly[k][0]
            ez = poly[k + 1][1] - poly[k][1]
            n = math.hypot(ex, ez) or 1e-12
            ax, az = -ez / n, ex / n
            pp = [x * ax + z * az for x, z in P]
            qq = [x * ax + z * az for x, z in Q]
            if max(pp) - min(qq) <= tol or max(qq) - min(pp) <= tol:
                return False
    return True


def _point_segment_dist(pts: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distances (P, S) from points (P, 2) to segments a->b (S, 2)."""
    ab = b - a
    ap = pts[:, None, :] - a[None]
    t = np.clip((ap * ab[None]).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-12)[None], 0.0, 1.0)
    return np.linalg.norm(ap - t[..., None] * ab[None], axis=-1)


def poly_distance(p: np.ndarray, q: np.ndarray) -> float:
    """Distance between two non-overlapping convex polygons (0 when they touch)."""
    d1 = _point_segment_dist(p, q, np.roll(q, -1, axis=0)).min()
    d2 = _point_segment_dist(q, p, np.roll(p, -1, axis=0)).min()
    return float(min(d1, d2))


class _RoomState:
    """Occupancy grid and placed objects of one room."""

    def __init__(self, room: Room, cfg: HouseConfig) -> None:
        self.room = room
        self.cfg = cfg
        self.inner = room.interior(cfg.wall_thickness)
        x0, z0, x1, z1 = self.inner
        r = cfg.grid_res
        self.nx = max(1, int(math.ceil((x1 - x0) / r)))
        self.nz = max(1, int(math.ceil((z1 - z0) / r)))
        self.X = x0 + (np.arange(self.nx) + 0.5) * r
        self.Z = z0 + (np.arange(self.nz) + 0.5) * r
        XX, ZZ = np.meshgrid(self.X, self.Z)  # rows = z, cols = x
        self.XX, self.ZZ = XX, ZZ
        # one occupancy grid per clearance radius: a pocket can open at one radius and not another
        self.blocked = [(XX < x0 + m) | (XX > x1 - m) | (ZZ < z0 + m) | (ZZ > z1 - m) for m in cfg.nav_radii]
        self.door_zones = [self._door_zone(d.side, d.center, d.width) for d in room.doors]
        self.objects: list[int] = []  # indices into the house list

    def _door_zone(self, side: str, c: float, w: float) -> np.ndarray:
        x0, z0, x1, z1 = self.inner
        dep, m = self.cfg.door_clear_depth, self.cfg.door_clear_margin
        a, b = c - w / 2 - m, c + w / 2 + m
        if side == "x0":
            r = (x0 - 1.0, a, x0 + dep, b)
        elif side == "x1":
            r = (x1 - dep, a, x1 + 1.0, b)
        elif side == "z0":
            r = (a, z0 - 1.0, b, z0 + dep)
        else:
            r = (a, z1 - dep, b, z1 + 1.0)
        return np.array([[r[0], r[1]], [r[2], r[1]], [r[2], r[3]], [r[0], r[3]]])

    def inside(self, corners: np.ndarray, eps: float = 1e-6) -> bool:
        x0, z0, x1, z1 = self.inner
        return bool(
            np.all(corners[:, 0] >= x0 - eps) and np.all(corners[:, 0] <= x1 + eps)
            and np.all(corners[:, 1] >= z0 - eps) and np.all(corners[:, 1] <= z1 + eps)
        )  # fmt: skip

    def footprint_mask(self, p: Placed, radius: float) -> np.ndarray:
        """Cells whose centre is within `radius` of the footprint (the agent's disc would touch it)."""
        c, s = math.cos(p.yaw), math.sin(p.yaw)
        dx = self.XX - p.pos[0]
        dz = self.ZZ - p.pos[2]
        ex = np.maximum(np.abs(c * dx - s * dz) - p.size[0] / 2, 0.0)
        ez = np.maximum(np.abs(s * dx + c * dz) - p.size[2] / 2, 0.0)
        return ex * ex + ez * ez <= radius * radius

    def wall_gaps(self, corners: np.ndarray) -> np.ndarray:
        """Gaps between a footprint and the four interior wall faces."""
        x0, z0, x1, z1 = self.inner
        return np.array(
            [corners[:, 0].min() - x0, x1 - corners[:, 0].max(), corners[:, 1].min() - z0, z1 - corners[:, 1].max()]
        )

    def obstructs(self, p: Placed) -> bool:
        """Does the object stand in the agent's body volume (above a climbable step, below its head)?"""
        fy = self.room.floor_y
        return p.y1 > fy + self.cfg.max_climb and p.y0 < fy + self.cfg.agent_height + 0.05


def _pick(rng: np.random.Generator, items: list[Category], weights: np.ndarray) -> Category | None:
    if not items or weights.sum() <= 0:
        return None
    return items[int(rng.choice(len(items), p=weights / weights.sum()))]


def _size(rng: np.random.Generator, cat: Category) -> tuple[float, float, float]:
    lo = np.array(cat.size_min)
    hi = np.array(cat.size_max)
    v = lo + (hi - lo) * rng.random(3)
    return (float(v[0]), float(v[1]), float(v[2]))


def _label(rng: np.random.Generator, cfg: HouseConfig, cat: Category) -> str:
    others = [r for r in cat.raw_labels if r != cat.name]
    if not others or rng.random() < cfg.canonical_label_prob:
        return cat.name
    return others[int(rng.integers(len(others)))]


def _color(rng: np.random.Generator, cfg: HouseConfig, cat: Category) -> np.ndarray:
    base = np.array(cat.colors[int(rng.integers(len(cat.colors)))], dtype=np.float64)
    j = cfg.color_jitter
    return np.clip(base * rng.uniform(1 - j, 1 + j) * rng.uniform(1 - j / 2, 1 + j / 2, 3), 0, 255)


class Furnisher:
    """Places objects room by room; `placed` is the house-wide list (supports refer to its indices)."""

    def __init__(self, vocab: Vocabulary, cfg: HouseConfig) -> None:
        self.vocab = vocab
        self.cfg = cfg
        self.placed: list[Placed] = []
        self._by_room: dict[tuple[str, str], tuple[list[Category], np.ndarray]] = {}

    def _cands(self, room: str, placement: str) -> tuple[list[Category], np.ndarray]:
        key = (room, placement)
        if key not in self._by_room:
            cats = sorted(self.vocab.for_room(room, placement), key=lambda c: c.name)  # type: ignore[arg-type]
            w = np.array([c.rooms[room] * c.frequency for c in cats], dtype=np.float64)
            self._by_room[key] = (cats, w)
        return self._by_room[key]

    def full(self) -> bool:
        return len(self.placed) >= self.cfg.max_objects

    # ---------------------------------------------------------------------------------------------
    def _collides(self, st: _RoomState, p: Placed, ignore: int | None = None) -> bool:
        tol = self.cfg.overlap_tol
        cp = p.corners()
        a = p._bb
        for i in st.objects:
            if i == ignore:
                continue
            q = self.placed[i]
            if min(p.y1, q.y1) - max(p.y0, q.y0) <= tol:
                continue
            b = q._bb
            if a[0] >= b[2] - tol or b[0] >= a[2] - tol or a[1] >= b[3] - tol or b[1] >= a[3] - tol:
                continue
            if polys_overlap(cp, q.corners(), tol):
                return True
        return False

    def _gaps_ok(self, st: _RoomState, p: Placed) -> bool:
        """No slit narrower than `min_gap` between obstacles: such slits make dead-end pockets whose
        connectivity flips with the exact agent radius and grid alignment. Touching (<= snap) is fine."""
        lo, hi = self.cfg.snap_gap, self.cfg.min_gap
        g = st.wall_gaps(p.corners())
        if np.any((g > lo) & (g < hi)):
            return False
        a = p._bb
        for i in st.objects:
            q = self.placed[i]
            if not st.obstructs(q):
                continue
            b = q._bb
            if a[0] >= b[2] + hi or b[0] >= a[2] + hi or a[1] >= b[3] + hi or b[1] >= a[3] + hi:
                continue
            d = poly_distance(p.corners(), q.corners())
            if lo < d < hi:
                return False
        return True

    def _try_accept(self, st: _RoomState, p: Placed, ignore: int | None = None) -> bool:
        """Accept p if it fits: inside the room, no overlap, doorways clear, room stays connected."""
        cp = p.corners()
        if not st.inside(cp):
            return False
        if p.y1 > st.room.floor_y + self.cfg.wall_height + 1e-6:
            return False
        if self._collides(st, p, ignore):
            return False
        obstructs = st.obstructs(p) and p.support is None  # on a support: inside an obstacle already
        new_blocked = None
        if obstructs:
            for dz in st.door_zones:
                if polys_overlap(cp, dz, 0.0):
                    return False
            if not self._gaps_ok(st, p):
                return False
            new_blocked = []
            for radius, blocked in zip(self.cfg.nav_radii, st.blocked):
                nb = blocked | st.footprint_mask(p, radius)
                free = ~nb
                if not free.any():
                    return False
                if ndimage.label(free)[1] != 1:
                    return False
                new_blocked.append(nb)
        self.placed.append(p)
        st.objects.append(len(self.placed) - 1)
        if new_blocked is not None:
            st.blocked = new_blocked
        return True

    # ---------------------------------------------------------------------------------------------
    def furnish(self, rng: np.random.Generator, layout: Layout) -> list[Placed]:
        for room in layout.rooms:
            if self.full():
                break
            rrng = np.random.default_rng(rng.integers(2**63))
            st = _RoomState(room, self.cfg)
            self._floor(rrng, st)
            self._wall(rrng, st)
            self._surfaces(rrng, st)
            self._ceiling(rrng, st)
        return self.placed

    def _floor(self, rng: np.random.Generator, st: _RoomState) -> None:
        cfg = self.cfg
        cats, w = self._cands(st.room.name, "floor")
        if not cats:
            return
        x0, z0, x1, z1 = st.inner
        area = (x1 - x0) * (z1 - z0)
        target = int(np.clip(round(area * cfg.floor_density * rng.uniform(0.7, 1.3)), 0, cfg.max_floor_per_room))
        counts = dict.fromkeys(range(len(cats)), 0)
        placed = 0
        tries = 0
        while placed < target and tries < 4 * target and not self.full():
            tries += 1
            ww = w.copy() ** (2.0 if placed == 0 else 1.0)
            for k, n in counts.items():
                if n >= cfg.max_same_category or (n and cats[k].family in _SINGLE_FAMILIES):
                    ww[k] = 0.0
                elif n:
                    ww[k] *= 0.4**n
            cat = _pick(rng, cats, ww)
            if cat is None:
                return
            k = cats.index(cat)
            if self._place_floor(rng, st, cat):
                counts[k] += 1
                placed += 1
            else:
                counts[k] += 1  # do not insist on a category that does not fit

    def _place_floor(self, rng: np.random.Generator, st: _RoomState, cat: Category) -> bool:
        cfg = self.cfg
        x0, z0, x1, z1 = st.inner
        if cat.family in _WALL_FAMILIES:
            p_wall = 0.95
        elif cat.family in _FREE_FAMILIES:
            p_wall = 0.25
        else:
            p_wall = cfg.against_wall_prob
        for _ in range(cfg.placement_attempts):
            size = _size(rng, cat)
            w, h, d = size
            if rng.random() < p_wall:
                side = ("x0", "x1", "z0", "z1")[int(rng.integers(4))]
                yaw = _SIDE_YAW[side]
                lo, hi = (z0, z1) if side[0] == "x" else (x0, x1)
                if hi - lo < w:
                    continue
                t = float(rng.uniform(lo + w / 2, hi - w / 2))
                if rng.random() < cfg.corner_snap_prob:  # tuck into a corner: no slit to the side wall
                    t = lo + w / 2 + 0.002 if rng.random() < 0.5 else hi - w / 2 - 0.002
                gap = 0.002
                if side == "x0":
                    x, z = x0 + d / 2 + gap, t
                elif side == "x1":
                    x, z = x1 - d / 2 - gap, t
                elif side == "z0":
                    x, z = t, z0 + d / 2 + gap
                else:
                    x, z = t, z1 - d / 2 - gap
            else:
                if rng.random() < cfg.free_yaw_prob:
                    yaw = float(rng.uniform(-math.pi, math.pi))
                else:
                    yaw = float(int(rng.integers(4)) * math.pi / 2)
                c, s = abs(math.cos(yaw)), abs(math.sin(yaw))
                ex, ez = (c * w + s * d) / 2, (s * w + c * d) / 2  # half extents of the turned footprint
                if 2 * ex >= x1 - x0 or 2 * ez >= z1 - z0:
                    continue
                x = float(rng.uniform(x0 + ex, x1 - ex))
                z = float(rng.uniform(z0 + ez, z1 - ez))
            p = Placed(cat, _label(rng, cfg, cat), size, np.array([x, st.room.floor_y, z]), yaw, st.room,
                       "floor", _color(rng, cfg, cat))  # fmt: skip
            if self._try_accept(st, p):
                return True
        return False

    def _wall(self, rng: np.random.Generator, st: _RoomState) -> None:
        cfg = self.cfg
        cats, w = self._cands(st.room.name, "wall")
        if not cats:
            return
        n = int(rng.integers(cfg.wall_objects[0], cfg.wall_objects[1] + 1))
        x0, z0, x1, z1 = st.inner
        fy, H = st.room.floor_y, cfg.wall_height
        for _ in range(n):
            if self.full():
                return
            cat = _pick(rng, cats, w.copy())
            if cat is None:
                return
            for _ in range(cfg.placement_attempts):
                size = _size(rng, cat)
                sw, sh, sd = size
                if sh > H - 0.1:
                    continue
                side = ("x0", "x1", "z0", "z1")[int(rng.integers(4))]
                lo, hi = (z0, z1) if side[0] == "x" else (x0, x1)
                m = cfg.wall_corner_margin
                if hi - lo < sw + 2 * m:
                    continue
                t = float(rng.uniform(lo + m + sw / 2, hi - m - sw / 2))
                bad = any(
                    d.side == side and abs(t - d.center) < (d.width + sw) / 2 + cfg.door_clear_margin
                    for d in st.room.doors
                )
                if bad:
                    continue
                if cat.family in ("radiator", "fireplace"):
                    y = 0.1 if cat.family == "radiator" else 0.0
                else:
                    a = max(cfg.wall_center_height[0], sh / 2 + 0.05)
                    b = min(cfg.wall_center_height[1], H - sh / 2 - 0.05)
                    yc = float(rng.uniform(a, b)) if b > a else (H / 2 if sh > H / 2 else (a + b) / 2)
                    y = max(0.0, yc - sh / 2)
                if side == "x0":
                    x, z = x0 + sd / 2, t
                elif side == "x1":
                    x, z = x1 - sd / 2, t
                elif side == "z0":
                    x, z = t, z0 + sd / 2
                else:
                    x, z = t, z1 - sd / 2
                p = Placed(cat, _label(rng, cfg, cat), size, np.array([x, fy + y, z]), _SIDE_YAW[side],
                           st.room, "wall", _color(rng, cfg, cat))  # fmt: skip
                if self._try_accept(st, p):
                    break

    def _surfaces(self, rng: np.random.Generator, st: _RoomState) -> None:
        cfg = self.cfg
        cats, w = self._cands(st.room.name, "surface")
        if not cats:
            return
        ceiling = st.room.floor_y + cfg.wall_height
        for si in list(st.objects):
            sup = self.placed[si]
            if not sup.category.is_surface or rng.random() > cfg.surface_prob:
                continue
            ty, (rx0, rz0, rx1, rz1) = surface_top(sup.category.family, sup.size)
            top_area = (rx1 - rx0) * (rz1 - rz0)
            n = int(min(cfg.max_per_surface, rng.poisson(max(0.6, top_area * cfg.surface_fill))))
            for _ in range(n):
                if self.full():
                    return
                cat = _pick(rng, cats, w.copy())
                if cat is None:
                    return
                for _ in range(cfg.placement_attempts // 2):
                    size = _size(rng, cat)
                    sw, sh, sd = size
                    turn = int(rng.integers(4))
                    ew, ed = (sd, sw) if turn % 2 else (sw, sd)
                    if ew > rx1 - rx0 or ed > rz1 - rz0:
                        continue
                    y = sup.pos[1] + ty
                    if y + sh > ceiling - 0.05:
                        continue
                    lx = float(rng.uniform(rx0 + ew / 2, rx1 - ew / 2))
                    lz = float(rng.uniform(rz0 + ed / 2, rz1 - ed / 2))
                    R = rotation(sup.yaw)
                    wp = sup.pos + R @ np.array([lx, 0.0, lz])
                    p = Placed(cat, _label(rng, cfg, cat), size, np.array([wp[0], y, wp[2]]),
                               sup.yaw + turn * math.pi / 2, st.room, "surface", _color(rng, cfg, cat),
                               support=si)  # fmt: skip
                    if self._try_accept(st, p, ignore=si):
                        break

    def _ceiling(self, rng: np.random.Generator, st: _RoomState) -> None:
        cfg = self.cfg
        if self.full() or rng.random() > cfg.ceiling_prob:
            return
        cats, w = self._cands(st.room.name, "ceiling")
        if not cats:
            return
        x0, z0, x1, z1 = st.inner
        top = st.room.floor_y + cfg.wall_height
        max_h = cfg.wall_height - cfg.agent_height - cfg.head_margin
        n = 2 if (x1 - x0) * (z1 - z0) > 20.0 else 1
        for k in range(n):
            cat = _pick(rng, cats, w.copy())
            if cat is None:
                return
            for _ in range(cfg.placement_attempts // 2):
                if cat.size_min[1] > max_h:
                    break
                size = _size(rng, cat)
                if size[1] > max_h:  # resample the height within [size_min, max_h]
                    size = (size[0], float(rng.uniform(cat.size_min[1], max_h)), size[2])
                if n == 1:
                    cx, cz = (x0 + x1) / 2, (z0 + z1) / 2
                elif (x1 - x0) >= (z1 - z0):
                    cx, cz = x0 + (x1 - x0) * (0.25 + 0.5 * k), (z0 + z1) / 2
                else:
                    cx, cz = (x0 + x1) / 2, z0 + (z1 - z0) * (0.25 + 0.5 * k)
                cx += float(rng.uniform(-0.3, 0.3))
                cz += float(rng.uniform(-0.3, 0.3))
                yaw = float(int(rng.integers(2)) * math.pi / 2)
                p = Placed(cat, _label(rng, cfg, cat), size, np.array([cx, top - size[1], cz]), yaw, st.room,
                           "ceiling", _color(rng, cfg, cat))  # fmt: skip
                if self._try_accept(st, p):
                    break
