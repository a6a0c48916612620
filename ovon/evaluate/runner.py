"""Run one episode of one agent in an env and return its JSON record."""

from __future__ import annotations

import dataclasses
import zlib

from ovon.agents.base import is_privileged
from ovon.env.privileged import privileged_of
from ovon.task.episode import EpisodeSpec


def episode_seed(seed: int, split: str, episode_id: str, scene: str) -> int:
    """Per-episode seed, stable across processes, so results do not depend on scheduling."""
    return zlib.crc32(f"{seed}|{split}|{scene}|{episode_id}".encode())


def episode_info(spec: EpisodeSpec, ep_seed: int, sim) -> dict:
    """What an agent's `reset` gets (also when `ovon video` replays an episode through the agent)."""
    return {
        "episode_id": spec.episode_id,
        "scene_id": spec.scene,
        "split": spec.split,
        "goal": spec.goal_category,
        "seed": ep_seed,
        # the robot's calibration (not privileged): camera intrinsics and body, for agents that map
        "camera": dataclasses.asdict(sim.camera),
        "embodiment": dataclasses.asdict(sim.agent),
    }


def run_episode(env, agent, spec: EpisodeSpec, seed: int, record_path: bool = False) -> dict:
    """`env` is an `ovon.env` stack, with `PrivilegedInfo` when the agent is privileged: such an agent
    gets `observation["privileged"]`; any other agent sees only the robot's observations."""
    ep_seed = episode_seed(seed, spec.split, spec.episode_id, spec.scene)
    obs, info = env.reset(seed=ep_seed, options={"episode": spec})
    truth = env.unwrapped  # the harness's own bookkeeping (paths for videos) may read ground truth
    agent.reset(episode_info(spec, ep_seed, truth.sim_cfg))
    privileged = is_privileged(agent)

    def pose() -> list[float]:
        s = truth.privileged().state
        return [*map(float, s.position), float(s.yaw)]

    path = [pose()] if record_path else []
    actions: list[int] = []
    while True:
        if privileged:
            obs = {**obs, "privileged": privileged_of(info)}
        action = int(agent.act(obs))
        obs, _reward, terminated, truncated, info = env.step(action)
        actions.append(action)
        if record_path:
            path.append(pose())
        if terminated or truncated:
            break
    m = info["metrics"]
    record = {
        "scene": spec.scene,
        "episode_id": spec.episode_id,
        "category": spec.goal_category,
        "split": spec.split,
        "seed": seed,
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
    record["actions"] = actions  # with the episode seed, enough to replay the episode exactly (videos)
    if record_path:
        record["path"] = path
    return record
