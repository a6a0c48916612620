"""Per-step overhead of a served agent (`ovon serve` + `--agent remote:HOST:PORT`) against the same agent
in-process, on loopback, at 160x120 RGB-D (issue 21's CPU camera) and the paper's 360x640 camera.

Usage: python benchmarks/remote_agent.py [OUT.json] [--steps 300] [--repeats 5] [--batch 8]
(default OUT: benchmarks/results/remote_agent.json)

Observations: real frames, a random walk of `--steps` steps in a procedural house (`procedural:0`), rendered
once per camera and replayed (RGB, depth, odometry, goal, bump flag: what `ovon evaluate` sends). The agent:
the random agent, in this process and served by `ovon serve random` in a separate process (the real
deployment), reached through `ovon.agents.remote.RemoteAgent` (the client `ovon evaluate` uses). Timed per
step, wall clock: the agent's `act` in-process, the whole round trip remote (encode, loopback TCP, decode,
the served agent's `act`, the answer). The two alternate in `--repeats` rounds; the overhead is remote
minus in-process (median, mean and p90 over all steps: on a loaded machine the mean and p90 carry the
scheduler's delays in waking the other process). CPU time per step is measured too (this process, all its
threads, plus every thread of the server from /proc/PID/task/*/schedstat), which the load of other
processes does not inflate: what the round trip costs in work. Also timed: `act_batch` of `--batch` streams
at once, per observation. Targets (issue 21): median overhead <= 1 ms at 160x120, <= 3 ms at 360x640.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from ovon.agents import make_agent  # noqa: E402
from ovon.agents.remote import RemoteAgent, RemoteConfig  # noqa: E402
from ovon.atomic import atomic_write_text  # noqa: E402
from ovon.config.sim import CameraConfig, SimConfig  # noqa: E402
from ovon.env.bench import pick_goal  # noqa: E402
from ovon.env.core import ObjectNavEnv  # noqa: E402

CAMERAS = {"160x120": (160, 120), "360x640": (360, 640)}
TARGET_MS = {"160x120": 1.0, "360x640": 3.0}
SCENE = "procedural:0"


def start_server() -> tuple[subprocess.Popen, int]:
    """`ovon serve random --port 0` in its own process; returns it and the port it printed."""
    env = dict(os.environ, OMP_NUM_THREADS="1")
    proc = subprocess.Popen(
        [sys.executable, "-m", "ovon.cli.main", "serve", "random", "--port", "0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
        env=env,
    )
    line = proc.stdout.readline() if proc.stdout else ""
    if "remote:" not in line:
        proc.kill()
        raise SystemExit(f"ovon serve did not start: {line!r}")
    return proc, int(line.split("remote:")[1].split(";")[0].rsplit(":", 1)[1])


def walk(width: int, height: int, steps: int) -> list[dict]:
    env = ObjectNavEnv(
        scene=SCENE, goal=pick_goal(SCENE), sim=SimConfig(camera=CameraConfig(width=width, height=height))
    )
    rng = np.random.default_rng(0)
    obs, _ = env.reset(seed=0)
    frames = [obs]
    while len(frames) < steps:
        obs, _, term, trunc, _ = env.step(int(rng.integers(1, 4)))
        frames.append(obs)
        if term or trunc:
            obs, _ = env.reset(seed=len(frames))
            frames.append(obs)
    env.close()
    return frames[:steps]


def server_cpu_s(pid: int | None) -> float:
    """CPU seconds used so far by every thread of process `pid` (0 when None, nan when unreadable)."""
    if pid is None:
        return 0.0
    try:
        tasks = os.listdir(f"/proc/{pid}/task")
        return sum(int(Path(f"/proc/{pid}/task/{t}/schedstat").read_text().split()[0]) for t in tasks) / 1e9
    except (OSError, ValueError, IndexError):
        return float("nan")


def time_calls(agent, frames: list[dict], server_pid: int | None = None) -> tuple[np.ndarray, float]:
    """Wall ms of each act, and CPU ms per act (this process + the server)."""
    agent.reset({"episode_id": "bench", "seed": 0, "goal": frames[0]["goal"]})
    out = np.empty(len(frames))
    cpu0, srv0 = time.process_time(), server_cpu_s(server_pid)
    for i, obs in enumerate(frames):
        t = time.perf_counter()
        agent.act(obs)
        out[i] = time.perf_counter() - t
    cpu = time.process_time() - cpu0 + server_cpu_s(server_pid) - srv0
    return out * 1e3, cpu * 1e3 / len(frames)


def time_batched(agent: RemoteAgent, frames: list[dict], batch: int) -> np.ndarray:
    streams = list(range(batch))
    for s in streams:
        agent.reset({"episode_id": f"bench-{s}", "seed": s, "goal": frames[0]["goal"]}, stream=s)
    out = []
    for i in range(0, len(frames) - batch + 1, batch):
        t = time.perf_counter()
        agent.act_batch(frames[i : i + batch], streams)
        out.append((time.perf_counter() - t) / batch)
    return np.array(out) * 1e3


def stats(v: np.ndarray) -> dict:
    return {"median_ms": float(np.median(v)), "mean_ms": float(v.mean()), "p90_ms": float(np.percentile(v, 90))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?", default=str(Path(__file__).parent / "results" / "remote_agent.json"))
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--batch", type=int, default=8)
    args = ap.parse_args()

    proc, port = start_server()
    results: dict = {}
    try:
        local = make_agent("random")
        remote = RemoteAgent(f"remote:127.0.0.1:{port}", RemoteConfig(timeout_s=30))
        for cam, (w, h) in CAMERAS.items():
            frames = walk(w, h, args.steps)
            time_calls(remote, frames[:20])  # warm-up: first connection, allocations
            ins, rem, ins_cpu, rem_cpu = [], [], [], []
            for _ in range(args.repeats):
                wall, cpu = time_calls(local, frames)
                ins.append(wall)
                ins_cpu.append(cpu)
                wall, cpu = time_calls(remote, frames, proc.pid)
                rem.append(wall)
                rem_cpu.append(cpu)
            ins_a, rem_a = np.concatenate(ins), np.concatenate(rem)
            batched = np.concatenate([time_batched(remote, frames, args.batch) for _ in range(args.repeats)])
            obs_bytes = sum(v.nbytes for v in frames[0].values() if isinstance(v, np.ndarray))
            overhead = {
                "median_ms": float(np.median(rem_a) - np.median(ins_a)),
                "mean_ms": float(rem_a.mean() - ins_a.mean()),
                "p90_ms": float(np.percentile(rem_a, 90) - np.percentile(ins_a, 90)),
                "cpu_ms": float(np.median(rem_cpu) - np.median(ins_cpu)),
            }
            results[cam] = {
                "observation_bytes": obs_bytes,
                "in_process": {**stats(ins_a), "cpu_ms": float(np.median(ins_cpu))},
                "remote": {**stats(rem_a), "cpu_ms": float(np.median(rem_cpu))},
                "overhead": overhead,
                "remote_batched_per_observation": {"batch": args.batch, **stats(batched)},
                "target_overhead_ms": TARGET_MS[cam],
                "meets_target": overhead["median_ms"] <= TARGET_MS[cam],
            }
        remote.close()
    finally:
        proc.kill()
        proc.wait()

    print("camera     bytes/obs   in-process    remote  overhead: median    mean     p90     CPU   batched/obs  target")
    for cam, r in results.items():
        o = r["overhead"]
        print(
            f"{cam:<9} {r['observation_bytes']:>10} {r['in_process']['median_ms']:>10.3f}ms "
            f"{r['remote']['median_ms']:>7.3f}ms "
            f"{o['median_ms']:>14.3f}ms {o['mean_ms']:>6.3f}ms {o['p90_ms']:>6.3f}ms {o['cpu_ms']:>6.3f}ms "
            f"{r['remote_batched_per_observation']['median_ms']:>10.3f}ms  median <= {r['target_overhead_ms']} ms: "
            f"{'ok' if r['meets_target'] else 'MISSED'}"
        )
    out = {
        "benchmark": "remote_agent",
        "command": "python benchmarks/remote_agent.py " + " ".join(sys.argv[1:]),
        "steps": args.steps,
        "repeats": args.repeats,
        "machine": {
            "cpus": os.cpu_count(),
            "load_avg": list(os.getloadavg()),
            "python": platform.python_version(),
            "platform": platform.platform(),
        },
        "results": results,
    }
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(Path(args.out), json.dumps(out, indent=2) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
