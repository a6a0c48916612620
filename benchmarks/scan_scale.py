"""Scan scale: load, navigability, distance field, render cost and peak memory on a ~1M-triangle textured
mesh with clutter, against a procedural house (the baseline) in the same run.

Real HM3D scans have about 1M small triangles and large textures; procedural houses ~10k big ones.
The scan is built here (no scan can be downloaded): a multi-room floor plan whose walls, floors,
ceilings and clutter boxes are tessellated into ~3 cm triangles with 3 mm vertex noise (a scan's
surface), UV-mapped onto one large texture, written as a `.glb` and loaded back through `load_scene`.
With `--semantic` it is written as an HM3DSem folder whose `.semantic.glb` triangulates the same surface
the other way (its own triangles, as real semantic meshes have) with a painted instance texture, so the
renderers run their second (semantic) pass.

    python benchmarks/scan_scale.py results.json [--triangles 1000000] [--size 4096] [--frames 20] [--semantic]

Rendering is measured as in `render_speed.py`: GL with chunk culling, GL without it (the previous path) and
embree draw the same poses round-robin -- `random` (independent navigable poses) and `walk` (agent steps) --
with RGB on and off; median CPU ms per frame and ratios. Prints a table and writes JSON to the path given
(ratios = scan / house).
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from ovon.atomic import atomic_write_text  # noqa: E402


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _tessellated_box(lo, hi, edge: float, rng: np.random.Generator, noise: float, other_diagonal: bool = False):  # noqa: ANN001, ANN202, E501
    """Vertices, faces and local UVs (0..1 per side) of a box whose six sides are grids of ~edge cells (each
    cell split along its a-c diagonal, or b-d with `other_diagonal`: same surface, other triangles)."""
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
        if other_diagonal:
            f = np.concatenate([np.stack([a, b, d], 1), np.stack([b, c, d], 1)])
        else:
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


def scan_boxes(rng: np.random.Generator) -> list:
    """Boxes of a 4-room, 12 x 10 m flat: walls, furniture and clutter."""
    from tests.meshes import room_boxes, wall_x_with_gap

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
    return boxes


def build_scan(target_triangles: int, tex_size: int, seed: int = 0, other_diagonal: bool = False):  # noqa: ANN201
    """(vertices, faces, uvs, texture) of the `scan_boxes` flat; box i is painted in tile i (row-major) of
    a texture atlas of `atlas_tiles(len(boxes))` tiles per side."""
    rng = np.random.default_rng(seed)
    boxes = scan_boxes(rng)
    area = sum(
        2 * ((h[0] - l[0]) * (h[1] - l[1]) + (h[1] - l[1]) * (h[2] - l[2]) + (h[0] - l[0]) * (h[2] - l[2]))
        for l, h in boxes
    )
    edge = math.sqrt(2 * area / target_triangles)
    verts, faces, uvs, off = [], [], [], 0
    tiles = atlas_tiles(len(boxes))
    for i, (lo, hi) in enumerate(boxes):
        v, f, uv = _tessellated_box(lo, hi, edge, rng, noise=0.003, other_diagonal=other_diagonal)
        r, c = divmod(i, tiles)
        uv = (np.array([c, r]) + 0.05 + 0.9 * uv) / tiles  # this box's tile of the atlas
        verts.append(v)
        faces.append(f + off)
        uvs.append(uv)
        off += len(v)
    yy, xx = np.mgrid[0:tex_size, 0:tex_size]
    texture = np.stack([(xx * 7 + yy * 3) % 256, (xx ^ yy) % 256, (yy * 5) % 256], -1).astype(np.uint8)
    return (
        np.concatenate(verts).astype(np.float32),
        np.concatenate(faces).astype(np.int64),
        np.concatenate(uvs).astype(np.float32),
        texture,
    )


def atlas_tiles(num_boxes: int) -> int:
    return int(math.ceil(math.sqrt(num_boxes)))


def write_semantic_scan(folder: Path, target_triangles: int, tex_size: int) -> Path:
    """HM3DSem folder: `scan.glb`, `scan.semantic.glb` (same surface, other diagonals, one instance colour
    per box tile) and `scan.semantic.txt`."""
    from ovon.scenes.hm3dsem import encode_glb
    from ovon.scenes.hm3dsem.semantic_txt import SemanticEntry, format_semantic_txt

    v, f, uv, tex = build_scan(target_triangles, tex_size)
    (folder / "scan.glb").write_bytes(encode_glb(v, f, uvs=uv, texture=tex))
    del v, f, uv, tex
    v, f, uv, _ = build_scan(target_triangles, 1, other_diagonal=True)
    n = len(scan_boxes(np.random.default_rng(0)))
    tiles = atlas_tiles(n)
    code = np.random.default_rng(1).choice(256**3 - 2, n, replace=False) + 1  # distinct non-black colours
    colors = np.stack([(code >> 16) & 255, (code >> 8) & 255, code & 255], 1).astype(np.uint8)
    sem_tex = np.zeros((tiles, tiles, 3), np.uint8)
    sem_tex.reshape(-1, 3)[:n] = colors
    sem_tex = sem_tex[::-1].copy()  # encode_glb's uv convention: v = 1 is the image's top row
    (folder / "scan.semantic.glb").write_bytes(encode_glb(v, f, uvs=uv, texture=sem_tex))
    entries = [SemanticEntry(i + 1, tuple(int(c) for c in colors[i]), "box", 0) for i in range(n)]
    (folder / "scan.semantic.txt").write_text(format_semantic_txt(entries))
    return folder


def measure(scene, label: str, frames: int, sizes: list[tuple[int, int]], repeats: int = 1) -> dict:  # noqa: ANN001
    from render_speed import RENDERERS, compare, random_poses, table_line, walk_poses

    from ovon.config.sim import AgentConfig, CameraConfig, NavConfig
    from ovon.sim.geodesic import distance_field
    from ovon.sim.navgrid import build_navigation, clear_cache
    from ovon.sim.render import gl_available

    out: dict = {
        "scene": label,
        "triangles": scene.mesh.num_faces,
        "texture": None if scene.mesh.texture is None else list(scene.mesh.texture.shape[:2]),
        "semantic_mesh_triangles": None if scene.semantic_mesh is None else scene.semantic_mesh.num_faces,
    }
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
    renderers = RENDERERS if gl_available() else ("embree",)
    modes = {"random": random_poses(scene, frames), "walk": walk_poses(scene, frames)}
    out["render"] = []
    for w, h in sizes:
        for rgb in (True, False):
            for mode, ps in modes.items():
                res = compare(scene, CameraConfig(width=w, height=h, rgb=rgb), ps, repeats, renderers)
                res.update(width=w, height=h, rgb=rgb, poses=mode)
                out["render"].append(res)
                print(table_line(f"{label[-12:]} {w}x{h} {'rgb' if rgb else 'no-rgb'} {mode}", res), flush=True)
                if rgb and mode == "random":
                    for k, ms in res["cpu_ms"].items():
                        out[f"fps_{k}_{w}x{h}"] = 1e3 / ms
    out["peak_rss_mb"] = peak_rss_mb()
    return out


def main() -> int:
    from render_speed import TABLE_HEAD, machine_meta

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", help="JSON result file")
    ap.add_argument("--triangles", type=int, default=1_000_000)
    ap.add_argument("--size", type=int, default=4096, help="texture side (texels)")
    ap.add_argument("--frames", type=int, default=20, help="poses per pose mode")
    ap.add_argument("--repeats", type=int, default=1, help="passes over the poses (medians pool them)")
    ap.add_argument("--semantic", action="store_true", help="HM3DSem folder with a separate semantic mesh")
    ap.add_argument("--work", default=None, help="folder for the generated files (default: a temp folder)")
    args = ap.parse_args()
    if args.triangles < 1000 or args.size < 1 or args.frames < 1 or args.repeats < 1:
        ap.error("--triangles >= 1000, --size, --frames and --repeats >= 1 expected, got "
                 f"{args.triangles}, {args.size}, {args.frames}, {args.repeats}")  # fmt: skip
    import os

    os.environ.setdefault("LP_NUM_THREADS", "0")
    from ovon.scenes.hm3dsem import encode_glb, load_scene
    from ovon.scenes.procedural import generate_house

    meta = machine_meta()
    sizes = [(160, 120), (360, 640)]
    print(TABLE_HEAD)
    t = time.perf_counter()
    house = generate_house(0)
    base = measure(house, "procedural:0", args.frames, sizes, args.repeats)
    base["load_s"] = time.perf_counter() - t  # generation, the house's "load"

    work = Path(args.work or tempfile.mkdtemp(prefix="ovon_scan_"))
    work.mkdir(parents=True, exist_ok=True)
    t = time.perf_counter()
    if args.semantic:
        path = write_semantic_scan(work, args.triangles, args.size)
    else:
        path = work / "scan.glb"
        v, f, uv, tex = build_scan(args.triangles, args.size)
        path.write_bytes(encode_glb(v, f, uvs=uv, texture=tex))
        del v, f, uv, tex
    build_s = time.perf_counter() - t
    t = time.perf_counter()
    scan = load_scene(path)
    load_s = time.perf_counter() - t
    res = measure(scan, str(path), args.frames, sizes, args.repeats)
    res["load_s"] = load_s
    res["build_s"] = build_s
    res["file_mb"] = sum(q.stat().st_size for q in work.iterdir() if q.name.startswith("scan.")) / 2**20

    keys = [k for k in res if k.endswith(("_s", "m2")) or k.startswith("fps_") or k == "peak_rss_mb"]
    ratios = {k: res[k] / base[k] for k in keys if k in base and base[k]}
    meta["loadavg_end"] = list(os.getloadavg())
    doc = meta | {"frames": args.frames, "repeats": args.repeats, "baseline": base, "scan": res,
                  "ratio_scan_over_house": ratios}  # fmt: skip
    print(f"{'metric':<26}{'house':>12}{'scan':>12}{'ratio':>9}")
    for k in keys:
        b = base.get(k)
        print(
            f"{k:<26}{(f'{b:.3f}' if b is not None else '-'):>12}{res[k]:>12.3f}"
            f"{(f'{ratios[k]:.2f}' if k in ratios else '-'):>9}"
        )
    print(
        f"triangles: house {base['triangles']:,}, scan {res['triangles']:,}; scan files {res['file_mb']:.1f} MB; "
        f"load average {meta['loadavg_start'][0]:.2f} -> {meta['loadavg_end'][0]:.2f}"
    )
    atomic_write_text(Path(args.out), json.dumps(doc, indent=2))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
