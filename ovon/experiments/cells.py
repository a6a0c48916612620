"""Typed experiment cells: a data cell's GenerationConfig, a train cell's TrainConfig plus its episode source,
an evaluation cell's `ovon evaluate` options (its EvalConfig is resolved when it runs: it reads the
checkpoint's camera). Why typed: the config is the cell's identity (`ovon.experiments.identity`), and the
command line is only rendered from it, for display, for the runner's child process and for reports.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ovon.experiments.definitions import EvalCell, Experiment, Scale
from ovon.runfolder import flatten  # {"a": {"b": 1}, "c.d": 2} -> {"a.b": 1, "c.d": 2}: the one flattener
from ovon.train.folder import EpisodeSource


def render_value(v: Any) -> str:
    """A value as `--set key=VALUE` text that `parse_overrides` (YAML) reads back as the same value."""
    import yaml

    if isinstance(v, str):
        try:
            same = yaml.safe_load(v) == v
        except yaml.YAMLError:
            same = False
        return v if same and v != "" else json.dumps(v)
    if isinstance(v, tuple):
        v = list(v)
    return json.dumps(v)


def overrides_text(values: dict) -> list[str]:
    """`values` as the `key=VALUE` texts of `--set` (flattened keys)."""
    return [f"{k}={render_value(v)}" for k, v in flatten(values).items()]


def set_args(values: dict, flag: str = "--set") -> list[str]:
    return [w for kv in overrides_text(values) for w in (flag, kv)]


@dataclass(frozen=True)
class DataRun:
    """Procedural scenes (`ovon scenes generate` per split) and their episodes (`ovon dataset generate`)."""

    config: Any  # the GenerationConfig
    preset: str
    overrides: dict  # flattened `--set` values over the preset
    scenes: Path
    episodes: Path
    train_scenes: int
    val_scenes: int
    seed: int
    workers: int

    def identity(self) -> dict:
        """The config the data depends on (not the number of workers: generation is the same with any)."""
        from ovon.config.base import to_dict

        gen = {"train_scenes": self.train_scenes, "val_scenes": self.val_scenes, "seed": self.seed}
        return {**to_dict(self.config), "scene_generation": gen}

    def commands(self) -> list[list[str]]:
        scenes = [
            ["scenes", "generate", "--split", split, "--count", str(n), "--seed", str(self.seed)]
            + ["--out", str(self.scenes), "--workers", str(self.workers)]
            for split, n in (("train", self.train_scenes), ("val", self.val_scenes))
        ]
        episodes = ["dataset", "generate", "--scenes", str(self.scenes), "--out", str(self.episodes)]
        episodes += ["--preset", self.preset, *set_args(self.overrides)]
        episodes += ["--workers", str(self.workers), "--no-progress"]
        return [*scenes, episodes]


@dataclass(frozen=True)
class TrainRun:
    """A TrainConfig (built from `preset`, the named choices and `overrides`, as `ovon train` builds it)
    and its episode source."""

    config: Any  # the TrainConfig
    source: EpisodeSource
    algo: str
    preset: str
    expert: str
    policy: str
    init: str  # the init policy.pt ("" = none)
    overrides: dict  # flattened `--set` values over the preset
    out: Path
    world_size: int = 1  # processes training it (torchrun): its batches depend on it

    def identity(self) -> dict:
        from ovon.config.base import to_dict

        return {**to_dict(self.config), "world_size": self.world_size}

    def commands(self) -> list[list[str]]:
        argv = ["train", "--algo", self.algo, "--preset", self.preset]
        argv += ["--expert", self.expert] if self.expert else []
        argv += ["--policy", self.policy] if self.policy else []
        argv += ["--init", self.init] if self.init else []
        argv += ["--data", str(self.source.data), "--scenes", str(self.source.scenes)]
        return [[*argv, *set_args(self.overrides), "--out", str(self.out)]]


@dataclass(frozen=True)
class EvalRun:
    """The options of `ovon evaluate` for one cell; `identity.resolved_config` resolves its EvalConfig."""

    agent: str
    checkpoint: str  # "" = none
    agent_args: dict
    data: Path
    scenes: Path
    splits: tuple[str, ...]
    seeds: tuple[int, ...]
    episodes: int | None
    noise: str
    overrides: dict  # flattened `--set` values (sim.* / task.*)
    workers: int
    executor: str
    out: Path

    def commands(self) -> list[list[str]]:
        argv = ["evaluate", "--agent", self.agent]
        argv += ["--checkpoint", self.checkpoint] if self.checkpoint else []
        argv += set_args(self.agent_args, "--agent-arg")
        argv += ["--data", str(self.data), "--scenes", str(self.scenes), "--splits", ",".join(self.splits)]
        argv += ["--seeds", ",".join(str(s) for s in self.seeds)]
        argv += ["--episodes", str(self.episodes)] if self.episodes is not None else []
        argv += ["--noise", self.noise] if self.noise else []
        argv += set_args(self.overrides)
        argv += ["--workers", str(self.workers), "--executor", self.executor]
        return [[*argv, "--out", str(self.out), "--no-progress"]]


@dataclass
class Cell:
    """One unit of work: the data, a training run or an evaluation; `run` is what it is (typed), its
    `commands` (`ovon` argvs without the program name) are rendered from it."""

    kind: str  # data | train | eval
    name: str
    folder: Path
    run: DataRun | TrainRun | EvalRun | None = None  # None: the user's own dataset (paper scale)
    deps: tuple[str, ...] = ()  # ids of the cells it needs
    launcher: tuple[str, ...] = ()  # torchrun prefix (training at paper scale)
    eval_cell: EvalCell | None = None
    total: int | None = None  # updates (train) or episodes (eval) when known, for progress
    unavailable: str = ""  # eval: why the agent cannot run in this installation

    @property
    def id(self) -> str:
        return f"{self.kind}:{self.name}"

    @property
    def commands(self) -> list[list[str]]:
        return self.run.commands() if self.run is not None else []

    @property
    def train_cfg(self) -> Any:
        """The TrainConfig of a training cell."""
        assert isinstance(self.run, TrainRun), self.id
        return self.run.config


@dataclass
class Plan:
    experiments: list[Experiment]
    scale: Scale
    root: Path  # as the user gave it
    catalogue: Any  # the definitions' Catalogue
    cells: dict[str, Cell] = field(default_factory=dict)  # id -> cell, dependencies first
    episodes_dir: Path = Path()
    scenes_dir: Path = Path()

    @property
    def base(self) -> Path:
        return self.root / self.scale.name

    @property
    def names(self) -> str:
        return "+".join(e.name for e in self.experiments)
