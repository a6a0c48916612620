"""Learned baselines: BC, DAgger and PPO (+ BC->RL / DAgger->RL fine-tuning), one readable file each.

The same code runs in one CPU process and under `torchrun` (DDP; see `distributed.py`). `train()` owns
its run folder (`folder.py`): identity, one writer at a time, resume rules, whoever calls it.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from ovon.task.episode import EpisodeSpec
from ovon.train.config import PRESETS, TrainConfig, build_config, train_preset
from ovon.train.folder import EpisodeSource, open_run_folder, resolve_episodes

_FIX_CFG = "fix: build it with train_preset(NAME, ...) or build_config(...)"


def check_config(cfg: TrainConfig) -> TrainConfig:
    """`cfg` checked as `ovon train` checks it (`ovon.config.base.validate`: declared domains and rules),
    returned with path objects stored as str. Why in `train()`: a config built in Python (`train_preset("tiny",
    num_envs=0)`, `dataclasses.replace(cfg, lr=-1)`) used to fail inside torch after the run folder was
    written, and the corrected call was then refused as a different run."""
    from ovon.config.base import ConfigError, validate

    if not isinstance(cfg, TrainConfig):
        raise ConfigError(f"train(cfg={type(cfg).__name__}): expected a TrainConfig; {_FIX_CFG}")
    return validate(cfg)


def check_source(specs: object) -> None:
    """The episodes argument of `train()`: a list of `EpisodeSpec`, an `EpisodeSource` whose fields lie in
    their domains (`ovon train`'s options: `--episodes` > 0, `--task`), or None. Why: `limit=-1` sliced
    the split to all episodes but the last, `limit=0` of procedural houses meant all of them, and a string
    (a dataset path) was read as a list of characters."""
    from ovon.config.base import ConfigError

    if specs is None:
        return
    if isinstance(specs, EpisodeSource):
        limit, task = specs.limit, specs.task
        if limit is not None and (not isinstance(limit, int) or isinstance(limit, bool) or limit <= 0):
            raise ConfigError(
                f"EpisodeSource(limit={limit!r}): expected an integer > 0 (at most that many "
                "episodes) or None (all); fix: pass limit=N with N > 0, or leave it out"
            )
        if task not in ("objectnav", "pointnav"):
            raise ConfigError(
                f"EpisodeSource(task={task!r}): expected one of 'objectnav', 'pointnav'; fix: "
                "pass task='objectnav' (the default) or task='pointnav'"
            )
        for key in ("data", "scenes", "procedural", "split"):
            value = getattr(specs, key)
            if value is not None and not isinstance(value, str | os.PathLike):
                raise ConfigError(
                    f"EpisodeSource({key}={value!r}): expected a string; fix: pass {key} as a "
                    "string (a path for data and scenes, seeds like '0-7' for procedural)"
                )
        return
    if isinstance(specs, str | bytes | os.PathLike) or not isinstance(specs, Sequence):
        raise ConfigError(
            f"train(specs={specs!r:.80}): expected a list of EpisodeSpec, an EpisodeSource or None; "
            "fix: pass EpisodeSource(data=ROOT, scenes=ROOT, split=NAME) for a dataset split"
        )
    bad = next((i for i, s in enumerate(specs) if not isinstance(s, EpisodeSpec)), None)
    if bad is not None:
        raise ConfigError(
            f"train(specs): item {bad} is a {type(specs[bad]).__name__}, not an EpisodeSpec; fix: "
            "pass a list of EpisodeSpec (ovon.task.episode) or an EpisodeSource"
        )


def check_out_dir(out_dir: object) -> Path:
    """The run folder argument: a path (str or os.PathLike; None would become a folder named 'None') that
    can be a run folder (`ovon.atomic.check_output_path`: not empty, not a file, not under a file)."""
    from ovon.atomic import check_output_path
    from ovon.config.base import ConfigError

    if not isinstance(out_dir, str | os.PathLike):
        raise ConfigError(
            f"train(out_dir={out_dir!r:.80}): expected the path of a run folder (a str or a Path); "
            "fix: pass out_dir='runs/NAME'"
        )
    return check_output_path(out_dir, "out_dir", folder=True, error=ConfigError)


def train(
    cfg: TrainConfig,
    specs: Sequence[EpisodeSpec] | EpisodeSource | None,
    out_dir: str | Path,
    resume: bool = False,
    init: str | None = None,
) -> dict:
    """Run `cfg.algo` in the run folder `out_dir`; returns the last logged metrics (rank 0; {} elsewhere).

    `specs`: the episodes (a list, or an `EpisodeSource` naming a dataset split or procedural houses;
    None for BC from `bc.shards`). A folder that already holds a run is refused unless `resume`, and
    then only if it is the same run (config, episodes, init; `folder.MAY_CHANGE` may differ); a second
    process on the same folder is refused while the first runs (`ovon.runfolder.RunFolderError`).

    Every argument is checked first (`check_config`, `check_source`, `check_out_dir`): a wrong one is one
    ConfigError line and nothing is written."""
    from ovon.config.base import ConfigError

    cfg = check_config(cfg)
    from ovon.train.distributed import check_device

    check_device(cfg.device)  # this rank's GPU exists (else one line, before the folder is made)
    check_source(specs)
    check_out_dir(out_dir)
    if not isinstance(resume, bool):
        raise ConfigError(
            f"train(resume={resume!r}): expected True or False; fix: pass resume=True to continue "
            "the run in out_dir, else leave it out"
        )
    if init is not None and not isinstance(init, str | os.PathLike):
        raise ConfigError(
            f"train(init={init!r:.80}): expected the path of a policy.pt (or of its run folder) or "
            "None; fix: pass init='runs/NAME/policy.pt'"
        )
    episodes, config_keys, inputs = resolve_episodes(specs)
    if cfg.algo not in ("bc", "dagger", "ppo"):
        raise ValueError(f"unknown algorithm {cfg.algo!r}; valid: bc, dagger, ppo")
    if cfg.algo != "bc" and not episodes:
        raise ValueError(f"{cfg.algo} needs episodes (--data/--scenes or --procedural)")
    if init:  # a wrong --init is refused before the run folder is made (it would block the fixed command)
        from ovon.train.run import load_init_policy

        load_init_policy(init, cfg.encoder, cfg.task.kind)
    folder = open_run_folder(cfg, out_dir, config_keys, inputs, resume, init)
    try:
        return _run(cfg, episodes, out_dir, resume, init)
    finally:
        if folder is not None:
            folder.close()


def _run(
    cfg: TrainConfig, specs: list[EpisodeSpec] | None, out_dir: str | Path, resume: bool, init: str | None
) -> dict:
    if cfg.algo == "bc":
        from ovon.train.bc import train_bc

        return train_bc(cfg, specs, out_dir, resume, init)
    if cfg.algo == "dagger":
        from ovon.train.dagger import train_dagger

        return train_dagger(cfg, specs, out_dir, resume, init)
    from ovon.train.ppo import train_ppo

    return train_ppo(cfg, specs, out_dir, resume, init)


__all__ = ["PRESETS", "EpisodeSource", "TrainConfig", "build_config", "train", "train_preset"]
