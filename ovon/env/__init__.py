"""The Gymnasium environment of the task, its wrappers and the one vector env.

    env = gymnasium.make("ovon/ObjectNav-v0", scene="procedural:3", goal="bed")           # a robot's view
    env = gymnasium.make("ovon/ObjectNav-v0", scene=..., goal=..., privileged=True)       # + info["privileged"]

Data flow: ovon.sim (scenes, navigability, rendering, kinematics) -> ovon.task (episode set-up,
tracker) -> ovon.env (reset/step, wrappers) -> agents / training / evaluation.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ovon.env.core import ObjectNavEnv
    from ovon.env.privileged import PrivilegedInfo

_LAZY = {
    "ObjectNavEnv": "ovon.env.core",
    "Privileged": "ovon.env.core",
    "PrivilegedInfo": "ovon.env.privileged",
    "privileged_of": "ovon.env.privileged",
    "EnvRecipe": "ovon.env.stack",
    "build_env": "ovon.env.stack",
    "make_vector_env": "ovon.env.stack",
    "ObjectNavVectorEnv": "ovon.env.vector",
}

__all__ = [*_LAZY, "make_objectnav"]


def __getattr__(name: str) -> Any:
    mod = _LAZY.get(name)
    if mod is None:
        raise AttributeError(f"module 'ovon.env' has no attribute {name!r}")
    return getattr(importlib.import_module(mod), name)


def make_objectnav(privileged: bool = False, **kwargs) -> ObjectNavEnv | PrivilegedInfo:
    """Entry point of "ovon/ObjectNav-v0": the plain env, or with `privileged=True` wrapped so that
    `info["privileged"]` carries the ground truth (true pose, semantic frame, goal field, map)."""
    from ovon.env.core import ObjectNavEnv
    from ovon.env.privileged import PrivilegedInfo

    env = ObjectNavEnv(**kwargs)
    return PrivilegedInfo(env) if privileged else env
