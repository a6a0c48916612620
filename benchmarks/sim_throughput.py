"""Env-stack throughput: ovon's vector env against one env in this process and against Gymnasium's
AsyncVectorEnv (one env per process, the layout ovon used before), in the same run; optionally against
the same measurements of an older ovon (`--baseline-rev`).

    python benchmarks/sim_throughput.py --out /tmp/sim_throughput.json [--scene procedural:0] [--steps 2000]
        [--workers 2] [--envs-per-worker 4] [--repeats 3] [--configs in_process,gymnasium_async,ovon_vector]
        [--baseline-rev REV_OR_WORKTREE_DIR] [--check-steps 300]

Every configuration steps random actions 1-3 with auto-reset and renders depth + the semantic frame
(always: the episode tracker needs it) + RGB unless the row says "no rgb". Rows: 160x120 (issue 21's CPU
camera) with and without RGB, and the paper's 360x640 portrait camera. For each row: in-process (one
env, no vector env), gymnasium AsyncVectorEnv with `workers` envs, and ovon's vector env with `workers`
processes x `envs-per-worker` envs. Reported: median steps/s over `--repeats` alternating runs, CPU ms
per env step (this process + workers), the "CPU-bound" rate min(workers, cores) * 1000 / cpu_ms (what
the machine would do with idle cores), ratios to the baselines, and the load average.

With `--baseline-rev` every in-process and ovon-vector measurement runs in a fresh process, alternately
for this tree and for REV's (a temporary git worktree of REV, or REV itself when it is a directory),
measured by this same script; `ratio_vs_baseline` compares the medians. Before timing, each tree steps
the vector env `--check-steps` times with the same seed and actions (untimed) and hashes every
observation array, reward, flag and episode metric: `same_as_baseline` says whether the two digests agree
(a speed-up must not change what the env computes).
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
# The ovon tree to measure: this checkout, or (with --baseline-rev) the baseline's, run by this same script.
TREE = Path(os.environ.get("OVON_BENCH_TREE") or Path(__file__).resolve().parents[1])
sys.path.insert(0, str(TREE))
import numpy as np  # noqa: E402

from ovon.atomic import atomic_write_text  # noqa: E402
from ovon.config.sim import CameraConfig, SimConfig  # noqa: E402
from ovon.env.bench import _cpu_seconds, _result, measure_throughput, pick_goal  # noqa: E402
from ovon.env.stack import EnvRecipe  # noqa: E402

TARGET = 1200.0  # steps/s of the vector env with 2 workers at 160x120 (RL on two cores needs it)


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


def digest(recipe: EnvRecipe, workers: int, envs: int, steps: int, seed: int = 0) -> str:
    """SHA-256 over `steps` vector-env steps (random actions 0-3, so episodes also end by STOP): every
    observation array, reward, termination/truncation flag and ended episode's metrics."""
    import hashlib

    from ovon.env.stack import make_vector_env

    h = hashlib.sha256()
    rng = np.random.default_rng(seed + 1)
    vec = make_vector_env(recipe, envs, workers=workers, base_seed=seed)
    try:
        obs, _ = vec.reset(seed=seed)
        for _ in range(steps):
            for k in sorted(obs):
                h.update(
                    k.encode() + np.ascontiguousarray(obs[k]).tobytes()
                    if isinstance(obs[k], np.ndarray)
                    else repr(obs[k]).encode()
                )
            obs, rew, term, trunc, infos = vec.step(rng.integers(0, 4, size=envs))
            h.update(np.asarray(rew, np.float64).tobytes() + np.asarray(term).tobytes() + np.asarray(trunc).tobytes())
            for i, info in enumerate(infos.get("final_info", {}).get("metrics", {}).items()):
                h.update(repr((i, info[0], np.asarray(info[1]).tolist())).encode())
    finally:
        vec.close()
    return h.hexdigest()


def _child(args) -> None:
    """One measurement (or the digest) in this process, for --baseline-rev; prints one JSON line."""
    goal, recipe = _recipe(args.scene, args.child_row)
    n = args.workers * args.envs_per_worker
    if args.child == "digest":
        out = {"digest": digest(recipe, args.workers, n, args.check_steps)}
    elif args.child == "in_process":
        out = measure_throughput(recipe, workers=0, steps=args.steps // 2)
    else:
        out = measure_throughput(recipe, workers=args.workers, envs=n, steps=args.steps)
    from train_throughput import tree_commit

    import ovon

    out["code"] = tree_commit(Path(ovon.__file__).resolve().parents[1])
    print("RESULT " + json.dumps(out), flush=True)


def _recipe(scene: str, row: str) -> tuple[str, EnvRecipe]:
    size, _, flag = row.partition("-")
    w, h = (int(x) for x in size.split("x"))
    goal = pick_goal(scene)
    cam = CameraConfig(width=w, height=h, rgb=flag != "norgb")
    return goal, EnvRecipe(sim=SimConfig(camera=cam), scene=scene, goal=goal)


def _in_tree(tree: Path, args, what: str, row: str) -> dict:
    """Run `what` for `row` in a fresh process on the ovon of `tree` (this script, that tree's package)."""
    import subprocess

    cmd = [
        sys.executable,
        str(Path(__file__).resolve()),
        "--out",
        "-",
        "--scene",
        args.scene,
        "--steps",
        str(args.steps),
        "--workers",
        str(args.workers),
        "--envs-per-worker",
        str(args.envs_per_worker),
        "--check-steps",
        str(args.check_steps),
        "--child",
        what,
        "--child-row",
        row,
    ]
    env = {**os.environ, "PYTHONPATH": str(tree), "OVON_BENCH_TREE": str(tree)}
    res = subprocess.run(cmd, cwd=tree, env=env, capture_output=True, text=True)
    lines = [x for x in res.stdout.splitlines() if x.startswith("RESULT ")]
    if res.returncode != 0 or not lines:
        raise SystemExit(f"benchmark child failed in {tree} ({what}, {row}):\n{res.stderr[-2000:]}")
    return json.loads(lines[-1][len("RESULT ") :])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="procedural:0")
    ap.add_argument("--steps", type=int, default=2000, help="timed env steps per configuration")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--envs-per-worker", type=int, default=4)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--rows", default="160x120,160x120-norgb,360x640")
    ap.add_argument(
        "--configs",
        default="in_process,gymnasium_async,ovon_vector",
        help="which of in_process, gymnasium_async, ovon_vector to measure",
    )
    ap.add_argument("--baseline-rev", help="git revision, or the directory of a worktree of it, to compare against")
    ap.add_argument("--check-steps", type=int, default=300, help="untimed steps hashed to compare with the baseline")
    ap.add_argument("--out", required=True, help="JSON output path")
    ap.add_argument("--child", choices=["in_process", "ovon_vector", "digest"], help=argparse.SUPPRESS)
    ap.add_argument("--child-row", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        _child(args)
        return 0
    configs = [c for c in args.configs.split(",") if c]
    unknown = set(configs) - {"in_process", "gymnasium_async", "ovon_vector"}
    if unknown:
        ap.error(f"--configs: unknown {sorted(unknown)}; expected in_process, gymnasium_async, ovon_vector")
    base_dir, own, tmp = None, False, None
    if args.baseline_rev:
        import tempfile

        from train_throughput import baseline_tree, tree_commit

        tmp = Path(tempfile.mkdtemp(prefix="ovon-sim-bench-rev-"))
        base_dir, own = baseline_tree(Path(__file__).resolve().parents[1], args.baseline_rev, tmp)
    try:
        return _run(args, configs, base_dir, tree_commit(base_dir) if base_dir else None)
    finally:
        if own:
            import subprocess

            subprocess.run(
                ["git", "-C", str(Path(__file__).resolve().parents[1]), "worktree", "remove", "--force", str(base_dir)],
                capture_output=True,
            )
        if tmp is not None:
            import shutil

            shutil.rmtree(tmp, ignore_errors=True)


def _run(args, configs: list[str], base_dir: Path | None, base_code: str | None) -> int:
    here = Path(__file__).resolve().parents[1]
    goal = pick_goal(args.scene)
    rows = []
    load_before = os.getloadavg()
    for row in args.rows.split(","):
        _, recipe = _recipe(args.scene, row)
        cam = recipe.sim.camera
        n = args.workers * args.envs_per_worker
        names = list(configs) + ([f"{c}_baseline" for c in configs if c != "gymnasium_async"] if base_dir else [])
        runs: dict[str, list[dict]] = {k: [] for k in names}
        entry: dict = {
            "row": row,
            "width": cam.width,
            "height": cam.height,
            "rgb": cam.rgb,
            "workers": args.workers,
            "envs": n,
        }
        if base_dir is not None:
            digests = {
                t: _in_tree(d, args, "digest", row)["digest"] for t, d in (("current", here), ("baseline", base_dir))
            }
            entry["digests"] = digests
            entry["same_as_baseline"] = digests["current"] == digests["baseline"]
        for _ in range(args.repeats):  # alternate, so slow phases of a shared machine hit all alike
            for c in configs:
                if c == "gymnasium_async":
                    runs[c].append(gymnasium_async(recipe, args.workers, args.steps))
                    continue
                trees = [(c, here), (f"{c}_baseline", base_dir)] if base_dir is not None else [(c, None)]
                for name, tree in trees:
                    if tree is not None:
                        runs[name].append(_in_tree(tree, args, c, row))
                    elif c == "in_process":
                        runs[name].append(measure_throughput(recipe, workers=0, steps=args.steps // 2))
                    else:
                        runs[name].append(measure_throughput(recipe, workers=args.workers, envs=n, steps=args.steps))
        med = {
            k: {
                m: statistics.median(r[m] for r in v)
                for m in ("steps_per_s", "cpu_ms_per_step", "cpu_bound_steps_per_s")
            }
            for k, v in runs.items()
        }
        entry.update(median=med, runs=runs)
        rate = {k: v["steps_per_s"] for k, v in med.items()}
        if "ovon_vector" in rate and "gymnasium_async" in rate:
            entry["ratio_vs_gymnasium_async"] = rate["ovon_vector"] / rate["gymnasium_async"]
        if "ovon_vector" in rate and "in_process" in rate:
            entry["ratio_vs_in_process"] = rate["ovon_vector"] / rate["in_process"]
        if base_dir is not None:
            both = [c for c in configs if f"{c}_baseline" in rate]
            entry["ratio_vs_baseline"] = {c: rate[c] / rate[f"{c}_baseline"] for c in both}
            entry["cpu_ratio_vs_baseline"] = {
                c: med[f"{c}_baseline"]["cpu_ms_per_step"] / med[c]["cpu_ms_per_step"] for c in both
            }
        rows.append(entry)
        parts = [f"{k} {v:7.0f}" for k, v in rate.items()]
        extra = ""
        if "ovon_vector" in med:
            bound = med["ovon_vector"]["cpu_bound_steps_per_s"]
            extra = f" (ovon vector {args.workers}x{args.envs_per_worker}, CPU-bound {bound:.0f})"
        print(f"{row:>16}: " + " | ".join(parts) + " steps/s" + extra, flush=True)
        if base_dir is not None:
            cpu = entry["cpu_ratio_vs_baseline"]
            vs = ", ".join(f"{c} x{r:.2f} (CPU per step x{cpu[c]:.2f})" for c, r in entry["ratio_vs_baseline"].items())
            print(f"{'':>16}  vs baseline: {vs}; same observations: {entry['same_as_baseline']}", flush=True)
    result = {
        "scene": args.scene,
        "goal": goal,
        "steps": args.steps,
        "repeats": args.repeats,
        "baseline": base_code,
        "target_steps_per_s": TARGET,
        "cpus": os.cpu_count(),
        "machine": platform.platform(),
        "time": time.strftime("%Y-%m-%dT%H:%M:%S"),
        "load_average_before": load_before,
        "load_average_after": os.getloadavg(),
        "rows": rows,
    }
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(Path(args.out), json.dumps(result, indent=1))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
