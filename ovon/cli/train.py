"""`ovon train`: BC, DAgger, PPO and BC/DAgger->RL fine-tuning; the same command under `torchrun`."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

from ovon.atomic import atomic_write_text


def register(sub) -> None:
    p = sub.add_parser("train", help="train a learned baseline (bc | dagger | ppo); works under torchrun")
    p.add_argument("--algo", choices=["bc", "dagger", "ppo"], required=True)
    p.add_argument("--task", choices=["objectnav", "pointnav"], default="objectnav",
                   help="objectnav (goal text) or pointnav (goal point from odometry; PPO, --procedural houses); "
                        "picks that task's version of --preset")
    p.add_argument("--policy", choices=["transformer", "lstm"], default=None, help="policy core (default: preset)")
    p.add_argument("--encoder", choices=["oracle-vl", "siglip", "cnn", "depth-grid"], default=None,
                   help="image encoder (default: preset; oracle-vl is ORACLE PERCEPTION)")
    p.add_argument("--expert", choices=["frontier", "shortest-path"], default=None,
                   help="expert for BC recording / DAgger labels (default: frontier)")
    p.add_argument("--init", help="policy.pt (or run folder) to start from; with --algo ppo: BC/DAgger->RL")
    p.add_argument("--resume", action="store_true", help="continue from <out>/checkpoint.pt exactly")
    p.add_argument("--data", help="episode dataset root (holds train/ ...)")
    p.add_argument("--scenes", help="scene-datasets root")
    p.add_argument("--split", default="train")
    p.add_argument("--episodes", type=int, default=None, help="use at most this many episodes of the split")
    p.add_argument("--procedural", metavar="SEEDS",
                   help="ad-hoc episodes on procedural houses instead of a dataset, e.g. 0-7 or 0,3")
    p.add_argument("--preset", choices=["paper", "cpu-small", "tiny"], default="cpu-small")
    p.add_argument("--config", help="YAML file merged over the preset")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override, e.g. num_envs=8 ppo.clip=0.1 policy.layers=2 bc.shards=DIR")
    p.add_argument("--out", required=True, help="run folder (checkpoint.pt, policy.pt, metrics.jsonl, tb/)")
    p.set_defaults(func=cmd_train)


def build_config(args):
    from ovon.config.base import build
    from ovon.train.config import train_preset

    changes: dict = {"algo": args.algo}
    if args.expert:
        changes["expert"] = args.expert
    if args.task == "pointnav" and args.algo != "ppo":
        raise ValueError(f"--task pointnav trains with --algo ppo, not {args.algo!r} (there is no PointNav expert)")
    preset = train_preset(args.preset, args.task, **changes)
    if args.policy:
        preset = dataclasses.replace(preset, policy=dataclasses.replace(preset.policy, core=args.policy))
    if args.encoder:
        preset = dataclasses.replace(preset, encoder=dataclasses.replace(preset.encoder, image=args.encoder))
    return build(type(preset), preset, args.config, args.set)


def episode_list(args):
    if args.task == "pointnav":
        if not args.procedural or args.data:
            raise ValueError("--task pointnav samples its episodes in procedural houses: pass --procedural SEEDS "
                             "(e.g. 0-23) and no --data")
        from ovon.task.pointgoal import pointnav_specs
        from ovon.train.episodes import parse_seed_list

        return pointnav_specs([f"procedural:{s}" for s in parse_seed_list(args.procedural)])
    if args.procedural:
        from ovon.train.episodes import adhoc_specs, parse_seed_list

        specs = adhoc_specs(parse_seed_list(args.procedural))
        return specs[: args.episodes] if args.episodes else specs
    if args.data:
        if not args.scenes:
            raise ValueError("--data needs --scenes")
        from ovon.evaluate.harness import load_specs

        specs = load_specs(args.data, args.scenes, args.split, args.episodes)
        if not specs:
            raise ValueError(f"split {args.split!r} in {args.data} has no episodes")
        return specs
    return None


# May differ between a run and its resume: where and how fast it runs, and the budget (to train longer),
# not what it learns from or how.
MAY_CHANGE = ("max_updates", "total_steps", "env_workers", "checkpoint_every", "threads", "rollout_threads",
              "device", "progress", "log_every", "keep_checkpoints", "text_cache", "inputs.data.path",
              "inputs.scenes.path")


def run_identity(args, cfg) -> tuple[dict, dict]:
    """What a training run folder is: the resolved config, the algorithm, and what it reads (episodes by
    content, the init policy by hash), so `--resume` with anything else is refused with the differences."""
    from ovon.config.base import to_dict
    from ovon.runfolder import file_sha256, path_identity

    config = {**to_dict(cfg), "cli": {"split": args.split, "episodes": args.episodes,
                                      "procedural": args.procedural or ""}}
    inputs: dict = {}
    if args.data:
        from ovon.dataset.io import EpisodeDataset

        inputs["data"] = {"path": path_identity(args.data),
                          "split": EpisodeDataset(args.data, args.split).fingerprint()}
        inputs["scenes"] = {"path": path_identity(args.scenes)}
    if args.init:
        p = Path(args.init) / "policy.pt" if Path(args.init).is_dir() else Path(args.init)
        inputs["init"] = {"sha256": file_sha256(p) if p.is_file() else str(p)}
    return config, inputs


def cmd_train(args) -> int:
    import os

    from ovon.config.base import to_dict
    from ovon.runfolder import RunFolder
    from ovon.train import train
    from ovon.train.distributed import launched_by_torchrun

    cfg = build_config(args)
    out = Path(args.out)
    rank0 = int(os.environ.get("RANK", "0")) == 0
    specs = episode_list(args)
    folder = None
    if rank0:  # one writer: rank 0 holds the folder's lock for the whole run (other ranks write nothing)
        config, inputs = run_identity(args, cfg)
        folder = RunFolder.open(out, "train", config, inputs, resume=args.resume, may_change=MAY_CHANGE,
                                markers=("checkpoint.pt", "policy.pt"))
        atomic_write_text(out / "config.json", json.dumps(to_dict(cfg), indent=1, default=str))
    try:
        last = train(cfg, specs, out, resume=args.resume, init=args.init)
    finally:
        if folder is not None:
            folder.close()
    if rank0:
        shown = {k: round(v, 4) for k, v in last.items() if isinstance(v, float)}
        print(json.dumps(shown))
        print(f"policy: {out / 'policy.pt'}" + (" (torchrun)" if launched_by_torchrun() else ""))
    from ovon.train.distributed import cleanup

    cleanup()
    return 0
