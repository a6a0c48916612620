"""Scan scale: load, navigability, distance field, render FPS and peak memory on a ~1M-triangle textured
mesh with clutter, against a procedural house (the baseline) in the same run.

Real HM3D scans have about 1M small triangles and large textures; procedural houses ~60k big ones.
The scan is built here (no scan can be downloaded): a multi-room floor plan whose walls, floors,
ceilings and clutter boxes are tessellated into ~3 cm triangles with 3 mm vertex noise (a scan's
surface), UV-mapped onto one large texture, written as a `.glb` and loaded back through `load_scene`.

    python benchmarks/scan_scale.py results.json [--triangles 1000000] [--size 4096] [--frames 30]

Prints a table and writes JSON to the path given (ratios = scan / house).
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _tessellated_box(lo, hi, edge: float, rng: np.random.Generator, noise: float):  # noqa: ANN001, ANN202
    """Vertices, faces and local UVs (0..1 per side) of a box whose six sides are grids of ~edge cells."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    verts, faces, uvs = [], [], []
    off = 0
    # (fixed axis, side, u axis, v axis)
    for ax, side in ((0, 0), (0, 1), (1, 0), (1, 1), (2, 0), (2, 1)):
        ua, va = [a for a in range(3) if a != ax]
        nu = max(1, int(math.ceil((hi[ua] - lo[ua]) / edge)))
        nv = max(1, int(math.ceil((hi[va] - lo[va]) / edge)))
        u, v = np.meshgrid(np.linspace(0, 1, nu + 1), np.linspace(0, 1, nv + 1))
        p = np.zeros((u.size, 3))
        p[:, ax] = hi[ax] if side else lo[ax]
        p[:, ua] = lo[ua] + u.ravel() * (hi[ua] - lo[ua])
        p[:, va] = lo[va] + v.ravel() * (hi[va] - lo[va])
        p[:, ax] += rng.normal(0, noise, len(p))
        idx = np.arange(u.size).reshape(nv + 1, nu + 1)
        a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
        f = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
        # outward winding: flip where the cross product points inward
        n = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])
        out = 1.0 if side else -1.0
        flip = n[:, ax] * out < 0
        f[flip] = f[flip][:, [0, 2, 1]]
        verts.append(p)
        faces.append(f + off)
        uvs.append(np.stack([u.ravel(), v.ravel()], 1))
        off += len(p)
    return np.concatenate(verts), np.concatenate(faces), np.concatenate(uvs)


def build_scan(target_triangles: int, tex_size: int, seed: int = 0):  # noqa: ANN201
    """(vertices, faces, uvs, texture) of a 4-room, 12 x 10 m flat with furniture and clutter."""
    from tests.meshes import room_boxes, wall_x_with_gap

    rng = np.random.default_rng(seed)
    boxes = room_boxes(0.0, 0.0, 12.0, 10.0, wall_height=2.6)
    boxes += wall_x_with_gap(6.0, 0.0, 10.0, 3.0, 4.0)
    boxes += [((0.0, 0.0, 4.95), (2.5, 2.6, 5.05)), ((3.5, 0.0, 4.95), (8.5, 2.6, 5.05)),
              ((9.5, 0.0, 4.95), (12.0, 2.6, 5.05))]  # fmt: skip
    for _ in range(40):  # furniture: low boxes (tables, beds, cabinets)
        c = rng.uniform([0.6, 0.6], [11.4, 9.4])
        w = rng.uniform(0.4, 1.6, 2)
        h = rng.choice([0.45, 0.75, 0.9, 1.8])
        boxes.append(((c[0] - w[0] / 2, 0.0, c[1] - w[1] / 2), (c[0] + w[0] / 2, h, c[1] + w[1] / 2)))
    for _ in range(150):  # clutter: small things on the floor and on furniture
        c = rng.uniform([0.3, 0.3], [11.7, 9.7])
        s = rng.uniform(0.05, 0.3, 3)
        y0 = float(rng.choice([0.0, 0.45, 0.75]))
        boxes.append(((c[0], y0, c[1]), (c[0] + s[0], y0 + s[1], c[1] + s[2])))
    area = sum(2 * ((h[0] - l[0]) * (h[1] - l[1]) + (h[1] - l[1]) * (h[2] - l[2]) + (h[0] - l[0]) * (h[2] - l[2]))
               for l, h in boxes)
    edge = math.sqrt(2 * area / target_triangles)
    verts, faces, uvs, off = [], [], [], 0
    tiles = int(math.ceil(math.sqrt(len(boxes))))
    for i, (lo, hi) in enumerate(boxes):
        v, f, uv = _tessellated_box(lo, hi, edge, rng, noise=0.003)
        r, c = divmod(i, tiles)
        uv = (np.array([c, r]) + 0.05 + 0.9 * uv) / tiles  # this box's tile of the atlas
        verts.append(v)
        faces.append(f + off)
        uvs.append(uv)
        off += len(v)
    yy, xx = np.mgrid[0:tex_size, 0:tex_size]
    texture = np.stack([(xx * 7 + yy * 3) % 256, (xx ^ yy) % 256, (yy * 5) % 256], -1).astype(np.uint8)
    return (np.concatenate(verts).astype(np.float32), np.concatenate(faces).astype(np.int64),
            np.concatenate(uvs).astype(np.float32), texture)


def measure(scene, label: str, frames: int, sizes: list[tuple[int, int]]) -> dict:  # noqa: ANN001
    from ovon.config.sim import AgentConfig, CameraConfig, NavConfig
    from ovon.sim.geodesic import distance_field
    from ovon.sim.navgrid import build_navigation, clear_cache
    from ovon.sim.render import gl_available, make_renderer

    out: dict = {"scene": label, "triangles": scene.mesh.num_faces,
                 "texture": None if scene.mesh.texture is None else list(scene.mesh.texture.shape[:2])}
    clear_cache()
    t = time.perf_counter()
    nav = build_navigation(scene, AgentConfig(), NavConfig())
    out["navigability_s"] = time.perf_counter() - t
    g = max(nav.floors, key=lambda g: g.navigable.sum())
    out["navigable_m2"] = float(g.navigable.sum()) * g.cell_size**2
    rng = np.random.default_rng(0)
    goals = np.stack([g.random_point(rng, 1.0) for _ in range(5)])
    t = time.perf_counter()
    distance_field(g, goals)
    out["distance_field_s"] = time.perf_counter() - t
    poses = [(g.random_point(rng, 1.0) + [0, 1.31, 0], float(rng.uniform(-math.pi, math.pi))) for _ in range(frames)]
    backends = ["embree"] + (["gl"] if gl_available() else [])
    for backend in backends:
        for w, h in sizes:
            r = make_renderer(scene, CameraConfig(width=w, height=h, backend=backend))
            r.render(poses[0][0], poses[0][1], 0.0)  # warm-up (JIT, upload)
            t = time.perf_counter()
            for eye, yaw in poses:
                r.render(eye, yaw, 0.0)
            out[f"fps_{backend}_{w}x{h}"] = frames / (time.perf_counter() - t)
            r.close()
    out["peak_rss_mb"] = peak_rss_mb()
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", help="JSON result file")
    ap.add_argument("--triangles", type=int, default=1_000_000)
    ap.add_argument("--size", type=int, default=4096, help="texture side (texels)")
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--work", default=None, help="folder for the generated .glb (default: a temp folder)")
    args = ap.parse_args()
    import os

    os.environ.setdefault("LP_NUM_THREADS", "0")
    from ovon.scenes.hm3dsem import encode_glb, load_scene
    from ovon.scenes.procedural import generate_house

    sizes = [(160, 120), (360, 640)]
    t = time.perf_counter()
    house = generate_house(0)
    base = measure(house, "procedural:0", args.frames, sizes)
    base["load_s"] = time.perf_counter() - t  # generation, the house's "load"

    work = Path(args.work or tempfile.mkdtemp(prefix="ovon_scan_"))
    work.mkdir(parents=True, exist_ok=True)
    path = work / "scan.glb"
    t = time.perf_counter()
    v, f, uv, tex = build_scan(args.triangles, args.size)
    path.write_bytes(encode_glb(v, f, uvs=uv, texture=tex))
    build_s = time.perf_counter() - t
    del v, f, uv, tex
    t = time.perf_counter()
    scan = load_scene(path)
    load_s = time.perf_counter() - t
    res = measure(scan, str(path), args.frames, sizes)
    res["load_s"] = load_s
    res["build_s"] = build_s
    res["file_mb"] = path.stat().st_size / 2**20

    keys = [k for k in res if k.endswith(("_s", "m2")) or k.startswith("fps_") or k == "peak_rss_mb"]
    ratios = {k: res[k] / base[k] for k in keys if k in base and base[k]}
    doc = {"machine": platform.platform(), "python": platform.python_version(), "baseline": base, "scan": res,
           "ratio_scan_over_house": ratios}
    print(f"{'metric':<26}{'house':>12}{'scan':>12}{'ratio':>9}")
    for k in keys:
        b = base.get(k)
        print(f"{k:<26}{(f'{b:.3f}' if b is not None else '-'):>12}{res[k]:>12.3f}"
              f"{(f'{ratios[k]:.2f}' if k in ratios else '-'):>9}")
    print(f"triangles: house {base['triangles']:,}, scan {res['triangles']:,}; scan file {res['file_mb']:.1f} MB")
    Path(args.out).write_text(json.dumps(doc, indent=2))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
