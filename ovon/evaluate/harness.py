"""`ovon evaluate`: agents over splits and seeds, episodes in worker processes (or Ray tasks), one JSON
line per episode as it finishes, resumable, then a summary and the paper-style table.

Before any work: the config is validated (declared domains), the agent is built once, every episode is
checked (`ovon.dataset.validate`: bad ones are skipped with a counted warning, starts off the navigable
map included) and the run folder is opened (`ovon.runfolder`: identity compared on resume, lock against a
second writer). Records are then written as episodes finish and rewritten in canonical order at the end.
"""

from __future__ import annotations

import dataclasses
import json
import typing
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar, Literal

from ovon.agents.base import ROW_NAME
from ovon.agents.remote import RemoteConfig
from ovon.atomic import atomic_write_text
from ovon.config.base import (
    ExistingDir,
    NonNegative,
    Pattern,
    constrained,
    in_range,
    merge,
    non_empty,
    parse_overrides,
    positive,
    rule,
    to_dict,
    validate,
)
from ovon.config.sim import CameraConfig, NoiseConfig, SimConfig
from ovon.config.task import TaskConfig
from ovon.dataset.io import SPLIT_NAME_PATTERN, VAL_SPLITS
from ovon.evaluate.plan import RunPlan
from ovon.evaluate.results import (
    RecordWriter,
    coverage_lines,
    paper_table,
    read_records,
    record_key,
    summarize,
    write_canonical,
    write_selection,
)
from ovon.parallel import init_worker, progress_bar, run_jobs
from ovon.task.episode import EpisodeSpec

SPLIT_NAME = Pattern(SPLIT_NAME_PATTERN, "split folder names (letters, digits, _ . -)")
HOUSE_SEEDS = Pattern(r" *([0-9]+(-[0-9]+)? *(, *[0-9]+(-[0-9]+)? *)*)?", "house seeds like 80000-80003 or 0,5-7")
# Settings that may differ between the sessions of one run folder: they change what is run or how fast,
# never the result of an episode (paths are compared through their normalised identities instead).
MAY_CHANGE = (
    "data",
    "scenes",
    "splits",
    "seeds",
    "episodes",
    "workers",
    "executor",
    "chunk",
    "name",
    "agent_kwargs.checkpoint",
    "remote.timeout_s",
    "remote.batch",
    "remote.allow_privileged",
    "strict",
)


@dataclass
class EvalConfig:
    agent: str = non_empty("random", flag="--agent")
    agent_kwargs: dict = field(default_factory=dict)
    # objectnav: the episode dataset and scenes roots; pointnav: "" (episodes sampled in `procedural` houses)
    data: str = constrained("data/datasets/ovon", ExistingDir(True, "with --task pointnav"), flag="--data")
    scenes: str = constrained("data/scene_datasets", ExistingDir(True, "with --task pointnav"), flag="--scenes")
    procedural: str = constrained("", HOUSE_SEEDS, flag="--procedural")  # pointnav only: house seeds, e.g. 80000-80003
    splits: tuple[str, ...] = non_empty(VAL_SPLITS, each=SPLIT_NAME, distinct=True, flag="--splits")
    seeds: tuple[int, ...] = non_empty((0,), each=NonNegative(), distinct=True, flag="--seeds")
    episodes: int | None = positive(None, flag="--episodes")  # per split; None = all
    workers: int = in_range(1, 1, 1024, flag="--workers")
    executor: Literal["process", "ray"] = constrained("process", flag="--executor")
    chunk: int = in_range(4, 1, 100_000)  # episodes per work unit (same scene)
    sim: SimConfig = field(default_factory=lambda: SimConfig(camera=CameraConfig(width=160, height=120)))
    task: TaskConfig = field(default_factory=TaskConfig)
    # row name in tables; default = agent (its own name if remote)
    name: str | None = constrained(None, ROW_NAME, flag="--name")
    remote: RemoteConfig = field(default_factory=RemoteConfig)  # --agent remote:HOST:PORT only
    strict: bool = False  # refuse a split holding an invalid episode instead of skipping it (counted)
    rules: ClassVar = (
        rule(
            ("task.failed_stop_ends",),
            bool,
            "task.failed_stop_ends true (false is a training-only setting: every STOP ends an evaluated episode)",
        ),
    )


def with_camera(cfg: EvalConfig, camera: dict) -> EvalConfig:
    """`cfg` with these camera fields changed (e.g. the camera a policy checkpoint was trained with)."""
    return dataclasses.replace(
        cfg, sim=dataclasses.replace(cfg.sim, camera=dataclasses.replace(cfg.sim.camera, **camera))
    )


def pointnav_config(**fields) -> EvalConfig:
    """An `EvalConfig` for PointNav: `ovon.evaluate.pointnav.pointnav_defaults()` updated with `fields`,
    validated."""
    from ovon.evaluate.pointnav import pointnav_defaults

    return validate(EvalConfig(**{**pointnav_defaults(), **fields}))


def parse_noise(spec: str | None) -> NoiseConfig:
    """`actuation,odometry`, `actuation:movebase`, `actuation:ilqr*2` (multiplier), `odometry:drift`
    (dead-reckoning drift instead of the paper's bounded per-reading error) or empty."""
    from ovon.config.base import ConfigError

    cfg = NoiseConfig()
    if not spec:
        return cfg
    models = typing.get_args(typing.get_type_hints(NoiseConfig)["actuation"])
    odo_modes = typing.get_args(typing.get_type_hints(NoiseConfig)["odometry_mode"])
    fix = "fix: use e.g. --noise actuation,odometry or --noise actuation:movebase*0.5"
    seen: dict[str, str] = {}
    for item in [s.strip() for s in spec.split(",") if s.strip()]:
        name, _, arg = item.partition(":")
        if name in seen:  # the last one would silently win
            raise ConfigError(
                f"--noise {spec!r}: {name} noise given twice ({seen[name]!r} and {item!r}); fix: keep one of them"
            )
        seen[name] = item
        if name == "actuation":
            model, _, mult = (arg or "ilqr").partition("*")
            if model not in models:
                raise ConfigError(
                    f"--noise {item!r}: unknown actuation model {model!r}, expected one of {', '.join(models)}; {fix}"
                )
            try:
                k = float(mult or 1.0)
            except ValueError:
                raise ConfigError(f"--noise {item!r}: multiplier {mult!r} is not a number; {fix}") from None
            cfg = dataclasses.replace(cfg, actuation=model, actuation_multiplier=k)
            if not 0 <= k <= 100:
                raise ConfigError(f"--noise {item!r}: multiplier {k:g} is outside [0, 100]; {fix}")
        elif name == "odometry" and arg in ("",) + odo_modes:
            cfg = dataclasses.replace(cfg, odometry=True, odometry_mode=arg or "bounded")
        else:
            raise ConfigError(
                f"--noise: unknown noise {item!r}, expected actuation[:ilqr|proportional|movebase|"
                f"gaussian][*k] or odometry[:bounded|drift]; {fix}"
            )
    return validate(cfg, "sim.noise")


def apply_overrides(cfg: EvalConfig, overrides: list[str]) -> EvalConfig:
    from ovon.config.base import ConfigError

    data = parse_overrides(overrides)
    groups = {g: merge(getattr(cfg, g), data.pop(g), g) for g in ("sim", "task", "remote") if g in data}
    if data:
        raise ConfigError(
            f"unknown override group(s) {sorted(data)}; fix: --set takes sim.*, task.* or remote.* keys "
            "here (e.g. --set task.max_steps=300); the other settings have their own options"
        )
    return dataclasses.replace(cfg, **groups)


@dataclass
class SplitEpisodes:
    """The episodes of one split a run picked: those it runs (`specs`, each with its `shards` file) and
    those it skipped, counted by problem, so the summary can say "2998 of 3000 episodes"."""

    specs: list[EpisodeSpec]
    shards: list[str]  # the shard file of each spec (for messages)
    picked: int  # episodes picked from the split (all, or the first `--episodes`), before skipping
    skipped: Counter = field(default_factory=Counter)


def strict_fix(data: str, scenes: str) -> str:
    return (
        f"fix: correct or remove the episode (`ovon dataset validate {data} --scenes {scenes}` lists every "
        "problem), or leave out --strict to skip invalid episodes with a counted warning"
    )


def load_split(data: str, scenes: str, split: str, limit: int | None, strict: bool = False) -> SplitEpisodes:
    """The episodes of a split, round-robin over scenes, the first `limit` of them when limited; those
    that fail validation (`ovon.dataset.validate.check_shard`) are skipped and counted, or with `strict`
    refused (one line naming the file and the episode). A split without episodes, or a scene id outside
    `scenes`, is an error."""
    from ovon.dataset.io import EpisodeDataset, goals_for
    from ovon.dataset.records import DatasetError, resolve_scene_path
    from ovon.dataset.validate import check_shard, split_problem
    from ovon.runfolder import path_identity
    from ovon.task.episode import spec_from_episode

    ds = EpisodeDataset(data, split)
    why = split_problem(ds)
    if why:
        raise DatasetError(
            f"split {split!r}: {why}; fix: pass a dataset written by `ovon dataset generate` or "
            "the released HM3D-OVON files"
        )
    per_scene: list[list[tuple]] = []  # (shard path, index, episode, problems, goals, scene path)
    for scene in ds.scenes():
        shard = ds.load_scene(scene)
        where = str(ds.shard_path(scene))
        paths: dict[str, str] = {}
        for ep in shard.episodes:  # a scene id outside the root refuses the file, whatever else is wrong
            if ep.scene_id not in paths:
                try:
                    paths[ep.scene_id] = path_identity(resolve_scene_path(ep.scene_id, scenes))
                except DatasetError as e:
                    raise DatasetError(f"{where}: episode {ep.episode_id!r}: {e}") from None
        chk = check_shard(shard)
        per_scene.append(
            [
                (where, i, ep, chk.episodes.get(i), shard.goals_by_category, paths[ep.scene_id])
                for i, ep in enumerate(shard.episodes)
            ]
        )
    order = [p[i] for i in range(max(map(len, per_scene), default=0)) for p in per_scene if i < len(p)]
    picked = order if limit is None else order[:limit]
    out = SplitEpisodes([], [], len(picked))
    for where, i, ep, problems, goals, path in picked:
        if problems:
            if strict:
                raise DatasetError(
                    f"{where}: episode {str(ep.episode_id)!r} (episodes[{i}]): {problems[0][1]}; "
                    f"{strict_fix(data, scenes)}"
                )
            out.skipped[problems[0][0]] += 1
            continue
        out.specs.append(spec_from_episode(ep, goals_for(ep, goals), path, split))
        out.shards.append(where)
    return out


def load_specs(data: str, scenes: str, split: str, limit: int | None) -> list[EpisodeSpec]:
    """The runnable episodes of a split as `EpisodeSpec`s (`load_split`), the skipped ones in one counted
    warning."""
    from ovon.dataset.validate import warn_skipped

    sel = load_split(data, scenes, split, limit)
    warn_skipped(f"{Path(data) / split}", sel.skipped, sel.picked)
    return sel.specs


def drop_off_map_starts(
    sel: SplitEpisodes,
    sim: SimConfig,
    workers: int = 1,
    executor: str = "process",
    strict: bool = False,
    data: str = "",
    scenes: str = "",
) -> SplitEpisodes:
    """`sel` without the episodes whose start is off the navigable map of their scene (for this agent's
    radius and the nav grid of `sim`), counted as `start_off_map` (refused with `strict`). One job per
    scene."""
    from ovon.dataset.records import DatasetError
    from ovon.dataset.validate import off_map_starts_job

    specs = sel.specs
    by_scene: dict[str, list[int]] = {}
    for i, s in enumerate(specs):
        if s.start_position is not None:
            by_scene.setdefault(s.scene, []).append(i)
    jobs = [
        {
            "scene": sc,
            "starts": [[float(x) for x in specs[i].start_position] for i in idx],
            "agent": to_dict(sim.agent),
            "nav": to_dict(sim.nav),
        }
        for sc, idx in sorted(by_scene.items())
    ]
    bad: dict[int, str] = {}
    # A pool costs seconds to start: worth it only when there are many scenes to load.
    many = len(jobs) > 4
    for res in run_jobs(off_map_starts_job, jobs, workers if many else 1, executor if many else "process"):
        idx = by_scene[res["scene"]]
        bad.update((idx[j], why) for j, why in res["bad"])
    if bad and strict:
        i = min(bad)
        s = specs[i]
        raise DatasetError(
            f"{sel.shards[i]}: episode {s.episode_id!r}: {bad[i]} of {s.scene} (agent radius "
            f"{sim.agent.radius} m); {strict_fix(data, scenes)}"
        )
    keep = [i for i in range(len(specs)) if i not in bad]
    skipped = sel.skipped + Counter({"start_off_map": len(bad)})
    return SplitEpisodes([specs[i] for i in keep], [sel.shards[i] for i in keep], sel.picked, skipped)


# -- worker side ---------------------------------------------------------------------------------
_CACHE: dict = {}


def _agent(unit: dict):
    """The unit's agent, cached per process across chunks (a remote one keeps its connection)."""
    from ovon.agents import make_agent
    from ovon.agents.remote import is_remote

    kwargs = unit["remote"] if is_remote(unit["agent"]) else unit["agent_kwargs"]
    key = (unit["agent"], json.dumps(kwargs, sort_keys=True))
    if _CACHE.get("agent_key") != key:
        release_agent()
        _CACHE["agent"] = make_agent(unit["agent"], **kwargs)
        _CACHE["agent_key"] = key
    return _CACHE["agent"]


def release_agent() -> None:
    """Drop the cached agent; a remote one closes its connection (the server frees its agents)."""
    agent = _CACHE.pop("agent", None)
    _CACHE.pop("agent_key", None)
    if agent is not None and callable(getattr(agent, "close", None)):
        agent.close()


def run_unit(unit: dict) -> list[dict]:
    """Runs a chunk of episodes of one scene; envs and agent are cached per process across chunks. A remote
    agent runs `remote.batch` episodes in lockstep (one env each) and skips colour rendering when it does
    not want RGB (frames are otherwise identical)."""
    from ovon.agents import is_privileged
    from ovon.agents.remote import is_remote
    from ovon.config.base import from_dict
    from ovon.env.stack import EnvRecipe, build_env
    from ovon.evaluate.runner import run_episode, run_lockstep

    init_worker()
    agent = _agent(unit)
    privileged = is_privileged(agent)
    remote = is_remote(unit["agent"])
    sim = from_dict(SimConfig, unit["sim"])
    if remote and "rgb" not in agent.observations:
        sim = dataclasses.replace(sim, camera=dataclasses.replace(sim.camera, rgb=False))
    n_envs = unit["remote"]["batch"] if remote else 1
    key = (json.dumps(to_dict(sim), sort_keys=True), json.dumps(unit["task"], sort_keys=True), privileged)
    if _CACHE.get("env_key") != key:
        for env in _CACHE.pop("envs", []):
            env.close()
        _CACHE["env_key"] = key
    recipe = EnvRecipe(
        sim=sim,
        task=from_dict(TaskConfig, unit["task"]),
        episodes=unit["specs"][:1],
        sample_episodes=False,
        privileged=privileged,
    )
    envs = _CACHE.setdefault("envs", [])
    while len(envs) < min(n_envs, len(unit["specs"])):
        envs.append(build_env(recipe))
    if remote and n_envs > 1:
        return run_lockstep(envs[:n_envs], agent, unit["specs"], unit["seed"])
    return [run_episode(envs[0], agent, spec, unit["seed"]) for spec in unit["specs"]]


# -- parent side ---------------------------------------------------------------------------------
def _units(cfg: EvalConfig, specs_by_split: dict[str, list[EpisodeSpec]], done: set) -> list[dict]:
    from ovon.agents.remote import is_remote

    units = []
    sim, task, remote = to_dict(cfg.sim), to_dict(cfg.task), to_dict(cfg.remote)
    chunk = max(cfg.chunk, cfg.remote.batch) if is_remote(cfg.agent) else cfg.chunk  # a full batch per unit
    for seed in cfg.seeds:
        for split, specs in specs_by_split.items():
            by_scene: dict[str, list[EpisodeSpec]] = {}
            for s in specs:
                if (split, int(seed), s.scene_key, s.episode_id) not in done:
                    by_scene.setdefault(s.scene, []).append(s)
            for scene_specs in by_scene.values():
                for i in range(0, len(scene_specs), chunk):
                    units.append(
                        {
                            "specs": scene_specs[i : i + chunk],
                            "seed": int(seed),
                            "agent": cfg.agent,
                            "agent_kwargs": cfg.agent_kwargs,
                            "remote": remote,
                            "sim": sim,
                            "task": task,
                        }
                    )
    return units


def run_inputs(cfg: EvalConfig) -> dict:
    """Identities of what an evaluation reads: the dataset's splits (content hashes), the scenes root and
    the policy checkpoint (content hash)."""
    from ovon.dataset.io import EpisodeDataset
    from ovon.runfolder import file_sha256, path_identity

    inputs: dict = {
        "data": {
            "path": path_identity(cfg.data),
            "splits": {s: EpisodeDataset(cfg.data, s).fingerprint() for s in cfg.splits},
        },
        "scenes": {"path": path_identity(cfg.scenes)},
    }
    ckpt = cfg.agent_kwargs.get("checkpoint")
    if isinstance(ckpt, str) and ckpt:
        p = Path(ckpt) / "policy.pt" if Path(ckpt).is_dir() else Path(ckpt)
        if p.is_file():
            inputs["checkpoint"] = {"path": path_identity(p), "sha256": file_sha256(p)}
    return inputs


def prepare_splits(cfg: EvalConfig, workers: int | None = None) -> tuple[dict[str, SplitEpisodes], str]:
    """Everything that can refuse a run, before any episode: config domains, the agent, the episodes
    (invalid ones and starts off the map skipped with one counted warning per split, or refused with
    `cfg.strict`); and the row name: `--name`, else the name a remote agent introduces itself with, else
    `--agent`."""
    from ovon.agents import check_agent
    from ovon.agents.remote import check_remote, is_remote
    from ovon.dataset.records import DatasetError
    from ovon.dataset.validate import warn_skipped

    validate(cfg)
    if is_remote(cfg.agent):
        # the handshake also when --name is given: a bad server is found here, not in the workers
        name = cfg.name or check_remote(cfg.agent, cfg.remote, cfg.agent_kwargs)
        if cfg.name:
            check_remote(cfg.agent, cfg.remote, cfg.agent_kwargs, row_name=cfg.name)
    else:
        check_agent(cfg.agent, cfg.agent_kwargs)
        name = cfg.name or cfg.agent
    out = {}
    for split in cfg.splits:
        sel = load_split(cfg.data, cfg.scenes, split, cfg.episodes, cfg.strict)
        sel = drop_off_map_starts(sel, cfg.sim, workers or cfg.workers, cfg.executor, cfg.strict, cfg.data, cfg.scenes)
        warn_skipped(f"{Path(cfg.data) / split}", sel.skipped, sel.picked)
        if not sel.specs:
            raise DatasetError(
                f"split {split!r} in {cfg.data} has no usable episodes; fix: run `ovon dataset "
                f"validate {cfg.data} --scenes {cfg.scenes}` to see why"
            )
        out[split] = sel
    return out, name


def prepare(cfg: EvalConfig, workers: int | None = None) -> dict[str, list[EpisodeSpec]]:
    """The episodes each split runs (`prepare_splits` without the skip counts and the name)."""
    return {split: sel.specs for split, sel in prepare_splits(cfg, workers)[0].items()}


def skip_counts(selected: dict[str, SplitEpisodes]) -> dict[str, dict]:
    """Per split: episodes picked, and those skipped before the run by problem (for `finalize`)."""
    return {
        split: {"picked": sel.picked, "count": sum(sel.skipped.values()), "reasons": dict(sorted(sel.skipped.items()))}
        for split, sel in selected.items()
    }


def check_source(cfg: EvalConfig) -> None:
    """Where the episodes come from fits the task: a dataset (`data`, `scenes`) for objectnav, procedural
    houses (`procedural`) for pointnav."""
    from ovon.config.base import ConfigError

    if cfg.task.kind == "pointnav":
        if cfg.data or cfg.scenes:
            raise ConfigError("--task pointnav samples episodes in --procedural houses; fix: drop --data / --scenes")
        if not cfg.procedural:
            raise ConfigError("--task pointnav needs --procedural SEEDS (held-out houses, e.g. 80000-80003)")
        return
    if cfg.procedural:
        raise ConfigError(
            f"--procedural = {cfg.procedural!r}: house seeds are for --task pointnav; fix: drop "
            "--procedural, or pass --task pointnav (Python: task.kind='pointnav')"
        )
    for flag, value in (("--data", cfg.data), ("--scenes", cfg.scenes)):
        if not value:
            raise ConfigError(
                f"{flag} = '': expected an existing folder; fix: pass {flag} (objectnav evaluates "
                "the episodes of a dataset; --task pointnav samples them in --procedural houses)"
            )


def plan(cfg: EvalConfig, workers: int | None = None) -> RunPlan:
    """Everything that can refuse a run, before any episode (`check_source`, then the task's own checks:
    `prepare_splits`, `ovon.evaluate.pointnav.pointnav_plan`)."""
    check_source(cfg)
    if cfg.task.kind == "pointnav":
        from ovon.evaluate.pointnav import pointnav_plan

        return pointnav_plan(cfg)
    selected, name = prepare_splits(cfg, workers)
    config = {k: v for k, v in to_dict(cfg).items() if k != "procedural"}  # identity as before pointnav joined
    return RunPlan(
        {split: sel.specs for split, sel in selected.items()},
        name,
        config,
        run_inputs(cfg),
        skip_counts(selected),
        f"evaluate {name}",
    )


def evaluate(cfg: EvalConfig, run_dir: str | Path, progress: bool = True) -> dict:
    """Run every (split, seed, episode) of `cfg` not yet in `run_dir` (objectnav: a dataset's splits;
    `task.kind=pointnav`: point goals in procedural houses, `ovon.evaluate.pointnav`); returns the summary."""
    from ovon.agents.remote import is_remote
    from ovon.atomic import check_output_path
    from ovon.runfolder import RunFolder

    check_output_path(run_dir, "--out", folder=True)  # "" would scatter the run's files in the current folder
    p = plan(cfg)
    run_dir = Path(run_dir)
    with RunFolder.open(run_dir, "evaluate", p.config, p.inputs, may_change=MAY_CHANGE, markers=("episodes.jsonl",)):
        atomic_write_text(run_dir / "run.json", json.dumps({**p.config, "name": p.name}, indent=2))
        done = {record_key(r) for r in read_records(run_dir, repair=True)}
        units = _units(cfg, p.specs, done)
        total = sum(len(u["specs"]) for u in units)
        writer = RecordWriter(run_dir)
        try:
            with progress_bar(p.label, total, progress and total > 0) as bar:
                for recs in run_jobs(run_unit, units, cfg.workers, cfg.executor):
                    for r in recs:
                        writer.write(r)
                    bar.advance(len(recs))
        finally:
            writer.close()
            if is_remote(cfg.agent):
                release_agent()  # in-process runs: the connection closes with the run
        wanted = {
            (split, int(seed), s.scene_key, s.episode_id)
            for seed in cfg.seeds
            for split, specs in p.specs.items()
            for s in specs
        }
        return finalize(run_dir, p.name, wanted, p.skipped)


def finalize(run_dir: str | Path, name: str, wanted: set | None = None, skipped: dict | None = None) -> dict:
    """episodes.jsonl in canonical order, then the summary and the table of the records in `wanted` (all
    when None), in that order: identical whatever the workers, the executor or the interruptions.

    `skipped` (`skip_counts`): per split, the episodes picked and those skipped before the run; written
    into each split's summary entry, and under the table when any was skipped, so a published SR never
    silently covers fewer episodes than the split."""
    run_dir = Path(run_dir)
    records = write_canonical(run_dir, read_records(run_dir))
    if wanted is not None:
        records = [r for r in records if record_key(r) in wanted]
    write_selection(run_dir, wanted)
    summary = {"name": name, "splits": summarize(records)}
    for split, entry in summary["splits"].items():
        if skipped and split in skipped:
            entry["skipped"] = skipped[split]
    atomic_write_text(run_dir / "summary.json", json.dumps(summary, indent=2, sort_keys=True))
    notes = coverage_lines(summary["splits"])
    table = paper_table({name: summary["splits"]}) + "\n" + ("\n" + "".join(f"- {n}\n" for n in notes) if notes else "")
    atomic_write_text(run_dir / "table.md", table)
    return summary
