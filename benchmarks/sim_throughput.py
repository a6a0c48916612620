"""Environment throughput: steps/s for backends (gl, embree) x resolutions x worker processes on a
procedural house, plus a cProfile breakdown of one in-process env step (render / kinematics / tracker).

    python benchmarks/sim_throughput.py [--scene procedural:0] [--steps 400] [--out FILE.json]

Every step renders RGB + depth + semantic (privileged env) and uses random actions 1-3 with auto-reset.
"1 in-process" = one env in this process; "N workers" = `make_vector_env(N)` (one env per process,
shared-memory observations). The machine is shared and noisy: compare ratios within one run. The load
average before and after is recorded so contended runs can be recognised.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

os.environ.setdefault("LP_NUM_THREADS", "0")

RESOLUTIONS = ((160, 120), (640, 360))
BACKENDS = ("gl", "embree")
TARGET = 300.0  # steps/s with 2 processes at 160x120


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="procedural:0")
    ap.add_argument("--steps", type=int, default=400, help="timed steps per configuration (all workers)")
    ap.add_argument("--profile-steps", type=int, default=150)
    ap.add_argument("--backends", default=",".join(BACKENDS))
    ap.add_argument("--out", default="benchmarks/results/sim_throughput.json")
    args = ap.parse_args(argv)

    from ovon.config.sim import CameraConfig, SimConfig
    from ovon.sim.vector import measure_throughput, pick_goal, profile_step

    goal = pick_goal(args.scene)
    backends = [b for b in args.backends.split(",") if b]
    load0 = os.getloadavg()
    rows, profiles = [], []
    print(f"scene {args.scene}, goal {goal!r}, {os.cpu_count()} cpus, load {load0[0]:.2f}")
    for backend in backends:
        for w, h in RESOLUTIONS:
            kw = dict(scene=args.scene, goal=goal, privileged=True,
                      sim=SimConfig(camera=CameraConfig(width=w, height=h, backend=backend)))
            prof = profile_step(kw, steps=args.profile_steps)
            profiles.append({"backend": backend, "width": w, "height": h, "ms_per_step": prof})
            for mode, workers, in_process in (("in-process", 1, True), ("workers", 1, False),
                                              ("workers", 2, False)):
                r = measure_throughput(kw, workers=workers, steps=args.steps, in_process=in_process)
                row = {"backend": backend, "width": w, "height": h, "mode": mode, **r}
                rows.append(row)
                print(f"  {backend:6s} {w}x{h} {mode:10s} x{workers}: {r['steps_per_s']:7.1f} steps/s, "
                      f"{r['cpu_ms_per_step']:.2f} CPU ms/step", flush=True)
    load1 = os.getloadavg()

    def sps(backend: str, w: int, h: int, mode: str, workers: int, key: str = "steps_per_s") -> float | None:
        for r in rows:
            if (r["backend"], r["width"], r["height"], r["mode"], r["workers"]) == (backend, w, h, mode, workers):
                return r[key]
        return None

    ratios = []
    for w, h in RESOLUTIONS:
        for backend in backends:
            one, two = sps(backend, w, h, "workers", 1), sps(backend, w, h, "workers", 2)
            ratios.append({"kind": "2 vs 1 workers", "backend": backend, "width": w, "height": h,
                           "ratio": two / one if one and two else None})
        if {"gl", "embree"} <= set(backends):
            for workers in (1, 2):
                gl, em = sps("gl", w, h, "workers", workers), sps("embree", w, h, "workers", workers)
                ratios.append({"kind": "gl vs embree", "workers": workers, "width": w, "height": h,
                               "ratio": gl / em if gl and em else None})

    print()
    print("steps/s measured (in parentheses: CPU-bound rate = workers x 1000 / CPU ms per step)")
    print("| backend | resolution | 1 in-process | 1 worker | 2 workers | 2 vs 1 workers |")
    print("|---|---|---|---|---|---|")
    cb = "cpu_bound_steps_per_s"
    for backend in backends:
        for w, h in RESOLUTIONS:
            cells = [(sps(backend, w, h, m, n), sps(backend, w, h, m, n, cb))
                     for m, n in (("in-process", 1), ("workers", 1), ("workers", 2))]
            txt = " | ".join(f"{a:.0f} ({c:.0f})" for a, c in cells)
            print(f"| {backend} | {w}x{h} | {txt} | {cells[2][0] / cells[1][0]:.2f} |")
    print()
    for r in ratios:
        if r["kind"] == "gl vs embree":
            print(f"gl vs embree, {r['width']}x{r['height']}, {r['workers']} worker(s): {r['ratio']:.2f}")
    print()
    print("ms per in-process env step (cProfile, includes profiler overhead):")
    keys = ["render", "kinematics", "tracker", "odometry", "observation", "total"]
    print("| backend | resolution | " + " | ".join(keys) + " |")
    print("|---|---|" + "---|" * len(keys))
    for p in profiles:
        ms = p["ms_per_step"]
        print(f"| {p['backend']} | {p['width']}x{p['height']} | " + " | ".join(f"{ms[k]:.2f}" for k in keys) + " |")
    best = max((sps(b, 160, 120, "workers", 2) or 0.0) for b in backends)
    verdict = "met" if best >= TARGET else "NOT met"
    print(f"\nbest 2-worker 160x120: {best:.0f} steps/s (target {TARGET:.0f}: {verdict});"
          f" load average {load0[0]:.2f} -> {load1[0]:.2f}")

    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({
        "scene": args.scene, "goal": goal, "steps": args.steps, "cpus": os.cpu_count(),
        "machine": platform.platform(), "time": time.strftime("%Y-%m-%dT%H:%M:%S"),
        "load_average_before": load0, "load_average_after": load1, "target_steps_per_s": TARGET,
        "rows": rows, "ratios": ratios, "profiles": profiles,
    }, indent=2))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
