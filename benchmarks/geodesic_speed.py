"""Navigability build time, distance-field time (fast marching vs 16-neighbour Dijkstra, same run),
field accuracy on an empty floor, and cached query / path time.

    .venv/bin/python benchmarks/geodesic_speed.py [--out benchmarks/results/geodesic_speed.json]

Compare ratios within one run: the machine is shared and noisy.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from meshes import empty_floor, grid_house, scene_from_boxes  # noqa: E402

from ovon.atomic import atomic_write_text  # noqa: E402
from ovon.sim import geodesic, navgrid  # noqa: E402


def _time(fn, repeat: int) -> float:
    best = math.inf
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def bench_scene(name: str, scene, repeat: int, rng: np.random.Generator) -> dict:
    navgrid.clear_cache()
    t = time.perf_counter()
    nav = navgrid.build_navigation(scene)
    first = time.perf_counter() - t

    def cold_build():
        navgrid.clear_cache()
        navgrid.build_navigation(scene)

    build = _time(cold_build, repeat)
    nav = navgrid.build_navigation(scene)
    g = max(nav.floors, key=lambda f: int(f.navigable.sum()))
    row = {
        "scene": name,
        "faces": int(scene.mesh.num_faces),
        "floors": len(nav.floors),
        "grid": list(g.navigable.shape),
        "navigable_m2": float(g.navigable.sum() * g.cell_size**2),
        "islands": g.num_islands,
        "nav_build_first_s": first,
        "nav_build_s": build,
    }
    goals = [g.random_point(rng, min_island_radius=1.0) for _ in range(repeat)]
    for method in ("fmm", "dijkstra"):
        geodesic.distance_field(g, goals[0][None], method=method)  # JIT warm-up
        times = []
        for p in goals:
            geodesic.clear_cache()
            t = time.perf_counter()
            geodesic.distance_field(g, p[None], method=method)
            times.append(time.perf_counter() - t)
        row[f"field_{method}_s"] = float(np.median(times))
    row["dijkstra_over_fmm"] = row["field_dijkstra_s"] / row["field_fmm_s"]
    f = geodesic.distance_field(g, goals[0][None])
    queries = [g.random_point(rng) for _ in range(200)]
    n = 0
    t = time.perf_counter()
    for _ in range(50):
        for q in queries:
            f.distance(q)
            n += 1
    row["query_us"] = (time.perf_counter() - t) / n * 1e6
    reach = [q for q in queries if math.isfinite(f.distance(q))][:50]
    f.path(reach[0])  # JIT warm-up
    t = time.perf_counter()
    for q in reach:
        f.path(q)
    row["path_ms"] = (time.perf_counter() - t) / max(len(reach), 1) * 1e3
    return row, g


def accuracy_empty(g, rng: np.random.Generator, n_goals: int = 5, n_q: int = 40) -> dict:
    """Relative error of the field against the straight-line distance (pairs > 1 m apart)."""
    out = {}
    for method in ("fmm", "dijkstra"):
        errs = []
        for _ in range(n_goals):
            goal = g.random_point(rng)
            f = geodesic.distance_field(g, goal[None], method=method)
            for _ in range(n_q):
                q = g.random_point(rng)
                e = math.hypot(q[0] - goal[0], q[2] - goal[2])
                if e > 1.0:
                    errs.append(f.distance(q) / e - 1.0)
        a = np.abs(np.asarray(errs))
        out[method] = {"mean_abs_rel_err": float(a.mean()), "max_abs_rel_err": float(a.max()), "n": len(a)}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="benchmarks/results/geodesic_speed.json")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    rows = []
    row, g = bench_scene("empty_20x20", scene_from_boxes(empty_floor(20, 20), floor_heights=[0.0]), args.repeat, rng)
    rows.append(row)
    accuracy = accuracy_empty(g, rng)
    boxes = scene_from_boxes(grid_house(0), floor_heights=[0.0], scene_id="grid_house")
    rows.append(bench_scene("box_house_20x20", boxes, args.repeat, rng)[0])
    try:
        from ovon.scenes.procedural import generate_house
    except ImportError:
        generate_house = None
    if generate_house is not None:
        for seed in (0, 1):
            try:
                house = generate_house(seed)
            except Exception as e:  # the generator is optional here; report why it was skipped
                print(f"skipping procedural house {seed}: {type(e).__name__}: {e}")
                break
            rows.append(bench_scene(f"procedural_{seed}", house, args.repeat, rng)[0])
    cols = [
        "scene",
        "faces",
        "grid",
        "floors",
        "islands",
        "nav_build_first_s",
        "nav_build_s",
        "field_fmm_s",
        "field_dijkstra_s",
        "dijkstra_over_fmm",
        "query_us",
        "path_ms",
    ]
    print(" | ".join(cols))
    for r in rows:
        print(" | ".join(f"{r[c]:.4g}" if isinstance(r[c], float) else str(r[c]) for c in cols))
    for m, a in accuracy.items():
        print(f"empty floor accuracy {m}: mean |rel err| {a['mean_abs_rel_err']:.4%}, max {a['max_abs_rel_err']:.4%}")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    result = {
        "machine": platform.platform(),
        "python": platform.python_version(),
        "rows": rows,
        "accuracy_empty_floor": accuracy,
        "note": "nav_build_first_s includes numba JIT (or loading its on-disk cache); other times are warm",
    }
    atomic_write_text(out, json.dumps(result, indent=2))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
