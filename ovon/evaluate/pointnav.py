"""`ovon evaluate --task pointnav`: an agent on point goals in procedural houses (held-out ones for a
trained PointNav policy), with the ObjectNav harness's workers, records, resume and table.

Why no dataset: a PointNav episode is (house, index); its start/goal pair is sampled at reset from the
episode seed (`ovon.evaluate.runner.episode_seed`), so a seed fixes every pair, every agent gets the same
ones, and the records replay like any other. The task (success radius, distance range, step limit) is the
one the checkpoint was trained with unless `--set task.*` changes it.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from ovon.agents.remote import RemoteConfig
from ovon.atomic import atomic_write_text
from ovon.config.base import NonNegative, constrained, in_range, non_empty, positive, to_dict, validate
from ovon.config.sim import CameraConfig, SimConfig
from ovon.config.task import TaskConfig

SPLIT = "val"
MAY_CHANGE = ("seeds", "episodes", "workers", "executor", "chunk", "name", "agent_kwargs.checkpoint")


@dataclass
class PointNavEvalConfig:
    agent: str = non_empty("policy", flag="--agent")
    agent_kwargs: dict = field(default_factory=dict)
    procedural: str = non_empty("80000-80003", flag="--procedural")  # house seeds, e.g. 80000-80003
    seeds: tuple[int, ...] = non_empty((0,), each=NonNegative(), distinct=True, flag="--seeds")
    episodes: int = positive(50, flag="--episodes")  # per house
    workers: int = in_range(1, 1, 1024, flag="--workers")
    executor: Literal["process", "ray"] = constrained("process", flag="--executor")
    chunk: int = in_range(10, 1, 100_000)
    sim: SimConfig = field(default_factory=lambda: SimConfig(camera=CameraConfig(width=72, height=128, rgb=False)))
    task: TaskConfig = field(default_factory=lambda: TaskConfig(kind="pointnav"))
    name: str | None = non_empty(None, flag="--name")


def checkpoint_task(checkpoint: str | None) -> TaskConfig:
    """The task a PointNav checkpoint was trained with, else the cpu-small PointNav preset's."""
    from ovon.config.base import from_dict
    from ovon.config.task import pointnav_task

    if checkpoint:
        import torch

        path = Path(checkpoint)
        path = path / "policy.pt" if path.is_dir() else path
        if path.is_file():
            extra = torch.load(path, map_location="cpu", weights_only=True).get("extra") or {}
            task = extra.get("task")
            if task:
                return from_dict(TaskConfig, task)
    return pointnav_task()


def evaluate_pointnav(cfg: PointNavEvalConfig, run_dir: str | Path, progress: bool = True) -> dict:
    """Run every (seed, house, episode) not yet in `run_dir`; returns the summary (split "val")."""
    from ovon.agents import check_agent
    from ovon.config.base import parse_seed_list
    from ovon.evaluate.harness import EvalConfig, _units, finalize, run_unit
    from ovon.evaluate.results import RecordWriter, read_records, record_key
    from ovon.parallel import progress_bar, run_jobs
    from ovon.runfolder import RunFolder
    from ovon.task.pointgoal import pointnav_specs

    validate(cfg)
    if cfg.task.kind != "pointnav":
        raise ValueError(f"task.kind = {cfg.task.kind!r}; fix: --task pointnav evaluates with task.kind=pointnav")
    houses = parse_seed_list(cfg.procedural)
    check_agent(cfg.agent, cfg.agent_kwargs)
    specs = pointnav_specs([f"procedural:{h}" for h in houses], cfg.episodes, SPLIT)
    run_dir = Path(run_dir)
    inputs = {"procedural": houses}
    ckpt = cfg.agent_kwargs.get("checkpoint")
    if isinstance(ckpt, str) and ckpt:
        from ovon.runfolder import file_sha256

        p = Path(ckpt) / "policy.pt" if Path(ckpt).is_dir() else Path(ckpt)
        if p.is_file():
            inputs["checkpoint"] = {"sha256": file_sha256(p)}
    name = cfg.name or cfg.agent
    with RunFolder.open(run_dir, "evaluate", to_dict(cfg), inputs, may_change=MAY_CHANGE, markers=("episodes.jsonl",)):
        atomic_write_text(run_dir / "run.json", json.dumps({**to_dict(cfg), "name": name}, indent=2))
        done = {record_key(r) for r in read_records(run_dir, repair=True)}
        shim = EvalConfig.__new__(EvalConfig)  # the harness's unit builder reads only these fields
        for f in ("seeds", "agent", "agent_kwargs", "sim", "task", "chunk"):
            object.__setattr__(shim, f, getattr(cfg, f))
        object.__setattr__(shim, "remote", RemoteConfig())  # a served agent is not supported for pointnav
        units = _units(shim, {SPLIT: specs}, done)
        writer = RecordWriter(run_dir)
        try:
            with progress_bar(
                f"evaluate {name} (pointnav)", sum(len(u["specs"]) for u in units), progress and bool(units)
            ) as bar:
                for recs in run_jobs(run_unit, units, cfg.workers, cfg.executor):
                    for r in recs:
                        writer.write(r)
                    bar.advance(len(recs))
        finally:
            writer.close()
        wanted = {(SPLIT, int(seed), s.scene, s.episode_id) for seed in cfg.seeds for s in specs}
        return finalize(run_dir, name, wanted)


def with_camera(cfg: PointNavEvalConfig, camera: dict) -> PointNavEvalConfig:
    return dataclasses.replace(
        cfg, sim=dataclasses.replace(cfg.sim, camera=dataclasses.replace(cfg.sim.camera, **camera))
    )
