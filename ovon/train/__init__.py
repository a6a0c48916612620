"""Learned baselines: BC, DAgger and PPO (+ BC->RL / DAgger->RL fine-tuning), one readable file each.

The same code runs in one CPU process and under `torchrun` (DDP; see `distributed.py`).
"""

from __future__ import annotations

from pathlib import Path

from ovon.task.episode import EpisodeSpec
from ovon.train.config import PRESETS, TrainConfig, train_preset


def train(cfg: TrainConfig, specs: list[EpisodeSpec] | None, out_dir: str | Path, resume: bool = False,
          init: str | None = None) -> dict:
    """Run `cfg.algo`; returns the last logged metrics (rank 0; {} elsewhere)."""
    if cfg.algo == "bc":
        from ovon.train.bc import train_bc

        return train_bc(cfg, specs, out_dir, resume, init)
    if not specs:
        raise ValueError(f"{cfg.algo} needs episodes (--data/--scenes or --procedural)")
    if cfg.algo == "dagger":
        from ovon.train.dagger import train_dagger

        return train_dagger(cfg, specs, out_dir, resume, init)
    if cfg.algo == "ppo":
        from ovon.train.ppo import train_ppo

        return train_ppo(cfg, specs, out_dir, resume, init)
    raise ValueError(f"unknown algorithm {cfg.algo!r}; valid: bc, dagger, ppo")


__all__ = ["PRESETS", "TrainConfig", "train", "train_preset"]
