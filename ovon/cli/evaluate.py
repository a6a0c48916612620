"""`ovon evaluate`, `ovon report`, `ovon video`."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

from ovon.config.base import ExistingDir, existing_dir, from_args, in_range, non_empty, non_negative
from ovon.config.sim import CameraConfig, cpu_sim_config
from ovon.dataset.io import VAL_SPLITS


def _camera_words(camera: CameraConfig) -> str:
    """A camera as `--preset`'s help says it, derived from the preset so the two cannot disagree."""
    vfov = math.degrees(2 * math.atan(math.tan(math.radians(camera.hfov_deg) / 2) * camera.height / camera.width))
    shape = "portrait" if camera.height > camera.width else "landscape"
    return (
        f"{camera.width}x{camera.height} {shape} frames ({camera.hfov_deg:g} deg horizontal, {vfov:.0f} deg vertical)"
    )


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
    p.add_argument("--splits", default=",".join(VAL_SPLITS), help="comma-separated splits to evaluate")
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
        help=f"cpu: {_camera_words(cpu_sim_config().camera)}; paper: the Stretch camera, "
        f"{_camera_words(CameraConfig())}; auto: the camera a policy checkpoint was trained with, else cpu",
    )
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="config override, e.g. sim.camera.width=224 or task.max_steps=300",
    )
    p.add_argument("--workers", default=min(2, os.cpu_count() or 1), help="worker processes")
    p.add_argument(
        "--executor", choices=["process", "ray"], default="process", help="run the workers as local processes or on ray"
    )
    p.add_argument("--name", help="row name in tables (default: the agent name)")
    p.add_argument(
        "--strict",
        action="store_true",
        help="refuse a split holding an invalid episode (one line naming the file and the episode) "
        "instead of skipping it with a counted warning",
    )
    p.add_argument(
        "--subset",
        metavar="FILE|NAME",
        help="run only a canonical subset of each split: a named one (mini: 360 per split) or a file written by "
        "`ovon dataset subset`",
    )
    p.add_argument(
        "--protocol",
        metavar="NAME",
        help="start from a named protocol's settings: hm3d-ovon (the authors' camera, task, no noise), none (ovon's "
        "CPU defaults) or auto (default: hm3d-ovon when the episodes name HM3D scenes, else none); an option that "
        "changes a setting makes the run's protocol card say custom",
    )
    p.add_argument("--out", required=True, help="run folder (episodes.jsonl, summary.json, table.md)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_evaluate)

    r = sub.add_parser("report", help="markdown table + figures comparing run folders")
    r.add_argument("runs", nargs="+", help="run folders written by ovon evaluate")
    r.add_argument("--out", help="report folder (default: <first run>/report)")
    r.set_defaults(func=cmd_report)

    c = sub.add_parser("curve", help="learning curve of training runs (SR vs env steps) as a PNG")
    c.add_argument("runs", nargs="+", help="run folders written by ovon train")
    c.add_argument("--metric", default="episode/success", help="a metrics.jsonl key (default: episode/success)")
    c.add_argument("--window", default=10, help="updates averaged per point (episode-weighted)")
    c.add_argument("--out", required=True, help="PNG file")
    c.set_defaults(func=cmd_curve)

    v = sub.add_parser("video", help="render an evaluated episode to mp4")
    v.add_argument("--run", required=True, help="run folder written by ovon evaluate")
    v.add_argument("--episode", required=True, help="episode id to render")
    v.add_argument("--split", help="split of the episode (needed when the run evaluated several)")
    v.add_argument("--seed", help="evaluation seed of the episode (needed when the run has several)")
    v.add_argument("--scene", help="part of the scene path (episode ids are unique per scene only)")
    v.add_argument("--data", help="episode dataset root, when it moved since the evaluation (default: the run's)")
    v.add_argument("--scenes", help="scenes root, when it moved since the evaluation (default: the run's)")
    v.add_argument("--fps", default=8, help="frames per second of the video")
    v.add_argument(
        "--no-agent-view",
        action="store_true",
        help="leave out the panel of what the agent believes (agents with debug_frame, e.g. vlfm)",
    )
    v.add_argument("--out", required=True, help="mp4 file to write")
    v.set_defaults(func=cmd_video)


def cmd_evaluate(args) -> int:
    from ovon.evaluate.config import eval_config
    from ovon.evaluate.harness import evaluate

    for flag, value, what in (
        ("--data", args.data, "the episode dataset root (holds val_seen/ ...)"),
        ("--scenes", args.scenes, "the scene-datasets root or the scene dataset folder"),
    ):
        check_folder(flag, value, what)
    notes: list[str] = []
    cfg = eval_config(args, notes)
    for note in notes:
        print(note)
    summary = evaluate(cfg, args.out, progress=not args.no_progress)
    print((Path(args.out) / "table.md").read_text(), end="")
    n = sum(s["episodes"] for s in summary["splits"].values())
    skipped = sum((s.get("skipped") or {}).get("count", 0) for s in summary["splits"].values())
    note = f" ({skipped} skipped before the run, see above)" if skipped else ""
    print(f"{n} episodes{note}; run folder: {args.out}")
    return 0


def check_folder(flag: str, value: str | None, what: str) -> None:
    """One line for a folder option naming no folder (before the config's own check, whose message
    would cite the config's default rather than what was typed)."""
    if value and value.strip() and not Path(value).is_dir():
        why = "is a file" if Path(value).exists() else "does not exist"
        raise ValueError(f"{flag} {value}: {why}; expected {what}; fix: check the path")


def check_runs(runs: list[str], written_by: str) -> None:
    """One line naming the first RUNS entry that is not a run folder, or a repeated one."""
    seen: set[str] = set()
    for run in runs:
        check_folder("RUNS", run, f"a run folder written by {written_by}")
        if str(Path(run).resolve()) in seen:
            raise ValueError(f"RUNS: {run} is given twice; expected distinct run folders; fix: name each once")
        seen.add(str(Path(run).resolve()))


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

    check_runs(args.runs, "`ovon evaluate`")
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

    check_runs(args.runs, "`ovon train`")
    a = from_args(CurveArgs, args, runs=tuple(args.runs))
    path = plot_learning_curves(list(a.runs), args.out, a.metric, a.window)
    print(f"curve: {path}")
    return 0


def cmd_video(args) -> int:
    from ovon.reports.video import render_video

    check_folder("--data", args.data, "the episode dataset root (holds val_seen/ ...)")
    check_folder("--scenes", args.scenes, "the scenes root")
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
