"""Episode sampling as a wrapper, with an exact, small resume state.

Each env samples its episodes from its own list with its own seeded generator: `scene_repeat` episodes
of one scene before it may switch (loading a world is slow), a fresh reset seed per episode. Its whole
state - generator, current episode, its reset seed and the actions taken so far - is a few hundred
bytes, and `set_state` replays the current episode to the same point through every wrapper below
(deterministic env, encoder noise and expert), so a resumed training run continues exactly.

An optional start-distance curriculum (RL from scratch): an env's first episodes are the ones whose
start is geodesically close to the goal (`info.geodesic_distance` of the dataset), where a random policy
reaches the success region and can learn when to STOP; the cap grows linearly with the episodes the env
has started, to every episode after `curriculum_episodes`. It counts per env, so it is the same whatever
the number of workers, and the count is part of the resume state.
"""

from __future__ import annotations

from collections.abc import Sequence

import gymnasium as gym
import numpy as np

from ovon.task.episode import EpisodeSpec

MAX_SKIPS = 100


class EpisodeSampler(gym.Wrapper):
    """`reset()` starts the next sampled episode (ignoring `options`); episodes whose set-up fails in
    this world (e.g. no reachable goal on the start floor) are skipped and counted in `skipped`."""

    def __init__(
        self,
        env: gym.Env,
        episodes: Sequence[EpisodeSpec],
        seed: int,
        scene_repeat: int = 4,
        curriculum_start_m: float = 0.0,
        curriculum_episodes: int = 0,
    ) -> None:
        super().__init__(env)
        if not episodes:
            raise ValueError("an episode sampler needs at least one episode")
        self.episodes = list(episodes)
        self.curriculum = curriculum_start_m > 0 and curriculum_episodes > 0
        self.curriculum_start_m, self.curriculum_episodes = float(curriculum_start_m), int(curriculum_episodes)
        self.distance = np.zeros(len(self.episodes))
        if self.curriculum:
            missing = [s.episode_id for s in self.episodes if "geodesic_distance" not in (s.info or {})]
            if missing:
                raise ValueError(
                    f"a start-distance curriculum needs info.geodesic_distance in every episode; "
                    f"episode {missing[0]!r} has none (fix: episodes from `ovon dataset generate`, "
                    f"or curriculum.start_m=0)"
                )
            self.distance = np.array([float(s.info["geodesic_distance"]) for s in self.episodes])
        self.top = float(self.distance.max())  # the cap reaches every episode here
        self.started = 0
        self.scene_repeat = max(1, int(scene_repeat))
        self.by_scene: dict[str, list[int]] = {}
        for i, s in enumerate(self.episodes):
            self.by_scene.setdefault(s.scene, []).append(i)
        self.scenes = sorted(self.by_scene)
        self.rng = np.random.default_rng(seed)
        self.scene: str | None = None
        self.remaining = 0
        self.spec_index, self.ep_seed = -1, 0
        self.actions: list[int] = []
        self.skipped = 0

    # -- sampling ---------------------------------------------------------------------------
    def max_distance(self) -> float:
        """The curriculum's cap on the start distance (m) for the next episode (inf without one)."""
        if not self.curriculum or self.started >= self.curriculum_episodes:
            return float("inf")
        start = self.curriculum_start_m
        return start + self.started / self.curriculum_episodes * max(0.0, self.top - start)

    def _eligible(self, scene: str) -> list[int]:
        """The scene's episodes under the cap; its closest one when none is."""
        idx = self.by_scene[scene]
        if not self.curriculum:
            return idx
        cap = self.max_distance()
        under = [i for i in idx if self.distance[i] <= cap]
        return under or [min(idx, key=lambda i: self.distance[i])]

    def _sample(self) -> tuple[int, int]:
        if self.remaining <= 0 or self.scene is None:
            self.scene = self.scenes[int(self.rng.integers(len(self.scenes)))]
            self.remaining = self.scene_repeat
        self.remaining -= 1
        idx = self._eligible(self.scene)
        self.started += 1
        return idx[int(self.rng.integers(len(idx)))], int(self.rng.integers(2**31 - 1))

    def _start(self, spec_index: int, ep_seed: int):
        obs, info = self.env.reset(seed=ep_seed, options={"episode": self.episodes[spec_index]})
        self.spec_index, self.ep_seed, self.actions = spec_index, ep_seed, []
        return obs, info

    @property
    def current(self) -> EpisodeSpec:
        return self.episodes[self.spec_index]

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        if options:  # silently sampling another episode than the one asked for would be a wrong result
            raise ValueError(
                f"reset(options={sorted(options)}): this env samples its own episodes; fix: build "
                "the env stack with sample_episodes=False to choose each episode with "
                "options={'episode': ...}"
            )
        if seed is not None:
            self.rng = np.random.default_rng(seed)
            self.scene, self.remaining = None, 0
        for _ in range(MAX_SKIPS):
            index, ep_seed = self._sample()
            try:
                return self._start(index, ep_seed)
            except ValueError:
                self.skipped += 1
        raise RuntimeError(f"{MAX_SKIPS} sampled episodes in a row could not be set up; check the episode list")

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.actions.append(int(action))
        if terminated or truncated:
            spec = self.current
            info = {
                **info,
                "episode": {
                    "scene": spec.scene,
                    "goal": spec.goal_category,
                    "episode_id": spec.episode_id,
                    "split": spec.split,
                },
            }
        return obs, reward, terminated, truncated, info

    # -- exact resume -------------------------------------------------------------------------
    def get_state(self) -> dict:
        return {
            "rng": self.rng.bit_generator.state,
            "scene": self.scene,
            "remaining": self.remaining,
            "spec_index": self.spec_index,
            "ep_seed": self.ep_seed,
            "actions": list(self.actions),
            "skipped": self.skipped,
            "started": self.started,
        }

    def set_state(self, state: dict):
        """Restore the sampler and replay the current episode; returns the (obs, info) reached."""
        self.rng.bit_generator.state = state["rng"]
        self.scene, self.remaining, self.skipped = state["scene"], state["remaining"], state["skipped"]
        self.started = int(state.get("started", 0))  # states written before the curriculum lack it
        obs, info = self._start(state["spec_index"], state["ep_seed"])
        for a in state["actions"]:
            obs, _, _, _, info = self.step(a)
        return obs, info
