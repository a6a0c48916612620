"""The episodes of a dataset split as something to run: `EpisodeSpec`s, round-robin over scenes, the
invalid ones skipped and counted (or refused with `strict`), starts off the navigable map dropped.

Why here and not in the evaluation: evaluation, training (`ovon.train.folder`) and videos
(`ovon.reports.video`) read a split the same way, so one reader below them all decides which episodes a
split holds.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from ovon.config.base import to_dict
from ovon.config.sim import SimConfig
from ovon.dataset.io import EpisodeDataset, goals_for
from ovon.dataset.records import DatasetError, resolve_scene_path
from ovon.dataset.validate import check_shard, off_map_starts_job, split_problem, warn_skipped
from ovon.parallel import run_jobs
from ovon.runfolder import path_identity
from ovon.task.episode import EpisodeSpec, spec_from_episode


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
