"""Procedural houses: determinism, layout sanity, geometry per family, physical plausibility, reachability."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage

from ovon.scenes.procedural import HouseConfig, generate_house
from ovon.scenes.procedural.furnish import polys_overlap
from ovon.scenes.procedural.shapes import build_shape, surface_top
from ovon.scenes.vocabulary import FAMILIES, ROOM_TYPES, Vocabulary, load_vocabulary, parse_vocabulary

ALL_ROOMS = {r: 0.3 for r in ROOM_TYPES}

# A small self-contained vocabulary covering every family (the shipped one may not exist yet).
# fmt: off
_FIXTURE = [
    # name, family, size_min, size_max, placement, rooms, surface, raw labels
    ("sofa", "sofa", (1.6, 0.8, 0.8), (2.4, 0.95, 1.0), "floor", {"living room": 3}, True, ["couch"]),
    ("armchair", "armchair", (0.7, 0.8, 0.7), (0.95, 1.0, 0.9), "floor", {"living room": 2, "office": 0.5},
     False, []),
    ("chair", "chair", (0.42, 0.85, 0.45), (0.5, 1.0, 0.55), "floor",
     {"dining room": 3, "kitchen": 1, "office": 2, "bedroom": 0.5}, False, ["dining chair"]),
    ("stool", "stool", (0.3, 0.45, 0.3), (0.4, 0.75, 0.4), "floor", {"kitchen": 1.5, "garage": 0.5}, False, []),
    ("bench", "bench", (1.0, 0.42, 0.35), (1.5, 0.5, 0.45), "floor", {"entryway": 2, "hallway": 1}, True, []),
    ("bed", "bed", (1.4, 0.9, 1.95), (1.8, 1.1, 2.1), "floor", {"bedroom": 5}, True, ["double bed"]),
    ("table", "table", (1.2, 0.72, 0.8), (1.8, 0.78, 1.0), "floor", {"dining room": 4, "kitchen": 1.5}, True,
     ["dining table"]),
    ("coffee table", "round_table", (0.6, 0.4, 0.6), (0.9, 0.48, 0.9), "floor", {"living room": 2}, True, []),
    ("desk", "desk", (1.0, 0.72, 0.55), (1.5, 0.78, 0.75), "floor", {"office": 4, "bedroom": 0.8}, True, []),
    ("kitchen counter", "counter", (1.2, 0.88, 0.6), (2.4, 0.92, 0.65), "floor", {"kitchen": 5}, True,
     ["counter"]),
    ("cabinet", "cabinet", (0.6, 0.8, 0.4), (1.2, 1.0, 0.5), "floor", {"kitchen": 1, "laundry room": 2,
     "garage": 1, "bathroom": 1}, True, ["cupboard"]),
    ("dresser", "dresser", (0.8, 0.8, 0.45), (1.3, 1.0, 0.55), "floor", {"bedroom": 2.5}, True,
     ["chest of drawers"]),
    ("wardrobe", "wardrobe", (1.0, 1.9, 0.55), (1.6, 2.2, 0.65), "floor", {"bedroom": 2, "closet": 3}, False, []),
    ("bookshelf", "shelf", (0.6, 1.2, 0.3), (1.0, 2.0, 0.4), "floor", {"office": 2, "living room": 1}, True,
     ["bookcase"]),
    ("refrigerator", "appliance", (0.6, 1.7, 0.65), (0.9, 1.9, 0.75), "floor", {"kitchen": 4}, False, ["fridge"]),
    ("washing machine", "appliance", (0.6, 0.85, 0.6), (0.6, 0.9, 0.65), "floor", {"laundry room": 4}, True,
     ["washer"]),
    ("stove", "stove", (0.6, 0.88, 0.6), (0.76, 0.92, 0.65), "floor", {"kitchen": 4}, False, ["oven"]),
    ("toilet", "toilet", (0.38, 0.75, 0.65), (0.42, 0.82, 0.72), "floor", {"bathroom": 5}, False, []),
    ("sink", "sink", (0.5, 0.82, 0.4), (0.65, 0.9, 0.5), "floor", {"bathroom": 4}, True, ["washbasin"]),
    ("bathtub", "bathtub", (1.5, 0.5, 0.7), (1.7, 0.6, 0.8), "floor", {"bathroom": 2}, False, ["tub"]),
    ("shower", "shower", (0.8, 2.0, 0.8), (1.0, 2.1, 1.0), "floor", {"bathroom": 1.5}, False, []),
    ("tv", "screen", (0.9, 0.6, 0.2), (1.4, 0.9, 0.3), "floor", {"living room": 2, "bedroom": 0.5}, False,
     ["television"]),
    ("picture", "wall_flat", (0.4, 0.3, 0.02), (1.0, 0.8, 0.04), "wall", ALL_ROOMS, False, ["painting"]),
    ("mirror", "wall_flat", (0.4, 0.5, 0.02), (0.7, 0.9, 0.03), "wall", {"bathroom": 3, "bedroom": 1}, False, []),
    ("wall cabinet", "wall_box", (0.5, 0.5, 0.3), (0.9, 0.7, 0.35), "wall", {"kitchen": 2, "laundry room": 1},
     True, []),
    ("floor lamp", "lamp", (0.3, 1.4, 0.3), (0.45, 1.7, 0.45), "floor", {"living room": 1.5, "bedroom": 0.8},
     False, []),
    ("table lamp", "lamp", (0.2, 0.35, 0.2), (0.35, 0.55, 0.35), "surface", {"living room": 1, "bedroom": 2,
     "office": 1.5}, False, ["lamp"]),
    ("ceiling lamp", "ceiling_light", (0.3, 0.15, 0.3), (0.6, 0.5, 0.6), "ceiling", ALL_ROOMS, False,
     ["ceiling light"]),
    ("potted plant", "plant", (0.3, 0.5, 0.3), (0.6, 1.3, 0.6), "floor", {"living room": 1.5, "office": 1,
     "entryway": 1, "hallway": 0.8}, False, ["plant"]),
    ("trash can", "bin", (0.25, 0.3, 0.25), (0.4, 0.7, 0.4), "floor", {"kitchen": 1.5, "office": 1,
     "bathroom": 1, "garage": 1}, False, ["garbage bin"]),
    ("vase", "container", (0.1, 0.2, 0.1), (0.2, 0.45, 0.2), "surface", {"living room": 2, "dining room": 2,
     "entryway": 1}, False, []),
    ("bottle", "container", (0.06, 0.2, 0.06), (0.09, 0.32, 0.09), "surface", {"kitchen": 2, "bathroom": 1.5},
     False, []),
    ("storage box", "box", (0.3, 0.2, 0.3), (0.5, 0.4, 0.4), "floor", {"garage": 2, "closet": 2,
     "playroom": 1}, True, ["box"]),
    ("bowl", "bowl", (0.12, 0.05, 0.12), (0.25, 0.1, 0.25), "surface", {"kitchen": 2, "dining room": 2},
     False, []),
    ("pillow", "cushion", (0.35, 0.1, 0.35), (0.5, 0.18, 0.5), "surface", {"living room": 2, "bedroom": 2},
     False, ["cushion"]),
    ("rug", "rug", (1.2, 0.01, 0.8), (2.4, 0.02, 1.7), "floor", {"living room": 1.5, "bedroom": 1,
     "dining room": 1}, False, ["carpet"]),
    ("coat rack", "rod", (0.35, 1.6, 0.35), (0.5, 1.8, 0.5), "floor", {"entryway": 2, "hallway": 1}, False, []),
    ("exercise ball", "sphere", (0.55, 0.55, 0.55), (0.75, 0.75, 0.75), "floor", {"gym": 2, "playroom": 1},
     False, ["ball"]),
    ("fan", "fan", (0.35, 0.9, 0.3), (0.45, 1.3, 0.4), "floor", {"bedroom": 0.5, "office": 0.5, "gym": 1},
     False, []),
    ("piano", "instrument", (1.4, 1.1, 0.55), (1.6, 1.3, 0.65), "floor", {"living room": 0.6, "playroom": 0.5},
     True, []),
    ("fireplace", "fireplace", (1.2, 1.0, 0.4), (1.6, 1.3, 0.55), "floor", {"living room": 0.8}, True, []),
    ("radiator", "radiator", (0.6, 0.5, 0.1), (1.2, 0.7, 0.12), "wall", {"bedroom": 1, "bathroom": 1,
     "hallway": 1, "office": 1}, False, ["heater"]),
    ("window", "window_frame", (0.8, 0.9, 0.06), (1.4, 1.3, 0.1), "wall", ALL_ROOMS, False, []),
    ("curtain", "curtain", (0.8, 1.9, 0.08), (1.4, 2.3, 0.12), "wall", {"living room": 1, "bedroom": 1}, False,
     ["drapes"]),
    ("towel", "towel", (0.4, 0.5, 0.06), (0.7, 0.8, 0.1), "wall", {"bathroom": 3}, False, []),
    ("clothes", "clothes", (0.3, 0.1, 0.3), (0.5, 0.25, 0.4), "surface", {"bedroom": 1, "laundry room": 2,
     "closet": 1}, False, ["laundry"]),
    ("book", "book", (0.13, 0.02, 0.2), (0.2, 0.05, 0.28), "surface", {"office": 2, "living room": 1,
     "bedroom": 1}, False, []),
    ("laptop", "device", (0.3, 0.02, 0.22), (0.38, 0.03, 0.26), "surface", {"office": 2, "bedroom": 0.5}, False,
     ["computer"]),
    ("traffic cone", "cone", (0.3, 0.4, 0.3), (0.4, 0.7, 0.4), "floor", {"garage": 1.5}, False, []),
    ("treadmill", "bench", (0.7, 1.2, 1.6), (0.9, 1.4, 1.9), "floor", {"gym": 3}, False, []),
    ("toaster", "box", (0.25, 0.18, 0.15), (0.3, 0.22, 0.2), "surface", {"kitchen": 2}, False, []),
]
# fmt: on


def fixture_vocab() -> Vocabulary:
    cats = []
    for name, fam, smin, smax, place, rooms, surf, raw in _FIXTURE:
        cats.append(
            {
                "name": name, "family": fam, "size_min": list(smin), "size_max": list(smax),
                "placement": place, "rooms": rooms, "colors": ["#8a6a4a", "#c0c0c0"],
                "is_surface": surf, "raw_labels": raw,
            }
        )  # fmt: skip
    return parse_vocabulary({"categories": cats}, {"drop_words": ["wall", "floor", "ceiling"]}, "test fixture")


def _vocabs() -> list[Vocabulary]:
    out = [fixture_vocab()]
    try:
        out.append(load_vocabulary())
    except (FileNotFoundError, OSError):
        pass
    return out


VOCABS = _vocabs()
SEEDS = (0, 1, 7, 23, 42)


@pytest.fixture(scope="module", params=range(len(VOCABS)), ids=["fixture", "shipped"][: len(VOCABS)])
def houses(request):
    vocab = VOCABS[request.param]
    return vocab, [generate_house(s, vocab) for s in SEEDS]


def _footprint(o) -> np.ndarray:
    hx, _, hz = o.obb_half_extents
    ax = o.obb_rotation[:, 0][[0, 2]]
    az = o.obb_rotation[:, 2][[0, 2]]
    c = o.obb_center[[0, 2]]
    return np.array([c - hx * ax - hz * az, c + hx * ax - hz * az, c + hx * ax + hz * az, c - hx * ax + hz * az])


def _yrange(o) -> tuple[float, float]:
    return float(o.obb_center[1] - o.obb_half_extents[1]), float(o.obb_center[1] + o.obb_half_extents[1])


def test_fixture_covers_every_family():
    assert {c.family for c in fixture_vocab().categories.values()} == set(FAMILIES)


@pytest.mark.parametrize("family", sorted(FAMILIES))
def test_family_winding_is_outward(family):
    import trimesh

    pm = build_shape(family, (0.8, 1.0, 0.6))
    parts = trimesh.Trimesh(pm.vertices, pm.faces, process=False).split(only_watertight=False)
    assert all(p.volume > -1e-9 for p in parts)


@pytest.mark.parametrize("family", sorted(FAMILIES))
def test_every_family_builds_within_its_box(family):
    for size in ((0.5, 0.8, 0.4), (1.6, 0.9, 0.9), (0.1, 0.3, 0.1)):
        pm = build_shape(family, size)
        assert len(pm.faces) > 0 and len(pm.shade) == len(pm.faces)
        assert pm.faces.min() >= 0 and pm.faces.max() < len(pm.vertices)
        w, h, d = size
        v = pm.vertices
        assert v[:, 0].min() >= -w / 2 - 1e-9 and v[:, 0].max() <= w / 2 + 1e-9
        assert v[:, 1].min() >= -1e-9 and v[:, 1].max() <= h + 1e-9
        assert v[:, 2].min() >= -d / 2 - 1e-9 and v[:, 2].max() <= d / 2 + 1e-9
        # the shape fills its box reasonably (not a speck)
        ext = v.max(0) - v.min(0)
        assert np.all(ext >= 0.5 * np.array(size))


def test_determinism():
    vocab = VOCABS[0]
    a, b = generate_house(5, vocab), generate_house(5, vocab)
    assert a.scene_id == b.scene_id and a.scene_id.startswith("00005-") and len(a.scene_id) == 17
    assert np.array_equal(a.mesh.vertices, b.mesh.vertices)
    assert np.array_equal(a.mesh.faces, b.mesh.faces)
    assert np.array_equal(a.mesh.face_colors, b.mesh.face_colors)
    assert np.array_equal(a.mesh.face_instance, b.mesh.face_instance)
    assert [(o.id, o.raw_label, o.category, o.color) for o in a.objects] == [
        (o.id, o.raw_label, o.category, o.color) for o in b.objects
    ]
    c = generate_house(6, vocab)
    assert c.scene_id != a.scene_id
    assert len(c.mesh.vertices) != len(a.mesh.vertices) or not np.array_equal(c.mesh.vertices, a.mesh.vertices)
    cfg = HouseConfig(second_floor_prob=1.0)
    assert generate_house(5, vocab, cfg).mesh.vertices.shape == generate_house(5, vocab, cfg).mesh.vertices.shape


def test_layout_and_arrays(houses):
    vocab, hs = houses
    for s in hs:
        assert 4 <= len(s.regions) <= 12
        assert all(r.name in ROOM_TYPES for r in s.regions)
        assert s.floor_heights == sorted(s.floor_heights) and s.floor_heights[0] == 0.0
        assert {r.floor for r in s.regions} == set(range(len(s.floor_heights)))
        ground = [r.name for r in s.regions if r.floor == 0]
        assert "kitchen" in ground and "living room" in ground
        for r in s.regions:
            x0, z0, x1, z1 = r.bounds
            long_max = 9.0 if r.name == "hallway" else 7.5
            assert 1.0 <= min(x1 - x0, z1 - z0) and max(x1 - x0, z1 - z0) <= long_max
        m = s.mesh
        assert m.vertices.dtype == np.float32 and m.faces.dtype == np.int32
        assert m.face_colors.dtype == np.uint8 and m.face_colors.shape == (len(m.faces), 3)
        assert m.face_instance.dtype == np.int32 and m.vertex_colors is None
        ids = [o.id for o in s.objects]
        assert ids == list(range(1, len(ids) + 1))
        assert set(np.unique(m.face_instance).tolist()) == set(ids)
        colors = [o.color for o in s.objects]
        assert len(set(colors)) == len(colors) and (0, 0, 0) not in colors
        assert s.semantic_colors == {o.id: o.color for o in s.objects}
        assert s.source.startswith("procedural:")
        structural = [o for o in s.objects if o.category is None]
        assert {o.raw_label for o in structural} == {"wall", "floor", "ceiling"}
        objs = [o for o in s.objects if o.category is not None]
        assert 20 <= len(objs) <= 400, len(objs)
        for o in objs:
            cat = vocab[o.category]
            assert o.raw_label in cat.raw_labels
            size = 2 * np.asarray(o.obb_half_extents)
            assert np.all(size >= np.array(cat.size_min) - 1e-6) and np.all(size <= np.array(cat.size_max) + 1e-6)


def test_no_overlaps_and_support(houses):
    vocab, hs = houses
    tol = 0.01
    for s in hs:
        objs = [o for o in s.objects if o.category is not None]
        walls = [o for o in s.objects if o.raw_label == "wall"]
        fps = {o.id: _footprint(o) for o in objs}
        parent: dict[int, int] = {}
        for o in objs:
            cat = vocab[o.category]
            y0, y1 = _yrange(o)
            fy = s.floor_heights[o.floor]
            if cat.placement == "floor":
                assert abs(y0 - fy) < tol, (o.name, y0, fy)
            elif cat.placement == "surface":
                ok = False
                for q in objs:
                    qc = vocab[q.category]
                    if q.id == o.id or not qc.is_surface or q.region_id != o.region_id:
                        continue
                    size = tuple(2 * np.asarray(q.obb_half_extents))
                    ty, (rx0, rz0, rx1, rz1) = surface_top(qc.family, size)
                    if abs(_yrange(q)[0] + ty - y0) > tol:
                        continue
                    loc = (fps[o.id] - q.obb_center[[0, 2]]) @ np.stack(
                        [q.obb_rotation[:, 0][[0, 2]], q.obb_rotation[:, 2][[0, 2]]], axis=1
                    )
                    if (
                        (loc[:, 0] >= rx0 - tol).all()
                        and (loc[:, 0] <= rx1 + tol).all()
                        and ((loc[:, 1] >= rz0 - tol).all() and (loc[:, 1] <= rz1 + tol).all())
                    ):
                        ok = True
                        parent[o.id] = q.id
                        break
                assert ok, f"{o.name} floats"
            elif cat.placement == "wall":
                lo = np.array([fps[o.id][:, 0].min(), y0, fps[o.id][:, 1].min()])
                hi = np.array([fps[o.id][:, 0].max(), y1, fps[o.id][:, 1].max()])
                gaps = [np.max(np.maximum(w.aabb_min - hi, lo - w.aabb_max)) for w in walls]
                assert min(gaps) <= tol, f"{o.name} is not on a wall"
            else:
                assert abs(y1 - (fy + HouseConfig().wall_height)) < tol, f"{o.name} does not hang from the ceiling"
                assert y0 >= fy + 1.41, f"{o.name} hangs into the agent's head room"
        for i, a in enumerate(objs):
            ya = _yrange(a)
            for b in objs[i + 1 :]:
                if a.floor != b.floor or parent.get(a.id) == b.id or parent.get(b.id) == a.id:
                    continue
                yb = _yrange(b)
                if min(ya[1], yb[1]) - max(ya[0], yb[0]) <= tol:
                    continue
                assert not polys_overlap(fps[a.id], fps[b.id], tol), f"{a.name} intersects {b.name}"


def _free_space(s, floor: int, res: float = 0.05, radius: float = 0.17, height: float = 1.41, climb: float = 0.1):
    """Floor cells where the agent's disc fits: on a floor slab, off walls and object footprints."""
    fy = s.floor_heights[floor]
    regs = [r for r in s.regions if r.floor == floor]
    xs = [r.bounds[0] for r in regs] + [r.bounds[2] for r in regs]
    zs = [r.bounds[1] for r in regs] + [r.bounds[3] for r in regs]
    x0, x1, z0, z1 = min(xs) - 0.5, max(xs) + 0.5, min(zs) - 0.5, max(zs) + 0.5
    X = np.arange(x0, x1, res) + res / 2
    Z = np.arange(z0, z1, res) + res / 2
    XX, ZZ = np.meshgrid(X, Z)
    floor_ok = np.zeros(XX.shape, bool)
    blocked = np.zeros(XX.shape, bool)
    for o in s.objects:
        if o.floor != floor:
            continue
        if o.raw_label == "floor":
            floor_ok |= (XX >= o.aabb_min[0]) & (XX <= o.aabb_max[0]) & (ZZ >= o.aabb_min[2]) & (ZZ <= o.aabb_max[2])
            continue
        if o.raw_label == "ceiling":
            continue
        y0, y1 = _yrange(o)
        if y1 <= fy + climb or y0 >= fy + height:
            continue
        hx, _, hz = o.obb_half_extents
        R = o.obb_rotation
        dx, dz = XX - o.obb_center[0], ZZ - o.obb_center[2]
        lx = R[0, 0] * dx + R[2, 0] * dz
        lz = R[0, 2] * dx + R[2, 2] * dz
        # distance from the cell centre to the box footprint <= radius
        ex = np.maximum(np.abs(lx) - hx, 0.0)
        ez = np.maximum(np.abs(lz) - hz, 0.0)
        blocked |= ex**2 + ez**2 <= radius**2
    return XX, ZZ, floor_ok & ~blocked


def test_every_room_reachable(houses):
    _, hs = houses
    for s in hs:
        for floor in range(len(s.floor_heights)):
            XX, ZZ, free = _free_space(s, floor)
            lab, n = ndimage.label(free)
            assert n >= 1
            comps = set()
            for r in s.regions:
                if r.floor != floor:
                    continue
                x0, z0, x1, z1 = r.bounds
                inside = (XX > x0) & (XX < x1) & (ZZ > z0) & (ZZ < z1) & free
                assert inside.any(), f"{s.scene_id}: {r.name} {r.id} has no free cell"
                comps |= set(np.unique(lab[inside]).tolist())
            sizes = ndimage.sum(free, lab, index=sorted(comps))
            # everything in one component, allowing only specks (< 0.05 m^2) cut off by rasterisation
            big = [c for c, sz in zip(sorted(comps), sizes) if sz * 0.05**2 >= 0.05]
            assert len(big) == 1, f"{s.scene_id} floor {floor}: free space in {len(big)} pieces"


def test_doors_pass_the_agent():
    vocab = VOCABS[0]
    s = generate_house(3, vocab, HouseConfig(floor_density=0.0, wall_objects=(0, 0), ceiling_prob=0.0))
    assert all(o.category is None for o in s.objects)
    XX, ZZ, free = _free_space(s, 0)
    assert ndimage.label(free)[1] == 1


def test_second_floor_and_timing():
    import time

    vocab = VOCABS[0]
    t0 = time.perf_counter()
    s = generate_house(11, vocab, HouseConfig(second_floor_prob=1.0, min_rooms=8))
    dt = time.perf_counter() - t0
    assert len(s.floor_heights) == 2 and math.isclose(s.floor_heights[1], 3.0)
    assert {r.floor for r in s.regions} == {0, 1}
    assert dt < 2.0
