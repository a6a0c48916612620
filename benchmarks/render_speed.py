"""Render cost per frame of GL with chunk culling, GL without it (the previous path) and embree, same poses.

    python benchmarks/render_speed.py OUT.json [--houses 0] [--frames 60] [--repeats 3] [--synthetic]

For each procedural house, size (160x120, the 72x128 CPU portrait, 224x224, the paper's 360x640; HFOV of
`CameraConfig`), RGB on/off and pose mode -- `random` (independent navigable poses, pitch -30/0/+30 deg) and
`walk` (agent steps: 0.25 m forward, 30 deg turns, look up/down; culling reuses the last frame's visible
set) -- the three renderers draw the same poses round-robin (in rotating order: each goes first, after the
others have used the caches, equally often), so machine noise hits them alike. Reported:
median CPU ms per frame (steadier than wall time on a shared machine) and wall ms, ratios (gl-nocull / gl
= the culling speed-up, embree / gl), faces GL rasterised, frames where culled and unculled GL differ (must
be 0) and GL-vs-embree instance agreement. Prints a table and writes JSON to OUT.json.
`benchmarks/scan_scale.py` runs the same measurement on a built ~1M-triangle scan.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from ovon.atomic import atomic_write_text  # noqa: E402
from ovon.config.sim import CameraConfig  # noqa: E402
from ovon.scenes.model import Mesh, Scene  # noqa: E402

SIZES = [(160, 120), (72, 128), (224, 224), (360, 640)]
RENDERERS = ("gl", "gl-nocull", "embree")
PITCHES_DEG = (-30.0, 0.0, 30.0)


def synthetic_house(rooms: int = 4, room: float = 4.0, height: float = 2.6, seed: int = 0) -> Scene:
    """rooms x rooms grid of box rooms (walls with door gaps) furnished with boxes and spheres (~50k faces)."""
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
    return Scene(scene_id=f"synthetic-house-{seed}", mesh=mesh, floor_heights=[0.0], source=f"synthetic:{seed}")


# ------------------------------------------------------------------------------------------------ poses


def _floor(scene: Scene):  # noqa: ANN202
    from ovon.sim.navgrid import build_navigation

    nav = build_navigation(scene)
    return max(nav.floors, key=lambda g: g.navigable.sum())


def random_poses(scene: Scene, n: int, seed: int = 0, eye_height: float = 1.31) -> list[tuple]:
    """Independent navigable positions at camera height, uniform yaw, pitch from PITCHES_DEG."""
    g, rng = _floor(scene), np.random.default_rng(seed)
    out = []
    for _ in range(n):
        eye = g.random_point(rng) + np.array([0.0, eye_height, 0.0])
        out.append((eye, float(rng.uniform(-math.pi, math.pi)), math.radians(float(rng.choice(PITCHES_DEG)))))
    return out


def walk_poses(scene: Scene, n: int, seed: int = 0, eye_height: float = 1.31) -> list[tuple]:
    """An agent-like trajectory: forward 0.25 m when the cell ahead is navigable, else turn; 30 deg turns;
    occasional look up/down -- consecutive frames overlap like an episode's."""
    g, rng = _floor(scene), np.random.default_rng(seed)
    pos, yaw, pitch, out = g.random_point(rng), float(rng.uniform(-math.pi, math.pi)), 0.0, []
    for _ in range(n):
        a = rng.choice(4, p=[0.5, 0.2, 0.2, 0.1])
        ahead = pos + 0.25 * np.array([-math.sin(yaw), 0.0, -math.cos(yaw)])
        if a == 0 and g.is_navigable(ahead):
            pos = ahead
        elif a == 3:
            pitch = math.radians(float(rng.choice(PITCHES_DEG)))
        else:
            yaw += math.radians(30.0 if a == 1 else -30.0)
        out.append((pos + np.array([0.0, eye_height, 0.0]), yaw, pitch))
    return out


# ------------------------------------------------------------------------------------------------ timing


def compare(scene: Scene, cfg: CameraConfig, poses: list[tuple], repeats: int, renderers=RENDERERS) -> dict:  # noqa: ANN001
    """Render `poses` with every renderer round-robin, `repeats` times; per-frame medians and checks."""
    from ovon.sim.render import make_renderer

    made = {}
    for name in renderers:
        backend = "embree" if name == "embree" else "gl"
        made[name] = make_renderer(scene, replace(cfg, cull=name != "gl-nocull"), backend)
    for r in made.values():  # warm-up: shader compile, JIT, first-frame buffers
        r.render(*poses[0])
    cpu: dict[str, list[float]] = {k: [] for k in made}
    wall: dict[str, list[float]] = {k: [] for k in made}
    faces: list[int] = []
    mismatch, agree = 0, []
    names = list(made)
    for rep in range(repeats):
        for k, (eye, yaw, pitch) in enumerate(poses):
            frames = {}
            for name in names[k % len(names) :] + names[: k % len(names)]:  # each goes first as often (caches)
                r = made[name]
                c0, w0 = time.process_time(), time.perf_counter()
                frames[name] = r.render(eye, yaw, pitch)
                cpu[name].append(time.process_time() - c0)
                wall[name].append(time.perf_counter() - w0)
            if rep:
                continue
            if "gl" in frames:
                faces.append(made["gl"].faces_drawn)
            if "gl" in frames and "gl-nocull" in frames:
                a, b = frames["gl"], frames["gl-nocull"]
                same = np.array_equal(a.depth, b.depth) and np.array_equal(a.semantic, b.semantic)
                mismatch += not (same and (a.rgb is None or np.array_equal(a.rgb, b.rgb)))
            if "gl" in frames and "embree" in frames:
                agree.append(float((frames["gl"].semantic == frames["embree"].semantic).mean()))
    for r in made.values():
        r.close()
    out: dict = {
        "cpu_ms": {k: 1e3 * float(np.median(v)) for k, v in cpu.items()},
        "wall_ms": {k: 1e3 * float(np.median(v)) for k, v in wall.items()},
    }
    base = out["cpu_ms"].get("gl")
    if base:
        out["ratio_cpu_vs_gl"] = {k: v / base for k, v in out["cpu_ms"].items() if k != "gl"}
        out["gl_faces_drawn_median"] = float(np.median(faces))
    if "gl-nocull" in made and "gl" in made:
        out["gl_culled_vs_unculled_mismatching_frames"] = mismatch
    if agree:
        out["gl_embree_instance_agreement"] = float(np.mean(agree))
    return out


def table_line(label: str, res: dict) -> str:
    ms = res["cpu_ms"]
    cells = " ".join(f"{ms.get(k, float('nan')):9.3f}" for k in RENDERERS)
    r = res.get("ratio_cpu_vs_gl", {})
    extra = f"  x{r.get('gl-nocull', float('nan')):5.2f}  x{r.get('embree', float('nan')):5.2f}"
    extra += f"  {res.get('gl_faces_drawn_median', float('nan')):9.0f}"
    extra += f"  {res.get('gl_culled_vs_unculled_mismatching_frames', '-')!s:>4}"
    return f"{label:<34}{cells}{extra}"


TABLE_HEAD = (
    f"{'case':<34}" + " ".join(f"{k + ' ms':>9}" for k in ("gl", "nocull", "embree"))
    + "  nocull/gl embree/gl  gl faces  diff"
)  # fmt: skip


def machine_meta() -> dict:
    return {
        "machine": platform.platform(),
        "python": platform.python_version(),
        "cpus": os.cpu_count(),
        "loadavg_start": list(os.getloadavg()),
        "timing": "median per-frame CPU time (time.process_time) and wall time; renderers round-robin per pose",
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", help="JSON result file")
    ap.add_argument("--houses", default="0", help="procedural house seeds, comma-separated")
    ap.add_argument("--synthetic", action="store_true", help="also the synthetic ~50k-face box house")
    ap.add_argument("--frames", type=int, default=60, help="poses per mode")
    ap.add_argument("--repeats", type=int, default=3, help="passes over the poses (medians pool them)")
    ap.add_argument("--sizes", default=",".join(f"{w}x{h}" for w, h in SIZES), help="WxH list")
    args = ap.parse_args()
    if args.frames < 1 or args.repeats < 1:
        ap.error(f"--frames and --repeats must be >= 1, got {args.frames}, {args.repeats}")
    try:
        sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes.split(",")]
        seeds = [int(s) for s in args.houses.split(",") if s != ""]
    except ValueError:
        ap.error(f"--sizes wants WxH,WxH (got {args.sizes!r}); --houses integers (got {args.houses!r})")
    os.environ.setdefault("LP_NUM_THREADS", "0")
    from ovon.scenes.procedural import generate_house

    scenes = [generate_house(s) for s in seeds] + ([synthetic_house()] if args.synthetic else [])
    doc = {"meta": machine_meta() | {"frames": args.frames, "repeats": args.repeats}, "results": []}
    print(TABLE_HEAD)
    for scene in scenes:
        modes = {"random": random_poses(scene, args.frames), "walk": walk_poses(scene, args.frames)}
        for w, h in sizes:
            for rgb in (True, False):
                cfg = CameraConfig(width=w, height=h, rgb=rgb)
                for mode, ps in modes.items():
                    res = compare(scene, cfg, ps, args.repeats)
                    res.update(scene=scene.scene_id, faces=scene.mesh.num_faces, width=w, height=h,
                               hfov_deg=cfg.hfov_deg, rgb=rgb, poses=mode)  # fmt: skip
                    doc["results"].append(res)
                    label = f"{scene.scene_id[:12]} {w}x{h} {'rgb' if rgb else 'no-rgb'} {mode}"
                    print(table_line(label, res), flush=True)
    doc["meta"]["loadavg_end"] = list(os.getloadavg())
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(Path(args.out), json.dumps(doc, indent=2))
    print(f"load average {doc['meta']['loadavg_start'][0]:.2f} -> {doc['meta']['loadavg_end'][0]:.2f}; "
          f"wrote {args.out}")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
