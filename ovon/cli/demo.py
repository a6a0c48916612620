"""`ovon demo` (`make demo`): the main job on the embedded world, end to end on a laptop CPU.

Generates a small scene dataset and its val episodes if missing (fast preset), evaluates the random,
shortest-path and frontier agents and the VLFM-style modular baseline (oracle detection, oracle-vl value:
the one non-privileged-navigation agent that needs no training) on the three val splits, prints the
paper-style table and writes the report folder. Without noise only the random agent draws random numbers:
the others give the same episodes for every seed, so they run with the first seed only (half the time).
"""

from __future__ import annotations

import time
from pathlib import Path

from ovon.dataset.io import VAL_SPLITS

AGENTS = ("random", "shortest-path", "frontier", "vlfm")
STOCHASTIC = ("random",)  # the demo runs without noise: every other agent is deterministic


def register(sub) -> None:
    p = sub.add_parser("demo", help="generate a small embedded dataset and benchmark the built-in agents")
    p.add_argument("--root", default="data/demo", help="where scenes, episodes and runs go")
    p.add_argument("--train-scenes", type=int, default=3)
    p.add_argument("--val-scenes", type=int, default=3)
    p.add_argument("--episodes", type=int, default=20, help="episodes per split and agent")
    p.add_argument("--seeds", default="0,1")
    p.add_argument("--workers", type=int, default=2)
    p.set_defaults(func=cmd_demo)


def cmd_demo(args) -> int:
    from ovon.cli.main import main as ovon

    t0 = time.perf_counter()
    root = Path(args.root)
    scenes, data, runs = root / "scenes", root / "episodes", root / "runs"
    for split, count in (("train", args.train_scenes), ("val", args.val_scenes)):
        rc = ovon(["scenes", "generate", "--split", split, "--count", str(count), "--seed", "0",
                   "--out", str(scenes), "--workers", str(args.workers)])
        if rc:
            return rc
    gen = ["dataset", "generate", "--scenes", str(scenes), "--out", str(data), "--preset", "fast",
           "--workers", str(args.workers), "--set", f"episodes_per_val_split={max(args.episodes, 30)}"]
    for s in VAL_SPLITS:
        gen += ["--split", s]
    rc = ovon(gen)
    if rc:
        return rc
    ovon(["dataset", "stats", str(data)])
    for agent in AGENTS:
        seeds = args.seeds if agent in STOCHASTIC else args.seeds.split(",")[0]
        rc = ovon(["evaluate", "--agent", agent, "--data", str(data), "--scenes", str(scenes),
                   "--seeds", seeds, "--episodes", str(args.episodes), "--workers", str(args.workers),
                   "--out", str(runs / agent)])
        if rc:
            return rc
    report = runs / "report"
    rc = ovon(["report", *[str(runs / a) for a in AGENTS], "--out", str(report)])
    print(f"demo finished in {time.perf_counter() - t0:.0f} s; report: {report / 'report.md'}")
    return rc
