"""`ovon perception pretrain` and `ovon perception evaluate`: ovon's own perception for the embedded world
(the world-vl network: the `world-owl` detector, the `world-vl` encoder and value scorer)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ovon.config.base import existing_dir, existing_file, in_range, non_negative, positive


@dataclass(frozen=True)
class PretrainArgs:
    config: str = existing_file("", optional=True, flag="--config")


@dataclass(frozen=True)
class PerceptionEvalArgs:
    """`evaluate`'s options through declared domains: `--frames-per-house 0` or `--houses -1` would give an
    empty report instead of a one-line refusal."""

    data: str = existing_dir("", flag="--data")
    scenes: str = existing_dir("", flag="--scenes")
    frames_per_house: int = in_range(200, 1, 100_000, flag="--frames-per-house")
    houses: int | None = positive(None, flag="--houses")
    seed: int = non_negative(0, flag="--seed")


def register(sub) -> None:
    p = sub.add_parser("perception", help="pretrain and evaluate ovon's world-vl perception (world-owl detector)")
    ps = p.add_subparsers(dest="perception_command", required=True)

    t = ps.add_parser(
        "pretrain",
        help="train the world-vl network on frames of the pretrain houses; writes <out>/world_vl.safetensors",
    )
    t.add_argument(
        "--out", required=True, help="run folder (frames/, checkpoint.pt, metrics.jsonl, world_vl.safetensors)"
    )
    t.add_argument("--preset", choices=["cpu", "tiny"], default="cpu", help="cpu: under an hour; tiny: seconds")
    t.add_argument("--config", help="YAML file of PretrainConfig keys merged over the preset")
    t.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE", help="override, e.g. steps=2000 net.fpn=64"
    )
    t.add_argument("--resume", action="store_true", help="continue from <out>/checkpoint.pt exactly")
    t.add_argument("--no-progress", action="store_true", help="no progress bars")
    t.set_defaults(func=cmd_pretrain)

    e = ps.add_parser(
        "evaluate",
        help="world-owl and world-vl on the val splits' houses, frame by frame, beside oracle detection",
    )
    e.add_argument("--data", required=True, help="episode dataset root (holds val_seen/ ...)")
    e.add_argument("--scenes", required=True, help="scene-datasets root or the scene dataset folder")
    e.add_argument("--out", required=True, help="folder for perception.json, perception.md, pr.png and frames/")
    e.add_argument("--checkpoint", help="world_vl.safetensors or its run folder (default: the shipped weights)")
    e.add_argument("--frames-per-house", help="frames rendered per house (default 200)")
    e.add_argument("--houses", help="at most this many houses per split (default: all)")
    e.add_argument("--seed", help="render and oracle-noise seed (default 0)")
    e.add_argument("--no-progress", action="store_true", help="no progress bars")
    e.set_defaults(func=cmd_evaluate)


def cmd_pretrain(args) -> int:
    from ovon.atomic import check_output_path
    from ovon.config.base import build, check_config_file, from_args
    from ovon.perception.config import PRESETS, PretrainConfig
    from ovon.perception.pretrain import train

    check_config_file(args.config, "PretrainConfig")
    a = from_args(PretrainArgs, args)
    check_output_path(args.out, "--out", folder=True)
    cfg = build(PretrainConfig, PRESETS[args.preset], a.config or None, args.set)
    path = train(cfg, args.out, resume=args.resume, progress=not args.no_progress)  # opens and locks --out
    print(f"weights: {path}")
    return 0


def cmd_evaluate(args) -> int:
    from ovon.atomic import check_output_path
    from ovon.config.base import from_args
    from ovon.perception.evaluate import evaluate

    a = from_args(PerceptionEvalArgs, args)
    check_output_path(args.out, "--out", folder=True)
    evaluate(
        a.data,
        a.scenes,
        args.out,
        checkpoint=args.checkpoint,
        frames_per_house=a.frames_per_house,
        houses=a.houses,
        seed=a.seed,
        progress=not args.no_progress,
    )
    out = Path(args.out)
    print((out / "perception.md").read_text(), end="")
    print(f"perception: {out / 'perception.json'}")
    return 0
