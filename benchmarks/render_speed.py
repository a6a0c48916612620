"""Render FPS of the GL and embree backends at the standard sizes, plus their per-frame agreement.

Usage: python benchmarks/render_speed.py [--frames 100] [--out benchmarks/results/render_speed.json]
Uses `ovon.scenes.procedural.generate_house(0)` when available, else a synthetic ~50k-triangle house.
Poses are random eye positions inside the house at camera height with random yaw and pitch in
{-30, 0, +30} deg, the same for every backend.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import time
from pathlib import Path

import numpy as np

from ovon.config.sim import CameraConfig
from ovon.scenes.model import Mesh, Scene

SIZES = [(160, 120), (224, 224), (640, 360)]


def synthetic_house(rooms: int = 4, room: float = 4.0, height: float = 2.6, seed: int = 0) -> Scene:
    """rooms x rooms grid of box rooms (walls with door gaps) furnished with boxes and spheres."""
    import trimesh

    rng = np.random.default_rng(seed)
    parts: list[trimesh.Trimesh] = []
    ids: list[int] = []

    def add(m: trimesh.Trimesh, inst: int) -> None:
        parts.append(m)
        ids.append(inst)

    size = rooms * room
    floor = trimesh.creation.box((size, 0.02, size))
    floor.apply_translation((size / 2, -0.01, size / 2))
    add(floor, 1)
    ceil = floor.copy()
    ceil.apply_translation((0, height + 0.02, 0))
    add(ceil, 2)
    inst = 3
    for i in range(rooms + 1):  # walls along x and z with a door gap in every room
        for j in range(rooms):
            for axis in (0, 1):
                a0, a1 = j * room, j * room + room / 2 - 0.5
                b0, b1 = j * room + room / 2 + 0.5, (j + 1) * room
                for s0, s1 in ((a0, a1), (b0, b1)):
                    ext = [s1 - s0, height, 0.1] if axis == 0 else [0.1, height, s1 - s0]
                    w = trimesh.creation.box(ext)
                    c = (s0 + s1) / 2
                    w.apply_translation((c, height / 2, i * room) if axis == 0 else (i * room, height / 2, c))
                    add(w, inst)
                inst += 1
    for _ in range(rooms * rooms * 2 + 6):
        o = trimesh.creation.icosphere(subdivisions=3, radius=rng.uniform(0.15, 0.4))
        o.apply_translation((rng.uniform(0.5, size - 0.5), rng.uniform(0.3, 1.5), rng.uniform(0.5, size - 0.5)))
        add(o, inst)
        inst += 1
    for _ in range(rooms * rooms * 4):
        b = trimesh.creation.box(rng.uniform(0.3, 1.2, 3))
        b.apply_translation((rng.uniform(0.5, size - 0.5), 0.3, rng.uniform(0.5, size - 0.5)))
        add(b, inst)
        inst += 1
    verts, faces, face_ids, colors = [], [], [], []
    off = 0
    for m, k in zip(parts, ids, strict=True):
        verts.append(np.asarray(m.vertices, np.float32))
        faces.append(np.asarray(m.faces, np.int32) + off)
        face_ids.append(np.full(len(m.faces), k, np.int32))
        colors.append(np.tile(rng.integers(40, 255, 3, dtype=np.uint8), (len(m.faces), 1)))
        off += len(m.vertices)
    mesh = Mesh(
        vertices=np.concatenate(verts),
        faces=np.concatenate(faces),
        face_colors=np.concatenate(colors),
        face_instance=np.concatenate(face_ids),
    )
    return Scene(scene_id=f"synthetic-house-{seed}", mesh=mesh, source=f"synthetic:{seed}")


def load_house(synthetic: bool = False) -> Scene:
    """The procedural house 0, or the synthetic one when asked or when the generator fails."""
    if synthetic:
        return synthetic_house()
    try:
        from ovon.scenes.procedural import generate_house

        return generate_house(0)
    except Exception as exc:  # generator missing or broken: still measure the renderers
        print(f"generate_house(0) unavailable ({type(exc).__name__}: {exc}); using the synthetic house")
        return synthetic_house()


def poses(scene: Scene, n: int, seed: int = 0) -> list[tuple[np.ndarray, float, float]]:
    lo, hi = scene.mesh.bounds()
    y = float(scene.floor_heights[0]) if scene.floor_heights else float(lo[1])
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        eye = np.array([rng.uniform(lo[0] + 0.5, hi[0] - 0.5), y + 1.31, rng.uniform(lo[2] + 0.5, hi[2] - 0.5)])
        out.append((eye, float(rng.uniform(-math.pi, math.pi)), math.radians(float(rng.choice([-30, 0, 30])))))
    return out


def time_backend(scene: Scene, cfg: CameraConfig, backend: str, ps: list) -> tuple[float, list]:
    """FPS from the median frame time (robust on a noisy shared machine) and the frames."""
    from ovon.sim.render import make_renderer

    r = make_renderer(scene, cfg, backend)
    for p in ps[:5]:  # warm-up (numba compile cache, GL shader compile)
        r.render(*p)
    frames, times = [], []
    for p in ps:
        t = time.perf_counter()
        frames.append(r.render(*p))
        times.append(time.perf_counter() - t)
    r.close()
    return 1.0 / float(np.median(times)), frames


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--backends", default="gl,embree")
    ap.add_argument("--out", default="benchmarks/results/render_speed.json")
    ap.add_argument("--synthetic", action="store_true", help="use the synthetic house, not generate_house(0)")
    args = ap.parse_args()

    scene = load_house(args.synthetic)
    ps = poses(scene, args.frames)
    backends = args.backends.split(",")
    rows = []
    print(f"scene {scene.scene_id}: {scene.mesh.num_faces} triangles, {args.frames} frames per cell")
    print(f"{'size':>9} " + " ".join(f"{b + ' FPS':>11}" for b in backends) + "   id-agree   max|dz| mm  >1mm frac")
    for w, h in SIZES:
        cfg = CameraConfig(width=w, height=h, hfov_deg=79.0)
        fps, frames = {}, {}
        for b in backends:
            fps[b], frames[b] = time_backend(scene, cfg, b, ps)
        row = {"width": w, "height": h, "fps": fps}
        line = f"{w}x{h:<5} " + " ".join(f"{fps[b]:>11.1f}" for b in backends)
        if len(backends) == 2:
            fa, fb = frames[backends[0]], frames[backends[1]]
            agree = float(np.mean([(a.semantic == b.semantic).mean() for a, b in zip(fa, fb, strict=True)]))
            diffs = []
            for a, b in zip(fa, fb, strict=True):
                both = (a.depth > 0) & (b.depth > 0) & (a.semantic == b.semantic)
                diffs.append(np.abs(a.depth[both] - b.depth[both]))
            d = np.concatenate(diffs)
            dz, over = float(d.max(initial=0.0)), float((d > 1e-3).mean()) if d.size else 0.0
            row.update(id_agreement=agree, max_depth_diff_m=dz, frac_depth_diff_over_1mm=over)
            line += f"   {agree * 100:7.3f}%   {dz * 1000:8.4f}   {over:.1e}"
        print(line)
        rows.append(row)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    meta = {"scene": scene.scene_id, "triangles": scene.mesh.num_faces, "frames": args.frames}
    meta["machine"] = platform.machine() + " " + platform.processor()
    out.write_text(json.dumps({"meta": meta, "results": rows}, indent=2))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
