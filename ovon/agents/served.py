"""`ovon serve AGENT`: any agent ovon can load, served to `ovon evaluate --agent remote:HOST:PORT`.

The agent is checked and built once before the socket opens (a bad name or `--agent-arg` is one line);
then one instance per episode stream, so several evaluation workers never share an agent's state. An
oracle agent reads the privileged channel as it travels (`ovon.env.privileged.from_wire`); the grid
experts, which need the navigation grid, are refused here.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ovon.agents import AgentError, check_agent, load_agent_class, make_agent
from ovon.runfolder import file_sha256


class ServedAgent:
    """An ovon agent behind the wire: rebuilds `observation["privileged"]` from its travelling parts."""

    def __init__(self, inner: Any) -> None:
        self.inner = inner
        self.privileged = bool(getattr(inner, "privileged", False))
        self._episode: dict | None = None

    def reset(self, episode_info: dict) -> None:
        from ovon.env.privileged import episode_from_wire

        info = dict(episode_info)
        episode = info.pop("privileged", None)
        self._episode = None if episode is None else episode_from_wire(episode)
        self.inner.reset(info)

    def act(self, observation: dict) -> int:
        step = observation.get("privileged")
        if step is not None:
            from ovon.env.privileged import from_wire

            if self._episode is None:
                raise RuntimeError("the privileged step data came without its episode part (send the reset first)")
            observation = {**observation, "privileged": from_wire(self._episode, step)}
        return self.inner.act(observation)


def servable_factory(agent: str, kwargs: dict | None = None):
    """A zero-argument factory of `ServedAgent`s for `agent` (built-in name or `package.module:Class`),
    checked before anything is served."""
    kwargs = dict(kwargs or {})
    cls = load_agent_class(agent)
    if not getattr(cls, "servable", True):
        raise AgentError(
            f"agent {agent!r} cannot be served: {getattr(cls, 'servable_reason', 'it reads ground truth')}"
            "; fix: evaluate it in-process (ovon evaluate --agent " + agent + ")"
        )
    check_agent(agent, kwargs)
    return lambda: ServedAgent(make_agent(agent, **kwargs))


def checkpoint_file(checkpoint: object) -> Path | None:
    """The policy file an agent's `checkpoint` argument names (a run folder means its policy.pt), None when
    it names no existing file."""
    if not isinstance(checkpoint, str) or not checkpoint:
        return None
    p = Path(checkpoint) / "policy.pt" if Path(checkpoint).is_dir() else Path(checkpoint)
    return p if p.is_file() else None


def served_config(agent: str, kwargs: dict | None = None) -> dict:
    """What a served agent says it is in its handshake beside its name: the agent and its arguments, a
    `checkpoint` by content (where the file lies does not change the agent, retraining it does). An
    evaluation run folder takes its identity from it, not from the server's address."""
    kwargs = dict(kwargs or {})
    out: dict[str, Any] = {"agent": agent}
    ckpt = checkpoint_file(kwargs.get("checkpoint"))
    if ckpt is not None:
        kwargs.pop("checkpoint")
        out["checkpoint_sha256"] = file_sha256(ckpt)
    out["agent_kwargs"] = kwargs
    return out
