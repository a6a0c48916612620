"""`ovon perception pretrain`'s config: every number of the perception pretraining, with its domain.

Presets: "cpu" (this project's 2-core machine, under an hour) and "tiny" (seconds, for the tests).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from ovon.config.base import in_range, non_negative, one_of, positive
from ovon.models.world.net import NetConfig


@dataclass(frozen=True)
class PretrainConfig:
    houses: int = in_range(160, 1, 60_000)  # pretrain houses to train on (indices 0..houses-1 of the split)
    calibration_houses: int = in_range(8, 1, 7_000)  # the next houses: threshold and score choice only
    frames_per_house: int = in_range(320, 1, 100_000)
    render_seed: int = non_negative(0)
    steps: int = in_range(7000, 1, 10_000_000)
    batch: int = in_range(32, 1, 4096)
    cells_per_frame: int = in_range(192, 1, 4096)  # cells per frame in the loss (object cells drawn 3x as often)
    lr: float = in_range(2e-3, 0.0, 1.0, lo_open=True)
    weight_decay: float = non_negative(1e-4)
    warmup: int = non_negative(200)
    obj_weight: float = non_negative(1.0)  # objectness BCE
    global_weight: float = non_negative(1.0)  # frame-level SigLIP loss (the value scorer)
    global_min_share: float = in_range(0.01, 0.0, 1.0)  # a name counts as in the frame from this share
    seed: int = non_negative(0)
    # the world's looks when rendering (HouseConfig.looks): "family" renders the houses as before issue 37,
    # for measuring what the looks add (benchmarks/looks_separability.py)
    looks: str = one_of("category", "category", "family")
    threads: int = in_range(2, 1, 256)
    workers: int = in_range(2, 1, 256)  # render processes
    checkpoint_every: int = in_range(250, 1, 10_000_000)
    visible_share: float = in_range(0.05, 0.0, 1.0, lo_open=True)  # a goal counts as visible from this share
    min_precision: float = in_range(0.5, 0.0, 1.0)  # the threshold: best recall at this precision
    net: NetConfig = field(default_factory=NetConfig)


PRESETS: dict[str, PretrainConfig] = {
    "cpu": PretrainConfig(),
    "tiny": replace(
        PretrainConfig(),
        houses=2,
        calibration_houses=1,
        frames_per_house=24,
        steps=6,
        batch=4,
        cells_per_frame=32,
        workers=1,
        threads=1,
        checkpoint_every=3,
        warmup=2,
    ),
}


def lr_at(cfg: PretrainConfig, step: int) -> float:
    """Linear warm-up then cosine decay to 5%."""
    import math

    if step < cfg.warmup:
        return cfg.lr * (step + 1) / cfg.warmup
    t = (step - cfg.warmup) / max(1, cfg.steps - cfg.warmup)
    return cfg.lr * (0.05 + 0.95 * 0.5 * (1 + math.cos(math.pi * min(1.0, t))))


__all__ = ["PRESETS", "PretrainConfig", "lr_at", "positive"]
