"""Env-stack throughput: ovon's vector env against one env in this process and against Gymnasium's
AsyncVectorEnv (one env per process, the layout ovon used before), in the same run.

    python benchmarks/sim_throughput.py --out /tmp/sim_throughput.json [--scene procedural:0] [--steps 2000]
        [--workers 2] [--envs-per-worker 4] [--repeats 3]

Every configuration steps random actions 1-3 with auto-reset and renders depth + the semantic frame
(always: the episode tracker needs it) + RGB unless the row says "no rgb". Rows: 160x120 (the CPU
camera) with and without RGB, and the paper's 360x640 portrait camera. For each row: in-process (one
env, no vector env), gymnasium AsyncVectorEnv with `workers` envs, and ovon's vector env with `workers`
processes x `envs-per-worker` envs. Reported: median steps/s over `--repeats` alternating runs, CPU ms
per env step (this process + workers), the "CPU-bound" rate min(workers, cores) * 1000 / cpu_ms (what
the machine would do with idle cores), ratios to the baselines, and the load average.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("LP_NUM_THREADS", "0")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from ovon.config.sim import CameraConfig, SimConfig  # noqa: E402
from ovon.env.bench import _cpu_seconds, _result, measure_throughput, pick_goal  # noqa: E402
from ovon.env.stack import EnvRecipe  # noqa: E402

TARGET = 1000.0  # steps/s with 2 workers at 160x120 (issue: "One environment stack, fast")


def gymnasium_async(recipe: EnvRecipe, workers: int, steps: int, warmup: int = 20, seed: int = 0) -> dict:
    """The old layout: gymnasium.vector.AsyncVectorEnv, one env per process, shared memory."""
    from gymnasium.vector import AsyncVectorEnv, AutoresetMode

    fns = [functools.partial(_make_notext, recipe) for _ in range(workers)]
    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    vec = AsyncVectorEnv(fns, shared_memory=True, context="spawn", autoreset_mode=AutoresetMode.SAME_STEP)
    try:
        vec.reset(seed=seed)
        pids = [p.pid for p in vec.processes]
        calls = max(1, steps // workers)
        for i in range(warmup + calls):
            if i == warmup:
                setup = time.perf_counter() - t0
                t1, c1, w1 = time.perf_counter(), time.process_time(), _cpu_seconds(pids)
            vec.step(rng.integers(1, 4, size=workers))
        dt = time.perf_counter() - t1
        cpu = time.process_time() - c1 + _cpu_seconds(pids) - w1
    finally:
        vec.close()
    return _result(calls * workers, dt, cpu, workers, workers, setup)


def _make_notext(recipe: EnvRecipe):
    from gymnasium import spaces

    from ovon.env.core import ObjectNavEnv

    env = ObjectNavEnv(scene=recipe.scene, goal=recipe.goal, sim=recipe.sim, task=recipe.task)
    env.observation_space = spaces.Dict({k: v for k, v in env.observation_space.spaces.items() if k != "goal"})
    inner_obs = env._obs

    def obs_without_goal(*a, **k):
        o = inner_obs(*a, **k)
        o.pop("goal")
        return o

    env._obs = obs_without_goal
    return env


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="procedural:0")
    ap.add_argument("--steps", type=int, default=2000, help="timed env steps per configuration")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--envs-per-worker", type=int, default=4)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--rows", default="160x120,160x120-norgb,360x640")
    ap.add_argument("--out", required=True, help="JSON output path")
    args = ap.parse_args(argv)

    goal = pick_goal(args.scene)
    rows = []
    load_before = os.getloadavg()
    for row in args.rows.split(","):
        size, _, flag = row.partition("-")
        w, h = (int(x) for x in size.split("x"))
        cam = CameraConfig(width=w, height=h, rgb=flag != "norgb")
        recipe = EnvRecipe(sim=SimConfig(camera=cam), scene=args.scene, goal=goal)
        n = args.workers * args.envs_per_worker
        runs: dict[str, list[dict]] = {"in_process": [], "gymnasium_async": [], "ovon_vector": []}
        for _ in range(args.repeats):  # alternate, so slow phases of a shared machine hit all alike
            runs["in_process"].append(measure_throughput(recipe, workers=0, steps=args.steps // 2))
            runs["gymnasium_async"].append(gymnasium_async(recipe, args.workers, args.steps))
            runs["ovon_vector"].append(measure_throughput(recipe, workers=args.workers, envs=n, steps=args.steps))
        med = {k: {m: statistics.median(r[m] for r in v) for m in ("steps_per_s", "cpu_ms_per_step",
                                                                  "cpu_bound_steps_per_s")} for k, v in runs.items()}
        entry = {"row": row, "width": w, "height": h, "rgb": cam.rgb, "workers": args.workers, "envs": n,
                 "median": med, "runs": runs,
                 "ratio_vs_gymnasium_async": med["ovon_vector"]["steps_per_s"] / med["gymnasium_async"]["steps_per_s"],
                 "ratio_vs_in_process": med["ovon_vector"]["steps_per_s"] / med["in_process"]["steps_per_s"]}
        rows.append(entry)
        print(f"{row:>16}: in-process {med['in_process']['steps_per_s']:7.0f} | gymnasium async x{args.workers} "
              f"{med['gymnasium_async']['steps_per_s']:7.0f} | ovon vector {args.workers}x{args.envs_per_worker} "
              f"{med['ovon_vector']['steps_per_s']:7.0f} steps/s (x{entry['ratio_vs_gymnasium_async']:.2f} vs async, "
              f"x{entry['ratio_vs_in_process']:.2f} vs in-process; CPU-bound "
              f"{med['ovon_vector']['cpu_bound_steps_per_s']:.0f})", flush=True)
    result = {"scene": args.scene, "goal": goal, "steps": args.steps, "repeats": args.repeats,
              "target_steps_per_s": TARGET, "cpus": os.cpu_count(), "machine": platform.platform(),
              "time": time.strftime("%Y-%m-%dT%H:%M:%S"), "load_average_before": load_before,
              "load_average_after": os.getloadavg(), "rows": rows}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=1))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
