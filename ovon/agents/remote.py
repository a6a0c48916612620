"""`--agent remote:HOST:PORT`: an agent that runs elsewhere (its own Python, its own GPU), served by
`ovon serve` or by `ovon_agent.serve` (clients/ovon-agent), driven by `ovon evaluate` like any other.

Why a client that looks like an agent: the harness, its workers, seeds, resume and reports stay the same;
only the calls travel. Each evaluation worker opens its own connection; `remote.batch` episodes run in
lockstep per worker and their observations go out as one batched act. The episode information (seeds
included) travels with the first act of each episode, so a served agent gives the same episodes as the same
agent in-process. The token, when the server has one, comes from the environment (`OVON_REMOTE_TOKEN`),
never from the command line or the run folder.
"""

from __future__ import annotations

import ipaddress
import json
import multiprocessing.util
import os
import re
import socket
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ovon.config.base import ConfigError, in_range

PREFIX = "remote:"
TOKEN_ENV = "OVON_REMOTE_TOKEN"
_FIX = "fix: --agent remote:HOST:PORT, e.g. remote:127.0.0.1:5555 (start the agent with `ovon serve AGENT --port 5555`)"


@dataclass(frozen=True)
class RemoteConfig:
    """Settings of `--agent remote:HOST:PORT` (`--set remote.timeout_s=120`); none changes a result."""

    timeout_s: float = in_range(60.0, 0.0, 86400.0, lo_open=True)  # per call, the handshake included
    batch: int = in_range(1, 1, 1024)  # episodes in flight per worker, sent as one batched act per step
    allow_privileged: bool = False  # serve ground truth to an agent that asks for it (oracles only)


def is_remote(agent: str) -> bool:
    return str(agent).startswith(PREFIX)


# a DNS name (labels of letters, digits, '-' and '_', dot-separated) or an IPv4 address
_LABEL = r"[A-Za-z0-9_](?:[A-Za-z0-9_-]{0,61}[A-Za-z0-9_])?"
_HOST_NAME = re.compile(rf"(?=.{{1,253}}$){_LABEL}(?:\.{_LABEL})*\.?")


def parse_address(agent: str) -> tuple[str, int]:
    """`remote:HOST:PORT` (IPv6 as `remote:[::1]:PORT`) -> (host, port); one-line ConfigError otherwise.

    HOST is checked here, not by ZeroMQ: a space, a scheme (`http://`), a wildcard (`*`) or a bare IPv6
    ended in "internal error: ZMQError: Invalid argument", and `127.0.0.1:5555:1` was read as the IPv6
    host `127.0.0.1:5555`."""
    rest = str(agent)[len(PREFIX) :]
    host, sep, port = rest.rpartition(":")
    bracketed = host.startswith("[") and host.endswith("]")
    host = host[1:-1] if bracketed else host
    if not sep or not host or not port.isdigit() or not 1 <= int(port) <= 65535:
        raise ConfigError(f"--agent {agent!r} is not remote:HOST:PORT with PORT in 1..65535; {_FIX}")
    why = _bad_host(host, bracketed)
    if why:
        raise ConfigError(f"--agent {agent!r}: HOST {host!r} {why}; {_FIX}")
    return host, int(port)


def _bad_host(host: str, bracketed: bool) -> str:
    """Why `host` cannot be connected to ("" when it can be): a DNS name, an IPv4 address, or an IPv6
    address in brackets."""
    if "://" in host:
        return "holds a scheme; expected a bare host name or IP address (no http:// or tcp://)"
    if bracketed:
        try:
            ipaddress.IPv6Address(host)
        except ValueError:
            return "in brackets is not an IPv6 address"
        return ""
    if ":" in host:
        return (
            "holds ':'; expected one HOST:PORT (an IPv6 address goes in brackets, e.g. remote:[::1]:5555, "
            "and nothing may follow PORT)"
        )
    if host == "*":
        return "is an address to listen on (ovon serve --host), not one to connect to; expected the server's host"
    if not _HOST_NAME.fullmatch(host):
        return "is not a host name or IP address (letters, digits, '-', '_' and dots)"
    return ""


def _resolve(spec: str, host: str, port: int) -> None:
    """Refuse a host that does not resolve, before connecting: ZeroMQ would retry it silently and the
    handshake would time out as "nothing is listening there"."""
    try:
        socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    except (socket.gaierror, UnicodeError) as e:
        why = getattr(e, "strerror", None) or str(e)
        raise ConfigError(
            f"--agent {spec}: the host {host!r} does not resolve ({why}); fix: check the host "
            "name (or pass the server's IP address), e.g. remote:127.0.0.1:5555"
        ) from None


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:60] + "..." + text[-15:]


def episode_name(info: dict) -> str:
    """How an error names an episode: split / scene / episode id."""
    scene = Path(str(info.get("scene_id", "?"))).name or "?"
    return f"episode {info.get('split', '?')}/{scene}/{info.get('episode_id', '?')}"


class RemoteAgent:
    """An `ovon.agents.Agent` whose decisions come from a served agent; `act_batch` drives several
    streams (episodes) at once. Construction connects and checks the handshake."""

    def __init__(self, agent: str, cfg: RemoteConfig | None = None) -> None:
        from ovon_agent import OBSERVATIONS, Client, RemoteError

        from ovon import __version__

        self.spec, self.cfg = str(agent), cfg or RemoteConfig()
        host, port = parse_address(self.spec)
        _resolve(self.spec, host, port)
        self._pending: dict[int, dict] = {}  # stream -> episode info not sent yet
        self._info: dict[int, dict] = {}  # stream -> info of its current episode (for error lines)
        self._steps: dict[int, int] = {}
        try:
            self.client = Client(
                host,
                port,
                token=os.environ.get(TOKEN_ENV) or None,
                timeout_s=self.cfg.timeout_s,
                client=f"ovon {__version__}",
            )
        except RemoteError as e:
            raise RemoteError(self._fix(str(e), e.kind, during_run=False), e.kind) from None
        # a worker process that ends normally says goodbye, so the server frees its agents at once
        multiprocessing.util.Finalize(self, self.client.close, exitpriority=10)
        hello = self.client.hello
        # The name it introduces itself with (the row name of table.md unless --name: `check_remote`
        # checks it); anything but a string is the address.
        agent_name = hello.get("agent")
        self.name = agent_name if isinstance(agent_name, str) and agent_name.strip() else self.spec
        privileged = hello.get("privileged")
        wanted = hello.get("observations")
        fix = (
            "fix: the `observations` the agent is served with (ovon serve --observations, "
            "ovon_agent.serve(observations=...))"
        )
        if not (wanted is None or (isinstance(wanted, list | tuple) and all(isinstance(o, str) for o in wanted))):
            self.close()  # a string would be split into letters, a number is not iterable
            raise ConfigError(
                f"--agent {self.spec}: the agent {_short(self.name)} answered the handshake with observations "
                f"{_short(wanted)}; expected a list of observation names ({', '.join(OBSERVATIONS)}); {fix}"
            )
        self.observations = tuple(OBSERVATIONS if wanted is None else dict.fromkeys(wanted))
        unknown = [o for o in self.observations if o not in OBSERVATIONS]
        if unknown:
            self.close()
            raise ConfigError(
                f"--agent {self.spec}: the agent {_short(self.name)} wants observations {_short(unknown)}, which "
                f"ovon does not provide ({', '.join(OBSERVATIONS)}); {fix}"
            )
        if not (privileged is None or isinstance(privileged, bool)):
            self.close()  # bool("false") is True
            raise ConfigError(
                f"--agent {self.spec}: the agent {_short(self.name)} answered the handshake with privileged "
                f"{_short(privileged)}; expected true or false; fix: serve it with ovon serve or ovon_agent.serve "
                "of the same version as this ovon"
            )
        self.privileged = bool(privileged)
        # What the agent says it is beside its name (`ovon serve`: the agent and its arguments): with the
        # name, the identity of the run folders it writes, so the same agent served elsewhere continues them.
        config = hello.get("config")
        try:
            self.agent_config = json.loads(
                json.dumps({} if config is None else config, sort_keys=True, allow_nan=False)
            )
        except (TypeError, ValueError, RecursionError):
            self.agent_config = None
        if not isinstance(self.agent_config, dict):
            self.close()
            raise ConfigError(
                f"--agent {self.spec}: the agent {_short(self.name)} answered the handshake with config "
                f"{_short(config)}; expected a map of JSON values (strings, numbers, lists, maps); fix: serve it "
                "with ovon serve, or pass ovon_agent.serve(config=...) a dict of plain values"
            )
        if self.privileged and not self.cfg.allow_privileged:
            self.close()
            raise ConfigError(
                f"--agent {self.spec}: the agent {self.name!r} asks for the privileged channel (ground "
                "truth: an oracle); fix: --set remote.allow_privileged=true to evaluate an oracle, or "
                "serve an agent that uses its sensors only"
            )

    def _fix(self, message: str, kind: str, during_run: bool = True) -> str:
        resume = ", then re-run the same command to resume (finished episodes are kept)" if during_run else ""
        if kind == "refused" and "token" in message:
            return f"{message}; fix: set {TOKEN_ENV} to the server's --token"
        if kind == "refused":
            return f"{message}; fix: install the same version of ovon on both sides (or of ovon-agent there)"
        if kind == "agent":
            return f"{message}; fix: see the server's log and fix the agent{resume}"
        if kind == "protocol":
            return (
                f"{message}; fix: check that {self.spec.removeprefix(PREFIX)} is an agent served by `ovon serve` "
                "or ovon_agent.serve, of the same version on both sides"
            )
        if kind == "address":
            return f"{message}; {_FIX}"
        port = self.spec.rpartition(":")[2]
        return (
            f"{message}; fix: check that the agent is served there (`ovon serve AGENT --port {port}`) and raise "
            f"--set remote.timeout_s if it is only slow{resume}"
        )

    # -- the Agent protocol ------------------------------------------------------------------------
    def reset(self, episode_info: dict, stream: int = 0) -> None:
        """Kept and sent with the episode's first act (one round trip per step, none per reset)."""
        self._pending[stream] = dict(episode_info)
        self._info[stream] = dict(episode_info)
        self._steps[stream] = 0

    def act(self, observation: dict) -> int:
        return self.act_batch([observation], [0])[0]

    def act_batch(self, observations: list[dict], streams: list[int]) -> list[int]:
        from ovon_agent import RemoteError

        from ovon.env.privileged import episode_to_wire, step_to_wire

        items = []
        for obs, stream in zip(observations, streams):
            item: dict = {"stream": int(stream), "obs": {k: obs[k] for k in self.observations if k in obs}}
            truth = obs.get("privileged") if self.privileged else None
            if truth is not None:
                item["obs"]["privileged"] = step_to_wire(truth)
            info = self._pending.pop(stream, None)
            if info is not None:
                if truth is not None:
                    info["privileged"] = episode_to_wire(truth)
                item["info"] = info
            items.append(item)
            self._steps[stream] = self._steps.get(stream, 0) + 1
        try:
            return self.client.act(items, self._what(streams))
        except RemoteError as e:
            raise RemoteError(self._fix(str(e), e.kind), e.kind) from None

    def _what(self, streams: list[int]) -> str:
        s = streams[0]
        more = f" and {len(streams) - 1} other episode(s)" if len(streams) > 1 else ""
        return f"step {self._steps.get(s, 0)} of {episode_name(self._info.get(s, {}))}{more}"

    def close(self) -> None:
        client = getattr(self, "client", None)
        if client is not None:
            client.close()


@dataclass(frozen=True)
class Handshake:
    """What a served agent says it is: its name (the table's row unless --name) and its config."""

    name: str
    config: dict


def check_remote(agent: str, cfg: RemoteConfig, agent_kwargs: dict | None = None, row_name: str = "") -> Handshake:
    """Before any work: the address parses, the agent answers the handshake and the run allows what it
    asks for. Returns what the agent says it is (its name checked as a row name unless `row_name`, the
    --name that replaces it, is given)."""
    if agent_kwargs:
        key = next(iter(agent_kwargs))
        flag = "--checkpoint" if key == "checkpoint" else f"--agent-arg {key}=..."
        raise ConfigError(
            f"{flag} is given with --agent {agent}: constructor arguments of a served agent belong to "
            f"the server; fix: pass them to `ovon serve AGENT {flag}` instead"
        )
    parse_address(agent)
    remote = RemoteAgent(agent, cfg)
    try:
        name, config = remote.name, remote.agent_config
    finally:
        remote.close()
    from ovon.agents.base import ROW_NAME as domain

    if not row_name and not domain.accepts(name):  # a '|' or a line break would break table.md ("x\n" * 5000)
        raise ConfigError(
            f"--agent {agent}: the agent introduces itself as {_short(name)}, which cannot name a row of the "
            f"table (expected {domain.describe('a string')}); fix: pass --name NAME, or serve the agent under "
            "another name (ovon serve --name, ovon_agent.serve(name=...))"
        )
    return Handshake(name, config)
