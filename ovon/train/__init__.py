"""Learned baselines: BC, DAgger and PPO (+ BC->RL / DAgger->RL fine-tuning), one readable file each.

The same code runs in one CPU process and under `torchrun` (DDP; see `distributed.py`). `train()` owns
its run folder (`folder.py`): identity, one writer at a time, resume rules, whoever calls it.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from ovon.task.episode import EpisodeSpec
from ovon.train.config import PRESETS, TrainConfig, build_config, train_preset
from ovon.train.folder import EpisodeSource, open_run_folder, resolve_episodes


def train(cfg: TrainConfig, specs: Sequence[EpisodeSpec] | EpisodeSource | None, out_dir: str | Path,
          resume: bool = False, init: str | None = None) -> dict:
    """Run `cfg.algo` in the run folder `out_dir`; returns the last logged metrics (rank 0; {} elsewhere).

    `specs`: the episodes (a list, or an `EpisodeSource` naming a dataset split or procedural houses;
    None for BC from `bc.shards`). A folder that already holds a run is refused unless `resume`, and
    then only if it is the same run (config, episodes, init; `folder.MAY_CHANGE` may differ); a second
    process on the same folder is refused while the first runs (`ovon.runfolder.RunFolderError`)."""
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


def _run(cfg: TrainConfig, specs: list[EpisodeSpec] | None, out_dir: str | Path, resume: bool,
         init: str | None) -> dict:
    if cfg.algo == "bc":
        from ovon.train.bc import train_bc

        return train_bc(cfg, specs, out_dir, resume, init)
    if cfg.algo == "dagger":
        from ovon.train.dagger import train_dagger

        return train_dagger(cfg, specs, out_dir, resume, init)
    from ovon.train.ppo import train_ppo

    return train_ppo(cfg, specs, out_dir, resume, init)


__all__ = ["PRESETS", "EpisodeSource", "TrainConfig", "build_config", "train", "train_preset"]
