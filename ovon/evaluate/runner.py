"""Run episodes of an agent in envs and return their JSON records: one at a time (`run_episode`), or
several in lockstep with one batched decision per step (`run_lockstep`, for agents served elsewhere)."""

from __future__ import annotations

import dataclasses
import zlib

from ovon.agents.base import is_privileged
from ovon.env.privileged import privileged_of
from ovon.task.episode import EpisodeSpec


def episode_seed(seed: int, split: str, episode_id: str, scene: str) -> int:
    """Per-episode seed, stable across processes, so results do not depend on scheduling. `scene` is the
    dataset's scene id (`EpisodeSpec.scene_key`), never a resolved path, so they do not depend on where the
    data lives either."""
    return zlib.crc32(f"{seed}|{split}|{scene}|{episode_id}".encode())


def episode_info(spec: EpisodeSpec, ep_seed: int, sim) -> dict:
    """What an agent's `reset` gets (also when `ovon video` replays an episode through the agent)."""
    return {
        "episode_id": spec.episode_id,
        "scene_id": spec.scene_key,
        "split": spec.split,
        "goal": spec.goal_category,
        "seed": ep_seed,
        # the robot's calibration (not privileged): camera intrinsics and body, for agents that map
        "camera": dataclasses.asdict(sim.camera),
        "embodiment": dataclasses.asdict(sim.agent),
    }


class EpisodeRun:
    """One episode stepped from outside: `info` for the agent's reset, then `observation` / `step(action)`
    until `done`, then `record()`. With `privileged`, the observation carries `observation["privileged"]`
    (the env must be stacked with `PrivilegedInfo`); any other agent sees only the robot's observations."""

    def __init__(self, env, spec: EpisodeSpec, seed: int, privileged: bool, record_path: bool = False) -> None:
        self.env, self.spec, self.seed, self.privileged = env, spec, seed, privileged
        ep_seed = episode_seed(seed, spec.split, spec.episode_id, spec.scene_key)
        self._obs, self._info = env.reset(seed=ep_seed, options={"episode": spec})
        self.truth = env.unwrapped  # the harness's own bookkeeping (paths for videos) may read ground truth
        self.info = episode_info(spec, ep_seed, self.truth.sim_cfg)
        self.record_path = record_path
        self.path = [self._pose()] if record_path else []
        self.actions: list[int] = []
        self.done = False

    def _pose(self) -> list[float]:
        s = self.truth.privileged().state
        return [*map(float, s.position), float(s.yaw)]

    @property
    def observation(self) -> dict:
        if self.privileged:
            return {**self._obs, "privileged": privileged_of(self._info)}
        return self._obs

    def step(self, action: int) -> bool:
        action = int(action)
        self._obs, _reward, terminated, truncated, self._info = self.env.step(action)
        self.actions.append(action)
        if self.record_path:
            self.path.append(self._pose())
        self.done = bool(terminated or truncated)
        return self.done

    def record(self) -> dict:
        spec, m = self.spec, self._info["metrics"]
        record = {
            "scene": spec.scene_key,
            "episode_id": spec.episode_id,
            "category": spec.goal_category,
            "split": spec.split,
            "seed": self.seed,
            "success": bool(m["success"]),
            "spl": m["spl"],
            "soft_spl": m["soft_spl"],
            "distance_to_goal": m["distance_to_goal"],
            "start_distance": m["start_distance"],
            "geodesic_distance": spec.info.get("geodesic_distance", m["start_distance"]),
            "path_length": m["path_length"],
            "steps": m["steps"],
            "collisions": m["collisions"],
            "goal_seen": m["goal_seen"],
            "failure": m["failure"],
            "distance_to_object": m["distance_to_object"],
            "goal_in_view": m["goal_in_view"],
        }
        record["actions"] = self.actions  # with the episode seed, enough to replay the episode exactly (videos)
        if self.record_path:
            record["path"] = self.path
        return record


def run_episode(env, agent, spec: EpisodeSpec, seed: int, record_path: bool = False) -> dict:
    """`env` is an `ovon.env` stack, with `PrivilegedInfo` when the agent is privileged."""
    run = EpisodeRun(env, spec, seed, is_privileged(agent), record_path)
    agent.reset(run.info)
    while not run.done:
        run.step(agent.act(run.observation))
    return run.record()


def run_lockstep(envs: list, agent, specs: list[EpisodeSpec], seed: int) -> list[dict]:
    """`specs` with up to len(envs) episodes in flight, one `agent.act_batch(observations, streams)` per
    step over those in flight; env i is stream i, which `agent.reset(info, stream=i)` starts anew. Every
    episode is reset with its own seed, so its record is the one `run_episode` gives."""
    privileged = is_privileged(agent)
    queue = list(specs)
    slots: list[EpisodeRun | None] = [None] * len(envs)
    records: list[dict] = []
    while queue or any(slots):
        for i, env in enumerate(envs):
            if slots[i] is None and queue:
                run = slots[i] = EpisodeRun(env, queue.pop(0), seed, privileged)
                agent.reset(run.info, stream=i)
        live = [i for i, run in enumerate(slots) if run is not None]
        actions = agent.act_batch([slots[i].observation for i in live], live)
        for i, action in zip(live, actions):
            run = slots[i]
            if run.step(action):
                records.append(run.record())
                slots[i] = None
    return records
