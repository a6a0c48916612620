"""The privileged channel as a wrapper: `info["privileged"]` = ground truth of the current step.

Why a wrapper: the plain env's observation and info carry nothing an agent could cheat with; oracle
agents, experts (DAgger labels) and oracle encoders get ground truth only where this wrapper is stacked,
and it never crosses a process boundary (the vector env drops it in the worker).
"""

from __future__ import annotations

import gymnasium as gym

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
