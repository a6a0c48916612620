"""Per-step cost of the frontier expert's `act` over whole episodes, at several map sizes.

Usage: python benchmarks/expert_speed.py [--out benchmarks/results/expert_speed.json] [--episodes 6]

Maps: house-like room grids (`ovon.experts.gridsim.room_grid`, 4 m rooms, doors, furniture, radius
erosion) at 0.05 m cells, square sizes 128, 256, 400 and 1000 cells (6.4 m to 50 m across), and
procedural houses (unless `--no-procedural`) (`generate_house` + `build_navigation`) at several cell sizes.
Episodes: random start and goal on the largest island (goal preferably beyond the bee-line distance,
so exploration dominates), 500 steps at most, simulator kinematics, no rendering. The first episode of a
run only warms up the numba kernels and is not counted.
Reported per map size: median / p95 / mean / max ms of `act` (wall clock around the call; `act_cpu` =
the calling thread's CPU time, robust to other processes sharing the cores) and of its phases
(visibility, frontier update, choice = decision incl. frontier choice and path following),
reset ms, steps, success rate. Reference (docs/spec.md#expert-speed): an upstream-like expert cost about 2 ms/step at
128x128 and 8 ms/step at 400x400 on a 2-core machine.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from ovon.atomic import atomic_write_text  # noqa: E402
from ovon.config.sim import AgentConfig  # noqa: E402
from ovon.experts import FrontierExpert, FrontierExpertConfig  # noqa: E402
from ovon.experts.gridsim import grid_from_arrays, room_grid  # noqa: E402
from ovon.sim.agent import STOP, Kinematics  # noqa: E402
from ovon.sim.geodesic import distance_field  # noqa: E402
from ovon.sim.types import AgentState  # noqa: E402

PHASES = ("visibility", "frontiers", "choice")


def pick_episode(grid, rng: np.random.Generator, min_goal_m: float) -> tuple[np.ndarray, np.ndarray] | None:
    big = int(np.argmax(grid.island_area))
    for _ in range(50):
        start = grid.random_point(rng, min_island_radius=float(grid.island_radius[big]) - 1e-6)
        goal = grid.random_point(rng, min_island_radius=float(grid.island_radius[big]) - 1e-6)
        d = distance_field(grid, goal[None]).distance(start)
        if math.isfinite(d) and d >= min_goal_m:
            return start, goal
    return None


def run_episode(expert: FrontierExpert, grid, start, goal, yaw: float, max_steps: int) -> dict:
    kin = Kinematics(grid, AgentConfig())
    state = AgentState(start, yaw)
    t0 = time.perf_counter()
    expert.reset(grid, [(goal, 0.0)], state)
    reset_ms = (time.perf_counter() - t0) * 1e3
    steps: list[list[float]] = []
    action = -1
    for _ in range(max_steps):
        c = time.thread_time()
        t = time.perf_counter()
        action = expert.act(state)
        act_ms = (time.perf_counter() - t) * 1e3
        cpu_ms = (time.thread_time() - c) * 1e3
        tm = expert.timing
        steps.append([act_ms, cpu_ms] + [tm[p] for p in PHASES])
        if action == STOP:
            break
        state = kin.step(state, action).state
    d = distance_field(grid, goal[None]).distance(state.position)
    return {
        "reset_ms": reset_ms,
        "steps": np.array(steps),
        "success": bool(action == STOP and d < 0.25),
        "choices": expert.n_choices,
    }


def summarise(rows: np.ndarray) -> dict:
    out = {}
    for j, name in enumerate(("act", "act_cpu") + PHASES):
        v = rows[:, j]
        out[name] = {
            "median_ms": float(np.median(v)),
            "p95_ms": float(np.percentile(v, 95)),
            "mean_ms": float(np.mean(v)),
            "max_ms": float(np.max(v)),
        }
    return out


def bench_grid(label: str, grid, episodes: int, rng: np.random.Generator, max_steps: int, cfg) -> dict:
    expert = FrontierExpert(cfg)
    all_rows, resets, succ, choices = [], [], [], 0
    for _ in range(episodes):
        ep = pick_episode(grid, rng, min_goal_m=cfg.beeline_distance_m + 2.0)
        if ep is None:
            ep = pick_episode(grid, rng, min_goal_m=0.5)
        if ep is None:
            continue
        r = run_episode(expert, grid, ep[0], ep[1], float(rng.uniform(-math.pi, math.pi)), max_steps)
        all_rows.append(r["steps"])
        resets.append(r["reset_ms"])
        succ.append(r["success"])
        choices += r["choices"]
    rows = np.concatenate(all_rows)
    res = {
        "map": label,
        "shape": list(grid.navigable.shape),
        "cell_size": float(grid.cell_size),
        "navigable_cells": int(grid.navigable.sum()),
        "episodes": len(all_rows),
        "steps": int(rows.shape[0]),
        "choices_per_step": choices / max(1, rows.shape[0]),
        "success_rate": float(np.mean(succ)) if succ else 0.0,
        "reset_ms_median": float(np.median(resets)),
        **summarise(rows),
    }
    a = res["act"]
    print(
        f"{label:>28s} {res['shape'][0]:>5d}x{res['shape'][1]:<5d} steps {res['steps']:>5d}  act median "
        f"{a['median_ms']:.3f} p95 {a['p95_ms']:.3f} mean {a['mean_ms']:.3f} max {a['max_ms']:.2f} ms | "
        + " ".join(f"{p} {res[p]['median_ms']:.3f}/{res[p]['p95_ms']:.3f}" for p in PHASES)
        + f" | cpu {res['act_cpu']['median_ms']:.3f}/{res['act_cpu']['p95_ms']:.3f}"
        + f" | SR {res['success_rate']:.2f} reset {res['reset_ms_median']:.1f} ms",
        flush=True,
    )
    return res


def procedural_grids(cell_sizes: list[float]) -> list[tuple[str, object]]:
    try:
        from ovon.config.sim import NavConfig
        from ovon.scenes.procedural import generate_house
        from ovon.sim.navgrid import build_navigation

        scene = generate_house(0)
        out = []
        for cs in cell_sizes:
            nav = build_navigation(scene, AgentConfig(), NavConfig(cell_size=cs))
            g = max(nav.floors, key=lambda f: int(f.navigable.sum()))
            out.append((f"procedural house 0 @{cs:g} m", g))
        return out
    except Exception as e:  # the procedural generator is optional here
        print(f"procedural houses skipped: {type(e).__name__}: {e}", flush=True)
        return []


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="benchmarks/results/expert_speed.json")
    ap.add_argument("--sizes", default="128,256,400,1000")
    ap.add_argument("--cell-size", type=float, default=0.05)
    ap.add_argument("--episodes", type=int, default=6)
    ap.add_argument("--max-steps", type=int, default=500)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-procedural", action="store_true", help="skip the procedural houses")
    args = ap.parse_args(argv)
    cfg = FrontierExpertConfig()
    rng = np.random.default_rng(args.seed)

    # warm-up: compile every numba kernel once (cache=True makes later processes start warm)
    wf, wn = room_grid(160, 160, np.random.default_rng(123), cell_size=args.cell_size)
    bench_grid("warm-up", grid_from_arrays(wf, wn, args.cell_size), 3, np.random.default_rng(1), 300, cfg)

    results = []
    for n in (int(s) for s in args.sizes.split(",") if s):
        free, nav = room_grid(n, n, np.random.default_rng(args.seed + n), cell_size=args.cell_size)
        grid = grid_from_arrays(free, nav, args.cell_size)
        results.append(bench_grid(f"rooms {n * args.cell_size:g} m", grid, args.episodes, rng, args.max_steps, cfg))
    if not args.no_procedural:
        for label, grid in procedural_grids([0.1, 0.05, 0.03]):
            results.append(bench_grid(label, grid, args.episodes, rng, args.max_steps, cfg))

    out = {
        "benchmark": "frontier expert act() per step",
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count(), "python": sys.version.split()[0]},
        "config": {k: getattr(cfg, k) for k in cfg.__dataclass_fields__},
        "reference_upstream_ms_per_step": {"128x128": 2.0, "400x400": 8.0},
        "results": results,
    }
    path = Path(args.out)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, json.dumps(out, indent=2))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
