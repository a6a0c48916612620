"""The worker side of an evaluation: a `WorkUnit` is a chunk of episodes of one scene under one seed,
run in a worker process (or Ray task) by `run_unit`, which returns their records.

Why a per-process cache: building an env loads a scene and its nav grid, and building an agent may load a
checkpoint or open a connection to a served agent; a worker keeps both across the units it gets while the
agent and the settings stay the same.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from typing import Any

from ovon.agents.remote import RemoteConfig, is_remote
from ovon.config.base import to_dict
from ovon.config.sim import SimConfig
from ovon.config.task import TaskConfig
from ovon.evaluate.config import EvalConfig
from ovon.parallel import init_worker
from ovon.task.episode import EpisodeSpec


@dataclass(frozen=True)
class WorkUnit:
    """Episodes of one scene under one seed, with everything a worker needs to run them."""

    specs: list[EpisodeSpec]
    seed: int
    agent: str
    agent_kwargs: dict
    remote: RemoteConfig
    sim: SimConfig
    task: TaskConfig


@dataclass
class _WorkerCache:
    """What a worker process keeps between units: the agent (with its key) and the envs (with theirs)."""

    agent: Any = None
    agent_key: tuple | None = None
    envs: list = field(default_factory=list)
    env_key: tuple | None = None


_CACHE = _WorkerCache()


def work_units(cfg: EvalConfig, specs_by_split: dict[str, list[EpisodeSpec]], done: set) -> list[WorkUnit]:
    """The units of the episodes of `specs_by_split` not yet `done` (record keys), per seed, split and scene,
    `cfg.chunk` episodes each (a remote agent's: at least a full lockstep batch)."""
    units = []
    chunk = max(cfg.chunk, cfg.remote.batch) if is_remote(cfg.agent) else cfg.chunk
    for seed in cfg.seeds:
        for split, specs in specs_by_split.items():
            by_scene: dict[str, list[EpisodeSpec]] = {}
            for s in specs:
                if (split, int(seed), s.scene_key, s.episode_id) not in done:
                    by_scene.setdefault(s.scene, []).append(s)
            for scene_specs in by_scene.values():
                for i in range(0, len(scene_specs), chunk):
                    units.append(
                        WorkUnit(
                            scene_specs[i : i + chunk],
                            int(seed),
                            cfg.agent,
                            cfg.agent_kwargs,
                            cfg.remote,
                            cfg.sim,
                            cfg.task,
                        )
                    )
    return units


def _agent(unit: WorkUnit) -> Any:
    """The unit's agent, cached per process across units (a remote one keeps its connection)."""
    from ovon.agents import make_agent

    kwargs = to_dict(unit.remote) if is_remote(unit.agent) else unit.agent_kwargs
    key = (unit.agent, json.dumps(kwargs, sort_keys=True))
    if _CACHE.agent_key != key:
        release_agent()
        _CACHE.agent = make_agent(unit.agent, **kwargs)
        _CACHE.agent_key = key
    return _CACHE.agent


def release_agent() -> None:
    """Drop the cached agent; a remote one closes its connection (the server frees its agents)."""
    agent, _CACHE.agent, _CACHE.agent_key = _CACHE.agent, None, None
    if agent is not None and callable(getattr(agent, "close", None)):
        agent.close()


def run_unit(unit: WorkUnit) -> list[dict]:
    """Runs a unit's episodes; envs and agent are cached per process across units. A remote agent runs
    `remote.batch` episodes in lockstep (one env each) and skips colour rendering when it does not want
    RGB (frames are otherwise identical)."""
    from ovon.agents import is_privileged
    from ovon.env.stack import EnvRecipe, build_env
    from ovon.evaluate.runner import run_episode, run_lockstep

    init_worker()
    agent = _agent(unit)
    privileged = is_privileged(agent)
    remote = is_remote(unit.agent)
    sim = unit.sim
    if remote and "rgb" not in agent.observations:
        sim = dataclasses.replace(sim, camera=dataclasses.replace(sim.camera, rgb=False))
    n_envs = unit.remote.batch if remote else 1
    key = (json.dumps(to_dict(sim), sort_keys=True), json.dumps(to_dict(unit.task), sort_keys=True), privileged)
    if _CACHE.env_key != key:
        for env in _CACHE.envs:
            env.close()
        _CACHE.envs, _CACHE.env_key = [], key
    recipe = EnvRecipe(sim=sim, task=unit.task, episodes=unit.specs[:1], sample_episodes=False, privileged=privileged)
    envs = _CACHE.envs
    while len(envs) < min(n_envs, len(unit.specs)):
        envs.append(build_env(recipe))
    if remote and n_envs > 1:
        return run_lockstep(envs[:n_envs], agent, unit.specs, unit.seed)
    return [run_episode(envs[0], agent, spec, unit.seed) for spec in unit.specs]
