"""Which houses belong to which split: house seed = dataset seed * SEED_STRIDE + split base + index.

The default dataset seed gives HM3D-like five-digit scene ids (train 00000.., val 80000..), and different
dataset seeds never share a house. The `pretrain` houses (the perception models' "web" data) sit above every
dataset seed's range, so no train or val house of any dataset seed is ever a pretraining house.
"""

from __future__ import annotations

SEED_STRIDE = 100_000
SPLIT_BASE = {"train": 0, "val": 80_000}
SPLIT_CAPACITY = {"train": 80_000, "val": 20_000}
# `generate_house` takes 32-bit house seeds (it refuses larger ones): the last house of a dataset seed must fit
MAX_HOUSE_SEED = 2**32 - 1
MAX_DATASET_SEED = (MAX_HOUSE_SEED - (SEED_STRIDE - 1)) // SEED_STRIDE  # 42948: its last house still fits
PRETRAIN_BASE = (MAX_DATASET_SEED + 1) * SEED_STRIDE  # 4_294_900_000: above every dataset seed's houses
PRETRAIN_CAPACITY = MAX_HOUSE_SEED + 1 - PRETRAIN_BASE  # 67_296 pretraining houses


def house_seed(seed: int, split: str, index: int) -> int:
    """Seed of house `index` of `split`: deterministic from (seed, split, index); train and val differ,
    and a larger --count keeps the earlier houses. `pretrain` houses ignore the dataset seed (one range)."""
    if split == "pretrain":
        if not 0 <= index < PRETRAIN_CAPACITY:
            raise ValueError(f"pretrain holds at most {PRETRAIN_CAPACITY} houses, index {index} is out of range")
        return PRETRAIN_BASE + int(index)
    if split not in SPLIT_BASE:
        raise ValueError(f"unknown split {split!r}; valid: {sorted(SPLIT_BASE) + ['pretrain']}")
    if not 0 <= index < SPLIT_CAPACITY[split]:
        raise ValueError(
            f"{split} holds at most {SPLIT_CAPACITY[split]} houses per seed, index {index} is out of range"
        )
    if not 0 <= seed <= MAX_DATASET_SEED:
        raise ValueError(
            f"--seed = {seed}: expected an integer in [0, {MAX_DATASET_SEED}] (house seeds are kept to "
            "32 bits); fix: pass a smaller --seed"
        )
    return int(seed) * SEED_STRIDE + SPLIT_BASE[split] + int(index)


def is_pretrain_house(house: int) -> bool:
    return PRETRAIN_BASE <= int(house) <= MAX_HOUSE_SEED
