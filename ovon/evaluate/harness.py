"""`ovon evaluate`: agents over splits and seeds, episodes in worker processes (or Ray tasks,
`ovon.evaluate.worker`), one JSON line per episode as it finishes, resumable, then a summary and the
paper-style table.

Before any work (`plan`): the config is validated (declared domains), the agent is built once (a served
one answers its handshake), every episode is checked (`ovon.dataset.episodes`: bad ones are skipped with a
counted warning, starts off the navigable map included) and the run folder is opened (`ovon.runfolder`:
identity compared on resume, lock against a second writer). Records are then written as episodes finish
and rewritten in canonical order at the end.

Two tasks, one harness (`EvalConfig.task.kind`): objectnav runs the episodes of a dataset's splits;
pointnav samples point-goal episodes in procedural houses (held-out ones for a trained PointNav policy).
Why no dataset for PointNav: an episode is (house, index); its start/goal pair is sampled at reset from
the episode seed (`ovon.evaluate.runner.episode_seed`), so a seed fixes every pair, every agent gets the
same ones, and the records replay like any other.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from ovon.agents.remote import is_remote
from ovon.atomic import atomic_write_text
from ovon.config.base import ConfigError, to_dict, validate
from ovon.dataset.episodes import SplitEpisodes, drop_off_map_starts, load_split
from ovon.dataset.subset import Subset, load_subset, restrict_to_subset
from ovon.evaluate.config import POINTNAV_SPLIT, EvalConfig, check_episode_source
from ovon.evaluate.protocol import agent_facts, card_line, episode_set, protocol_card
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
from ovon.evaluate.worker import release_agent, run_unit, work_units
from ovon.parallel import progress_bar, run_jobs
from ovon.task.episode import EpisodeSpec

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
    "subset",
)
# The EvalConfig fields a PointNav run folder is identified by (run.json), in this order.
POINTNAV_KEYS = ("agent", "agent_kwargs", "procedural", "seeds", "episodes", "workers", "executor", "chunk", "sim",
                 "task", "name")  # fmt: skip
REMOTE = "remote"  # a served agent's `agent` in a run folder's identity: what it is, not where it is served


@dataclass
class RunPlan:
    """What an evaluation runs, whatever its task (`plan`): the episodes per split, the row name, the
    config written to run.json, the config and inputs that identify the run folder, and the episodes
    skipped before the run (None: the task skips none, and the summary says nothing about skipping)."""

    specs: dict[str, list[EpisodeSpec]]
    name: str
    config: dict
    identity: dict
    inputs: dict
    skipped: dict | None
    label: str  # progress bar title
    card: dict | None = None  # the protocol card (ovon.evaluate.protocol), built before any episode runs


def check_agent_of(cfg: EvalConfig) -> tuple[str, dict]:
    """The agent can run (built once; a served one answers its handshake), before any episode. Returns the
    row name (`--name`, else the name a served agent introduces itself with, else `--agent`) and what
    replaces `agent` in the run folder's identity: for a served agent, what it says it is (its handshake
    name and config), so the same agent served at another address continues the folder."""
    from ovon.agents import check_agent
    from ovon.agents.remote import check_remote
    from ovon.runfolder import flatten

    if not is_remote(cfg.agent):
        check_agent(cfg.agent, cfg.agent_kwargs)
        return cfg.name or cfg.agent, {}
    # the handshake also when --name is given: a bad server is found here, not in the workers
    hs = check_remote(cfg.agent, cfg.remote, cfg.agent_kwargs, row_name=cfg.name or "")
    # with its keys: a resume compares the keys both sides have, and a key the agent adds or drops counts too
    served = {"name": hs.name, "config": hs.config, "config_keys": sorted(flatten(hs.config))}
    return cfg.name or hs.name, {"agent": REMOTE, "served_agent": served}


def run_inputs(cfg: EvalConfig) -> dict:
    """Identities of what an evaluation reads: the dataset's splits (content hashes), the scenes root and
    the policy checkpoint (content hash)."""
    from ovon.agents.served import checkpoint_file
    from ovon.dataset.io import EpisodeDataset
    from ovon.runfolder import file_sha256, path_identity

    inputs: dict = {
        "data": {
            "path": path_identity(cfg.data),
            "splits": {s: EpisodeDataset(cfg.data, s).fingerprint() for s in cfg.splits},
        },
        "scenes": {"path": path_identity(cfg.scenes)},
    }
    p = checkpoint_file(cfg.agent_kwargs.get("checkpoint"))
    if p is not None:
        inputs["checkpoint"] = {"path": path_identity(p), "sha256": file_sha256(p)}
    return inputs


def prepare_splits(
    cfg: EvalConfig, workers: int | None = None, subset: Subset | None = None
) -> dict[str, SplitEpisodes]:
    """The episodes of each split of an objectnav run (invalid ones and starts off the map skipped with one
    counted warning per split, or refused with `cfg.strict`); a split left without episodes is refused."""
    from ovon.dataset.records import DatasetError
    from ovon.dataset.validate import warn_skipped

    out = {}
    if subset is None and cfg.subset:
        subset = load_subset(cfg.subset, cfg.data, cfg.splits)
    for split in cfg.splits:
        if subset is None:
            sel = load_split(cfg.data, cfg.scenes, split, cfg.episodes, cfg.strict)
        else:
            sel = load_split(cfg.data, cfg.scenes, split, None, cfg.strict)
            sel = restrict_to_subset(sel, subset, split, f"{Path(cfg.data) / split}", cfg.episodes)
        sel = drop_off_map_starts(sel, cfg.sim, workers or cfg.workers, cfg.executor, cfg.strict, cfg.data, cfg.scenes)
        warn_skipped(f"{Path(cfg.data) / split}", sel.skipped, sel.picked)
        if not sel.specs:
            raise DatasetError(
                f"split {split!r} in {cfg.data} has no usable episodes; fix: run `ovon dataset "
                f"validate {cfg.data} --scenes {cfg.scenes}` to see why"
            )
        out[split] = sel
    return out


def prepare(cfg: EvalConfig, workers: int | None = None) -> dict[str, list[EpisodeSpec]]:
    """The episodes each split of an objectnav run runs, after every check that can refuse the run."""
    validate(cfg)
    check_agent_of(cfg)
    return {split: sel.specs for split, sel in prepare_splits(cfg, workers).items()}


def skip_counts(selected: dict[str, SplitEpisodes]) -> dict[str, dict]:
    """Per split: episodes picked, and those skipped before the run by problem (for `finalize`)."""
    return {
        split: {"picked": sel.picked, "count": sum(sel.skipped.values()), "reasons": dict(sorted(sel.skipped.items()))}
        for split, sel in selected.items()
    }


def plan(cfg: EvalConfig, workers: int | None = None) -> RunPlan:
    """Everything that can refuse a run, before any episode: where the episodes come from
    (`check_episode_source`), the config's domains, the task's own checks, the agent, the episodes."""
    check_episode_source(cfg)
    validate(cfg)
    if cfg.task.kind == "pointnav":
        return _pointnav_plan(cfg)
    name, served = check_agent_of(cfg)
    subset = load_subset(cfg.subset, cfg.data, cfg.splits) if cfg.subset else None
    selected = prepare_splits(cfg, workers, subset)
    config = {k: v for k, v in to_dict(cfg).items() if k != "procedural"}  # identity as before pointnav joined
    specs = {split: sel.specs for split, sel in selected.items()}
    label = f"subset {subset.name}" if subset else ""
    return RunPlan(
        specs,
        name,
        config,
        {**config, **served},
        run_inputs(cfg),
        skip_counts(selected),
        f"evaluate {name}",
        card_of(cfg, config, specs, label),
    )


def card_of(cfg: EvalConfig, config: dict, specs: dict[str, list[EpisodeSpec]], subset: str) -> dict:
    """The run's protocol card, from what the plan resolved (before any episode: nothing it reads can vanish)."""
    if subset:
        kind = subset + (f", its first {cfg.episodes} per split" if cfg.episodes is not None else "")
    elif cfg.task.kind == "pointnav":
        kind = f"{cfg.episodes} point goals per house of {cfg.procedural}"
    elif cfg.episodes is not None:
        kind = f"the first {cfg.episodes} per split (round-robin over scenes)"
    else:
        kind = "whole splits"
    facts = agent_facts(cfg.agent, cfg.agent_kwargs, cfg.remote.allow_privileged)
    return protocol_card(config, episode_set(specs, cfg.seeds, kind), facts)


def _pointnav_plan(cfg: EvalConfig) -> RunPlan:
    """`cfg.episodes` point-goal episodes per house of `cfg.procedural`, all in split "val"; the run folder
    is identified by the houses and the checkpoint's content. The task (success radius, distance range,
    step limit) is the one the checkpoint was trained with unless `--set task.*` changes it
    (`ovon.evaluate.config.checkpoint_task`)."""
    from ovon.agents.served import checkpoint_file
    from ovon.config.base import parse_seed_list
    from ovon.runfolder import file_sha256
    from ovon.task.pointgoal import pointnav_specs

    if tuple(cfg.splits) != (POINTNAV_SPLIT,):
        raise ConfigError(
            f"splits = {list(cfg.splits)}: --task pointnav has one split, {POINTNAV_SPLIT!r}; fix: leave "
            f"splits out (Python: ovon.evaluate.config.pointnav_config)"
        )
    if cfg.episodes is None:
        raise ConfigError("episodes = None: --task pointnav samples a given number per house; fix: pass --episodes N")
    houses = parse_seed_list(cfg.procedural)
    name, served = check_agent_of(cfg)
    specs = pointnav_specs([f"procedural:{h}" for h in houses], cfg.episodes, POINTNAV_SPLIT)
    inputs: dict = {"procedural": houses}
    p = checkpoint_file(cfg.agent_kwargs.get("checkpoint"))
    if p is not None:
        inputs["checkpoint"] = {"sha256": file_sha256(p)}
    fields = to_dict(cfg)
    config = {k: fields[k] for k in POINTNAV_KEYS}
    label = f"evaluate {name} (pointnav)"
    card = card_of(cfg, config, {POINTNAV_SPLIT: specs}, "")
    return RunPlan({POINTNAV_SPLIT: specs}, name, config, {**config, **served}, inputs, None, label, card)


def evaluate(cfg: EvalConfig, run_dir: str | Path, progress: bool = True) -> dict:
    """Run every (split, seed, episode) of `cfg` not yet in `run_dir` (objectnav: a dataset's splits;
    `task.kind=pointnav`: point goals in procedural houses); returns the summary."""
    from ovon.atomic import check_output_path
    from ovon.runfolder import RunFolder

    check_output_path(run_dir, "--out", folder=True)  # "" would scatter the run's files in the current folder
    p = plan(cfg)
    run_dir = Path(run_dir)
    with RunFolder.open(run_dir, "evaluate", p.identity, p.inputs, may_change=MAY_CHANGE, markers=("episodes.jsonl",)):
        atomic_write_text(run_dir / "run.json", json.dumps({**p.config, "name": p.name}, indent=2))
        records = read_records(run_dir, repair=True)
        refuse_path_keyed_records(run_dir, records)
        done = {record_key(r) for r in records}
        units = work_units(cfg, p.specs, done)
        total = sum(len(u.specs) for u in units)
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
        return finalize(run_dir, p.name, wanted, p.skipped, p.card)


def refuse_path_keyed_records(run_dir: Path, records: list[dict]) -> None:
    """Records written before seeds and records named a scene by the dataset's id (by its resolved path)
    would neither count as done nor match the new seeds: such a folder cannot be continued."""
    old = next((r["scene"] for r in records if Path(str(r["scene"])).is_absolute()), None)
    if old is not None:
        raise ConfigError(
            f"{run_dir}: its records name scenes by file path (e.g. {old}), written by an older ovon whose "
            "episode seeds depended on where the data lived; fix: evaluate into a new --out folder"
        )


def finalize(
    run_dir: str | Path, name: str, wanted: set | None = None, skipped: dict | None = None, protocol: dict | None = None
) -> dict:
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
    if protocol is not None:
        summary["protocol"] = protocol  # what the numbers were measured under (ovon.evaluate.protocol)
    atomic_write_text(run_dir / "summary.json", json.dumps(summary, indent=2, sort_keys=True))
    notes = coverage_lines(summary["splits"]) + ([card_line(protocol)] if protocol is not None else [])
    table = paper_table({name: summary["splits"]}) + "\n" + ("\n" + "".join(f"- {n}\n" for n in notes) if notes else "")
    atomic_write_text(run_dir / "table.md", table)
    return summary
