"""Agents served in the remote-agent tests (`ovon serve tests.remote_agents:X` from the repository root),
`serving`, a server on a free loopback port in a thread that is always stopped, and `free_ports`, ports for a
server that must be told its port before it starts (the README's)."""

from __future__ import annotations

import os
import socket
import threading
import zlib
from contextlib import contextmanager

import numpy as np

from ovon.agents.random_agent import RandomAgent


class OracleProbe(RandomAgent):
    """A random walker whose every move is a hash of every privileged field that travels (so a field that
    arrived different changes the episode), and that STOPs within 1 m of the goal."""

    privileged = True

    def act(self, observation: dict) -> int:
        p = observation["privileged"]
        if super().act(observation) == 0 or p.distance_to_goal < 1.0:
            return 0
        categories = {o.id: o.category for o in p.world.scene.objects}
        visible = [(i, categories.get(i)) for i in np.unique(p.frame.semantic).tolist()]
        near = min((float(np.hypot(*(p.state.position - v.position)[[0, 2]])) for v in p.viewpoints), default=9.0)
        key = (
            f"{visible}|{sorted(p.goal_ids)}|{p.state.position.tolist()}|{p.state.yaw}|{p.state.pitch}|{near}|"
            f"{p.world.key}|{p.distance_to_goal}"
        )
        return 1 + zlib.crc32(key.encode()) % 3


def free_ports(n: int = 1) -> list[int]:
    """n distinct loopback ports that were free a moment ago (bound together, then closed).

    Racy by nature: another process may take one before the server binds it. Prefer port 0 wherever the
    server reports the port it bound (`Server(..., 0).port`, the line `ovon serve --port 0` prints); else
    pick as late as possible and start the server again, on a fresh port, if it says "Address already in use"."""
    socks = [socket.socket() for _ in range(n)]
    try:
        for s in socks:
            s.bind(("127.0.0.1", 0))
        return [s.getsockname()[1] for s in socks]
    finally:
        for s in socks:
            s.close()


@contextmanager
def serving(agent, **kw):
    """`ovon_agent.Server(agent, "127.0.0.1", 0, **kw)` answering in a thread; stopped on exit."""
    from ovon_agent import Server

    server = Server(agent, "127.0.0.1", 0, log=lambda line: None, **kw)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield server
    finally:
        server.stop()
        thread.join(10)
        assert not thread.is_alive()


class DieAt(RandomAgent):
    """The random agent, except that the serving process dies (as in a crash) when its n-th episode starts,
    n from the environment variable OVON_TEST_DIE_AT (never when unset)."""

    episodes = 0

    def reset(self, episode_info: dict) -> None:
        DieAt.episodes += 1
        if DieAt.episodes == int(os.environ.get("OVON_TEST_DIE_AT", "0")):
            os._exit(1)
        super().reset(episode_info)


class BatchedRandom:
    """One object for every stream, with `act_batch`: a random agent per stream (`episode_info["stream"]`),
    and the size of every batch it was given."""

    def __init__(self) -> None:
        self.agents: dict[str, RandomAgent] = {}
        self.batch_sizes: list[int] = []

    def reset(self, episode_info: dict) -> None:
        agent = self.agents.setdefault(episode_info["stream"], RandomAgent())
        agent.reset(episode_info)

    def act(self, observation: dict) -> int:
        return self.act_batch([observation])[0]

    def act_batch(self, observations: list[dict]) -> list[int]:
        self.batch_sizes.append(len(observations))
        return [self.agents[o["stream"]].act(o) for o in observations]
