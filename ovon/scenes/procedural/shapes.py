"""Mesh builders, one per vocabulary shape family, made of boxes, cylinders, cones and spheres.

Why per family: synonyms share a family and therefore a silhouette, unrelated categories differ.

Every builder takes the sampled size (w, h, d) and returns a `PartMesh` in the object's local frame:
centred in x and z, bottom at y = 0, everything inside [-w/2, w/2] x [0, h] x [-d/2, d/2]. The object's
front faces local +z (placement turns it to face into the room). Each face carries a shade multiplier
so parts (legs, doors, shades) read as darker or lighter than the base colour.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

_BOX_FACES = np.array(
    [
        [0, 2, 1],
        [0, 3, 2],  # bottom (y0)
        [4, 5, 6],
        [4, 6, 7],  # top (y1)
        [0, 1, 5],
        [0, 5, 4],  # back (z0)
        [2, 3, 7],
        [2, 7, 6],  # front (z1)
        [0, 4, 7],
        [0, 7, 3],  # left (x0)
        [1, 2, 6],
        [1, 6, 5],  # right (x1)
    ],
    dtype=np.int32,
)[:, ::-1].copy()  # fmt: skip  (reversed: counter-clockwise seen from outside, outward normals)


@dataclass
class PartMesh:
    """Vertices (N, 3) float64, faces (M, 3) int32 and per-face shade (M,) float32."""

    vertices: np.ndarray
    faces: np.ndarray
    shade: np.ndarray


class _Builder:
    """Collects primitive parts; concatenated once at the end (fast and simple)."""

    def __init__(self, segments: int = 12) -> None:
        self.n = segments
        self.v: list[np.ndarray] = []
        self.f: list[np.ndarray] = []
        self.s: list[np.ndarray] = []
        self.count = 0

    def _add(self, v: np.ndarray, f: np.ndarray, shade: float) -> None:
        self.v.append(v)
        self.f.append(f + self.count)
        self.s.append(np.full(len(f), shade, dtype=np.float32))
        self.count += len(v)

    def box(self, x0: float, y0: float, z0: float, x1: float, y1: float, z1: float, shade: float = 1.0) -> None:
        x0, x1 = min(x0, x1), max(x0, x1)
        y0, y1 = min(y0, y1), max(y0, y1)
        z0, z1 = min(z0, z1), max(z0, z1)
        v = np.array(
            [[x0, y0, z0], [x1, y0, z0], [x1, y0, z1], [x0, y0, z1],
             [x0, y1, z0], [x1, y1, z0], [x1, y1, z1], [x0, y1, z1]],
            dtype=np.float64,
        )  # fmt: skip
        self._add(v, _BOX_FACES, shade)

    def frustum(
        self,
        cx: float,
        cz: float,
        rx0: float,
        rz0: float,
        rx1: float,
        rz1: float,
        y0: float,
        y1: float,
        shade: float = 1.0,
        bottom: bool = True,
        top: bool = True,
    ) -> None:
        """Elliptic frustum about a vertical axis (cylinder when radii match, cone when the top is 0)."""
        n = self.n
        a = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False)
        c, s = np.cos(a), np.sin(a)
        ring0 = np.stack([cx + rx0 * c, np.full(n, y0), cz + rz0 * s], axis=1)
        ring1 = np.stack([cx + rx1 * c, np.full(n, y1), cz + rz1 * s], axis=1)
        v = np.concatenate([ring0, ring1, [[cx, y0, cz], [cx, y1, cz]]])
        i = np.arange(n)
        j = (i + 1) % n
        faces = [np.stack([i, n + j, j], 1), np.stack([i, n + i, n + j], 1)]
        if bottom:
            faces.append(np.stack([np.full(n, 2 * n), i, j], 1))
        if top and (rx1 > 0 or rz1 > 0):
            faces.append(np.stack([np.full(n, 2 * n + 1), n + j, n + i], 1))
        self._add(v, np.concatenate(faces).astype(np.int32), shade)

    def cylinder(self, cx: float, cz: float, rx: float, rz: float, y0: float, y1: float, shade: float = 1.0,
                 top: bool = True) -> None:  # fmt: skip
        self.frustum(cx, cz, rx, rz, rx, rz, y0, y1, shade, top=top)

    def zcylinder(self, cx: float, cy: float, r: float, z0: float, z1: float, shade: float = 1.0) -> None:
        """Cylinder along z (fan discs, knobs)."""
        start = self.count
        self.frustum(0.0, 0.0, r, r, r, r, z0, z1, shade)
        v = self.v[-1]
        # swap y <-> z, then move to (cx, cy); swapping two axes flips winding, so flip faces back
        self.v[-1] = np.stack([v[:, 0] + cx, v[:, 2] + cy, v[:, 1]], axis=1)
        self.f[-1] = self.f[-1][:, ::-1].copy()
        assert self.f[-1].min() >= start

    def ellipsoid(self, cx: float, cy: float, cz: float, rx: float, ry: float, rz: float,
                  shade: float = 1.0) -> None:  # fmt: skip
        nu, nv = self.n, max(4, self.n // 2)
        th = np.linspace(0.0, math.pi, nv + 1)[1:-1]  # polar angles, poles added separately
        ph = np.linspace(0.0, 2.0 * math.pi, nu, endpoint=False)
        st, ct = np.sin(th)[:, None], np.cos(th)[:, None]
        ring = np.stack(
            [cx + rx * st * np.cos(ph), cy + ry * ct * np.ones_like(ph), cz + rz * st * np.sin(ph)], axis=-1
        ).reshape(-1, 3)
        v = np.concatenate([ring, [[cx, cy + ry, cz], [cx, cy - ry, cz]]])
        rows = nv - 1
        faces = []
        i = np.arange(nu)
        j = (i + 1) % nu
        for r in range(rows - 1):
            a, b = r * nu, (r + 1) * nu
            faces.append(np.stack([a + i, a + j, b + j], 1))
            faces.append(np.stack([a + i, b + j, b + i], 1))
        top, bot = rows * nu, rows * nu + 1
        faces.append(np.stack([np.full(nu, top), j, i], 1))
        last = (rows - 1) * nu
        faces.append(np.stack([np.full(nu, bot), last + i, last + j], 1))
        self._add(v, np.concatenate(faces).astype(np.int32), shade)

    def result(self) -> PartMesh:
        return PartMesh(
            np.concatenate(self.v).astype(np.float64),
            np.concatenate(self.f).astype(np.int32),
            np.concatenate(self.s).astype(np.float32),
        )


# ---------------------------------------------------------------------------------------------
# family builders: b = builder, w/h/d = size, x in [-hw, hw], z in [-hd, hd], front = +z


def _legs(b: _Builder, hw: float, hd: float, y1: float, t: float, shade: float = 0.7, inset: float = 0.0) -> None:
    for sx in (-1, 1):
        for sz in (-1, 1):
            x = sx * (hw - inset - t / 2)
            z = sz * (hd - inset - t / 2)
            b.box(x - t / 2, 0.0, z - t / 2, x + t / 2, y1, z + t / 2, shade)


def _sofa(b: _Builder, w: float, h: float, d: float, arm: float = 0.12, legs: bool = False) -> None:
    hw, hd = w / 2, d / 2
    y0 = 0.12 * h if legs else 0.0
    if legs:
        _legs(b, hw, hd, y0, min(0.05, 0.1 * w), 0.5, inset=0.02)
    back = 0.25 * d
    aw = arm * w
    seat_top = 0.45 * h
    b.box(-hw + aw, y0, -hd + back, hw - aw, seat_top - 0.08 * h, hd, 0.8)  # seat base
    b.box(-hw + aw, seat_top - 0.08 * h, -hd + back, hw - aw, seat_top, hd, 1.05)  # cushion
    b.box(-hw, y0, -hd, hw, h, -hd + back, 0.9)  # back
    for sx in (-1, 1):
        b.box(sx * hw, y0, -hd + back, sx * (hw - aw), 0.68 * h, hd, 0.85)  # arms


def b_sofa(b: _Builder, w: float, h: float, d: float) -> None:
    _sofa(b, w, h, d, arm=min(0.12, 0.2 / max(w, 0.5)), legs=False)


def b_armchair(b: _Builder, w: float, h: float, d: float) -> None:
    _sofa(b, w, h, d, arm=0.18, legs=True)


def b_chair(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    t = min(0.05, 0.12 * w)
    seat0, seat1 = 0.46 * h, 0.51 * h
    _legs(b, hw, hd, seat0, t)
    b.box(-hw, seat0, -hd, hw, seat1, hd, 1.0)
    for sx in (-1, 1):  # back posts
        b.box(sx * hw, seat1, -hd, sx * (hw - t), h, -hd + t, 0.75)
    b.box(-hw + t, 0.68 * h, -hd, hw - t, h, -hd + t * 0.8, 0.95)  # back rest


def b_stool(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    b.cylinder(0, 0, hw, hd, 0.9 * h, h, 1.0)
    r = min(hw, hd) * 0.12
    for k in range(4):
        a = math.pi / 4 + k * math.pi / 2
        b.cylinder(0.7 * hw * math.cos(a), 0.7 * hd * math.sin(a), r, r, 0.0, 0.9 * h, 0.7, top=False)
    b.frustum(0, 0, 0.75 * hw, 0.75 * hd, 0.75 * hw, 0.75 * hd, 0.35 * h, 0.38 * h, 0.7)  # foot ring


def b_bench(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    b.box(-hw, 0.85 * h, -hd, hw, h, hd, 1.0)
    t = min(0.06, 0.2 * d)
    for sx in (-1, 1):  # two panel legs
        b.box(sx * (hw - 0.05 * w), 0, -hd + 0.05 * d, sx * (hw - 0.05 * w - t), 0.85 * h, hd - 0.05 * d, 0.7)


def b_bed(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    hb = min(0.08, 0.05 * d)
    b.box(-hw, 0, -hd + hb, hw, 0.3 * h, hd, 0.7)  # frame
    b.box(-hw + 0.02, 0.3 * h, -hd + hb, hw - 0.02, 0.5 * h, hd - 0.02, 1.15)  # mattress
    b.box(-hw, 0, -hd, hw, h, -hd + hb, 0.65)  # headboard
    pw = 0.38 * w
    for sx in (-1, 1):
        cx = sx * w * 0.23
        b.box(cx - pw / 2, 0.5 * h, -hd + hb + 0.05, cx + pw / 2, 0.58 * h, -hd + hb + 0.05 + 0.18 * d, 1.25)
    b.box(-hw + 0.01, 0.3 * h, 0.1 * d, hw - 0.01, 0.52 * h, hd - 0.01, 0.95)  # blanket


def b_table(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    t = min(0.06, 0.1 * min(w, d))
    b.box(-hw, 0.94 * h, -hd, hw, h, hd, 1.0)
    _legs(b, hw, hd, 0.94 * h, t, inset=0.03 * min(w, d))
    b.box(-hw + t, 0.86 * h, -hd + t, hw - t, 0.94 * h, hd - t, 0.8)  # apron


def b_round_table(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    b.cylinder(0, 0, hw, hd, 0.94 * h, h, 1.0)
    b.cylinder(0, 0, 0.08 * hw + 0.02, 0.08 * hd + 0.02, 0.05 * h, 0.94 * h, 0.7)
    b.cylinder(0, 0, 0.45 * hw, 0.45 * hd, 0.0, 0.05 * h, 0.6)


def b_desk(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    t = min(0.04, 0.05 * w)
    b.box(-hw, 0.95 * h, -hd, hw, h, hd, 1.0)
    for sx in (-1, 1):
        b.box(sx * hw, 0, -hd, sx * (hw - t), 0.95 * h, hd, 0.8)
    b.box(-hw + t, 0.45 * h, -hd, hw - t, 0.95 * h, -hd + t, 0.7)  # modesty panel
    b.box(hw - t - 0.35 * w, 0.75 * h, -hd + t, hw - t, 0.95 * h, hd - 0.02, 0.85)  # drawer
    b.box(hw - t - 0.25 * w, 0.84 * h, hd - 0.02, hw - t - 0.1 * w, 0.86 * h, hd, 0.5)  # handle


def b_counter(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    b.box(-hw, 0.95 * h, -hd, hw, h, hd, 1.1)  # overhanging top
    b.box(-hw, 0.1 * h, -hd, hw, 0.95 * h, hd - 0.06 * d, 0.85)  # body
    b.box(-hw, 0, -hd, hw, 0.1 * h, hd - 0.12 * d, 0.4)  # toe kick
    n = max(1, int(round(w / 0.6)))
    for k in range(1, n):  # door lines
        x = -hw + k * w / n
        b.box(x - 0.005, 0.12 * h, hd - 0.06 * d, x + 0.005, 0.9 * h, hd - 0.05 * d, 0.4)


def _doors(b: _Builder, w: float, h: float, d: float, n: int, y0: float, y1: float) -> None:
    hw, hd = w / 2, d / 2
    for k in range(1, n):
        x = -hw + k * w / n
        b.box(x - 0.006, y0, hd - 0.01, x + 0.006, y1, hd, 0.45)
    for k in range(n):
        x = -hw + (k + 0.5) * w / n + (0.3 if k % 2 == 0 else -0.3) * w / n
        b.box(x - 0.01, y0 + 0.45 * (y1 - y0), hd - 0.01, x + 0.01, y0 + 0.6 * (y1 - y0), hd, 0.3)


def b_cabinet(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    b.box(-hw, 0, -hd, hw, h, hd - 0.01, 0.9)
    _doors(b, w, h, d, max(1, int(round(w / 0.5))), 0.05 * h, 0.95 * h)


def b_dresser(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    b.box(-hw, 0, -hd, hw, h, hd - 0.01, 0.9)
    rows = max(2, min(5, int(h / 0.22)))
    for k in range(1, rows):
        y = k * h / rows
        b.box(-hw + 0.02, y - 0.005, hd - 0.01, hw - 0.02, y + 0.005, hd, 0.45)
    for k in range(rows):
        y = (k + 0.5) * h / rows
        b.box(-0.1 * w, y - 0.01, hd - 0.01, 0.1 * w, y + 0.01, hd, 0.3)


def b_wardrobe(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    b.box(-hw, 0, -hd, hw, h, hd - 0.01, 0.92)
    _doors(b, w, h, d, 2, 0.03 * h, 0.97 * h)


def b_shelf(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    t = min(0.03, 0.1 * w)
    for sx in (-1, 1):
        b.box(sx * hw, 0, -hd, sx * (hw - t), h, hd, 0.85)
    b.box(-hw + t, 0, -hd, hw - t, h, -hd + 0.015, 0.6)  # back panel
    n = max(2, min(6, int(h / 0.35)))
    for k in range(n + 1):
        y = k * (h - t) / n
        b.box(-hw + t, y, -hd + 0.015, hw - t, y + t, hd, 1.0)


def b_appliance(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    b.box(-hw, 0, -hd, hw, h, hd - 0.02, 1.0)
    b.box(-hw + 0.02, 0.03 * h, hd - 0.02, hw - 0.02, 0.97 * h, hd - 0.01, 0.92)  # door panel
    b.box(hw - 0.08, 0.4 * h, hd - 0.01, hw - 0.05, 0.7 * h, hd, 0.35)  # handle
    b.box(-hw + 0.02, 0.97 * h, hd - 0.03, hw - 0.02, h, hd - 0.02, 0.5)  # control strip


def b_stove(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    b.box(-hw, 0, -hd, hw, 0.97 * h, hd - 0.01, 0.95)
    b.box(-hw + 0.04, 0.15 * h, hd - 0.01, hw - 0.04, 0.7 * h, hd, 0.3)  # oven window
    r = 0.18 * min(w, d)
    for sx in (-1, 1):
        for sz in (-1, 1):
            b.cylinder(sx * w / 4, sz * d / 4, r, r, 0.97 * h, h, 0.25)


def b_toilet(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    tank = 0.3 * d
    b.frustum(0, hd * 0.2, 0.5 * hw, 0.4 * hd, 0.7 * hw, 0.55 * hd, 0, 0.45 * h, 1.0)  # pedestal
    b.cylinder(0, hd * 0.25, hw, 0.72 * hd, 0.45 * h, 0.55 * h, 1.05)  # bowl + seat
    b.box(-hw, 0.4 * h, -hd, hw, h, -hd + tank, 0.95)  # tank
    b.box(-0.8 * hw, 0.55 * h, -hd + tank, 0.8 * hw, 0.6 * h, -hd + tank + 0.05 * d, 0.8)


def b_sink(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    b.cylinder(0, -0.1 * hd, 0.2 * hw, 0.2 * hd, 0, 0.8 * h, 0.95)  # pedestal
    b.box(-hw, 0.8 * h, -hd, hw, 0.97 * h, hd, 1.05)  # basin block
    b.cylinder(0, 0.1 * hd, 0.7 * hw, 0.55 * hd, 0.96 * h, 0.97 * h, 0.6)  # basin inside
    b.cylinder(0, -0.8 * hd, 0.04 * hw, 0.1 * hd, 0.97 * h, h, 0.5)  # faucet


def b_bathtub(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    t = min(0.07, 0.1 * d)
    b.box(-hw, 0, -hd, hw, 0.15 * h, hd, 0.9)
    b.box(-hw, 0, -hd, hw, h, -hd + t, 1.0)
    b.box(-hw, 0, hd - t, hw, h, hd, 1.0)
    for sx in (-1, 1):
        b.box(sx * hw, 0, -hd + t, sx * (hw - t), h, hd - t, 1.0)
    b.box(-hw + t, 0.15 * h, -hd + t, hw - t, 0.2 * h, hd - t, 1.15)  # inner bottom


def b_shower(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    p = 0.04
    b.box(-hw, 0, -hd, hw, 0.06, hd, 0.9)  # tray
    for sx in (-1, 1):
        for sz in (-1, 1):
            b.box(sx * hw, 0.06, sz * hd, sx * (hw - p), h, sz * (hd - p), 0.6)
    g = 0.01
    b.box(-hw + p, 0.06, -hd, hw - p, h, -hd + g, 1.2)
    b.box(-hw + p, 0.06, hd - g, hw - p, h, hd, 1.25)
    for sx in (-1, 1):
        b.box(sx * hw, 0.06, -hd + p, sx * (hw - g), h, hd - p, 1.2)
    b.cylinder(0, -hd + 0.1 * d, 0.08, 0.08, 0.85 * h, 0.87 * h, 0.5)  # shower head


def b_screen(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    b.box(-0.3 * hw, 0, -hd, 0.3 * hw, 0.03 * h, hd, 0.5)  # foot
    b.box(-0.05 * w, 0.03 * h, -0.15 * hd, 0.05 * w, 0.2 * h, 0.15 * hd, 0.5)  # neck
    t = min(0.06, 0.4 * d) / 2
    b.box(-hw, 0.18 * h, -t, hw, h, t, 0.6)  # panel
    b.box(-hw + 0.02 * w, 0.2 * h, t * 0.6, hw - 0.02 * w, h - 0.02 * h, t, 0.25)  # glass


def b_wall_flat(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    f = 0.07 * min(w, h)
    b.box(-hw, 0, -hd, -hw + f, h, hd, 0.6)
    b.box(hw - f, 0, -hd, hw, h, hd, 0.6)
    b.box(-hw + f, 0, -hd, hw - f, f, hd, 0.6)
    b.box(-hw + f, h - f, -hd, hw - f, h, hd, 0.6)
    b.box(-hw + f, f, -hd, hw - f, h - f, hd * 0.3, 1.1)  # picture / mirror surface


def b_wall_box(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    b.box(-hw, 0, -hd, hw, h, hd - 0.1 * d, 0.95)
    b.box(-0.8 * hw, 0.1 * h, hd - 0.1 * d, 0.8 * hw, 0.9 * h, hd, 0.65)


def b_lamp(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    b.cylinder(0, 0, 0.5 * hw, 0.5 * hd, 0, 0.04 * h, 0.5)
    r = max(0.008, 0.05 * min(hw, hd))
    b.cylinder(0, 0, r, r, 0.04 * h, 0.62 * h, 0.45)
    b.frustum(0, 0, hw, hd, 0.65 * hw, 0.65 * hd, 0.6 * h, h, 1.2)  # shade


def b_ceiling_light(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    b.cylinder(0, 0, 0.3 * hw, 0.3 * hd, 0.9 * h, h, 0.7)  # canopy
    r = max(0.006, 0.04 * min(hw, hd))
    b.cylinder(0, 0, r, r, 0.35 * h, 0.9 * h, 0.5)  # rod
    b.frustum(0, 0, hw, hd, 0.4 * hw, 0.4 * hd, 0.0, 0.35 * h, 1.25)  # dome
    b.cylinder(0, 0, 0.9 * hw, 0.9 * hd, 0.0, 0.01 * h, 1.4)  # glowing disc


def b_plant(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    b.frustum(0, 0, 0.4 * hw, 0.4 * hd, 0.55 * hw, 0.55 * hd, 0, 0.3 * h, 0.55)  # pot
    b.cylinder(0, 0, 0.05 * hw, 0.05 * hd, 0.3 * h, 0.45 * h, 0.5)  # stem
    b.ellipsoid(0, 0.65 * h, 0, hw, 0.35 * h, hd, 1.0)  # crown


def b_bin(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    b.frustum(0, 0, 0.85 * hw, 0.85 * hd, hw, hd, 0, h, 1.0, top=False)
    b.cylinder(0, 0, 0.8 * hw, 0.8 * hd, 0.05 * h, 0.06 * h, 0.3)  # dark inside


def b_container(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    b.cylinder(0, 0, hw, hd, 0, 0.7 * h, 1.0)
    b.frustum(0, 0, hw, hd, 0.4 * hw, 0.4 * hd, 0.7 * h, 0.85 * h, 1.0)
    b.cylinder(0, 0, 0.35 * hw, 0.35 * hd, 0.85 * h, h, 0.8)


def b_box(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    b.box(-hw * 0.98, 0, -hd * 0.98, hw * 0.98, 0.85 * h, hd * 0.98, 1.0)
    b.box(-hw, 0.85 * h, -hd, hw, h, hd, 0.85)  # lid


def b_bowl(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    b.frustum(0, 0, 0.55 * hw, 0.55 * hd, hw, hd, 0, h, 1.0, top=False)
    b.cylinder(0, 0, 0.5 * hw, 0.5 * hd, 0.1 * h, 0.12 * h, 0.7)


def b_cushion(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    b.box(-hw, 0.15 * h, -hd, hw, 0.85 * h, hd, 1.0)
    b.box(-0.9 * hw, 0, -0.9 * hd, 0.9 * hw, h, 0.9 * hd, 1.05)


def b_rug(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    b.box(-hw, 0, -hd, hw, 0.6 * h, hd, 0.8)
    b.box(-0.85 * hw, 0.6 * h, -0.85 * hd, 0.85 * hw, h, 0.85 * hd, 1.1)


def b_rod(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    b.cylinder(0, 0, hw, hd, 0, 0.03 * h, 0.6)
    b.cylinder(0, 0, 0.3 * hw, 0.3 * hd, 0.03 * h, h, 1.0)


def b_sphere(b: _Builder, w: float, h: float, d: float) -> None:
    b.ellipsoid(0, h / 2, 0, w / 2, h / 2, d / 2, 1.0)


def b_fan(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    r = min(hw, 0.3 * h)
    b.cylinder(0, 0, 0.6 * hw, 0.6 * hd, 0, 0.04 * h, 0.5)
    b.cylinder(0, 0, 0.04 * hw, 0.04 * hd, 0.04 * h, h - 2 * r, 0.5)
    b.zcylinder(0, h - r, r, -0.3 * hd, 0.0, 1.05)  # cage / blade disc
    b.zcylinder(0, h - r, 0.25 * r, 0.0, 0.4 * hd, 0.6)  # hub
    b.box(-0.12 * r, h - 2 * r, -0.45 * hd, 0.12 * r, h, -0.4 * hd, 0.8)  # blade bar
    b.box(-r, h - r - 0.12 * r, -0.45 * hd, r, h - r + 0.12 * r, -0.4 * hd, 0.8)


def b_instrument(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    b.box(-hw, 0.1 * h, -hd, hw, h, 0.1 * hd, 0.8)  # upright body
    b.box(-hw, 0, -hd, hw, 0.1 * h, -0.6 * hd, 0.5)  # plinth
    b.box(-hw, 0.55 * h, 0.1 * hd, hw, 0.62 * h, hd, 0.75)  # key bed
    b.box(-0.92 * hw, 0.62 * h, 0.2 * hd, 0.92 * hw, 0.65 * h, 0.9 * hd, 1.5)  # white keys
    for sx in (-1, 1):
        b.box(sx * (hw - 0.04), 0, 0.7 * hd, sx * (hw - 0.09), 0.55 * h, 0.9 * hd, 0.6)  # legs


def b_fireplace(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    b.box(-hw, 0.9 * h, -hd, hw, h, hd, 1.05)  # mantel
    b.box(-hw, 0.65 * h, -hd, hw, 0.9 * h, 0.8 * hd, 0.9)  # lintel
    for sx in (-1, 1):
        b.box(sx * hw, 0, -hd, sx * 0.65 * hw, 0.65 * h, 0.8 * hd, 0.9)
    b.box(-0.65 * hw, 0, -hd, 0.65 * hw, 0.65 * h, -0.3 * hd, 0.15)  # dark firebox back
    b.box(-0.65 * hw, 0, -0.3 * hd, 0.65 * hw, 0.03 * h, 0.8 * hd, 0.25)  # hearth floor


def b_radiator(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    n = max(3, int(w / 0.06))
    fw = w / n * 0.6
    for k in range(n):
        x = -hw + (k + 0.5) * w / n
        b.box(x - fw / 2, 0.08 * h, -hd, x + fw / 2, h, hd, 1.0)
    b.box(-hw, 0.15 * h, -0.3 * hd, hw, 0.22 * h, 0.3 * hd, 0.8)
    b.box(-hw, 0.85 * h, -0.3 * hd, hw, 0.92 * h, 0.3 * hd, 0.8)
    for sx in (-1, 1):
        b.box(sx * (hw - 0.02), 0, -0.3 * hd, sx * (hw - 0.06), 0.08 * h, 0.3 * hd, 0.6)


def b_window_frame(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    f = 0.06 * min(w, h)
    b.box(-hw, 0, -hd, -hw + f, h, hd, 1.1)
    b.box(hw - f, 0, -hd, hw, h, hd, 1.1)
    b.box(-hw + f, 0, -hd, hw - f, f, hd, 1.1)
    b.box(-hw + f, h - f, -hd, hw - f, h, hd, 1.1)
    b.box(-f / 3, f, -hd, f / 3, h - f, 0.5 * hd, 1.05)  # mullion
    b.box(-hw + f, h / 2 - f / 3, -hd, hw - f, h / 2 + f / 3, 0.5 * hd, 1.05)
    b.box(-hw + f, f, -hd, hw - f, h - f, -0.5 * hd, 0.55)  # glass (sky, darker)


def b_curtain(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    b.box(-hw, 0.96 * h, -hd, hw, h, -0.6 * hd, 0.5)  # rod / rail
    n = max(2, int(w / 0.15))
    for k in range(n):
        x0 = -hw + k * w / n
        z0 = -hd + (0.45 if k % 2 else 0.0) * d
        b.box(x0, 0, z0, x0 + w / n, 0.96 * h, z0 + 0.55 * d, 0.9 + 0.15 * (k % 2))


def b_towel(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    b.box(-hw, 0.9 * h, -hd, hw, h, hd, 0.6)  # bar
    b.box(-0.9 * hw, 0, -0.1 * hd, 0.9 * hw, 0.95 * h, 0.9 * hd, 1.0)


def b_clothes(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    b.ellipsoid(0, 0.4 * h, 0, hw, 0.4 * h, hd, 1.0)
    b.ellipsoid(0.2 * hw, 0.7 * h, 0.1 * hd, 0.5 * hw, 0.3 * h, 0.5 * hd, 0.85)


def b_book(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    c = 0.1 * min(h, w)
    b.box(-hw, 0, -hd, hw, c, hd, 1.0)  # cover
    b.box(-hw, h - c, -hd, hw, h, hd, 1.0)
    b.box(-hw, c, -hd, -hw + c, h - c, hd, 0.9)  # spine
    b.box(-hw + c, c, -hd + 0.01 * d, hw - 0.01 * w, h - c, hd - 0.01 * d, 1.6)  # pages


def b_device(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    b.box(-hw, 0, -hd, hw, 0.8 * h, hd, 0.9)
    b.box(-0.85 * hw, 0.8 * h, -0.85 * hd, 0.85 * hw, h, 0.85 * hd, 0.4)


def b_cone(b: _Builder, w: float, h: float, d: float) -> None:
    hw, hd = w / 2, d / 2
    b.box(-hw, 0, -hd, hw, 0.05 * h, hd, 0.8)
    b.frustum(0, 0, 0.9 * hw, 0.9 * hd, 0.0, 0.0, 0.05 * h, h, 1.0)


BUILDERS: dict[str, Callable[[_Builder, float, float, float], None]] = {
    "sofa": b_sofa,
    "armchair": b_armchair,
    "chair": b_chair,
    "stool": b_stool,
    "bench": b_bench,
    "bed": b_bed,
    "table": b_table,
    "round_table": b_round_table,
    "desk": b_desk,
    "counter": b_counter,
    "cabinet": b_cabinet,
    "dresser": b_dresser,
    "wardrobe": b_wardrobe,
    "shelf": b_shelf,
    "appliance": b_appliance,
    "stove": b_stove,
    "toilet": b_toilet,
    "sink": b_sink,
    "bathtub": b_bathtub,
    "shower": b_shower,
    "screen": b_screen,
    "wall_flat": b_wall_flat,
    "wall_box": b_wall_box,
    "lamp": b_lamp,
    "ceiling_light": b_ceiling_light,
    "plant": b_plant,
    "bin": b_bin,
    "container": b_container,
    "box": b_box,
    "bowl": b_bowl,
    "cushion": b_cushion,
    "rug": b_rug,
    "rod": b_rod,
    "sphere": b_sphere,
    "fan": b_fan,
    "instrument": b_instrument,
    "fireplace": b_fireplace,
    "radiator": b_radiator,
    "window_frame": b_window_frame,
    "curtain": b_curtain,
    "towel": b_towel,
    "clothes": b_clothes,
    "book": b_book,
    "device": b_device,
    "cone": b_cone,
}


def build_shape(family: str, size: tuple[float, float, float], segments: int = 12) -> PartMesh:
    """Local-frame mesh of a family at size (w, h, d); clipped into the size box as a safety net."""
    try:
        fn = BUILDERS[family]
    except KeyError:
        raise KeyError(f"no shape builder for family {family!r}; known: {sorted(BUILDERS)}") from None
    w, h, d = (float(x) for x in size)
    b = _Builder(segments)
    fn(b, w, h, d)
    pm = b.result()
    lo = np.array([-w / 2, 0.0, -d / 2])
    pm.vertices = np.clip(pm.vertices, lo, -lo + np.array([0.0, h, 0.0]))
    return pm


def box_mesh(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World-space axis-aligned box (walls, slabs)."""
    b = _Builder()
    b.box(lo[0], lo[1], lo[2], hi[0], hi[1], hi[2])
    pm = b.result()
    return pm.vertices, pm.faces


def surface_top(family: str, size: tuple[float, float, float]) -> tuple[float, tuple[float, float, float, float]]:
    """Height and local rectangle (xmin, zmin, xmax, zmax) where small objects may rest on this shape.

    Why: a sofa's usable surface is its seat between the arms, a bed's the mattress below the pillows,
    a round table's top is an ellipse (use the inscribed rectangle); most other tops are flat at h.
    """
    w, h, d = size
    hw, hd = w / 2, d / 2
    if family == "sofa":
        aw = min(0.12, 0.2 / max(w, 0.5)) * w
        return 0.45 * h, (-hw + aw, -hd + 0.25 * d, hw - aw, hd)
    if family == "armchair":
        return 0.45 * h, (-hw + 0.18 * w, -hd + 0.25 * d, hw - 0.18 * w, hd)
    if family == "bed":
        return 0.52 * h, (-hw + 0.02, 0.1 * d, hw - 0.02, hd - 0.02)
    if family in ("round_table", "stool"):
        return h, (-0.7 * hw, -0.7 * hd, 0.7 * hw, 0.7 * hd)
    if family == "bench":
        return h, (-hw, -hd, hw, hd)
    if family == "bathtub":
        return h, (-hw, -hd, hw, -hd + min(0.07, 0.1 * d))
    if family == "sink":
        return h, (-hw, -hd, hw, -0.85 * hd)
    return h, (-hw, -hd, hw, hd)
