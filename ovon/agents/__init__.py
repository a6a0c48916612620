"""Agents: the protocol, built-ins chosen by name, and `package.module:ClassName` for your own.

`check_agent(name, kwargs)` is what a command calls before any work: it loads the class, checks that it
has `reset` and `act`, binds the keyword arguments to its constructor and builds one instance, so a
wrong name, a bogus `--agent-arg` or an unreadable checkpoint is one clear line instead of a traceback
in a worker process."""

from __future__ import annotations

import inspect

from ovon.agents.base import Agent, is_privileged
from ovon.plugins import PluginError, load_object, lookup

BUILTIN: dict[str, str] = {
    "random": "ovon.agents.random_agent:RandomAgent",
    "shortest-path": "ovon.agents.expert_agents:ShortestPathAgent",
    "frontier": "ovon.agents.expert_agents:FrontierAgent",
    "policy": "ovon.agents.policy_agent:PolicyAgent",
    "vlfm": "ovon.agents.modular.vlfm:VLFMAgent",
    "dagrl-od": "ovon.agents.modular.dagrl_od:DAgRLODAgent",
}

_FIX = "fix: use one of {builtin} or 'package.module:ClassName' (a class with reset(episode_info) and act(observation))"


class AgentError(ValueError):
    """The agent cannot be loaded or built; the message names the agent, the argument and the fix."""


def load_agent_class(name: str) -> type:
    fix = _FIX.format(builtin=sorted(BUILTIN))
    target = lookup(name, BUILTIN)
    if target is None:
        raise AgentError(f"unknown agent {name!r}; {fix}")
    try:
        obj = load_object(target)
    except PluginError as e:
        raise AgentError(f"agent {name!r}: {e}; {fix}") from None
    module_name, _, cls_name = str(target).partition(":")
    if not inspect.isclass(obj):
        raise AgentError(f"agent {name!r}: {module_name}:{cls_name} is a {type(obj).__name__}, not a class; {fix}")
    missing = [m for m in ("reset", "act") if not callable(getattr(obj, m, None))]
    if missing:
        raise AgentError(
            f"agent {name!r}: class {obj.__module__}.{obj.__qualname__} has no {' / '.join(missing)} method; {fix}"
        )
    return obj


def _bind(name: str, cls: type, kwargs: dict) -> None:
    try:
        sig = inspect.signature(cls)
    except (TypeError, ValueError):
        return
    params = sig.parameters.values()
    accepts_any = any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params)
    names = [p.name for p in params if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]
    unknown = [k for k in kwargs if k not in names]
    if unknown and not accepts_any:
        raise AgentError(
            f"agent {name!r} has no constructor argument {unknown[0]!r} (--agent-arg {unknown[0]}=...); "
            f"fix: use one of {names or 'none'}"
        )
    missing = [
        p.name
        for p in params
        if p.default is inspect.Parameter.empty
        and p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)
        and p.name not in kwargs
    ]
    if missing:
        flag = "--checkpoint PATH" if missing[0] == "checkpoint" else f"--agent-arg {missing[0]}=VALUE"
        raise AgentError(f"agent {name!r} needs the argument {missing[0]!r}; fix: pass {flag}")


def check_agent(name: str, kwargs: dict | None = None) -> None:
    """Load, bind and build the agent once (then drop it); any problem is one AgentError line."""
    kwargs = dict(kwargs or {})
    cls = load_agent_class(name)
    _bind(name, cls, kwargs)
    from ovon.config.base import ConfigError

    try:
        agent = cls(**kwargs)
    except ConfigError:  # already one line naming the argument and its fix
        raise
    except Exception as e:  # noqa: BLE001 - the constructor is user code: report, don't trace
        detail = " ".join(str(e).split())[:200]
        args = ", ".join(f"{k}={v!r}" for k, v in kwargs.items()) or "no arguments"
        raise AgentError(
            f"agent {name!r} cannot be built with {args}: {type(e).__name__}: {detail}; fix: check "
            "--agent, --agent-arg and --checkpoint"
        ) from None
    if not isinstance(agent, Agent):
        raise AgentError(f"agent {name!r} must define reset(episode_info) and act(observation)")
    del agent


def make_agent(name: str, **kwargs) -> Agent:
    """The agent `name` built with `kwargs`; for `remote:HOST:PORT` a connected `RemoteAgent`, `kwargs` being
    `RemoteConfig` fields (timeout_s, batch, allow_privileged)."""
    from ovon.agents.remote import is_remote

    if is_remote(name):
        from ovon.agents.remote import RemoteAgent, RemoteConfig
        from ovon.config.base import from_dict

        return RemoteAgent(name, from_dict(RemoteConfig, kwargs))
    agent = load_agent_class(name)(**kwargs)
    if not isinstance(agent, Agent):
        raise AgentError(f"agent {name!r} must define reset(episode_info) and act(observation)")
    return agent


__all__ = ["Agent", "AgentError", "BUILTIN", "check_agent", "is_privileged", "load_agent_class", "make_agent"]
