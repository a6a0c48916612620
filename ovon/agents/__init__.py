"""Agents: the protocol, built-ins chosen by name, and `package.module:ClassName` for your own."""

from __future__ import annotations

import importlib

from ovon.agents.base import Agent, is_privileged

BUILTIN: dict[str, str] = {
    "random": "ovon.agents.random_agent:RandomAgent",
    "shortest-path": "ovon.agents.expert_agents:ShortestPathAgent",
    "frontier": "ovon.agents.expert_agents:FrontierAgent",
    "policy": "ovon.agents.policy_agent:PolicyAgent",
    "vlfm": "ovon.agents.modular.vlfm:VLFMAgent",
    "dagrl-od": "ovon.agents.modular.dagrl_od:DAgRLODAgent",
}


def load_agent_class(name: str) -> type:
    target = BUILTIN.get(name, name)
    if ":" not in target:
        raise ValueError(
            f"unknown agent {name!r}: use one of {sorted(BUILTIN)} or 'package.module:ClassName'"
        )
    module_name, cls_name = target.split(":", 1)
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as e:
        raise ValueError(f"agent {name!r}: cannot import module {module_name!r} ({e})") from None
    try:
        cls = getattr(module, cls_name)
    except AttributeError:
        raise ValueError(f"agent {name!r}: module {module_name!r} has no attribute {cls_name!r}") from None
    return cls


def make_agent(name: str, **kwargs) -> Agent:
    agent = load_agent_class(name)(**kwargs)
    if not isinstance(agent, Agent):
        raise TypeError(f"agent {name!r} must define reset(episode_info) and act(observation)")
    return agent


__all__ = ["Agent", "BUILTIN", "is_privileged", "load_agent_class", "make_agent"]
