"""Shared fixtures: a tiny embedded world (3 procedural houses in the HM3D layout) and its val episodes,
built once per test session and reused by the dataset, evaluation and report tests."""

from __future__ import annotations

import os
from dataclasses import replace
from pathlib import Path

import pytest

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("LP_NUM_THREADS", "0")
# The shell's settings must not change what the tests see (subprocesses inherit os.environ):
# OVON_DEBUG turns every one-line refusal into a traceback; a RAY_ADDRESS, or a `ray start` cluster
# that Ray would attach to, would run the tests' tasks in someone else's workers ("local": a new one).
os.environ.pop("OVON_DEBUG", None)
os.environ["RAY_ADDRESS"] = "local"

try:  # the same examples on every run (CI must not fail by chance); HYPOTHESIS_PROFILE=explore searches anew
    from hypothesis import settings

    settings.register_profile("ci", derandomize=True)
    settings.register_profile("explore", derandomize=False)
    settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))
except ImportError:  # pragma: no cover
    pass

try:
    import torch

    torch.set_num_threads(1)
except ImportError:  # pragma: no cover
    pass

TINY_HOUSES = {"train": [11], "val": [21, 22]}


def tiny_generation_config():
    from ovon.config.dataset import fast_generation

    g = fast_generation()
    return replace(
        g,
        episodes_per_train_scene=12,
        episodes_per_val_split=16,
        viewpoints=replace(g.viewpoints, render_size=48, max_viewpoints=6),
    )


def write_tiny_scenes(root: Path) -> Path:
    from ovon.scenes.hm3dsem import write_scene
    from ovon.scenes.procedural import HouseConfig, generate_house

    cfg = HouseConfig(min_rooms=4, max_rooms=5, second_floor_prob=0.0)
    for split, seeds in TINY_HOUSES.items():
        for seed in seeds:
            scene = generate_house(seed, cfg=cfg)
            write_scene(scene, root / split / scene.scene_id)
    return root


@pytest.fixture(scope="session")
def tiny_scenes(tmp_path_factory) -> Path:
    return write_tiny_scenes(tmp_path_factory.mktemp("world") / "ovon_world")


@pytest.fixture(scope="session")
def tiny_dataset(tiny_scenes, tmp_path_factory) -> Path:
    from ovon.dataset.generate import generate
    from ovon.dataset.io import VAL_SPLITS

    out = tmp_path_factory.mktemp("episodes") / "ovon_episodes"
    generate(tiny_scenes, out, tiny_generation_config(), splits=VAL_SPLITS, workers=1, progress=False)
    return out
