"""ovon against habitat's own numbers on habitat's own navmeshes (golden data habitat-lab and
habitat-sim keep in their tests): geodesic distances and reachability, an agent trajectory with
sliding, the top-down navigability map, navigable area and islands.

Used by `benchmarks/navmesh_agreement.py` (benchmarks/README.md) and by the tests, so both
measure the same thing. Every function takes plain data (parsed JSON / arrays) and returns a dict.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ovon.config.sim import AgentConfig
from ovon.sim.navgrid import SceneNav
from ovon.sim.navmesh.format import NavMesh
from ovon.sim.navmesh.polys import compute_islands, navmesh_triangles
from ovon.sim.navmesh.raster import lowest_samples

# habitat-lab's default agent (habitat.config.default_structured_configs): what its golden trajectory used
HABITAT_AGENT = AgentConfig(radius=0.1, height=1.5, max_climb=0.2, forward_step=0.25, turn_angle_deg=10.0,
                            allow_sliding=True)  # fmt: skip


def _distance(sn: SceneNav, start: np.ndarray, goals: np.ndarray, how: str) -> float:
    from ovon.sim.geodesic import distance_field, geodesic_distance

    if how == "navmesh":
        return geodesic_distance(sn, start, goals, how="navmesh")
    if not sn.floors:
        return math.inf
    fi = sn.floor_index(start)
    same = np.array([sn.floor_index(g) == fi for g in goals], dtype=bool)
    if not same.any():
        return math.inf
    f = distance_field(sn.floors[fi], goals[same])
    return f.distance(start) if how == "field" else f.path_length(start)


def geodesic_agreement(sn: SceneNav, golden: dict, how: str = "field") -> dict[str, Any]:
    """habitat-lab's geodesic golden file ({"single_end": [{start, end, expected}], "multi_end": [{start,
    ends, expected}]}) against ovon's distance (`how`: "navmesh", "field" or "path", see `geodesic_distance`)."""
    rows = []
    for kind, key in (("single", "end"), ("multi", "ends")):
        for case in golden.get(f"{kind}_end", []):
            goals = np.asarray(case[key], dtype=np.float64).reshape(-1, 3)
            ours = _distance(sn, np.asarray(case["start"], dtype=np.float64), goals, how)
            rows.append({"kind": kind, "habitat": float(case["expected"]), "ovon": ours})
    hab = np.array([r["habitat"] for r in rows])
    our = np.array([r["ovon"] for r in rows])
    both = np.isfinite(hab) & np.isfinite(our)
    rel = np.abs(our[both] - hab[both]) / np.maximum(hab[both], 1e-9)
    return {
        "how": how,
        "pairs": len(rows),
        "habitat_unreachable": int((~np.isfinite(hab)).sum()),
        "reachability_agrees": int((np.isfinite(hab) == np.isfinite(our)).sum()),
        "mean_rel_error": float(rel.mean()) if len(rel) else math.nan,
        "median_rel_error": float(np.median(rel)) if len(rel) else math.nan,
        "p95_rel_error": float(np.quantile(rel, 0.95)) if len(rel) else math.nan,
        "max_rel_error": float(rel.max()) if len(rel) else math.nan,
        "mean_abs_error_m": float(np.abs(our[both] - hab[both]).mean()) if len(rel) else math.nan,
        "rows": [{"kind": r["kind"], "habitat": r["habitat"] if math.isfinite(r["habitat"]) else None,
                  "ovon": r["ovon"] if math.isfinite(r["ovon"]) else None} for r in rows],
    }  # fmt: skip


def trajectory_agreement(
    sn: SceneNav, trajectory: dict, agent: AgentConfig = HABITAT_AGENT, how: str = "grid"
) -> dict[str, Any]:
    """Replay habitat-lab's recorded trajectory ({"positions", "rotations" [x, y, z, w], "actions"}) from its
    first pose with ovon's kinematics, on the grid (`how="grid"`) or on the navmesh's polygons ("navmesh",
    what a scene read from a navmesh does); per step the xz distance to habitat's position after that action."""
    from ovon.sim.agent import ACTION_NAMES, Kinematics
    from ovon.sim.navmesh.pathfind import path_finder
    from ovon.sim.types import AgentState

    pos = np.asarray(trajectory["positions"], dtype=np.float64)
    q = trajectory["rotations"][0]
    state = AgentState(pos[0].copy(), 2.0 * math.atan2(float(q[1]), float(q[3])))
    if how not in ("grid", "navmesh"):
        raise ValueError(f"unknown kinematics {how!r} (grid | navmesh)")
    surface = path_finder(sn.source) if how == "navmesh" else None
    kin = Kinematics(sn.grid_for(pos[min(1, len(pos) - 1)]), agent, surface=surface)
    errors = []
    collisions = 0
    for i, name in enumerate(trajectory["actions"][:-1]):  # the last action is STOP
        step = kin.step(state, ACTION_NAMES.index(name))
        state = step.state
        collisions += int(step.collided)
        errors.append(float(np.hypot(*(state.position - pos[i + 1])[[0, 2]])))
    e = np.asarray(errors)
    return {
        "how": how,
        "steps": len(e),
        "median_xz_error_m": float(np.median(e)),
        "p95_xz_error_m": float(np.quantile(e, 0.95)),
        "mean_xz_error_m": float(e.mean()),
        "max_xz_error_m": float(e.max()),
        "final_xz_error_m": float(e[-1]),
        "collisions": collisions,
        "errors_m": [round(x, 5) for x in errors],
    }


def navigability_agreement(sn: SceneNav, points: int = 4000, seed: int = 0) -> dict[str, Any]:
    """Points habitat calls navigable (uniform over the navmesh's bounds, each lifted onto the surface below,
    kept when habitat's is_navigable says so): the fraction the scene's grid blocks, and the fraction the
    scene itself refuses (`sn.is_navigable`, `sn.start_problem`; 0 on a navmesh scene, whose polygons decide)."""
    from ovon.sim.navmesh.pathfind import path_finder

    pf = path_finder(sn.source)
    rng = np.random.default_rng(seed)
    lo, hi = pf.g.bmin.min(axis=0), pf.g.bmax.max(axis=0)
    kept = []
    for p in rng.uniform(lo, hi, size=(points, 3)):
        y = pf.snap_point(p)[1]
        q = np.array([p[0], y, p[2]])
        if math.isfinite(y) and pf.is_navigable(q):
            kept.append(q)
    n = max(len(kept), 1)
    return {
        "points": len(kept),
        "grid_blocked": sum(not sn.grid_for(q).is_navigable(q) for q in kept) / n,
        "scene_refuses": sum(not sn.is_navigable(q) for q in kept) / n,
        "start_refused": sum(sn.start_problem(q) is not None for q in kept) / n,
    }


def topdown_agreement(
    mesh: NavMesh,
    sn: SceneNav,
    golden: np.ndarray,
    meters_per_pixel: float = 0.1,
    max_y_delta: float = 0.5,
    xz_tolerance: float = 0.01,
) -> dict[str, Any]:
    """habitat's `get_topdown_view(mpp, lowest navmesh y)` against (a) the navmesh read by ovon, point by
    point (habitat also counts points within 1 cm of the navmesh), (b) ovon's grid (`sn`)."""
    isl = compute_islands(mesh)
    tris, _ = navmesh_triangles(mesh, isl)
    height = float(tris[:, :, 1].min())
    bmin = np.min([t.bmin for t in mesh.tiles], axis=0)
    bmax = np.max([t.bmax for t in mesh.tiles], axis=0)
    mpp32 = np.float32(meters_per_pixel)  # habitat's resolution arithmetic is float32
    cols = int(np.float32(abs(bmax[0] - bmin[0])) / mpp32)
    rows = int(np.float32(abs(bmax[2] - bmin[2])) / mpp32)
    mpp = float(mpp32)
    if golden.shape != (rows, cols):
        raise ValueError(
            f"golden top-down map has shape {golden.shape}, this navmesh gives {(rows, cols)} at "
            f"{meters_per_pixel} m per pixel: is it the map of another navmesh?"
        )
    h, _ = lowest_samples(
        tris,
        np.zeros(len(tris), np.int32),
        np.array([float(bmin[0]) - mpp / 2, float(bmin[2]) - mpp / 2]),
        float(mpp),
        rows,
        cols,
        np.array([height - max_y_delta]),
        np.array([height + max_y_delta]),
    )
    exact = ~np.isnan(h[0].reshape(rows, cols))
    rr, cc = np.nonzero(exact != golden)
    pts = np.stack([bmin[0] + cc * mpp, bmin[2] + rr * mpp], axis=1)
    near = _edge_distance(pts, tris[:, :, [0, 2]]) <= xz_tolerance + 1e-6 if len(pts) else np.zeros(0, bool)
    xs = bmin[0] + np.arange(cols) * mpp
    zs = bmin[2] + np.arange(rows) * mpp
    X, Z = np.meshgrid(xs, zs)
    P = np.stack([X.ravel(), np.full(X.size, height), Z.ravel()], axis=1)
    g = sn.grid_for(P[0])
    r, c = g.world_to_cell(P)
    ok = g.in_bounds(r, c)
    grid = np.zeros(len(P), bool)
    grid[ok] = g.navigable[r[ok], c[ok]] & (np.abs(g.heights[r[ok], c[ok]] - height) <= max_y_delta)
    grid = grid.reshape(rows, cols)
    return {
        "pixels": int(golden.size),
        "habitat_navigable": int(golden.sum()),
        "navmesh_point_test_agrees": float((exact == golden).mean()),
        "navmesh_point_test_mismatch": int(len(pts)),
        "navmesh_point_test_mismatch_beyond_1cm": int((~near).sum()),
        "grid_agrees": float((grid == golden).mean()),
        "grid_iou": float((grid & golden).sum() / max((grid | golden).sum(), 1)),
    }  # fmt: skip


def _edge_distance(p: np.ndarray, tri2: np.ndarray) -> np.ndarray:
    """Distance from each 2D point to the nearest edge of any 2D triangle."""
    a = tri2.reshape(-1, 3, 2)
    b = np.roll(a, -1, axis=1)
    a, b = a.reshape(-1, 2), b.reshape(-1, 2)
    ab = b - a
    out = np.empty(len(p))
    for i, q in enumerate(p):
        t = np.clip(((q - a) * ab).sum(1) / np.maximum((ab * ab).sum(1), 1e-12), 0.0, 1.0)
        out[i] = np.sqrt((((a + t[:, None] * ab) - q) ** 2).sum(1)).min()
    return out


def island_agreement(mesh: NavMesh, golden: dict, sn: SceneNav | None = None) -> dict[str, Any]:
    """Navigable area, island count / areas / radii (and bounds) against habitat-sim's recorded values;
    the walkable area projected on the floor (what a grid can cover) and, with `sn`, the area of ovon's grid
    (cells x cell area)."""
    isl = compute_islands(mesh)
    out: dict[str, Any] = {"num_islands": isl.count, "habitat_num_islands": int(golden.get("num_islands", -1))}
    if "navigable_area" in golden:
        out.update(
            navigable_area=isl.total_area,
            habitat_navigable_area=float(golden["navigable_area"]),
            area_rel_error=abs(isl.total_area - golden["navigable_area"]) / golden["navigable_area"],
        )
    hab = golden.get("islands", [])
    if hab and len(hab) == isl.count:
        out["island_area_max_rel_error"] = max(abs(isl.area[i] - h["area"]) / h["area"] for i, h in enumerate(hab))
        out["island_radius_max_rel_error"] = max(
            abs(isl.radius[i] - h["radius"]) / h["radius"] for i, h in enumerate(hab)
        )
    if "bounds_min" in golden:
        bmin = np.min([t.bmin for t in mesh.tiles], axis=0)
        bmax = np.max([t.bmax for t in mesh.tiles], axis=0)
        out["bounds_max_abs_error"] = float(
            max(np.abs(bmin - golden["bounds_min"]).max(), np.abs(bmax - golden["bounds_max"]).max())
        )
    tris, _ = navmesh_triangles(mesh, isl)
    e1, e2 = tris[:, 1, [0, 2]] - tris[:, 0, [0, 2]], tris[:, 2, [0, 2]] - tris[:, 0, [0, 2]]
    out["navigable_area_2d"] = float(0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum())
    if sn is not None:
        out["grid_navigable_area"] = float(sum(g.navigable.sum() * g.cell_size**2 for g in sn.floors))
    return out
