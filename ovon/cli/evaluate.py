"""`ovon evaluate`, `ovon report`, `ovon video`."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import yaml

from ovon.config.sim import SimConfig


def _csv(s: str) -> list[str]:
    return [x.strip() for x in s.split(",") if x.strip()]


def register(sub) -> None:
    p = sub.add_parser("evaluate", help="run an agent over val splits and seeds; resumable")
    p.add_argument("--agent", required=True,
                   help="random | shortest-path | frontier | policy | vlfm | dagrl-od | pkg.module:Class")
    p.add_argument("--agent-arg", action="append", default=[], metavar="KEY=VALUE",
                   help="keyword argument for the agent's constructor (repeatable)")
    p.add_argument("--checkpoint", help="policy checkpoint (for --agent policy and dagrl-od)")
    p.add_argument("--data", required=True, help="episode dataset root (holds val_seen/ ...)")
    p.add_argument("--scenes", required=True, help="scene-datasets root or the scene dataset folder")
    p.add_argument("--splits", default="val_seen,val_seen_synonyms,val_unseen")
    p.add_argument("--seeds", default="0")
    p.add_argument("--episodes", type=int, default=None, help="episodes per split (default: all)")
    p.add_argument("--noise", default="", help="e.g. actuation,odometry or actuation:movebase*0.5")
    p.add_argument("--preset", choices=["auto", "cpu", "paper"], default="auto",
                   help="cpu: 160x120 frames; paper: the 360x640 Stretch camera; auto: the camera a policy "
                        "checkpoint was trained with, else cpu")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="config override, e.g. sim.camera.width=224 or task.max_steps=300")
    p.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    p.add_argument("--executor", choices=["process", "ray"], default="process")
    p.add_argument("--name", help="row name in tables (default: the agent name)")
    p.add_argument("--out", required=True, help="run folder (episodes.jsonl, summary.json, table.md)")
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=cmd_evaluate)

    r = sub.add_parser("report", help="markdown table + figures comparing run folders")
    r.add_argument("runs", nargs="+")
    r.add_argument("--out", help="report folder (default: <first run>/report)")
    r.set_defaults(func=cmd_report)

    v = sub.add_parser("video", help="render an evaluated episode to mp4")
    v.add_argument("--run", required=True)
    v.add_argument("--episode", required=True)
    v.add_argument("--split")
    v.add_argument("--seed", type=int)
    v.add_argument("--scene", help="part of the scene path (episode ids are unique per scene only)")
    v.add_argument("--fps", type=int, default=8)
    v.add_argument("--out", required=True)
    v.set_defaults(func=cmd_video)


def _agent_kwargs(items: list[str], checkpoint: str | None) -> dict:
    kwargs = {}
    for item in items:
        if "=" not in item:
            raise ValueError(f"--agent-arg {item!r} is not KEY=VALUE")
        k, v = item.split("=", 1)
        kwargs[k] = yaml.safe_load(v)
    if checkpoint:
        kwargs["checkpoint"] = checkpoint
    return kwargs


def trained_camera(checkpoint: str) -> dict:
    """Camera fields a policy checkpoint was trained with ({} when it does not say): a policy sees the
    world through the resolution it learned on unless the user asks otherwise."""
    import torch

    from ovon.config.sim import CameraConfig

    path = Path(checkpoint)
    path = path / "policy.pt" if path.is_dir() else path
    if not path.is_file():
        raise FileNotFoundError(f"policy checkpoint {path} does not exist; pass the policy.pt written by ovon train")
    extra = torch.load(path, map_location="cpu", weights_only=True).get("extra", {}) or {}
    fields = {f.name for f in dataclasses.fields(CameraConfig)}
    return {k: v for k, v in (extra.get("camera") or {}).items() if k in fields and k != "backend"}


def cmd_evaluate(args) -> int:
    from ovon.evaluate.harness import EvalConfig, apply_overrides, evaluate, parse_noise

    cfg = EvalConfig(
        agent=args.agent,
        agent_kwargs=_agent_kwargs(args.agent_arg, args.checkpoint),
        data=args.data,
        scenes=args.scenes,
        splits=tuple(_csv(args.splits)),
        seeds=tuple(int(s) for s in _csv(args.seeds)),
        episodes=args.episodes,
        workers=args.workers,
        executor=args.executor,
        name=args.name,
    )
    if args.preset == "paper":
        cfg = dataclasses.replace(cfg, sim=SimConfig())
    elif args.preset == "auto" and args.agent in ("policy", "dagrl-od") and cfg.agent_kwargs.get("checkpoint"):
        camera = trained_camera(cfg.agent_kwargs["checkpoint"])
        if camera:
            cfg = dataclasses.replace(cfg, sim=dataclasses.replace(
                cfg.sim, camera=dataclasses.replace(cfg.sim.camera, **camera)))
            print(f"camera of the checkpoint: {camera['width']}x{camera['height']} (--preset cpu|paper overrides)")
    cfg = dataclasses.replace(cfg, sim=dataclasses.replace(cfg.sim, noise=parse_noise(args.noise)))
    cfg = apply_overrides(cfg, args.set)
    summary = evaluate(cfg, args.out, progress=not args.no_progress)
    print((Path(args.out) / "table.md").read_text(), end="")
    n = sum(s["episodes"] for s in summary["splits"].values())
    print(f"{n} episodes; run folder: {args.out}")
    return 0


def cmd_report(args) -> int:
    from ovon.reports.build import build_report

    out = args.out or str(Path(args.runs[0]) / "report")
    path = build_report(args.runs, out)
    print(path.read_text().split("## Failure breakdown")[0], end="")
    print(f"report: {path}")
    return 0


def cmd_video(args) -> int:
    from ovon.reports.video import render_video

    path = render_video(args.run, args.episode, args.out, split=args.split, seed=args.seed, fps=args.fps,
                        scene=args.scene)
    print(f"video: {path}")
    return 0
