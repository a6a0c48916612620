"""The training run folder: what a run is, one writer at a time, and when a resume may continue.

Why in the library and not in the command line: `ovon.train.train(...)` is the documented Python API,
so the rules that keep a run folder honest (a second writer is refused, a resume with other settings,
other episodes or another init policy is refused with the differences) hold for every caller; `ovon
train` and the experiment runner only call `train()`. The identity is what `ovon.runfolder` stores in
`run_identity.json`: the resolved config, where the episodes come from (a dataset split by content, or
the episodes themselves by hash) and the init policy by hash.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ovon.atomic import atomic_write_text
from ovon.config.base import to_dict
from ovon.runfolder import RunFolder, file_sha256, path_identity
from ovon.task.episode import EpisodeSpec
from ovon.train.config import TrainConfig

# May differ between a run and its resume: where and how fast it runs, and the budget (to train longer),
# not what it learns from or how.
MAY_CHANGE = (
    "max_updates",
    "total_steps",
    "env_workers",
    "checkpoint_every",
    "threads",
    "rollout_threads",
    "device",
    "progress",
    "log_every",
    "keep_checkpoints",
    "text_cache",
    "inputs.data.path",
    "inputs.scenes.path",
)
KIND = "train"
MARKERS = ("checkpoint.pt", "policy.pt")  # run data written before identities existed


@dataclass(frozen=True)
class EpisodeSource:
    """Where a run's episodes come from, as `ovon train` names them: a dataset split (`data` = the episode
    root, `scenes` = the scene-datasets root, `split`, at most `limit` episodes), or ad-hoc episodes on
    procedural houses (`procedural`, seeds like "0-7"). Passed to `train()` instead of a list, the run
    folder records the dataset by content and the scenes root by path (which may move)."""

    data: str | None = None
    scenes: str | None = None
    split: str = "train"
    limit: int | None = None
    procedural: str | None = None
    task: str = "objectnav"  # pointnav: point-goal episodes sampled in the `procedural` houses

    def load(self) -> list[EpisodeSpec] | None:
        """The episodes (None without `data` or `procedural`: BC from recorded shards)."""
        if self.task == "pointnav":
            if not self.procedural or self.data:
                raise ValueError(
                    "--task pointnav samples its episodes in procedural houses: pass --procedural "
                    "SEEDS (e.g. 0-23) and no --data"
                )
            from ovon.config.base import parse_seed_list
            from ovon.task.pointgoal import pointnav_specs

            return pointnav_specs([f"procedural:{s}" for s in parse_seed_list(self.procedural)])
        if self.procedural:
            from ovon.config.base import parse_seed_list
            from ovon.train.episodes import adhoc_specs

            specs = adhoc_specs(parse_seed_list(self.procedural))
            return specs[: self.limit] if self.limit else specs
        if self.data:
            if not self.scenes:
                raise ValueError("--data needs --scenes")
            from ovon.dataset.episodes import load_specs

            specs = load_specs(self.data, self.scenes, self.split, self.limit)
            if not specs:
                raise ValueError(f"split {self.split!r} in {self.data} has no episodes")
            return specs
        return None

    def identity(self) -> tuple[dict, dict]:
        """(config keys, inputs) this source adds to the run's identity. The config key is named `cli`
        because these are `ovon train`'s options; run folders written by earlier versions keep resuming."""
        config = {"cli": {"split": self.split, "episodes": self.limit, "procedural": self.procedural or ""}}
        inputs: dict = {}
        if self.data:
            from ovon.dataset.io import EpisodeDataset

            inputs["data"] = {
                "path": path_identity(self.data),
                "split": EpisodeDataset(self.data, self.split).fingerprint(),
            }
            inputs["scenes"] = {"path": path_identity(self.scenes or "")}
        return config, inputs


def specs_sha256(specs: Sequence[EpisodeSpec]) -> str:
    """Content hash of an episode list (ids, scenes, goals, starts, viewpoints), for a run given episodes
    directly: resuming it with other episodes is refused like resuming it with another dataset."""
    h = hashlib.sha256()
    for spec in specs:
        h.update(json.dumps(dataclasses.asdict(spec), sort_keys=True, default=_plain).encode() + b"\n")
    return h.hexdigest()


def _plain(x: Any) -> Any:
    if isinstance(x, np.ndarray | np.generic):
        return x.tolist()
    return str(x)


def resolve_episodes(episodes: Sequence[EpisodeSpec] | EpisodeSource | None) -> tuple[list | None, dict, dict]:
    """(the episode list, config keys, inputs) for a run given a list, a source or nothing."""
    if isinstance(episodes, EpisodeSource):
        return (episodes.load(), *episodes.identity())
    if episodes is None:
        return None, {}, {}
    specs = list(episodes)
    return specs, {}, {"episodes": {"sha256": specs_sha256(specs)}}


def init_identity(init: str | Path) -> dict:
    """The init policy by content (a missing file by its path: `train` refuses it with the fix)."""
    p = Path(init) / "policy.pt" if Path(init).is_dir() else Path(init)
    return {"sha256": file_sha256(p) if p.is_file() else str(p)}


def open_run_folder(
    cfg: TrainConfig, out: str | Path, config_keys: dict, inputs: dict, resume: bool, init: str | None
) -> RunFolder | None:
    """Rank 0 opens (creates or reopens) `out` for this run and holds its lock until `close()`; other
    torchrun ranks write nothing there and get None. Writes `config.json` (the resolved config)."""
    if int(os.environ.get("RANK", "0")) != 0:
        return None
    inputs = {**inputs, **({"init": init_identity(init)} if init else {})}
    folder = RunFolder.open(
        out, KIND, {**to_dict(cfg), **config_keys}, inputs, resume=resume, may_change=MAY_CHANGE, markers=MARKERS
    )
    try:
        atomic_write_text(Path(out) / "config.json", json.dumps(to_dict(cfg), indent=1, default=str))
    except BaseException:
        folder.close()
        raise
    return folder
