"""The EpisodeSampler's start-distance curriculum: close starts first, every episode later, exact resume."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from ovon.env.sampler import EpisodeSampler
from ovon.task.episode import EpisodeSpec


class _Recorder(gym.Env):
    """Stands in for the env stack: records which episode each reset starts."""

    observation_space = gym.spaces.Discrete(1)
    action_space = gym.spaces.Discrete(2)

    def __init__(self) -> None:
        self.started: list[str] = []

    def reset(self, *, seed=None, options=None):
        self.started.append(options["episode"].episode_id)
        return 0, {}

    def step(self, action):
        return 0, 0.0, bool(action), False, {}


def _specs(with_distance: bool = True) -> list[EpisodeSpec]:
    specs = []
    for house in range(3):
        for k in range(20):
            info = {"geodesic_distance": 1.0 + 0.5 * k} if with_distance else {}
            specs.append(
                EpisodeSpec(episode_id=f"{house}-{k}", scene=f"procedural:{house}", goal_category="bed", info=info)
            )
    return specs


def _distance(episode_id: str) -> float:
    return 1.0 + 0.5 * int(episode_id.split("-")[1])


def _run(sampler: EpisodeSampler, n: int) -> list[str]:
    for _ in range(n):
        sampler.reset()
        sampler.step(1)
    return list(sampler.env.started)


def test_curriculum_starts_close_and_widens_to_every_episode() -> None:
    sampler = EpisodeSampler(
        _Recorder(), _specs(), seed=0, scene_repeat=2, curriculum_start_m=2.0, curriculum_episodes=50
    )
    started = _run(sampler, 400)
    caps = [2.0 + i / 50 * (10.5 - 2.0) for i in range(50)]
    assert all(_distance(e) <= cap + 1e-9 for e, cap in zip(started[:50], caps))
    assert max(_distance(e) for e in started[:10]) <= 3.5  # the first starts are close ones
    assert max(_distance(e) for e in started[50:]) > 9.0  # afterwards the far ones come too
    assert sampler.max_distance() == float("inf")


def test_without_curriculum_the_draws_are_unchanged() -> None:
    plain = _run(EpisodeSampler(_Recorder(), _specs(), seed=3, scene_repeat=2), 60)
    off = _run(
        EpisodeSampler(_Recorder(), _specs(), seed=3, scene_repeat=2, curriculum_start_m=0.0, curriculum_episodes=50),
        60,
    )
    assert plain == off
    assert max(_distance(e) for e in plain[:10]) > 3.5  # far starts from the beginning


def test_curriculum_state_resumes_exactly() -> None:
    def make() -> EpisodeSampler:
        return EpisodeSampler(
            _Recorder(), _specs(), seed=1, scene_repeat=3, curriculum_start_m=1.5, curriculum_episodes=40
        )

    whole = _run(make(), 60)
    first = make()
    _run(first, 25)
    state = first.get_state()
    assert state["started"] == 25
    second = make()
    second.set_state(state)
    second.env.started.clear()
    second.step(1)  # finish the replayed episode as the first run did
    assert _run(second, 35) == whole[25:]


def test_curriculum_needs_start_distances() -> None:
    with pytest.raises(ValueError, match="geodesic_distance.*episode '0-0'.*curriculum.start_m=0"):
        EpisodeSampler(_Recorder(), _specs(with_distance=False), seed=0, curriculum_start_m=2.0, curriculum_episodes=10)


def test_curriculum_config_has_a_domain() -> None:
    from ovon.config.base import ConfigError, merge, parse_overrides
    from ovon.train.config import PRESETS

    cfg = merge(PRESETS["tiny"](), parse_overrides(["curriculum.start_m=2.5", "curriculum.episodes=100"]))
    assert (cfg.curriculum.start_m, cfg.curriculum.episodes) == (2.5, 100)
    with pytest.raises(ConfigError, match="curriculum.start_m"):
        merge(PRESETS["tiny"](), parse_overrides(["curriculum.start_m=-1"]))
    assert np.isinf(EpisodeSampler(_Recorder(), _specs(), seed=0).max_distance())


def test_reset_options_are_refused_not_ignored() -> None:
    """The sampler picks the episodes: an asked-for episode would silently be another one."""
    sampler = EpisodeSampler(_Recorder(), _specs(), seed=0, scene_repeat=2)
    with pytest.raises(ValueError, match="samples its own episodes"):
        sampler.reset(options={"episode": _specs()[0]})
    sampler.reset(options={})
