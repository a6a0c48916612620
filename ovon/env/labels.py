"""Expert labels as a wrapper: `obs["expert_action"]` = what the expert would do in the true state.

The expert (frontier or shortest-path, ovon.experts) is reset with the episode's true map and goal
viewpoints and then fed every true state the env visits, whoever chose the actions: the online DAgger
labeller, and the driver of BC recordings. Its embodiment (turn angle, step, field of view, success
distance) is derived from the env's own sim/task config, so they cannot disagree.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from ovon.env.privileged import privileged_of
from ovon.experts.factory import make_expert

KEY = "expert_action"
NO_LABEL = -1  # the observation after an episode's last step has no label


def inner_viewpoints(p, radius: float) -> list:
    """The goal viewpoints within `radius` m (horizontally) of a goal object's box, or all when none is.

    Why: success only needs any viewpoint (up to 1 m from the object), so an expert aiming at the nearest
    one stops at the outer edge of that band, where the object looks about as big as two steps earlier;
    a student that stops a step or two early then fails. Aiming at the inner viewpoints gives STOP labels
    where the goal fills the view, and an early STOP still lands inside the band. Evaluation is unchanged."""
    if radius <= 0:
        return list(p.viewpoints)
    boxes = [(o.aabb_min, o.aabb_max) for o in p.world.scene.objects if o.id in p.goal_ids]
    if not boxes or not p.viewpoints:
        return list(p.viewpoints)
    lo = np.array([b[0] for b in boxes], np.float64)[:, [0, 2]]  # (B, 2) x, z
    hi = np.array([b[1] for b in boxes], np.float64)[:, [0, 2]]
    xz = np.array([v.position for v in p.viewpoints], np.float64)[:, None, [0, 2]]  # (V, 1, 2)
    gap = np.maximum(np.maximum(lo - xz, 0.0), xz - hi)  # (V, B, 2) distance outside each box, per axis
    near = np.hypot(gap[..., 0], gap[..., 1]).min(axis=1) <= radius
    inner = [v for v, keep in zip(p.viewpoints, near) if keep]
    return inner or list(p.viewpoints)


class ExpertLabels(gym.Wrapper):
    """Needs `PrivilegedInfo` below it. `expert` is "frontier" or "shortest-path"; `expert_cfg` its
    config (None = defaults); `viewpoint_radius` > 0 aims the expert at the inner viewpoints."""

    def __init__(self, env: gym.Env, expert: str, expert_cfg=None, viewpoint_radius: float = 0.0) -> None:
        super().__init__(env)
        base = env.unwrapped
        self.expert = make_expert(expert, expert_cfg, base.sim_cfg, base.task_cfg)
        self.viewpoint_radius = float(viewpoint_radius)
        self.observation_space = spaces.Dict({**env.observation_space.spaces, KEY: spaces.Discrete(7, start=NO_LABEL)})

    def reset(self, **kwargs):
        obs, info = self.env.reset(**kwargs)
        p = privileged_of(info)
        vps = inner_viewpoints(p, self.viewpoint_radius)
        self.expert.reset(p.grid, [(v.position, v.yaw) for v in vps], p.state)
        return {**obs, KEY: np.int64(self.expert.act(p.state))}, info

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        label = NO_LABEL
        if not (terminated or truncated):
            label = self.expert.act(privileged_of(info).state, last_action=int(action))
        return {**obs, KEY: np.int64(label)}, reward, terminated, truncated, info
