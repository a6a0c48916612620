"""Per-step cost of the VLFM agent's `act` at the CPU camera, against the frontier expert in the same run.

Usage: python benchmarks/vlfm_step.py OUT.json [--houses 0,1,2] [--episodes 4] [--max-steps 500]

Episodes: procedural houses (`procedural:<seed>`), a random goal category present in the house, a random
reachable start (the env's seeded reset), the CPU camera (`ovon.config.sim.cpu_sim_config`: 72x128
portrait; 160x120 before issue 33, as in results/vlfm_step.json), no noise. Each episode is run twice on
the same start: once by the VLFM agent (oracle detection, oracle-vl value: the CPU preset) and once by
the frontier expert (`--agent frontier`). Timed: the agent's `act` only
(wall clock, and the calling thread's CPU time, which other processes on the shared cores disturb less);
rendering and the env are not. The first episode of each agent only warms up (numba, the text model) and
is not counted. Printed and written: median / p95 / mean ms per step of both, their ratio, and VLFM's
phases (maps from depth, detection + lifting, value map, decision incl. frontier choice and planning).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from ovon.agents import make_agent  # noqa: E402
from ovon.atomic import atomic_write_text  # noqa: E402
from ovon.config.sim import cpu_sim_config  # noqa: E402
from ovon.env.core import ObjectNavEnv  # noqa: E402
from ovon.scenes.procedural import generate_house  # noqa: E402
from ovon.task.episode import EpisodeSpec  # noqa: E402

PHASES = ("maps", "detect", "value", "decide")


def run(env, agent, spec: EpisodeSpec, seed: int, max_steps: int) -> tuple[list[list[float]], dict]:
    obs, _ = env.reset(seed=seed, options={"episode": spec})
    agent.reset(
        {
            "episode_id": spec.episode_id,
            "seed": seed,
            "goal": spec.goal_category,
            "camera": vars(env.sim_cfg.camera),
            "embodiment": vars(env.sim_cfg.agent),
        }
    )
    rows = []
    info: dict = {}
    for _ in range(max_steps):
        if agent.privileged:  # the harness's privileged channel (ovon.env.PrivilegedInfo does the same)
            obs = {**obs, "privileged": env.privileged()}
        c, t = time.thread_time(), time.perf_counter()
        action = agent.act(obs)
        wall, cpu = (time.perf_counter() - t) * 1e3, (time.thread_time() - c) * 1e3
        tm = getattr(agent, "timing", {}) or {}
        rows.append([wall, cpu] + [float(tm.get(p, 0.0)) for p in PHASES])
        obs, _, term, trunc, info = env.step(action)
        if term or trunc:
            break
    return rows, info.get("metrics", {})


def stats(v: np.ndarray) -> dict:
    return {"median_ms": float(np.median(v)), "p95_ms": float(np.percentile(v, 95)), "mean_ms": float(v.mean())}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", help="JSON file to write (e.g. benchmarks/results/vlfm_step.json)")
    ap.add_argument("--houses", default="0,1,2")
    ap.add_argument("--episodes", type=int, default=4, help="episodes per house")
    ap.add_argument("--max-steps", type=int, default=500)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    houses = [s for s in args.houses.split(",") if s]
    if args.episodes < 1 or len(houses) * args.episodes < 2:
        ap.error(
            f"--houses {args.houses!r} x --episodes {args.episodes}: expected at least 2 episodes in all "
            "(the first one is a warm-up and not timed); fix: raise --episodes"
        )
    import torch

    torch.set_num_threads(1)
    sim = cpu_sim_config()
    agents = {"vlfm": make_agent("vlfm"), "frontier": make_agent("frontier")}
    rows: dict[str, list[list[float]]] = {k: [] for k in agents}
    success: dict[str, list[bool]] = {k: [] for k in agents}
    rng = np.random.default_rng(args.seed)
    first = True
    for h in (int(s) for s in args.houses.split(",") if s):
        scene = generate_house(h)
        cats = sorted({o.category for o in scene.objects if o.category})
        env = ObjectNavEnv(scene=scene, sim=sim, goal=cats[0])
        done = 0
        while done < args.episodes:
            goal = cats[int(rng.integers(len(cats)))]
            spec = EpisodeSpec(f"h{h}-{done}", scene.scene_id, goal)
            seed = int(rng.integers(2**31))
            try:
                results = {k: run(env, a, spec, seed, args.max_steps) for k, a in agents.items()}
            except ValueError:  # no navigable point near this goal: draw another
                continue
            done += 1
            for k, (r, m) in results.items():
                if not first:
                    rows[k] += r
                    success[k].append(bool(m.get("success", False)))
            first = False
            v = np.array([r[0] for r in results["vlfm"][0]])
            f = np.array([r[0] for r in results["frontier"][0]])
            print(
                f"house {h} {goal!r:>22}: vlfm {len(v):3d} steps {np.median(v):6.2f} ms, frontier {len(f):3d} "
                f"steps {np.median(f):6.2f} ms",
                flush=True,
            )
        env.close()
    out: dict = {
        "benchmark": "VLFM agent act() per step vs the frontier expert, CPU camera "
        f"{sim.camera.width}x{sim.camera.height}",
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count(), "python": sys.version.split()[0]},
        "camera": vars(sim.camera),
        "agents": {},
    }
    for k, r in rows.items():
        a = np.array(r)
        entry = {
            "steps": int(a.shape[0]),
            "episodes": len(success[k]),
            "success_rate": float(np.mean(success[k])),
            "act": stats(a[:, 0]),
            "act_cpu": stats(a[:, 1]),
        }
        if k == "vlfm":
            entry["phases"] = {p: stats(a[:, 2 + i]) for i, p in enumerate(PHASES)}
        out["agents"][k] = entry
    v, f = out["agents"]["vlfm"], out["agents"]["frontier"]
    out["ratio_vlfm_over_frontier"] = {
        "median": v["act"]["median_ms"] / f["act"]["median_ms"],
        "mean": v["act"]["mean_ms"] / f["act"]["mean_ms"],
        "median_cpu": v["act_cpu"]["median_ms"] / f["act_cpu"]["median_ms"],
    }
    for k, e in out["agents"].items():
        print(
            f"{k:>9}: {e['steps']} steps, act median {e['act']['median_ms']:.2f} p95 {e['act']['p95_ms']:.2f} "
            f"mean {e['act']['mean_ms']:.2f} ms (cpu median {e['act_cpu']['median_ms']:.2f}), "
            f"SR {e['success_rate']:.2f}"
        )
    print("vlfm phases (median ms): " + ", ".join(f"{p} {v['phases'][p]['median_ms']:.2f}" for p in PHASES))
    r = out["ratio_vlfm_over_frontier"]
    print(f"ratio vlfm / frontier: median {r['median']:.1f}x, mean {r['mean']:.1f}x, cpu median {r['median_cpu']:.1f}x")
    path = Path(args.out)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, json.dumps(out, indent=2))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
