"""`ovon serve AGENT`: serve an agent to `ovon evaluate --agent remote:HOST:PORT` (see ovon.agents.served)."""

from __future__ import annotations

import ipaddress
import os
import socket
from dataclasses import dataclass

from ovon.config.base import in_range, non_empty


def register(sub) -> None:
    p = sub.add_parser("serve", help="serve an agent to `ovon evaluate --agent remote:HOST:PORT`")
    p.add_argument("agent", help="random | policy | vlfm | dagrl-od | pkg.module:Class")
    p.add_argument(
        "--agent-arg",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="keyword argument for the agent's constructor (repeatable)",
    )
    p.add_argument("--checkpoint", help="policy checkpoint (for policy and dagrl-od)")
    p.add_argument(
        "--host",
        default="127.0.0.1",
        help="address to listen on (default loopback only; 0.0.0.0 listens on every interface)",
    )
    p.add_argument("--port", default=5555, help="TCP port (0: any free port, printed)")
    p.add_argument(
        "--token",
        default=None,
        help="shared secret clients must present (default: $OVON_REMOTE_TOKEN; none when unset)",
    )
    p.add_argument(
        "--observations",
        default=None,
        help="observations the agent wants, e.g. depth,odometry,goal,collided (default: all; without "
        "rgb the evaluation skips colour rendering)",
    )
    p.add_argument("--name", default=None, help="the name the agent introduces itself with (default: AGENT)")
    p.set_defaults(func=cmd_serve)


@dataclass(frozen=True)
class ServeArgs:
    agent: str = non_empty("", flag="AGENT")
    host: str = non_empty("127.0.0.1", flag="--host")
    port: int = in_range(5555, 0, 65535, flag="--port")
    name: str | None = non_empty(None, flag="--name")


def _observations(text: str | None) -> list[str] | None:
    from ovon_agent import OBSERVATIONS

    from ovon.config.base import ConfigError

    if text is None:
        return None
    wanted = [x.strip() for x in text.split(",") if x.strip()]
    bad = [x for x in wanted if x not in OBSERVATIONS]
    if bad or not wanted:
        raise ConfigError(
            f"--observations {text!r}: expected a comma-separated subset of {', '.join(OBSERVATIONS)}; "
            "fix: e.g. --observations depth,odometry,goal,collided"
        )
    return wanted


def _is_loopback(host: str) -> bool:
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return host == "localhost"


def cmd_serve(args) -> int:
    from ovon_agent import PROTOCOL, Server

    from ovon.agents.served import servable_factory, served_config
    from ovon.config.base import ConfigError, from_args
    from ovon.evaluate.config import parse_agent_args

    a = from_args(ServeArgs, args)
    observations = _observations(args.observations)
    token = args.token if args.token is not None else os.environ.get("OVON_REMOTE_TOKEN") or None
    kwargs = parse_agent_args(args.agent_arg, args.checkpoint)
    factory = servable_factory(a.agent, kwargs)
    try:
        server = Server(
            factory,
            a.host,
            a.port,
            token=token,
            name=a.name or a.agent,
            observations=observations,
            config=served_config(a.agent, kwargs),
        )
    except OSError as e:
        raise ConfigError(
            f"--host {a.host} --port {a.port}: {e}; fix: another --port (0 picks a free one) or a "
            "local address for --host"
        ) from None
    if not _is_loopback(a.host) and token is None:
        print(
            f"ovon: warning: serving on {a.host} without a token: anyone who reaches this port can drive the agent "
            "(pass --token, or keep the default loopback and tunnel with ssh -L)",
            flush=True,
        )
    host = a.host if a.host not in ("0.0.0.0", "::") else socket.gethostname()  # what a client dials
    host = f"[{host}]" if ":" in host else host
    print(
        f"ovon serve: {server.name!r} (protocol {PROTOCOL}) on {server.address}"
        f"{', token required' if token else ''}; evaluate with --agent remote:{host}:{server.port}; "
        "stop with Ctrl-C",
        flush=True,
    )
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        print("ovon serve: stopped", flush=True)
    return 0
