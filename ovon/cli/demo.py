"""`ovon demo` (`make demo`): the main job on the embedded world, end to end on a laptop CPU.

Generates a small scene dataset and its val episodes if missing (fast preset), evaluates the random,
shortest-path and frontier agents and the VLFM-style modular baseline (oracle detection, oracle-vl value:
the one non-privileged-navigation agent that needs no training) on the three val splits, prints the
paper-style table and writes the report folder. Without noise only the random agent draws random numbers:
the others give the same episodes for every seed, so they run with the first seed only (half the time).
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass
from pathlib import Path

from ovon.cli.scenes import SPLIT_CAPACITY
from ovon.config.base import Range, constrained, domain_of
from ovon.config.dataset import GenerationConfig
from ovon.dataset.io import VAL_SPLITS
from ovon.evaluate.config import EvalConfig

AGENTS = ("random", "shortest-path", "frontier", "vlfm")
STOCHASTIC = ("random",)  # the demo runs without noise: every other agent is deterministic
TRAIN_CAP, VAL_CAP = SPLIT_CAPACITY["train"], SPLIT_CAPACITY["val"]  # houses per split and seed


@dataclass(frozen=True)
class DemoArgs:
    """`ovon demo`'s options through declared domains, checked before any house is generated. Why: the
    demo chains `scenes generate`, `dataset generate` and `evaluate`, and each option used to be refused
    only by the command that used it, minutes into the demo (`--seeds x` after the houses and episodes).
    The domains are those commands' own: --seeds and --workers evaluate's, --episodes the generator's
    episodes_per_val_split (it sets it), the scene counts `scenes generate --count`'s (0 train scenes:
    the val scenes alone give the categories; the val splits need a val scene)."""

    train_scenes: int = constrained(3, Range(0, TRAIN_CAP), flag="--train-scenes")
    val_scenes: int = constrained(3, Range(1, VAL_CAP), flag="--val-scenes")
    episodes: int = constrained(20, domain_of(GenerationConfig, "episodes_per_val_split"), flag="--episodes")
    seeds: tuple[int, ...] = constrained((0, 1), domain_of(EvalConfig, "seeds"), flag="--seeds")
    workers: int = constrained(2, domain_of(EvalConfig, "workers"), flag="--workers")


def register(sub) -> None:
    p = sub.add_parser("demo", help="generate a small embedded dataset and benchmark the built-in agents")
    p.add_argument("--root", default="data/demo", help="where scenes, episodes and runs go")
    p.add_argument("--train-scenes", default=3, help=f"procedural train houses (0 to {TRAIN_CAP})")
    p.add_argument("--val-scenes", default=3, help=f"procedural val houses (1 to {VAL_CAP})")
    p.add_argument("--episodes", default=20, help="episodes per split and agent")
    p.add_argument("--seeds", default="0,1", help="comma-separated, distinct, >= 0 (e.g. 0,1)")
    p.add_argument("--workers", default=2, help="worker processes")
    p.set_defaults(func=cmd_demo)


def demo_args(args: argparse.Namespace) -> DemoArgs:
    """Every option of `ovon demo` checked (one line naming the first bad one), before any work."""
    from ovon.atomic import check_output_path
    from ovon.config.base import ConfigError, from_args

    a = from_args(DemoArgs, args)
    check_output_path(args.root, "--root", folder=True, example="data/demo", error=ConfigError)
    return a


def cmd_demo(args) -> int:
    from ovon.cli.main import main as ovon

    a = demo_args(args)  # before the first house: a bad option never costs a generated dataset
    t0 = time.perf_counter()
    root = Path(args.root)
    scenes, data, runs = root / "scenes", root / "episodes", root / "runs"
    for split, count in (("train", a.train_scenes), ("val", a.val_scenes)):
        if count == 0:
            continue
        rc = ovon(
            [
                "scenes",
                "generate",
                "--split",
                split,
                "--count",
                str(count),
                "--seed",
                "0",
                "--out",
                str(scenes),
                "--workers",
                str(a.workers),
            ]
        )
        if rc:
            return rc
    gen = [
        "dataset",
        "generate",
        "--scenes",
        str(scenes),
        "--out",
        str(data),
        "--preset",
        "fast",
        "--workers",
        str(a.workers),
        "--set",
        f"episodes_per_val_split={max(a.episodes, 30)}",
    ]
    for s in VAL_SPLITS:
        gen += ["--split", s]
    rc = ovon(gen)
    if rc:
        return rc
    ovon(["dataset", "stats", str(data)])
    for agent in AGENTS:
        seeds = a.seeds if agent in STOCHASTIC else a.seeds[:1]
        rc = ovon(
            [
                "evaluate",
                "--agent",
                agent,
                "--data",
                str(data),
                "--scenes",
                str(scenes),
                "--seeds",
                ",".join(str(s) for s in seeds),
                "--episodes",
                str(a.episodes),
                "--workers",
                str(a.workers),
                "--out",
                str(runs / agent),
            ]
        )
        if rc:
            return rc
    report = runs / "report"
    rc = ovon(["report", *[str(runs / agent) for agent in AGENTS], "--out", str(report)])
    print(f"demo finished in {time.perf_counter() - t0:.0f} s; report: {report / 'report.md'}")
    return rc
