"""Milliseconds per geodesic query to a new goal, per method, in one run: the polygon A* + funnel on the
navmesh (`navmesh`, habitat's own answer) beside the distance field built for that goal (`field`, today's
default for episodes and metrics) and its string-pulled path (`path`), plus a query to a cached field.

    .venv/bin/python benchmarks/geodesic_query_speed.py [--navmesh-dir DIR] [--pairs 200]
        [--houses 0,1] [--out /tmp/geodesic_query_speed.json]

Scenes: every `*.navmesh` in --navmesh-dir (default: the checkout's tests/fixtures/habitat, which holds
habitat's van-gogh-room; habitat's other test scenes download with `python -m
habitat_sim.utils.datasets_download --uids habitat_test_scenes`), and procedural houses turned into a
navmesh of 0.25 m squares (more polygons than Recast would make: a pessimistic case for the A*). Each
field method runs on the grid ovon rasterises from that same navmesh. Writes JSON to --out (default: the
temp folder, so a casual run leaves the checkout unchanged). Compare ratios, not absolute times: the
machine is shared and noisy.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from navmesh_files import cells_to_polys, make_navmesh, make_tile  # noqa: E402

from ovon.atomic import atomic_write_text  # noqa: E402
from ovon.sim import geodesic, navgrid  # noqa: E402
from ovon.sim.navmesh import NavMeshWarning, load_navmesh, read_navmesh, write_navmesh  # noqa: E402
from ovon.sim.navmesh.agreement import HABITAT_AGENT  # noqa: E402
from ovon.sim.navmesh.pathfind import PathFinder  # noqa: E402

COARSE = 0.25  # m: polygon size of a procedural house's navmesh


def house_navmesh(seed: int, folder: Path) -> Path:
    """A procedural house's largest floor as a navmesh of COARSE squares (a square where every grid cell
    under it is navigable)."""
    from ovon.scenes.procedural import generate_house

    nav = navgrid.build_navigation(generate_house(seed))
    g = max(nav.floors, key=lambda f: int(f.navigable.sum()))
    k = max(1, round(COARSE / g.cell_size))
    rows, cols = g.navigable.shape[0] // k, g.navigable.shape[1] // k
    blocks = g.navigable[: rows * k, : cols * k].reshape(rows, k, cols, k)
    mask = blocks.all(axis=(1, 3))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-nan blocks are not in the mask
        heights = np.nanmean(g.heights[: rows * k, : cols * k].reshape(rows, k, cols, k), axis=(1, 3))
    polys = cells_to_polys(mask, (float(g.origin[0]), float(g.origin[1])), k * g.cell_size, heights)
    path = folder / f"procedural_{seed}.navmesh"
    write_navmesh(make_navmesh([make_tile(polys, radius=HABITAT_AGENT.radius)]), path)
    return path


def _pairs(sn, pf: PathFinder, n: int, rng: np.random.Generator) -> list[tuple[np.ndarray, np.ndarray]]:
    g = max(sn.floors, key=lambda f: int(f.navigable.sum()))
    out, tries = [], 0
    while len(out) < n and tries < 50 * n:
        tries += 1
        a, b = g.random_point(rng), g.random_point(rng)
        if pf.is_navigable(a) and pf.is_navigable(b) and math.isfinite(pf.geodesic_distance(a, b)):
            out.append((a, b))
    return out


def bench(path: Path, n: int, rng: np.random.Generator) -> dict:
    navgrid.clear_cache()
    sn = load_navmesh(path, HABITAT_AGENT)
    t = time.perf_counter()
    pf = PathFinder(read_navmesh(path))
    build_s = time.perf_counter() - t
    pairs = _pairs(sn, pf, n, rng)
    grid = max(sn.floors, key=lambda f: int(f.navigable.sum()))
    a0, b0 = pairs[0]
    pf.geodesic_distance(a0, b0)
    geodesic.distance_field(grid, b0[None]).path_length(a0)  # JIT warm-up
    times: dict[str, list[float]] = {
        k: [] for k in ("navmesh", "field", "path", "field_cached", "navmesh_cold", "navmesh_step", "field_step")
    }
    errs: dict[str, list[float]] = {"field": [], "path": []}
    d_nav = []
    for a, b in pairs:  # back to back, as dataset generation and validation ask
        t = time.perf_counter()
        d_nav.append(pf.geodesic_distance(a, b))
        times["navmesh"].append(time.perf_counter() - t)
    # an episode's distance-to-goal per step: VIEWPOINTS goal points around one object, snapped once
    ring = [b0 + np.array([math.cos(t), 0.0, math.sin(t)]) * r for t in np.linspace(0, 2 * math.pi, 20, endpoint=False)
            for r in (0.5, 1.0)]  # fmt: skip
    vps = np.array([p for p in ring if pf.is_navigable(p)] or [b0])
    measure = pf.distance_to(vps)
    field_vps = geodesic.distance_field(grid, vps)
    for a, _ in pairs:
        t = time.perf_counter()
        measure(a)
        times["navmesh_step"].append(time.perf_counter() - t)
        t = time.perf_counter()
        field_vps.distance(a)
        times["field_step"].append(time.perf_counter() - t)
    for (a, b), dn in zip(pairs, d_nav):
        geodesic.clear_cache()
        t = time.perf_counter()
        d_field = geodesic.distance_field(grid, b[None]).distance(a)
        times["field"].append(time.perf_counter() - t)
        t = time.perf_counter()
        d_field2 = geodesic.distance_field(grid, b[None]).distance(a)
        times["field_cached"].append(time.perf_counter() - t)
        assert d_field2 == d_field
        t = time.perf_counter()  # right after a field was built: the polygon arrays are out of the caches
        pf.geodesic_distance(a, b)
        times["navmesh_cold"].append(time.perf_counter() - t)
        geodesic.clear_cache()
        t = time.perf_counter()
        d_path = geodesic.distance_field(grid, b[None]).path_length(a)
        times["path"].append(time.perf_counter() - t)
        for k, d in (("field", d_field), ("path", d_path)):
            if math.isfinite(d) and dn > 0.5:
                errs[k].append(abs(d - dn) / dn)
    row: dict = {
        "navmesh": path.name,
        "polygons": pf.g.count,
        "pairs": len(pairs),
        "grid": list(grid.navigable.shape),
        "pathfinder_build_s": build_s,
        "step_viewpoints": len(vps),
    }
    for k, v in times.items():
        row[f"{k}_ms"] = float(np.median(v)) * 1e3
    for k in ("field", "path", "field_cached"):
        row[f"{k}_over_navmesh"] = row[f"{k}_ms"] / row["navmesh_ms"]
    row["field_over_navmesh_cold"] = row["field_ms"] / row["navmesh_cold_ms"]
    for k, e in errs.items():
        a = np.asarray(e)
        row[f"{k}_vs_navmesh_rel_err"] = (
            {"mean": float(a.mean()), "median": float(np.median(a)), "p95": float(np.quantile(a, 0.95))}
            if len(a)
            else None
        )
    return row


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--navmesh-dir", default=str(ROOT / "tests" / "fixtures" / "habitat"))
    ap.add_argument("--pairs", type=int, default=200)
    ap.add_argument("--houses", default="0,1", help="procedural house seeds ('' for none)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=str(Path(tempfile.gettempdir()) / "geodesic_query_speed.json"))
    args = ap.parse_args()
    folder = Path(args.navmesh_dir)
    if not folder.is_dir():
        print(f"geodesic_query_speed: error: --navmesh-dir {folder} is not a folder", file=sys.stderr)
        return 2
    if args.pairs < 2:
        print(f"geodesic_query_speed: error: --pairs {args.pairs}: expected at least 2", file=sys.stderr)
        return 2
    warnings.simplefilter("ignore", NavMeshWarning)
    rng = np.random.default_rng(args.seed)
    paths = sorted(folder.glob("*.navmesh"))
    with tempfile.TemporaryDirectory() as tmp:
        for s in (x for x in args.houses.split(",") if x.strip()):
            paths.append(house_navmesh(int(s), Path(tmp)))
        rows = [bench(p, args.pairs, rng) for p in paths]
    cols = ["navmesh", "polygons", "pairs", "navmesh_ms", "navmesh_cold_ms", "field_ms", "path_ms",
            "field_cached_ms", "field_over_navmesh", "field_over_navmesh_cold", "path_over_navmesh",
            "step_viewpoints", "navmesh_step_ms", "field_step_ms"]  # fmt: skip
    print(" | ".join(cols))
    for r in rows:
        print(" | ".join(f"{r[c]:.4g}" if isinstance(r[c], float) else str(r[c]) for c in cols))
    for r in rows:
        for k in ("field", "path"):
            e = r[f"{k}_vs_navmesh_rel_err"]
            if e:
                print(f"{r['navmesh']}: {k} vs navmesh rel err mean {e['mean']:.3%}, median {e['median']:.3%}, "
                      f"p95 {e['p95']:.3%}")  # fmt: skip
    result = {"machine": platform.platform(), "python": platform.python_version(), "rows": rows}
    atomic_write_text(args.out, json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
