"""The agent-side module `ovon_agent` on its own: encoding, the server's answers to good and bad requests,
streams and batching, tokens, timeouts and a server that dies. Servers listen on loopback, on free ports,
and are always stopped."""

from __future__ import annotations

import ast
import subprocess
import sys
import threading
import time
from pathlib import Path

import msgpack
import numpy as np
import ovon_agent
import pytest
import zmq
from ovon_agent import Client, ProtocolError, RemoteError, pack, unpack

from tests.remote_agents import serving

ROOT = Path(__file__).resolve().parents[1]
MODULE = ROOT / "clients" / "ovon-agent" / "ovon_agent" / "__init__.py"


def obs(h: int = 12, w: int = 16, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    return {
        "rgb": rng.integers(0, 256, (h, w, 3), dtype=np.uint8),
        "depth": rng.random((h, w), dtype=np.float32),
        "odometry": np.array([0.25, 0.0, 0.1], np.float32),
        "goal": "chair",
        "collided": 0,
    }


class Counter:
    """Actions 1, 2, 3, 1, ... per episode; remembers what it was given."""

    def __init__(self) -> None:
        self.n, self.infos, self.seen = 0, [], []

    def reset(self, episode_info: dict) -> None:
        self.n = 0
        self.infos.append(episode_info)

    def act(self, observation: dict) -> int:
        self.seen.append(observation)
        self.n += 1
        return 1 + (self.n - 1) % 3


# -- encoding ---------------------------------------------------------------------------------------
def test_arrays_travel_as_raw_buffers_with_dtype_and_shape():
    arrays = {
        "u8": np.arange(24, dtype=np.uint8).reshape(2, 3, 4),
        "f4": np.linspace(0, 1, 12, dtype=np.float32).reshape(3, 4),
        "i64": np.array([-(2**40), 7]),
        "bool": np.array([True, False]),
        "strided": np.arange(20, dtype=np.float64).reshape(4, 5)[:, ::2],
        "scalar": np.array(3.5),
        "empty": np.zeros((0, 3), np.int32),
        "big_endian": np.arange(3, dtype=">i4"),
    }
    frames = pack({"op": "x", "a": arrays, "n": np.float32(0.5), "ids": frozenset({3, 1}), "text": "sofa"})
    assert len(frames) == 1 + len(arrays)  # one buffer frame per array, nothing of them in the header
    assert len(frames[0]) < 600
    back = unpack([bytes(memoryview(f)) for f in frames])
    for k, a in arrays.items():
        assert back["a"][k].dtype == a.dtype and back["a"][k].shape == a.shape and np.array_equal(back["a"][k], a), k
    assert back["n"] == 0.5 and back["ids"] == [1, 3] and back["text"] == "sofa"


def test_no_pickle_on_the_wire():
    with pytest.raises(ProtocolError, match="dtype object"):
        pack({"op": "x", "a": np.array([{}], dtype=object)})
    with pytest.raises(ProtocolError, match="cannot send a Counter"):
        pack({"op": "x", "a": Counter()})
    header = msgpack.packb({"op": "x", "a": {"$nd": 1, "dtype": "|O", "shape": [1]}})
    with pytest.raises(ProtocolError, match="not one of the plain numeric dtypes"):
        unpack([header, b"\0" * 8])


@pytest.mark.parametrize(
    "frames, match",
    [
        ([b"\xc1garbage"], "not a msgpack map"),
        ([msgpack.packb([1, 2])], "a msgpack map with a string 'op'"),
        ([msgpack.packb({"op": "x", "a": {"$nd": 3, "dtype": "<f4", "shape": [1]}}), b"1234"], "names no buffer"),
        ([msgpack.packb({"op": "x", "a": {"$nd": 1, "dtype": "<f4", "shape": [2, 2]}}), b"1234"], "needs 16 bytes"),
        ([msgpack.packb({"op": "x", "a": {"$nd": 1, "dtype": "<f4", "shape": [-1]}}), b"1234"], "non-negative"),
        ([msgpack.packb({"op": "x", "e": msgpack.ExtType(5, b"z")})], "extension types"),
        ([], "empty message"),
    ],
)
def test_malformed_messages_are_named(frames, match):
    with pytest.raises(ProtocolError, match=match):
        unpack(frames)


# -- the server ---------------------------------------------------------------------------------------
def test_handshake_reset_act_and_what_the_agent_receives():
    agent = Counter()
    agent.observations = ("depth", "goal")
    with serving(Counter, name="counter") as server:
        client = Client("127.0.0.1", server.port, timeout_s=5)
        try:
            assert client.hello["agent"] == "counter" and client.hello["protocol"] == ovon_agent.PROTOCOL
            assert client.hello["privileged"] is False and client.hello["batch"] is False
            assert client.hello["config"] == {}
            o = obs()
            assert client.act([{"stream": 0, "obs": o, "info": {"seed": 5, "goal": "chair"}}]) == [1]
            client.reset([{"stream": 0, "info": {"seed": 6}}])
            assert client.act([{"stream": 0, "obs": o}]) == [1]
            assert client.act([{"stream": 0, "obs": o}, {"stream": 1, "obs": o, "info": {}}]) == [2, 1]
        finally:
            client.close()
        assert server.first is None  # the instance built at start-up went to the first stream
    with serving(agent, config={"agent": "counter", "agent_kwargs": {"step": 1}}) as server:
        client = Client("127.0.0.1", server.port, timeout_s=5)
        assert client.hello["observations"] == ["depth", "goal"]
        assert client.hello["config"] == {"agent": "counter", "agent_kwargs": {"step": 1}}  # what it is, for identities
        o = obs()
        client.act([{"stream": 0, "obs": o, "info": {"seed": 5}}])
        client.close()
    got = agent.seen[0]
    assert agent.infos[0]["seed"] == 5 and agent.infos[0]["stream"] == "1/0"
    for k in ("rgb", "depth", "odometry"):
        assert got[k].dtype == o[k].dtype and np.array_equal(got[k], o[k]) and got[k].flags.writeable


def test_bad_requests_get_an_error_reply_and_the_server_keeps_serving():
    with serving(Counter) as server:
        ctx = zmq.Context()
        raw = ctx.socket(zmq.DEALER)
        raw.setsockopt(zmq.LINGER, 0)
        raw.connect(server.address)

        def ask(*frames) -> str:
            raw.send_multipart(list(frames))
            assert raw.poll(5000), "no answer"
            reply = unpack(raw.recv_multipart())
            assert reply["op"] == "error"
            return reply["error"]

        assert "not a msgpack map" in ask(b"\xff\x00junk")
        assert "no handshake" in ask(*pack({"op": "act", "items": [{"stream": 0, "obs": {}}]}))
        assert "speaks 1" in ask(*pack({"op": "hello", "protocol": 99}))
        raw.send_multipart(pack({"op": "hello", "protocol": 1, "id": 1}))
        assert raw.poll(5000) and unpack(raw.recv_multipart())["op"] == "hello"
        assert "unknown op 'fly'" in ask(*pack({"op": "fly"}))
        assert "'items' must be a list" in ask(*pack({"op": "act", "items": "all"}))
        assert "needs 'obs'" in ask(*pack({"op": "act", "items": [{"stream": 0}]}))
        assert "stream -1" in ask(*pack({"op": "act", "items": [{"stream": -1, "obs": {}}]}))
        assert "needs 16 bytes" in ask(
            msgpack.packb({"op": "act", "a": {"$nd": 1, "dtype": "<f4", "shape": [4]}}), b"12"
        )
        raw.close()
        ctx.term()
        client = Client("127.0.0.1", server.port, timeout_s=5)  # still serving
        assert client.act([{"stream": 0, "obs": obs(), "info": {}}]) == [1]
        client.close()


def test_agent_errors_and_bad_actions_are_answered_not_fatal():
    class Faulty(Counter):
        def act(self, observation: dict) -> int:
            if observation.get("goal") == "boom":
                raise KeyError("rgb")
            return 7 if observation.get("goal") == "seven" else super().act(observation)

    with serving(Faulty) as server:
        client = Client("127.0.0.1", server.port, timeout_s=5)
        with pytest.raises(RemoteError, match=r"agent.act raised KeyError: 'rgb' \(at .*test_remote_protocol.py"):
            client.act([{"stream": 0, "obs": {**obs(), "goal": "boom"}, "info": {}}])
        with pytest.raises(RemoteError, match=r"returned 7; expected an integer action in 0..5"):
            client.act([{"stream": 0, "obs": {**obs(), "goal": "seven"}}])
        assert client.act([{"stream": 0, "obs": obs()}]) == [1]
        client.close()


def test_an_agent_object_without_act_batch_refuses_interleaved_episodes():
    with serving(Counter()) as server:
        a, b = (Client("127.0.0.1", server.port, timeout_s=5) for _ in range(2))
        a.act([{"stream": 0, "obs": obs(), "info": {}}])
        b.act([{"stream": 0, "obs": obs(), "info": {}}])
        with pytest.raises(RemoteError, match="one episode at a time"):
            a.act([{"stream": 0, "obs": obs()}])
        a.close()
        b.close()


def test_act_batch_sees_every_pending_stream_at_once():
    class Batched(Counter):
        def __init__(self) -> None:
            super().__init__()
            self.batches: list[list[str]] = []

        def act_batch(self, observations: list[dict]) -> list[int]:
            self.batches.append([o["stream"] for o in observations])
            return [int(o["odometry"][2] * 10) for o in observations]

    agent = Batched()
    with serving(agent) as server:
        client = Client("127.0.0.1", server.port, timeout_s=5)
        assert client.hello["batch"] is True
        items = [
            {"stream": s, "obs": {**obs(), "odometry": np.array([0, 0, s / 10], np.float32)}, "info": {}}
            for s in range(4)
        ]
        assert client.act(items) == [0, 1, 2, 3]
        client.close()
    assert agent.batches == [["1/0", "1/1", "1/2", "1/3"]]


def test_a_client_that_only_shook_hands_says_goodbye():
    """`check_remote` connects, reads the hello and closes: the server must free that session at once. The
    answer may arrive before the socket monitor's CONNECTED event is read; the goodbye must not depend on
    which came first (it did: one session in three was left for the server's hour-long idle expiry)."""
    with serving(Counter) as server:
        for _ in range(8):
            Client("127.0.0.1", server.port, timeout_s=5).close()
        deadline = time.monotonic() + 10
        while server._sessions and time.monotonic() < deadline:
            time.sleep(0.02)
        assert not server._sessions


def test_token_is_required_when_the_server_has_one():
    with serving(Counter, token="s3cret") as server:
        for bad in (None, "wrong"):
            with pytest.raises(RemoteError, match="wrong or missing token") as e:
                Client("127.0.0.1", server.port, token=bad, timeout_s=5)
            assert e.value.kind == "refused"
        Client("127.0.0.1", server.port, token="s3cret", timeout_s=5).close()


def test_a_hung_agent_times_out_and_nothing_listening_is_named():
    release = threading.Event()

    class Hung(Counter):
        def act(self, observation: dict) -> int:
            release.wait(30)
            return 1

    with serving(Hung) as server:
        client = Client("127.0.0.1", server.port, timeout_s=10)  # a stalled handshake is not what is tested
        client.timeout_s = 0.5
        t = time.monotonic()
        with pytest.raises(RemoteError, match=r"did not answer step 3 within 0.5 s: no answer") as e:
            client.act([{"stream": 0, "obs": obs(), "info": {}}], "step 3")
        assert e.value.kind == "timeout" and time.monotonic() - t < 3
        release.set()
        client.close()
        port = server.port
    with pytest.raises(
        RemoteError,
        match=rf"tcp://127.0.0.1:{port} did not answer the handshake within 0.5 s: "
        r"nothing is listening there \(connection refused\)",
    ):
        Client("127.0.0.1", port, timeout_s=0.5)


SERVE_SCRIPT = """
import sys, ovon_agent
class Slow:
    def reset(self, info): pass
    def act(self, obs):
        if obs["goal"] == "die":
            import os; os._exit(1)
        return 1
s = ovon_agent.Server(Slow, "127.0.0.1", 0, log=lambda l: None)
print(s.port, flush=True)
s.serve_forever()
"""


def test_a_server_that_dies_fails_the_call_at_once():
    proc = subprocess.Popen([sys.executable, "-c", SERVE_SCRIPT], stdout=subprocess.PIPE, text=True)
    try:
        port = int(proc.stdout.readline())
        client = Client("127.0.0.1", port, timeout_s=30)
        assert client.act([{"stream": 0, "obs": obs(), "info": {}}]) == [1]
        t = time.monotonic()
        with pytest.raises(
            RemoteError, match=r"closed the connection \(the server stopped or crashed\) during step 9"
        ) as e:
            client.act([{"stream": 0, "obs": {**obs(), "goal": "die"}}], "step 9")
        assert e.value.kind == "disconnected" and time.monotonic() - t < 10  # not the 30 s timeout
        client.close()
    finally:
        proc.kill()
        proc.wait()


def test_remote_errors_survive_pickling():
    import pickle

    e = pickle.loads(pickle.dumps(RemoteError("gone", "disconnected")))
    assert str(e) == "gone" and e.kind == "disconnected"


# -- the module stands alone --------------------------------------------------------------------------
def test_the_agent_side_is_one_python_3_8_module_on_numpy_pyzmq_msgpack():
    source = MODULE.read_text()
    tree = ast.parse(source, feature_version=(3, 8))
    imported = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            imported |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            imported.add(node.module.split(".")[0])
    third_party = imported - set(sys.stdlib_module_names) - {"__future__"}
    assert third_party == {"numpy", "zmq", "msgpack"}
    pyproject = (MODULE.parents[1] / "pyproject.toml").read_text()
    assert 'requires-python = ">=3.8"' in pyproject and '"pyzmq' in pyproject and '"msgpack' in pyproject
    assert sorted(p.name for p in MODULE.parent.iterdir() if p.suffix == ".py") == ["__init__.py"]
