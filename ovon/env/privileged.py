"""The privileged channel as a wrapper: `info["privileged"]` = ground truth of the current step.

Why a wrapper: the plain env's observation and info carry nothing an agent could cheat with; oracle
agents, experts (DAgger labels) and oracle encoders get ground truth only where this wrapper is stacked,
and it never crosses a process boundary (the vector env drops it in the worker), except as the plain
arrays of `episode_to_wire` / `step_to_wire` for an agent served elsewhere that the run allows oracles.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np

from ovon.env.core import Privileged

KEY = "privileged"


class PrivilegedInfo(gym.Wrapper):
    """Adds `info["privileged"]` (an `ovon.env.Privileged`) after every reset and step."""

    def reset(self, **kwargs):
        obs, info = self.env.reset(**kwargs)
        return obs, {**info, KEY: self.env.unwrapped.privileged()}

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        return obs, reward, terminated, truncated, {**info, KEY: self.env.unwrapped.privileged()}


def privileged_of(info: dict) -> Privileged:
    """The ground truth a `PrivilegedInfo` wrapper put into `info` (a clear error when it is absent)."""
    try:
        return info[KEY]
    except KeyError:
        raise RuntimeError("this consumer needs ground truth: wrap the env in ovon.env.PrivilegedInfo") from None


# -- the privileged channel across a process boundary (`ovon serve`, `--agent remote:HOST:PORT`) ----
# What travels: per episode the scene key, the instance -> category map, the goal instances and viewpoints;
# per step the true pose, the semantic frame and the geodesic distance to the goal. Enough for oracle
# detection and oracle perception (VLFM, DAgRL+OD, the oracle-vl policy); not the navigation grid or the
# goal distance field, which the grid experts need (they are evaluated in-process).
CARRIED = ("state", "frame.semantic", "goal_ids", "viewpoints", "world.key", "world.scene.objects", "distance_to_goal")


def episode_to_wire(p: Privileged) -> dict:
    """The per-episode part of `p` as plain numbers, strings and arrays."""
    objects = [o for o in p.world.scene.objects if o.category]
    return {
        "scene": str(p.world.key),
        "object_ids": np.array([o.id for o in objects], dtype=np.int64),
        "object_categories": [str(o.category) for o in objects],
        "goal_ids": np.array(sorted(p.goal_ids), dtype=np.int64),
        "viewpoints": np.array(
            [[*map(float, v.position), float(v.yaw)] for v in p.viewpoints], dtype=np.float64
        ).reshape(-1, 4),
    }


def step_to_wire(p: Privileged) -> dict:
    """The per-step part of `p` as plain numbers and arrays."""
    return {
        "position": np.asarray(p.state.position, dtype=np.float64),
        "yaw": float(p.state.yaw),
        "pitch": float(p.state.pitch),
        "semantic": np.asarray(p.frame.semantic),
        "distance_to_goal": float(p.distance_to_goal),
    }


class _Part:
    """Attributes of a privileged view; one that did not travel is a one-line error naming what did."""

    def __init__(self, where: str, **values) -> None:
        self.__dict__.update(values)
        self._where = where

    def __getattr__(self, name: str):
        if name.startswith("__") or name == "_where":
            raise AttributeError(name)
        raise AttributeError(
            f"privileged.{self._where}{name} is not carried by the remote protocol (it carries "
            f"{', '.join(CARRIED)}); evaluate this agent in-process instead"
        )


def episode_from_wire(episode: dict) -> dict:
    """The per-episode part as the objects a `Privileged` holds (built once per episode)."""
    from types import SimpleNamespace

    from ovon.task.episode import GoalViewpoint

    objects = [
        SimpleNamespace(id=int(i), category=c)
        for i, c in zip(np.asarray(episode["object_ids"]).tolist(), episode["object_categories"])
    ]
    scene = _Part("world.scene.", objects=objects, scene_id=episode["scene"])
    viewpoints = [
        GoalViewpoint(np.asarray(v[:3], dtype=np.float64), float(v[3]))
        for v in np.asarray(episode["viewpoints"], dtype=np.float64).reshape(-1, 4)
    ]
    return {
        "goal_ids": frozenset(np.asarray(episode["goal_ids"]).tolist()),
        "viewpoints": viewpoints,
        "world": _Part("world.", key=episode["scene"], scene=scene),
    }


def from_wire(episode: dict, step: dict) -> _Part:
    """A read-only stand-in for `Privileged` on the agent's side of `ovon serve`: `episode` from
    `episode_from_wire`, `step` as `step_to_wire` wrote it."""
    from ovon.sim.types import AgentState

    state = AgentState(np.asarray(step["position"], dtype=np.float64), float(step["yaw"]), float(step["pitch"]))
    return _Part(
        "",
        state=state,
        frame=_Part("frame.", semantic=np.asarray(step["semantic"])),
        distance_to_goal=float(step["distance_to_goal"]),
        **episode,
    )
