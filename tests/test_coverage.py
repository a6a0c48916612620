"""The exploration term: floor seen (camera cone) rewards turning in place; floor visited (360 degrees)
rewards only moving, so PPO cannot farm it by spinning."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from ovon.config.base import ConfigError, build
from ovon.config.task import RewardConfig
from ovon.task.coverage import Coverage


def _open_room(cells: int = 40, cell_size: float = 0.1):
    """A walled-less open floor of `cells` x `cells` navigable cells, origin at (0, 0)."""
    free = np.ones((cells, cells), dtype=bool)

    def world_to_cell(p):
        return math.floor(p[2] / cell_size), math.floor(p[0] / cell_size)

    return SimpleNamespace(free=free, navigable=free.copy(), cell_size=cell_size, world_to_cell=world_to_cell)


def _gains(fov_deg: float, poses) -> list[float]:
    cov = Coverage(_open_room(), fov_deg, 1.0)
    (x, z, yaw), *rest = poses
    cov.reset(np.array([x, 0.0, z]), yaw)
    return [cov.update(np.array([x, 0.0, z]), yaw) for x, z, yaw in rest]


def test_turning_in_place_gains_seen_floor_but_no_visited_floor() -> None:
    turns = [(2.0, 2.0, k * math.radians(30)) for k in range(12)]
    assert sum(_gains(42.0, turns)) > 1.0  # m^2: a full turn sees a disk the first cone did not
    assert sum(_gains(360.0, turns)) == 0.0


def test_moving_gains_visited_floor() -> None:
    walk = [(2.0, 2.0 - 0.25 * k, 0.0) for k in range(5)]
    gains = _gains(360.0, walk)
    assert all(g > 0.2 for g in gains)  # each 0.25 m step uncovers a crescent of the 1 m disk (~0.5 m^2)
    assert _gains(360.0, walk[:2] + walk[:1]) == [pytest.approx(gains[0]), 0.0]  # going back pays nothing


def test_coverage_fov_domain() -> None:
    with pytest.raises(ConfigError, match="coverage_fov_deg"):
        build(RewardConfig, overrides=["coverage_fov_deg=400"])
