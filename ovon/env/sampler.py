"""Episode sampling as a wrapper, with an exact, small resume state.

Each env samples its episodes from its own list with its own seeded generator: `scene_repeat` episodes
of one scene before it may switch (loading a world is slow), a fresh reset seed per episode. Its whole
state - generator, current episode, its reset seed and the actions taken so far - is a few hundred
bytes, and `set_state` replays the current episode to the same point through every wrapper below
(deterministic env, encoder noise and expert), so a resumed training run continues exactly.

An optional start-distance curriculum (RL from scratch): an env's first episodes are the ones whose
start is geodesically close to the goal (`info.geodesic_distance` of the dataset), where a random policy
reaches the success region and can learn when to STOP; the cap grows linearly to every episode, either
with the trainer's update count (`set_update`, the same for every env: the curriculum ends when the
schedule says) or with the episodes the env has started. Either count is the same whatever the number
of workers, and both are part of the resume state.

A training schedule of the task's STOP rule: from update `strict_stop_from` on (`set_update`), episodes
start under evaluation's rule (a STOP outside the success region ends the episode) even when the task
config says `failed_stop_ends` false. The rule is fixed per episode, at its start, and kept in the state.
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
        curriculum_updates: int = 0,
        strict_stop_from: int | None = None,
    ) -> None:
        """`curriculum_updates` > 0: the cap counts the trainer's updates (`set_update`) instead of
        `curriculum_episodes`. `strict_stop_from`: the update from which a failed STOP ends the episode
        (None: the task config's rule throughout)."""
        super().__init__(env)
        if not episodes:
            raise ValueError("an episode sampler needs at least one episode")
        self.episodes = list(episodes)
        self.curriculum_updates = max(0, int(curriculum_updates))
        self.curriculum = curriculum_start_m > 0 and (curriculum_episodes > 0 or self.curriculum_updates > 0)
        self.curriculum_start_m, self.curriculum_episodes = float(curriculum_start_m), int(curriculum_episodes)
        self.update = 0  # the trainer's update in progress (`set_update`)
        self.strict_stop_from = strict_stop_from
        self.base_task = getattr(env.unwrapped, "task_cfg", None)
        self.strict_stop = False  # the current episode's rule (set at its start)
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
    def set_update(self, update: int) -> None:
        """The trainer's update now starting (0-based): the curriculum's and the STOP rule's clock. Called
        on every env at the same point of the run, so the schedule does not depend on the worker layout."""
        self.update = int(update)

    def max_distance(self) -> float:
        """The curriculum's cap on the start distance (m) for the next episode (inf without one)."""
        if not self.curriculum:
            return float("inf")
        if self.curriculum_updates:
            done, length = self.update, self.curriculum_updates
        else:
            done, length = self.started, self.curriculum_episodes
        if done >= length:
            return float("inf")
        start = self.curriculum_start_m
        return start + done / length * max(0.0, self.top - start)

    def _strict_now(self) -> bool:
        return self.strict_stop_from is not None and self.update >= self.strict_stop_from

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

    def _start(self, spec_index: int, ep_seed: int, strict: bool | None = None):
        """Start episode `spec_index`; under evaluation's STOP rule when `strict` (default: the schedule's now)."""
        strict = self._strict_now() if strict is None else strict
        if self.base_task is not None and not self.base_task.failed_stop_ends:
            import dataclasses

            self.env.unwrapped.set_task(dataclasses.replace(self.base_task, failed_stop_ends=strict))
        obs, info = self.env.reset(seed=ep_seed, options={"episode": self.episodes[spec_index]})
        self.spec_index, self.ep_seed, self.actions, self.strict_stop = spec_index, ep_seed, [], strict
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
            "update": self.update,
            "strict_stop": self.strict_stop,
        }

    def set_state(self, state: dict):
        """Restore the sampler and replay the current episode; returns the (obs, info) reached."""
        self.rng.bit_generator.state = state["rng"]
        self.scene, self.remaining, self.skipped = state["scene"], state["remaining"], state["skipped"]
        self.started = int(state.get("started", 0))  # states written before the curriculum lack it
        self.update = int(state.get("update", 0))
        obs, info = self._start(state["spec_index"], state["ep_seed"], bool(state.get("strict_stop", False)))
        for a in state["actions"]:
            obs, _, _, _, info = self.step(a)
        return obs, info
