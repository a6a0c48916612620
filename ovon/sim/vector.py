"""Vectorised environments: one `ObjectNavEnv` per worker process (`gymnasium.vector.AsyncVectorEnv`).

On the project's 2-core CPU machines neither llvmpipe threads nor Python threads speed rendering up
(docs: platform.md), so parallelism is one single-threaded environment per process: every worker calls
`ovon.parallel.init_worker()` (1 torch/OpenMP thread) and sets `LP_NUM_THREADS=0` (llvmpipe renders in
the calling thread) unless the variable is already set.

Batched observations are a dict of stacked arrays plus `obs["goal"]`, a tuple of `num_envs` strings
(gymnasium batches a `Text` space as a `Tuple` of `Text`). Transport: gymnasium 1.4's shared memory
does store `Text`, but `AsyncVectorEnv` reads it back only once at construction, so every later goal
string would be stale (a run of the first character). With `shared_memory=True` (the default) each
worker therefore moves the goal into `info["goal"]` and the parent-side `GoalFromInfo` wrapper puts it
back into the observation: images travel through shared memory, the short goal string through the
pipe. `shared_memory=False` pickles whole observations through the pipe instead (also correct).
"""

from __future__ import annotations

import functools
import math
import os
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AsyncVectorEnv, AutoresetMode, VectorEnv, VectorWrapper
from gymnasium.vector.utils import batch_space

EnvFactory = Callable[[int], gym.Env]


class GoalToInfo(gym.Wrapper):
    """Worker side: drops the `Text` "goal" from the observation and returns it as `info["goal"]`."""

    def __init__(self, env: gym.Env):
        super().__init__(env)
        space = env.observation_space
        assert isinstance(space, spaces.Dict) and isinstance(space["goal"], spaces.Text)
        self.goal_space = space["goal"]
        self.observation_space = spaces.Dict({k: v for k, v in space.items() if k != "goal"})

    def _split(self, obs: dict, info: dict) -> tuple[dict, dict]:
        obs = dict(obs)
        info = dict(info)
        info["goal"] = obs.pop("goal")
        return obs, info

    def reset(self, **kwargs):
        return self._split(*self.env.reset(**kwargs))

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        obs, info = self._split(obs, info)
        return obs, reward, terminated, truncated, info


class GoalFromInfo(VectorWrapper):
    """Parent side of `GoalToInfo`: puts the goal strings back as `obs["goal"]` (tuple of str)."""

    def __init__(self, env: VectorEnv, goal_space: spaces.Text):
        super().__init__(env)
        single = dict(env.single_observation_space.spaces)
        single["goal"] = goal_space
        self.single_observation_space = spaces.Dict(single)
        self.observation_space = batch_space(self.single_observation_space, env.num_envs)
        self._goals: list[str] = [""] * env.num_envs

    def _merge(self, obs: dict, info: dict) -> dict:
        goals = info.get("goal")
        mask = info.get("_goal")
        if goals is not None:
            for i in range(self.num_envs):
                if mask is None or mask[i]:
                    self._goals[i] = str(goals[i])
        obs = dict(obs)
        obs["goal"] = tuple(self._goals)
        return obs

    def reset(self, *, seed=None, options=None):
        obs, info = self.env.reset(seed=seed, options=options)
        return self._merge(obs, info), info

    def step(self, actions):
        obs, reward, terminated, truncated, info = self.env.step(actions)
        return self._merge(obs, info), reward, terminated, truncated, info


def _worker_env(
    index: int, kwargs: Mapping[str, Any] | None, factory: EnvFactory | None, goal_to_info: bool
) -> gym.Env:
    """Runs in the worker process: limit threads, then build the environment."""
    os.environ.setdefault("LP_NUM_THREADS", "0")
    from ovon.parallel import init_worker

    init_worker()
    if factory is not None:
        env = factory(index)
    else:
        from ovon.sim.env import ObjectNavEnv

        env = ObjectNavEnv(**dict(kwargs or {}))
    return GoalToInfo(env) if goal_to_info and _has_text_goal(env.observation_space) else env


def _has_text_goal(space: spaces.Space) -> bool:
    return isinstance(space, spaces.Dict) and isinstance(space.spaces.get("goal"), spaces.Text)


def make_vector_env(
    num_envs: int,
    envs: Sequence[Mapping[str, Any]] | Mapping[str, Any] | EnvFactory | None = None,
    *,
    context: str = "spawn",
    shared_memory: bool = True,
    autoreset_mode: str | AutoresetMode = AutoresetMode.NEXT_STEP,
    daemon: bool = True,
) -> VectorEnv:
    """`num_envs` environments, one per worker process.

    `envs` is one of: a list of `ObjectNavEnv` keyword dicts (one per env), a single dict used for all,
    or a picklable module-level `factory(index) -> gym.Env` (with the "spawn" context, lambdas and local
    functions cannot be sent to workers). Seeds: `vec.reset(seed=s)` seeds env i with s + i.
    `autoreset_mode`: gymnasium's NextStep (default; the step after an episode end is a reset) or
    SameStep (reset inside the ending step; the last observation is in `info["final_obs"]`, without
    "goal" under shared memory). Returns the `AsyncVectorEnv`, wrapped in `GoalFromInfo` when shared
    memory carries the observations (see the module docstring); `.unwrapped` is the AsyncVectorEnv.
    """
    if num_envs < 1:
        raise ValueError(f"num_envs must be >= 1, got {num_envs}")
    if callable(envs):
        fns = [functools.partial(_worker_env, i, None, envs, shared_memory) for i in range(num_envs)]
    else:
        if envs is None or isinstance(envs, Mapping):
            kw_list = [dict(envs or {}) for _ in range(num_envs)]
        else:
            kw_list = [dict(k) for k in envs]
            if len(kw_list) != num_envs:
                raise ValueError(f"got {len(kw_list)} env kwargs for num_envs={num_envs}")
        fns = [functools.partial(_worker_env, i, kw, None, shared_memory) for i, kw in enumerate(kw_list)]
    vec = AsyncVectorEnv(
        fns,
        shared_memory=shared_memory,
        context=context,
        daemon=daemon,
        autoreset_mode=AutoresetMode(autoreset_mode),
    )
    if not shared_memory:
        return vec
    goal_space = _goal_space(vec)
    return vec if goal_space is None else GoalFromInfo(vec, goal_space)


def _goal_space(vec: AsyncVectorEnv) -> spaces.Text | None:
    """The workers' goal `Text` space (asked from worker 0), None when the envs have no text goal."""
    if "goal" in vec.single_observation_space.spaces:
        return None
    try:
        space = vec.get_attr("goal_space")[0]
    except AttributeError:  # a factory env without a text goal
        return None
    return space if isinstance(space, spaces.Text) else None


# -- throughput measurement (`ovon sim bench`, benchmarks/sim_throughput.py) ---------------------------
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
    env_kwargs: Mapping[str, Any],
    workers: int = 1,
    steps: int = 400,
    warmup: int = 20,
    seed: int = 0,
    in_process: bool | None = None,
) -> dict[str, float]:
    """Environment steps per second with random actions 1-3 and auto-reset (resets are counted inside
    the timed loop). `workers` envs run in that many processes (`make_vector_env`, SameStep autoreset);
    `in_process` (default: when workers == 1) runs one env in this process instead. `steps` counts env
    steps over all workers. Returns steps_per_s, seconds, steps, workers, setup_s and cpu_ms_per_step
    (CPU time of this process + the workers per env step, mostly independent of other load) and
    cpu_bound_steps_per_s = min(workers, cpu_count) * 1000 / cpu_ms_per_step, the rate if every worker
    had an idle core (what a contended shared machine hides)."""
    import time

    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    in_process = workers == 1 if in_process is None else in_process
    if in_process:
        os.environ.setdefault("LP_NUM_THREADS", "0")
        from ovon.parallel import init_worker
        from ovon.sim.env import ObjectNavEnv

        init_worker()
        env = ObjectNavEnv(**dict(env_kwargs))
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
        return _result(steps, dt, cpu, 1, setup)
    vec = make_vector_env(workers, dict(env_kwargs), autoreset_mode=AutoresetMode.SAME_STEP)
    try:
        vec.reset(seed=seed)
        calls = max(1, steps // workers)
        pids = [p.pid for p in vec.unwrapped.processes]
        for i in range(warmup + calls):
            if i == warmup:
                setup = time.perf_counter() - t0
                t1, c1, w1 = time.perf_counter(), time.process_time(), _cpu_seconds(pids)
            vec.step(rng.integers(1, 4, size=workers))
        dt = time.perf_counter() - t1
        cpu = time.process_time() - c1 + _cpu_seconds(pids) - w1
    finally:
        vec.close()
    return _result(calls * workers, dt, cpu, workers, setup)


def _result(steps: int, seconds: float, cpu: float, workers: int, setup: float) -> dict[str, float]:
    cpu_ms = 1000.0 * cpu / steps
    return {
        "steps_per_s": steps / seconds,
        "seconds": seconds,
        "steps": steps,
        "workers": workers,
        "setup_s": setup,
        "cpu_ms_per_step": cpu_ms,
        "cpu_bound_steps_per_s": min(workers, os.cpu_count() or 1) * 1000.0 / cpu_ms if cpu_ms > 0 else math.nan,
    }


def profile_step(env_kwargs: Mapping[str, Any], steps: int = 200, seed: int = 0) -> dict[str, float]:
    """cProfile one in-process env for `steps` random steps; returns milliseconds per step spent in
    rendering, kinematics, the episode tracker, odometry, observation packing, and in total."""
    import cProfile
    import pstats

    os.environ.setdefault("LP_NUM_THREADS", "0")
    from ovon.parallel import init_worker
    from ovon.sim.env import ObjectNavEnv

    init_worker()
    rng = np.random.default_rng(seed)
    env = ObjectNavEnv(**dict(env_kwargs))
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
        "observation": ("_obs", ("sim/env.py",)),
        "total": ("step", ("sim/env.py",)),
    }
    out: dict[str, float] = {}
    for key, (func, files) in wanted.items():
        ct = sum(v[3] for (f, _, name), v in stats.items() if name == func and f.replace("\\", "/").endswith(files))
        out[key] = 1000.0 * ct / steps
    return out
