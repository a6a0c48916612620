"""`ovon train`: BC, DAgger, PPO and BC/DAgger->RL fine-tuning; the same command under `torchrun`."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path


def register(sub) -> None:
    p = sub.add_parser("train", help="train a learned baseline (bc | dagger | ppo); works under torchrun")
    p.add_argument("--algo", choices=["bc", "dagger", "ppo"], required=True)
    p.add_argument("--policy", choices=["transformer", "lstm"], default=None, help="policy core (default: preset)")
    p.add_argument("--encoder", choices=["oracle-vl", "siglip", "cnn"], default=None,
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
    preset = train_preset(args.preset, **changes)
    if args.policy:
        preset = dataclasses.replace(preset, policy=dataclasses.replace(preset.policy, core=args.policy))
    if args.encoder:
        preset = dataclasses.replace(preset, encoder=dataclasses.replace(preset.encoder, image=args.encoder))
    return build(type(preset), preset, args.config, args.set)


def episode_list(args):
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


def cmd_train(args) -> int:
    from ovon.config.base import to_dict
    from ovon.train import train
    from ovon.train.distributed import launched_by_torchrun

    cfg = build_config(args)
    out = Path(args.out)
    rank0 = int(__import__("os").environ.get("RANK", "0")) == 0
    if (out / "checkpoint.pt").exists() and not args.resume:
        raise ValueError(f"{out} already holds a checkpoint: pass --resume to continue or choose another --out")
    if rank0:
        out.mkdir(parents=True, exist_ok=True)
        (out / "config.json").write_text(json.dumps(to_dict(cfg), indent=1, default=str))
    specs = episode_list(args)
    last = train(cfg, specs, out, resume=args.resume, init=args.init)
    if rank0:
        shown = {k: round(v, 4) for k, v in last.items() if isinstance(v, float)}
        print(json.dumps(shown))
        print(f"policy: {out / 'policy.pt'}" + (" (torchrun)" if launched_by_torchrun() else ""))
    from ovon.train.distributed import cleanup

    cleanup()
    return 0
