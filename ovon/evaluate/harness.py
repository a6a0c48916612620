"""`ovon evaluate`: agents over splits and seeds, episodes in worker processes (or Ray tasks), one JSON
line per episode as it finishes, resumable, then a summary and the paper-style table."""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from pathlib import Path

from ovon.atomic import atomic_write_text
from ovon.config.base import merge, parse_overrides, to_dict
from ovon.config.sim import CameraConfig, NoiseConfig, SimConfig
from ovon.config.task import TaskConfig
from ovon.evaluate.results import RecordWriter, paper_table, read_records, record_key, summarize
from ovon.parallel import init_worker, progress_bar, run_jobs
from ovon.task.episode import EpisodeSpec

DEFAULT_SPLITS = ("val_seen", "val_seen_synonyms", "val_unseen")


@dataclass
class EvalConfig:
    agent: str = "random"
    agent_kwargs: dict = field(default_factory=dict)
    data: str = "data/datasets/ovon"
    scenes: str = "data/scene_datasets"
    splits: tuple[str, ...] = DEFAULT_SPLITS
    seeds: tuple[int, ...] = (0,)
    episodes: int | None = None  # per split; None = all
    workers: int = 1
    executor: str = "process"  # process | ray
    chunk: int = 4  # episodes per work unit (same scene)
    sim: SimConfig = field(default_factory=lambda: SimConfig(camera=CameraConfig(width=160, height=120)))
    task: TaskConfig = field(default_factory=TaskConfig)
    name: str | None = None  # row name in tables; default = agent


def parse_noise(spec: str | None) -> NoiseConfig:
    """`actuation,odometry`, `actuation:movebase`, `actuation:ilqr*2` (multiplier) or empty."""
    cfg = NoiseConfig()
    if not spec:
        return cfg
    for item in [s.strip() for s in spec.split(",") if s.strip()]:
        name, _, arg = item.partition(":")
        if name == "actuation":
            model, _, mult = (arg or "ilqr").partition("*")
            cfg = dataclasses.replace(cfg, actuation=model, actuation_multiplier=float(mult or 1.0))
        elif name == "odometry":
            cfg = dataclasses.replace(cfg, odometry=True)
        else:
            raise ValueError(
                f"unknown noise {item!r}: use actuation[:ilqr|proportional|movebase|gaussian][*k], odometry"
            )
    if cfg.actuation not in ("none", "gaussian", "ilqr", "proportional", "movebase"):
        raise ValueError(f"unknown actuation model {cfg.actuation!r}")
    return cfg


def apply_overrides(cfg: EvalConfig, overrides: list[str]) -> EvalConfig:
    data = parse_overrides(overrides)
    sim = merge(cfg.sim, data.pop("sim"), "sim") if "sim" in data else cfg.sim
    task = merge(cfg.task, data.pop("task"), "task") if "task" in data else cfg.task
    if data:
        raise ValueError(f"unknown override group(s) {sorted(data)}: use sim.* or task.*")
    return dataclasses.replace(cfg, sim=sim, task=task)


def load_specs(data: str, scenes: str, split: str, limit: int | None) -> list[EpisodeSpec]:
    """Episodes of a split as `EpisodeSpec`s, spread round-robin over scenes when limited."""
    from ovon.dataset.io import EpisodeDataset, goals_for
    from ovon.dataset.records import resolve_scene_path
    from ovon.task.episode import spec_from_episode

    ds = EpisodeDataset(data, split)
    per_scene: list[list[EpisodeSpec]] = []
    for scene in ds.scenes():
        shard = ds.load_scene(scene)
        specs = []
        for ep in shard.episodes:
            path = str(resolve_scene_path(ep.scene_id, scenes))
            specs.append(spec_from_episode(ep, goals_for(ep, shard.goals_by_category), path, split))
        per_scene.append(specs)
    out = [p[i] for i in range(max(map(len, per_scene), default=0)) for p in per_scene if i < len(p)]
    return out if limit is None else out[:limit]


# -- worker side ---------------------------------------------------------------------------------
_CACHE: dict = {}


def run_unit(unit: dict) -> list[dict]:
    """Runs a chunk of episodes of one scene; env and agent are cached per process across chunks."""
    from ovon.agents import is_privileged, make_agent
    from ovon.config.base import from_dict
    from ovon.env.stack import EnvRecipe, build_env
    from ovon.evaluate.runner import run_episode

    init_worker()
    agent_key = (unit["agent"], json.dumps(unit["agent_kwargs"], sort_keys=True))
    if _CACHE.get("agent_key") != agent_key:
        _CACHE["agent"] = make_agent(unit["agent"], **unit["agent_kwargs"])
        _CACHE["agent_key"] = agent_key
    agent = _CACHE["agent"]
    privileged = is_privileged(agent)
    key = (json.dumps(unit["sim"], sort_keys=True), json.dumps(unit["task"], sort_keys=True), privileged)
    if _CACHE.get("env_key") != key:
        if "env" in _CACHE:
            _CACHE["env"].close()
        recipe = EnvRecipe(sim=from_dict(SimConfig, unit["sim"]), task=from_dict(TaskConfig, unit["task"]),
                           episodes=unit["specs"][:1], sample_episodes=False, privileged=privileged)
        _CACHE["env"] = build_env(recipe)
        _CACHE["env_key"] = key
    env = _CACHE["env"]
    return [run_episode(env, agent, spec, unit["seed"]) for spec in unit["specs"]]


# -- parent side ---------------------------------------------------------------------------------
def _units(cfg: EvalConfig, specs_by_split: dict[str, list[EpisodeSpec]], done: set) -> list[dict]:
    units = []
    sim, task = to_dict(cfg.sim), to_dict(cfg.task)
    for seed in cfg.seeds:
        for split, specs in specs_by_split.items():
            by_scene: dict[str, list[EpisodeSpec]] = {}
            for s in specs:
                if (split, int(seed), s.scene, s.episode_id) not in done:
                    by_scene.setdefault(s.scene, []).append(s)
            for scene_specs in by_scene.values():
                for i in range(0, len(scene_specs), cfg.chunk):
                    units.append(
                        {
                            "specs": scene_specs[i : i + cfg.chunk],
                            "seed": int(seed),
                            "agent": cfg.agent,
                            "agent_kwargs": cfg.agent_kwargs,
                            "sim": sim,
                            "task": task,
                        }
                    )
    return units


def evaluate(cfg: EvalConfig, run_dir: str | Path, progress: bool = True) -> dict:
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    specs_by_split = {s: load_specs(cfg.data, cfg.scenes, s, cfg.episodes) for s in cfg.splits}
    for split, specs in specs_by_split.items():
        if not specs:
            raise ValueError(f"split {split!r} in {cfg.data} has no episodes")
    atomic_write_text(run_dir / "run.json", json.dumps({**to_dict(cfg), "name": cfg.name or cfg.agent}, indent=2))
    done = {record_key(r) for r in read_records(run_dir, repair=True)}
    units = _units(cfg, specs_by_split, done)
    total = sum(len(u["specs"]) for u in units)
    writer = RecordWriter(run_dir)
    try:
        with progress_bar(f"evaluate {cfg.name or cfg.agent}", total, progress and total > 0) as bar:
            for recs in run_jobs(run_unit, units, cfg.workers, cfg.executor):
                for r in recs:
                    writer.write(r)
                bar.advance(len(recs))
    finally:
        writer.close()
    return finalize(run_dir, cfg.name or cfg.agent)


def finalize(run_dir: str | Path, name: str) -> dict:
    """Summary JSON and the table, from whatever the jsonl holds (so it is identical after a resume)."""
    run_dir = Path(run_dir)
    records = read_records(run_dir)
    summary = {"name": name, "splits": summarize(records)}
    atomic_write_text(run_dir / "summary.json", json.dumps(summary, indent=2, sort_keys=True))
    atomic_write_text(run_dir / "table.md", paper_table({name: summary["splits"]}) + "\n")
    return summary
