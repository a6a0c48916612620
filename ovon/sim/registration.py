"""Gymnasium registration, run on `import ovon`."""

from __future__ import annotations


def register_envs() -> None:
    import gymnasium as gym

    if "ovon/ObjectNav-v0" not in gym.registry:
        gym.register(id="ovon/ObjectNav-v0", entry_point="ovon.sim.env:ObjectNavEnv")
