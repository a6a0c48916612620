"""`ovon train`: BC, DAgger, PPO and BC/DAgger->RL fine-tuning; the same command under `torchrun`."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from ovon.config.base import existing_file, positive


@dataclass(frozen=True)
class TrainArgs:
    """`ovon train`'s own options through declared domains, as `ovon evaluate`'s: `--episodes -1` would
    slice the split to all episodes but the last, `--episodes 0` to none; both are one line instead."""

    episodes: int | None = positive(None, flag="--episodes")
    config: str = existing_file("", optional=True, flag="--config")


def register(sub) -> None:
    p = sub.add_parser("train", help="train a learned baseline (bc | dagger | ppo); works under torchrun")
    p.add_argument(
        "--algo", choices=["bc", "dagger", "ppo"], required=True, help="behaviour cloning, DAgger or PPO (RL)"
    )
    p.add_argument(
        "--task",
        choices=["objectnav", "pointnav"],
        default="objectnav",
        help="objectnav (goal text) or pointnav (goal point from odometry; PPO, --procedural houses); "
        "picks that task's version of --preset",
    )
    p.add_argument("--policy", choices=["transformer", "lstm"], default=None, help="policy core (default: preset)")
    p.add_argument(
        "--encoder",
        choices=["oracle-vl", "world-vl", "siglip", "cnn", "depth-grid"],
        default=None,
        help="image encoder (default: preset; oracle-vl is ORACLE PERCEPTION; world-vl is ovon's pretrained "
        "encoder from RGB, shipped weights or encoder.world_checkpoint=PATH)",
    )
    p.add_argument(
        "--expert",
        choices=["frontier", "shortest-path"],
        default=None,
        help="expert for BC recording / DAgger labels (default: frontier)",
    )
    p.add_argument("--init", help="policy.pt (or run folder) to start from; with --algo ppo: BC/DAgger->RL")
    p.add_argument("--resume", action="store_true", help="continue from <out>/checkpoint.pt exactly")
    p.add_argument("--data", help="episode dataset root (holds train/ ...)")
    p.add_argument("--scenes", help="scene-datasets root")
    p.add_argument("--split", default="train", help="episode split to train on")
    p.add_argument("--episodes", default=None, help="use at most this many episodes of the split (an integer > 0)")
    p.add_argument(
        "--procedural",
        metavar="SEEDS",
        help="ad-hoc episodes on procedural houses instead of a dataset, e.g. 0-7 or 0,3",
    )
    p.add_argument(
        "--preset", choices=["paper", "cpu-small", "tiny"], default="cpu-small", help="starting TrainConfig values"
    )
    p.add_argument("--config", help="YAML file merged over the preset")
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override, e.g. num_envs=8 ppo.clip=0.1 policy.layers=2 bc.shards=DIR",
    )
    p.add_argument("--out", required=True, help="run folder (checkpoint.pt, policy.pt, metrics.jsonl, tb/)")
    p.set_defaults(func=cmd_train)


def build_config(args):
    """The TrainConfig of these options (`ovon.train.config.build_config`; imported lazily: `ovon --help`
    should not pay for the training stack)."""
    from ovon.train.config import build_config as build

    return build(args)


def check_args(args) -> TrainArgs:
    """The options checked before any work: the declared domains, a `--config` naming a folder, and an
    `--out` that cannot be a run folder (empty, an existing file, under a file)."""
    from ovon.atomic import check_output_path
    from ovon.config.base import check_config_file, from_args

    check_config_file(args.config, "TrainConfig")
    a = from_args(TrainArgs, args)
    check_output_path(args.out, "--out", folder=True)
    return a


def cmd_train(args) -> int:
    import os

    from ovon.train import EpisodeSource, train
    from ovon.train.distributed import cleanup, launched_by_torchrun

    a = check_args(args)
    cfg = build_config(args)
    out = Path(args.out)
    source = EpisodeSource(
        data=args.data,
        scenes=args.scenes,
        split=args.split,
        limit=a.episodes,
        procedural=args.procedural,
        task=args.task,
    )
    last = train(cfg, source, out, resume=args.resume, init=args.init)  # opens, checks and locks --out
    if int(os.environ.get("RANK", "0")) == 0:
        shown = {k: round(v, 4) for k, v in last.items() if isinstance(v, float)}
        print(json.dumps(shown))
        print(f"policy: {out / 'policy.pt'}" + (" (torchrun)" if launched_by_torchrun() else ""))
    cleanup()
    return 0
