"""Throughput of the env stack (`ovon sim bench`, benchmarks/sim_throughput.py).

Random actions 1-3 with same-step auto-reset (resets are inside the timed loop). CPU time of this
process and of the workers is reported beside wall time: on a shared machine, cpu_ms_per_step is the
figure that does not depend on what else runs.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Sequence

import numpy as np

from ovon.env.stack import EnvRecipe, build_env, make_vector_env


def pick_goal(scene: str) -> str:
    """A goal category for benchmarking: the most frequent floor-standing category of the scene."""
    from ovon.sim.world import load_scene_any

    s = load_scene_any(scene)
    counts: dict[str, int] = {}
    for o in s.objects:
        if o.category and float(o.aabb_min[1]) - (s.floor_heights[0] if s.floor_heights else 0.0) < 0.3:
            counts[o.category] = counts.get(o.category, 0) + 1
    if not counts:
        raise ValueError(f"scene {scene!r} has no categorised object to use as a goal")
    return max(sorted(counts), key=lambda c: counts[c])


def _cpu_seconds(pids: Sequence[int]) -> float:
    """User + system CPU seconds consumed so far by these processes (Linux /proc; 0 elsewhere)."""
    tick = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
    total = 0.0
    for pid in pids:
        try:
            with open(f"/proc/{pid}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
            total += (int(fields[11]) + int(fields[12])) / tick
        except (OSError, IndexError, ValueError):
            return 0.0
    return total


def measure_throughput(
    recipe: EnvRecipe, workers: int = 1, envs: int | None = None, steps: int = 400, warmup: int = 20, seed: int = 0
) -> dict[str, float]:
    """Env steps per second of `envs` copies of `recipe` (default: 4 per worker) on `workers` processes
    (0 = one env stepped directly in this process, no vector env at all). `steps` counts env steps
    over all envs. Returns steps_per_s, seconds, steps, workers, envs, setup_s, cpu_ms_per_step and
    cpu_bound_steps_per_s = min(workers, cpu_count) * 1000 / cpu_ms_per_step (the rate with an idle
    core per worker, which a contended machine hides)."""
    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    if workers <= 0:
        os.environ.setdefault("LP_NUM_THREADS", "0")
        from ovon.parallel import init_worker

        init_worker()
        env = build_env(recipe)
        env.reset(seed=seed)
        try:
            for i in range(warmup + steps):
                if i == warmup:
                    setup = time.perf_counter() - t0
                    t1, c1 = time.perf_counter(), time.process_time()
                _, _, term, trunc, _ = env.step(int(rng.integers(1, 4)))
                if term or trunc:
                    env.reset()
            dt, cpu = time.perf_counter() - t1, time.process_time() - c1
        finally:
            env.close()
        return _result(steps, dt, cpu, 0, 1, setup)
    n = envs or 4 * workers
    vec = make_vector_env(recipe, n, workers=workers, base_seed=seed)
    try:
        vec.reset(seed=seed)
        calls = max(1, steps // n)
        pids = vec.worker_pids
        for i in range(warmup + calls):
            if i == warmup:
                setup = time.perf_counter() - t0
                t1, c1, w1 = time.perf_counter(), time.process_time(), _cpu_seconds(pids)
            vec.step(rng.integers(1, 4, size=n))
        dt = time.perf_counter() - t1
        cpu = time.process_time() - c1 + _cpu_seconds(pids) - w1
    finally:
        vec.close()
    return _result(calls * n, dt, cpu, workers, n, setup)


def _result(steps: int, seconds: float, cpu: float, workers: int, envs: int, setup: float) -> dict[str, float]:
    cpu_ms = 1000.0 * cpu / steps
    return {
        "steps_per_s": steps / seconds,
        "seconds": seconds,
        "steps": steps,
        "workers": workers,
        "envs": envs,
        "setup_s": setup,
        "cpu_ms_per_step": cpu_ms,
        "cpu_bound_steps_per_s": max(1, min(workers, os.cpu_count() or 1)) * 1000.0 / cpu_ms
        if cpu_ms > 0
        else math.nan,
    }


def profile_step(recipe: EnvRecipe, steps: int = 200, seed: int = 0) -> dict[str, float]:
    """cProfile one in-process env stack for `steps` random steps; returns milliseconds per step spent
    in rendering, kinematics, the episode tracker, odometry, observation packing, and in total."""
    import cProfile
    import pstats

    os.environ.setdefault("LP_NUM_THREADS", "0")
    from ovon.parallel import init_worker

    init_worker()
    rng = np.random.default_rng(seed)
    env = build_env(recipe)
    env.reset(seed=seed)
    for _ in range(10):
        env.step(int(rng.integers(1, 4)))
    prof = cProfile.Profile()
    n = 0
    prof.enable()
    while n < steps:
        _, _, term, trunc, _ = env.step(int(rng.integers(1, 4)))
        n += 1
        if term or trunc:
            prof.disable()
            env.reset()
            prof.enable()
    prof.disable()
    env.close()
    stats = pstats.Stats(prof).stats  # {(file, line, func): (cc, nc, tt, ct, callers)}
    wanted = {
        "render": ("render", ("render/gl.py", "render/embree.py")),
        "kinematics": ("step", ("sim/agent.py",)),
        "tracker": ("update", ("task/tracker.py",)),
        "odometry": ("update", ("sim/agent.py",)),
        "observation": ("_obs", ("env/core.py",)),
        "total": ("step", ("env/core.py",)),
    }
    out: dict[str, float] = {}
    for key, (func, files) in wanted.items():
        ct = sum(v[3] for (f, _, name), v in stats.items() if name == func and f.replace("\\", "/").endswith(files))
        out[key] = 1000.0 * ct / steps
    return out
