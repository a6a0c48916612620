"""ovon on habitat's own navmeshes against habitat's own numbers: navigable area and islands, the
top-down navigability map, geodesic distances and reachability, and an agent trajectory with sliding.

    .venv/bin/python benchmarks/navmesh_agreement.py [--navmesh-dir DIR] [--golden-dir DIR]
        [--cell-sizes 0.05,0.025] [--out benchmarks/results/navmesh_agreement.json]

Inputs (nothing is downloaded at run time):
* navmeshes: `<scene>.navmesh` files of habitat's test scenes in --navmesh-dir (default: the checkout's
  tests/fixtures/habitat, which holds van-gogh-room.navmesh). All of them come with the
  `habitat_test_scenes` dataset: `python -m habitat_sim.utils.datasets_download --uids habitat_test_scenes
  --data-path data/` (or clone huggingface.co/datasets/ai-habitat/habitat_test_scenes), then
  --navmesh-dir data/scene_datasets/habitat-test-scenes.
* golden numbers (habitat-lab and habitat-sim tests, MIT): tests/fixtures/habitat (see its README).

Baselines in the same run: geodesics from the distance field with the fast-marching front started at
0.75 cells (the seeding before this change) and at `SEED_CIRCLE_CELLS` (now), and the 3D length of the
string-pulled path; each at every cell size; and `navmesh`, habitat's own polygon A* and funnel
(`ovon.sim.navmesh.pathfind`), which needs no grid (repeated per cell size, identical).
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import ovon  # noqa: E402
from ovon.atomic import atomic_write_text, json_dumps  # noqa: E402
from ovon.config.sim import NavConfig  # noqa: E402
from ovon.sim import geodesic, navgrid  # noqa: E402
from ovon.sim.navmesh import NavMeshWarning, load_navmesh, read_navmesh  # noqa: E402
from ovon.sim.navmesh.agreement import (  # noqa: E402
    HABITAT_AGENT,
    geodesic_agreement,
    island_agreement,
    navigability_agreement,
    topdown_agreement,
    trajectory_agreement,
)

FIXTURES = Path(ovon.__file__).resolve().parents[1] / "tests" / "fixtures" / "habitat"  # in a checkout
OLD_SEED_CELLS = 0.75  # the fast-marching seed circle before this benchmark was written


def _geodesics(sn, golden: dict) -> dict:
    out = {}
    now = geodesic.SEED_CIRCLE_CELLS
    try:
        for label, cells in (("field_seed_0.75_cells", OLD_SEED_CELLS), (f"field_seed_{now}_cells", now)):
            geodesic.SEED_CIRCLE_CELLS = cells
            geodesic.clear_cache()
            out[label] = geodesic_agreement(sn, golden, "field")
    finally:
        geodesic.SEED_CIRCLE_CELLS = now
        geodesic.clear_cache()
    out["path"] = geodesic_agreement(sn, golden, "path")
    out["navmesh"] = geodesic_agreement(sn, golden, "navmesh")  # polygon A* + funnel, the default here
    return out


def run(navmesh_dir: Path, golden_dir: Path, cell_sizes: list[float]) -> dict:
    habitat = json.loads((golden_dir / "habitat_sim_golden.json").read_text())
    geo = json.loads((golden_dir / "test-sim-geodesic-distance-test-golden.json").read_text())
    traj = json.loads((golden_dir / "habitat-sim_trajectory_data.json").read_text())
    scenes: dict = {}
    missing = []
    for name, gold in habitat["scenes"].items():
        path = navmesh_dir / f"{name}.navmesh"
        if not path.is_file():
            missing.append(name)
            continue
        mesh = read_navmesh(path)
        row: dict = {"navmesh": str(path), "islands": island_agreement(mesh, gold), "by_cell_size": {}}
        for cs in cell_sizes:
            navgrid.clear_cache()
            t = time.perf_counter()
            sn = load_navmesh(path, HABITAT_AGENT, NavConfig(cell_size=cs))
            cell: dict = {
                "load_s": time.perf_counter() - t,
                "grid_navigable_area": island_agreement(mesh, {}, sn)["grid_navigable_area"],
            }
            if gold.get("topdown_binary") and (golden_dir / gold["topdown_binary"]).is_file():
                cell["topdown"] = topdown_agreement(mesh, sn, np.load(golden_dir / gold["topdown_binary"]))
            cell["navigability"] = navigability_agreement(sn)
            if name == "van-gogh-room":  # habitat-lab's geodesic and trajectory goldens are on this scene
                cell["geodesic"] = _geodesics(sn, geo)
                cell["trajectory"] = {h: trajectory_agreement(sn, traj, how=h) for h in ("grid", "navmesh")}
            row["by_cell_size"][str(cs)] = cell
        scenes[name] = row
    return {"scenes": scenes, "navmeshes_not_found": missing}


def _print(res: dict) -> None:
    for name, row in res["scenes"].items():
        isl = row["islands"]
        nan = float("nan")
        area, hab, err = (isl.get(k, nan) for k in ("navigable_area", "habitat_navigable_area", "area_rel_error"))
        ia, ir = (isl.get(k, nan) for k in ("island_area_max_rel_error", "island_radius_max_rel_error"))
        print(
            f"{name}: habitat area {hab:.4f} m^2, ovon (navmesh) {area:.4f} m^2 (rel err {err:.1e}); islands "
            f"{isl['num_islands']} (habitat {isl['habitat_num_islands']}), island area / radius max rel err "
            f"{ia:.1e} / {ir:.1e}"
        )
        for cs, cell in row["by_cell_size"].items():
            line = (
                f"  cells {cs} m: grid area {cell['grid_navigable_area']:.3f} m^2 (navmesh projected on the floor "
                f"{isl['navigable_area_2d']:.3f}), load {cell['load_s']:.2f} s"
            )
            if "topdown" in cell:
                td = cell["topdown"]
                line += (
                    f"; top-down map: navmesh point test {100 * td['navmesh_point_test_agrees']:.2f}% "
                    f"({td['navmesh_point_test_mismatch_beyond_1cm']} pixels off by > 1 cm), grid "
                    f"{100 * td['grid_agrees']:.2f}% (IoU {td['grid_iou']:.3f})"
                )
            print(line)
            nv = cell["navigability"]
            print(
                f"    of {nv['points']} points habitat calls navigable: the grid blocks "
                f"{100 * nv['grid_blocked']:.2f}%, the scene refuses {100 * nv['scene_refuses']:.2f}% "
                f"(as a start {100 * nv['start_refused']:.2f}%)"
            )
            for label, g in cell.get("geodesic", {}).items():
                print(
                    f"    geodesic {label}: rel err mean {100 * g['mean_rel_error']:.3f}%, median "
                    f"{100 * g['median_rel_error']:.3f}%, p95 {100 * g['p95_rel_error']:.3f}%, max "
                    f"{100 * g['max_rel_error']:.3f}% (mean abs {100 * g['mean_abs_error_m']:.2f} cm), reachability "
                    f"{g['reachability_agrees']}/{g['pairs']} ({g['habitat_unreachable']} unreachable in habitat)"
                )
            for how, tr in cell.get("trajectory", {}).items():
                print(
                    f"    trajectory on the {how} ({tr['steps']} steps, sliding): xz error mean "
                    f"{100 * tr['mean_xz_error_m']:.4f} cm, median {100 * tr['median_xz_error_m']:.4f}, p95 "
                    f"{100 * tr['p95_xz_error_m']:.4f}, max {100 * tr['max_xz_error_m']:.4f} cm"
                )
    if res["navmeshes_not_found"]:
        print(f"not found (skipped): {', '.join(n + '.navmesh' for n in res['navmeshes_not_found'])}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--navmesh-dir", default=str(FIXTURES), help="folder of <scene>.navmesh files")
    ap.add_argument("--golden-dir", default=str(FIXTURES), help="folder of habitat's golden data")
    ap.add_argument("--cell-sizes", default="0.05,0.025")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "navmesh_agreement.json"))
    args = ap.parse_args()
    navmesh_dir, golden_dir = Path(args.navmesh_dir), Path(args.golden_dir)
    for d in (navmesh_dir, golden_dir):
        if not d.is_dir():
            print(f"navmesh_agreement: error: {d} is not a folder", file=sys.stderr)
            return 2
    try:
        cell_sizes = [float(x) for x in args.cell_sizes.split(",") if x.strip()]
    except ValueError:
        print(
            f"navmesh_agreement: error: --cell-sizes {args.cell_sizes!r}: expected numbers like 0.05,0.025",
            file=sys.stderr,
        )
        return 2
    warnings.simplefilter("ignore", NavMeshWarning)
    res = run(navmesh_dir, golden_dir, cell_sizes)
    if not res["scenes"]:
        print(
            f"navmesh_agreement: error: no <scene>.navmesh of {', '.join(res['navmeshes_not_found'])} in {navmesh_dir}",
            file=sys.stderr,
        )
        return 2
    res["machine"] = {"python": platform.python_version(), "platform": platform.platform()}
    _print(res)
    atomic_write_text(args.out, json_dumps(res, indent=1) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
