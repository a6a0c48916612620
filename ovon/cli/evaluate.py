"""`ovon evaluate`, `ovon report`, `ovon video`."""

from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass
from pathlib import Path

import yaml

from ovon.config.base import ExistingDir, existing_dir, from_args, in_range, non_empty, non_negative, validate
from ovon.config.sim import SimConfig
from ovon.dataset.io import VAL_SPLITS
from ovon.evaluate.harness import EvalConfig, apply_overrides, check_source, parse_noise, with_camera


def _csv(s: str) -> list[str]:
    return [x.strip() for x in s.split(",") if x.strip()]


def register(sub) -> None:
    p = sub.add_parser("evaluate", help="run an agent over val splits and seeds; resumable")
    p.add_argument(
        "--agent",
        required=True,
        help="random | shortest-path | frontier | policy | vlfm | dagrl-od | pkg.module:Class | "
        "remote:HOST:PORT (an agent served by `ovon serve` or ovon_agent.serve)",
    )
    p.add_argument(
        "--agent-arg",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="keyword argument for the agent's constructor (repeatable)",
    )
    p.add_argument("--checkpoint", help="policy checkpoint (for --agent policy and dagrl-od)")
    p.add_argument(
        "--task",
        choices=["objectnav", "pointnav"],
        default="objectnav",
        help="pointnav: point goals sampled in --procedural houses (no --data / --scenes)",
    )
    p.add_argument("--procedural", metavar="SEEDS", help="--task pointnav: house seeds, e.g. 80000-80003")
    p.add_argument("--data", help="episode dataset root (holds val_seen/ ...); required for objectnav")
    p.add_argument("--scenes", help="scene-datasets root or the scene dataset folder; required for objectnav")
    p.add_argument("--splits", default=",".join(VAL_SPLITS))
    p.add_argument("--seeds", default="0", help="comma-separated, e.g. 0,1,2")
    p.add_argument(
        "--episodes", default=None, help="episodes per split (default: all); pointnav: per house (default 50)"
    )
    p.add_argument(
        "--noise",
        default="",
        help="e.g. actuation,odometry, actuation:movebase*0.5 or odometry:drift "
        "(default odometry: bounded per reading)",
    )
    p.add_argument(
        "--preset",
        choices=["auto", "cpu", "paper"],
        default="auto",
        help="cpu: 160x120 landscape frames (32 deg vertical field; --set sim.camera.width=72 --set "
        "sim.camera.height=128 keeps the paper's portrait view); paper: the 360x640 Stretch camera; "
        "auto: the camera a policy "
        "checkpoint was trained with, else cpu",
    )
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="config override, e.g. sim.camera.width=224 or task.max_steps=300",
    )
    p.add_argument("--workers", default=min(2, os.cpu_count() or 1))
    p.add_argument("--executor", choices=["process", "ray"], default="process")
    p.add_argument("--name", help="row name in tables (default: the agent name)")
    p.add_argument(
        "--strict",
        action="store_true",
        help="refuse a split holding an invalid episode (one line naming the file and the episode) "
        "instead of skipping it with a counted warning",
    )
    p.add_argument("--out", required=True, help="run folder (episodes.jsonl, summary.json, table.md)")
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=cmd_evaluate)

    r = sub.add_parser("report", help="markdown table + figures comparing run folders")
    r.add_argument("runs", nargs="+")
    r.add_argument("--out", help="report folder (default: <first run>/report)")
    r.set_defaults(func=cmd_report)

    c = sub.add_parser("curve", help="learning curve of training runs (SR vs env steps) as a PNG")
    c.add_argument("runs", nargs="+", help="run folders written by ovon train")
    c.add_argument("--metric", default="episode/success", help="a metrics.jsonl key (default: episode/success)")
    c.add_argument("--window", default=10, help="updates averaged per point (episode-weighted)")
    c.add_argument("--out", required=True, help="PNG file")
    c.set_defaults(func=cmd_curve)

    v = sub.add_parser("video", help="render an evaluated episode to mp4")
    v.add_argument("--run", required=True)
    v.add_argument("--episode", required=True)
    v.add_argument("--split")
    v.add_argument("--seed")
    v.add_argument("--scene", help="part of the scene path (episode ids are unique per scene only)")
    v.add_argument("--data", help="episode dataset root, when it moved since the evaluation (default: the run's)")
    v.add_argument("--scenes", help="scenes root, when it moved since the evaluation (default: the run's)")
    v.add_argument("--fps", default=8)
    v.add_argument(
        "--no-agent-view",
        action="store_true",
        help="leave out the panel of what the agent believes (agents with debug_frame, e.g. vlfm)",
    )
    v.add_argument("--out", required=True)
    v.set_defaults(func=cmd_video)


def _agent_kwargs(items: list[str], checkpoint: str | None) -> dict:
    from ovon.config.base import ConfigError

    kwargs = {}
    for item in items:
        k, sep, v = item.partition("=")
        if not sep or not all(part.isidentifier() for part in k.strip().split(".")):
            raise ConfigError(
                f"--agent-arg {item!r} is not KEY=VALUE with KEY a Python name (or dotted names, "
                "for agents that take nested settings); fix: e.g. --agent-arg temperature=0.5 or "
                "--agent-arg navigator.stop_distance_m=0.6"
            )
        try:
            kwargs[k.strip()] = yaml.safe_load(v) if v != "" else ""
        except (yaml.YAMLError, RecursionError, ValueError):
            kwargs[k.strip()] = v  # not YAML: the text itself
        if not _finite(kwargs[k.strip()]):
            # the arguments are part of the run's identity (JSON, which has no nan / inf): refused later
            # with a message naming no key
            raise ConfigError(
                f"--agent-arg {item!r}: {v.strip()} is not a finite number (nan and inf cannot be "
                f"recorded in the run folder); fix: pass a finite number, e.g. --agent-arg "
                f"{k.strip()}=0.5"
            )
    if checkpoint is not None:
        if "checkpoint" in kwargs:
            raise ConfigError("--checkpoint and --agent-arg checkpoint=... both given; fix: pass one of them")
        kwargs["checkpoint"] = checkpoint
    return kwargs


def _finite(value: object) -> bool:
    """No nan / inf anywhere in a parsed `--agent-arg` value (YAML reads `.nan`, `.inf`, `[1, .nan]`)."""
    if isinstance(value, float):
        return math.isfinite(value)
    if isinstance(value, list | tuple):
        return all(_finite(v) for v in value)
    if isinstance(value, dict):
        return all(_finite(v) for v in value.values())
    return True


def checkpoint_facts(checkpoint: str, task: str) -> dict:
    """Camera fields a policy checkpoint was trained with ({} when it does not say): a policy sees the
    world through the resolution it learned on unless the user asks otherwise. Refuses, before any work, a
    file that is not a policy and a policy of the other task (`task`: the --task being evaluated)."""
    from ovon.config.base import ConfigError
    from ovon.config.sim import CameraConfig
    from ovon.models.policy import policy_task_kind, read_policy_file

    ckpt = read_policy_file(checkpoint, "--checkpoint")
    kind = policy_task_kind(ckpt)
    if kind is not None and kind != task:
        fix = (
            "evaluate it with --task pointnav (point goals in procedural houses), or use it as VLFM's "
            "navigator: --agent vlfm --agent-arg navigator=learned --agent-arg navigator.checkpoint=PATH"
            if kind == "pointnav"
            else "leave --task pointnav out"
        )
        name = {"objectnav": "an ObjectNav", "pointnav": "a PointNav"}
        raise ConfigError(
            f"--checkpoint {checkpoint!r} is {name.get(kind, kind)} policy, this is "
            f"{name.get(task, task)} evaluation; fix: {fix}"
        )
    extra = ckpt.get("extra", {}) or {}
    camera = extra.get("camera") if isinstance(extra, dict) else None
    fields = {f.name for f in dataclasses.fields(CameraConfig)}
    return {k: v for k, v in (camera or {}).items() if k in fields and k != "backend"}


def eval_config(args) -> EvalConfig:
    """The command line as an `EvalConfig`, through the one config path (coercion + declared domains), so
    `--episodes -1`, `--seeds ''` or `--splits ''` are refused with the same one-line message as `--set`."""
    from ovon.config.base import from_dict

    cfg = from_dict(
        EvalConfig,
        {
            "agent": args.agent,
            "agent_kwargs": _agent_kwargs(args.agent_arg, args.checkpoint),
            "data": args.data,
            "scenes": args.scenes,
            "procedural": args.procedural or "",
            "splits": args.splits,
            "seeds": args.seeds,
            "episodes": args.episodes,
            "workers": args.workers,
            "executor": args.executor,
            "name": args.name,
            "strict": args.strict,
        },
    )
    checkpoint = cfg.agent_kwargs.get("checkpoint") if args.agent in ("policy", "dagrl-od") else None
    camera = checkpoint_facts(str(checkpoint), "objectnav") if checkpoint else {}
    if args.preset == "paper":
        cfg = dataclasses.replace(cfg, sim=SimConfig())
    elif args.preset == "auto" and checkpoint:
        if camera:
            cfg = with_camera(cfg, camera)
            print(
                f"camera of the checkpoint: {camera.get('width')}x{camera.get('height')} (--preset cpu|paper overrides)"
            )
    cfg = dataclasses.replace(cfg, sim=dataclasses.replace(cfg.sim, noise=parse_noise(args.noise)))
    return validate(apply_overrides(cfg, args.set))


def pointnav_config(args) -> EvalConfig:
    """The command line as a PointNav `EvalConfig` (`ovon.evaluate.pointnav`): the checkpoint's task and
    camera unless --set says otherwise."""
    from ovon.config.base import from_dict
    from ovon.evaluate.pointnav import checkpoint_task, pointnav_defaults

    kwargs = _agent_kwargs(args.agent_arg, args.checkpoint)
    data = {
        "agent": args.agent,
        "agent_kwargs": kwargs,
        "data": args.data or "",
        "scenes": args.scenes or "",
        "procedural": args.procedural or "",
        "seeds": args.seeds,
        "workers": args.workers,
        "executor": args.executor,
        "name": args.name,
    }
    if args.episodes is not None:
        data["episodes"] = args.episodes
    cfg = from_dict(EvalConfig, {**pointnav_defaults(), **data})
    check_source(cfg)
    ckpt = kwargs.get("checkpoint")
    camera = checkpoint_facts(str(ckpt), "pointnav") if ckpt else {}
    cfg = dataclasses.replace(cfg, task=checkpoint_task(str(ckpt) if ckpt else None))
    if args.preset == "paper":
        cfg = dataclasses.replace(cfg, sim=SimConfig())
    elif args.preset == "auto" and ckpt:
        if camera:
            cfg = with_camera(cfg, camera)
    elif args.preset == "cpu":
        cfg = with_camera(cfg, {"width": 160, "height": 120})
    cfg = dataclasses.replace(cfg, sim=dataclasses.replace(cfg.sim, noise=parse_noise(args.noise)))
    return validate(apply_overrides(cfg, args.set))


def cmd_evaluate(args) -> int:
    from ovon.evaluate.harness import evaluate

    cfg = pointnav_config(args) if args.task == "pointnav" else eval_config(args)
    summary = evaluate(cfg, args.out, progress=not args.no_progress)
    print((Path(args.out) / "table.md").read_text(), end="")
    n = sum(s["episodes"] for s in summary["splits"].values())
    skipped = sum((s.get("skipped") or {}).get("count", 0) for s in summary["splits"].values())
    note = f" ({skipped} skipped before the run, see above)" if skipped else ""
    print(f"{n} episodes{note}; run folder: {args.out}")
    return 0


@dataclass(frozen=True)
class ReportArgs:
    runs: tuple[str, ...] = non_empty((), each=ExistingDir(), distinct=True, flag="RUNS")


@dataclass(frozen=True)
class VideoArgs:
    run: str = existing_dir(flag="--run")
    episode: str = non_empty("", flag="--episode")
    seed: int | None = non_negative(None, flag="--seed")
    fps: int = in_range(8, 1, 120, flag="--fps")
    data: str = existing_dir("", optional=True, flag="--data")
    scenes: str = existing_dir("", optional=True, flag="--scenes")


def cmd_report(args) -> int:
    from ovon.reports.build import build_report

    a = from_args(ReportArgs, args, runs=tuple(args.runs))
    out = args.out or str(Path(a.runs[0]) / "report")
    path = build_report(list(a.runs), out)
    print(path.read_text().split("## Failure breakdown")[0], end="")
    print(f"report: {path}")
    return 0


@dataclass(frozen=True)
class CurveArgs:
    runs: tuple[str, ...] = non_empty((), each=ExistingDir(), distinct=True, flag="RUNS")
    window: int = in_range(10, 1, 100_000, flag="--window")
    metric: str = non_empty("episode/success", flag="--metric")


def cmd_curve(args) -> int:
    from ovon.reports.plots import plot_learning_curves

    a = from_args(CurveArgs, args, runs=tuple(args.runs))
    path = plot_learning_curves(list(a.runs), args.out, a.metric, a.window)
    print(f"curve: {path}")
    return 0


def cmd_video(args) -> int:
    from ovon.reports.video import render_video

    a = from_args(VideoArgs, args)
    path = render_video(
        a.run,
        a.episode,
        args.out,
        split=args.split,
        seed=a.seed,
        fps=a.fps,
        scene=args.scene,
        agent_view=not args.no_agent_view,
        data=a.data or None,
        scenes=a.scenes or None,
    )
    print(f"video: {path}")
    return 0
