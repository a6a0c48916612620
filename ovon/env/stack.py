"""The one recipe for an env stack: training, BC recording, evaluation and the benchmarks all build
their envs here, from the same wrappers in the same order.

    ObjectNavEnv                      the task: RGB/depth/odometry/goal/collided, nothing privileged
      -> PrivilegedInfo               info["privileged"]   (experts, oracle encoder, oracle agents)
      -> ExpertLabels                 obs["expert_action"] (DAgger labels, BC recording)
      -> EncodeObservation            obs["image"], obs["goal_emb"] (frozen encoders)
      -> EpisodeSampler               next episode on reset, get_state / set_state (exact resume)

A recipe is a small picklable dataclass, so a spawned worker rebuilds exactly the same stack.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym

from ovon.config.sim import SimConfig
from ovon.config.task import TaskConfig
from ovon.models.config import EncoderConfig
from ovon.task.episode import EpisodeSpec


@dataclass
class EnvRecipe:
    sim: SimConfig = field(default_factory=SimConfig)
    task: TaskConfig = field(default_factory=TaskConfig)
    # plain env arguments when there is no episode list (ad-hoc goal in one scene)
    scene: str | None = None
    goal: str | None = None
    privileged: bool = False  # info["privileged"] (implied by an expert or the oracle encoder)
    expert: str | None = None  # "frontier" | "shortest-path": obs["expert_action"]
    expert_cfg: Any = None
    expert_viewpoint_radius: float = 0.0
    encoder: EncoderConfig | None = None  # frozen encoders -> obs["image"], obs["goal_emb"]
    text_table: dict[str, Any] = field(default_factory=dict)
    episodes: list[EpisodeSpec] | None = None  # EpisodeSampler over these
    sample_episodes: bool = True  # False: the caller picks each episode (reset(options={"episode": ...}))
    seed: int = 0
    scene_repeat: int = 4
    # start-distance curriculum of the EpisodeSampler (0 = off): cap in m, and when the cap reaches every
    # episode: after `curriculum_updates` trainer updates (> 0), else after `curriculum_episodes` per env
    curriculum_start_m: float = 0.0
    curriculum_episodes: int = 0
    curriculum_updates: int = 0
    # the trainer update from which a failed STOP ends the episode (evaluation's rule); None = task's rule
    strict_stop_from: int | None = None

    @property
    def needs_privileged(self) -> bool:
        oracle = self.encoder is not None and self.encoder.image == "oracle-vl"
        return self.privileged or self.expert is not None or oracle

    def rendering(self) -> SimConfig:
        """The sim config with RGB off when no consumer of this stack reads it (the oracle encoder
        needs depth + the semantic frame; experts need neither)."""
        if self.encoder is None:
            return self.sim
        from ovon.models.encoders import image_encoder_inputs

        rgb = "rgb" in image_encoder_inputs(self.encoder) and self.sim.camera.rgb
        return dataclasses.replace(self.sim, camera=dataclasses.replace(self.sim.camera, rgb=rgb))


def build_env(recipe: EnvRecipe) -> gym.Env:
    """The env stack of `recipe` (see the module docstring for the order)."""
    from ovon.env.core import ObjectNavEnv

    env: gym.Env = ObjectNavEnv(
        scene=recipe.scene,
        goal=recipe.goal,
        episodes=recipe.episodes[:1] if recipe.episodes else None,
        sim=recipe.rendering(),
        task=recipe.task,
    )
    if recipe.needs_privileged:
        from ovon.env.privileged import PrivilegedInfo

        env = PrivilegedInfo(env)
    if recipe.expert is not None:
        from ovon.env.labels import ExpertLabels

        env = ExpertLabels(env, recipe.expert, recipe.expert_cfg, recipe.expert_viewpoint_radius)
    if recipe.encoder is not None:
        from ovon.env.encode import EncodeObservation

        env = EncodeObservation(env, recipe.encoder, recipe.text_table)
    if recipe.episodes and recipe.sample_episodes:
        from ovon.env.sampler import EpisodeSampler

        env = EpisodeSampler(
            env,
            recipe.episodes,
            recipe.seed,
            recipe.scene_repeat,
            recipe.curriculum_start_m,
            recipe.curriculum_episodes,
            recipe.curriculum_updates,
            recipe.strict_stop_from,
        )
    return env


def split_episodes(specs: Sequence[EpisodeSpec], n: int) -> list[list[EpisodeSpec]]:
    """Scenes round-robin over `n` envs (each env keeps few scenes: fewer world loads); with fewer
    scenes than envs, envs share scenes and split their episodes."""
    by_scene: dict[str, list[EpisodeSpec]] = {}
    for s in specs:
        by_scene.setdefault(s.scene, []).append(s)
    scenes = sorted(by_scene)
    if len(scenes) >= n:
        return [[s for sc in scenes[i::n] for s in by_scene[sc]] for i in range(n)]
    out = []
    for i in range(n):
        sc = by_scene[scenes[i % len(scenes)]]
        share = sc[(i // len(scenes)) :: max(1, -(-n // len(scenes)))]
        out.append(share or sc)
    return out


def make_vector_env(recipe: EnvRecipe, num_envs: int, workers: int = 0, base_seed: int = 0):
    """`num_envs` copies of `recipe` on `workers` processes; with an episode list, env i samples from its
    share of the episodes (`split_episodes`) with seed `base_seed * 10007 + i`."""
    from ovon.config.base import validate
    from ovon.env.vector import ObjectNavVectorEnv

    if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
        raise ValueError(f"num_envs = {num_envs!r}: expected an integer >= 1; fix: e.g. num_envs=4")
    # checked here, before a worker is started (each env checks them again when built)
    validate(recipe.sim, "sim")
    validate(recipe.task, "task")
    recipes = []
    parts = split_episodes(recipe.episodes, num_envs) if recipe.episodes else [None] * num_envs
    for i, part in enumerate(parts):
        recipes.append(dataclasses.replace(recipe, episodes=part, seed=base_seed * 10007 + i))
    return ObjectNavVectorEnv([functools.partial(build_env, r) for r in recipes], workers=workers)
