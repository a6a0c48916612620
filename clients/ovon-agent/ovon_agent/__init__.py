"""ovon_agent: serve a navigation agent to `ovon evaluate --agent remote:HOST:PORT` from any Python >= 3.8.

    import ovon_agent

    class MyAgent:
        def reset(self, episode_info): ...          # episode_id, scene_id, split, goal, seed, camera, embodiment
        def act(self, observation): return 1        # rgb (H,W,3) uint8, depth (H,W) float32, odometry, goal, collided

    ovon_agent.serve(MyAgent, port=5555)            # a class (or factory): one instance per episode stream

Why a separate module: a vision-language agent lives in its own environment (its CUDA stack, its pinned
libraries) and cannot import the simulator; this file needs only numpy, pyzmq and msgpack, so it can be
vendored (copy this folder) or installed alone (`pip install clients/ovon-agent`).

Wire (protocol 1, ZeroMQ DEALER -> ROUTER over TCP): every message is a multipart message whose first
frame is a msgpack map and whose other frames are raw array buffers; an array inside the map is
`{"$nd": frame_index, "dtype": "<f4", "shape": [120, 160]}`. No pickle, no pixels in JSON. Requests:
`hello` (protocol, token, allow_privileged) -> the agent's name, wanted observations, whether it needs the
privileged channel, whether it batches and its config (what it is, for run folder identities); `reset` /
`act` with a list of items (`stream`, `info` and / or `obs`) -> one action per item; `close`. A bad
request gets `{"op": "error", "error": "..."}`; the server never stops on one. The full description is
docs/remote_protocol.md in the ovon repository.

Streams: the client runs several episodes at once (evaluation workers, several environments per worker);
each has a stream number. `serve(SomeClass)` or `serve(factory)` builds one agent per stream; an agent
*object* with `act_batch(observations) -> actions` serves every stream itself (a GPU model sees batches)
and finds the stream in `episode_info["stream"]` / `observation["stream"]`; an object without `act_batch`
serves one episode at a time.
"""

from __future__ import annotations

import hmac
import inspect
import itertools
import math
import sys
import threading
import time
import traceback
from typing import Any, Callable, Sequence

import msgpack
import numpy as np
import zmq

__version__ = "0.1.0"
PROTOCOL = 1
OBSERVATIONS = ("rgb", "depth", "odometry", "goal", "collided")
N_ACTIONS = 6  # 0 STOP, 1 MOVE_FORWARD, 2 TURN_LEFT, 3 TURN_RIGHT, 4 LOOK_UP, 5 LOOK_DOWN
# plain numeric dtypes only: an object dtype would be pickle in disguise
DTYPES = frozenset(
    o + k for o in "<>|" for k in ("b1", "i1", "i2", "i4", "i8", "u1", "u2", "u4", "u8", "f2", "f4", "f8")
)
MAX_ITEMS = 4096  # items in one request
MAX_FRAME_BYTES = 1 << 28  # one array (a 4096 x 4096 RGB frame is 48 MiB)
SESSION_IDLE_S = 3600.0  # a client silent for this long is forgotten (its agents freed)


class ProtocolError(ValueError):
    """A message that does not follow the protocol; the text says what is wrong."""


class RemoteError(RuntimeError):
    """A call to a remote agent failed. `kind`: "timeout", "disconnected", "refused" (handshake or token),
    "agent" (the server answered with an error), "protocol" (the answer does not follow the protocol: not
    an ovon_agent server, or another version), "address" (the address cannot be connected to)."""

    def __init__(self, message: str, kind: str = "agent") -> None:
        super().__init__(message)
        self.kind = kind

    def __reduce__(self):  # picklable with its kind (errors cross evaluation worker processes)
        return (RemoteError, (self.args[0], self.kind))


# ------------------------------------------------------------------------------------------------
# encoding: a msgpack header + raw buffers


def pack(header: dict[str, Any]) -> list[Any]:
    """`header` -> [msgpack bytes, buffer, ...]; every numpy array becomes a reference to a buffer frame."""
    frames: list[Any] = [b""]

    def default(obj: Any) -> Any:
        if isinstance(obj, np.ndarray):
            a = obj if obj.flags.c_contiguous else obj.copy(order="C")
            if a.dtype.str not in DTYPES:
                raise ProtocolError(f"cannot send an array of dtype {a.dtype} (plain numbers and booleans only)")
            frames.append(a if a.ndim and a.size else a.tobytes())
            return {"$nd": len(frames) - 1, "dtype": a.dtype.str, "shape": list(a.shape)}
        if isinstance(obj, np.generic):
            return obj.item()
        if isinstance(obj, (set, frozenset)):
            return sorted(obj)
        raise ProtocolError(f"cannot send a {type(obj).__name__}")

    frames[0] = msgpack.packb(header, default=default, use_bin_type=True)
    return frames


def _array(ref: dict[str, Any], frames: Sequence[Any]) -> np.ndarray:
    i, dtype, shape = ref.get("$nd"), ref.get("dtype"), ref.get("shape")
    if not isinstance(i, int) or isinstance(i, bool) or not 1 <= i < len(frames):
        raise ProtocolError(f"array reference {i!r} names no buffer frame (the message has {len(frames) - 1})")
    if dtype not in DTYPES:
        raise ProtocolError(f"array dtype {dtype!r} is not one of the plain numeric dtypes")
    if not isinstance(shape, list) or not all(isinstance(s, int) and not isinstance(s, bool) and s >= 0 for s in shape):
        raise ProtocolError(f"array shape {shape!r} is not a list of non-negative integers")
    buf = memoryview(frames[i])
    dt = np.dtype(dtype)
    if math.prod(shape) * dt.itemsize != buf.nbytes:
        raise ProtocolError(
            f"array of shape {shape} and dtype {dtype} needs {math.prod(shape) * dt.itemsize} bytes, its frame has "
            f"{buf.nbytes}"
        )
    return np.frombuffer(buf, dtype=dt).reshape(shape)


def unpack(frames: Sequence[Any]) -> dict[str, Any]:
    """The inverse of `pack`: arrays are views of the received buffers (writable, no copy)."""
    if not frames:
        raise ProtocolError("empty message")

    def hook(m: dict[Any, Any]) -> Any:
        return _array(m, frames) if "$nd" in m else m

    def ext(code: int, data: bytes) -> Any:
        raise ProtocolError(f"msgpack extension types are not part of the protocol (got type {code})")

    try:
        header = msgpack.unpackb(memoryview(frames[0]), object_hook=hook, ext_hook=ext, raw=False)
    except ProtocolError:
        raise
    except Exception as e:  # noqa: BLE001 - msgpack raises several types for garbage
        raise ProtocolError(f"the first frame is not a msgpack map ({type(e).__name__}: {e})") from None
    if not isinstance(header, dict) or not isinstance(header.get("op"), str):
        raise ProtocolError("the first frame must be a msgpack map with a string 'op'")
    return header


# ------------------------------------------------------------------------------------------------
# server


def _short(e: BaseException) -> str:
    where = ""
    tb = traceback.extract_tb(e.__traceback__)
    if tb:
        where = f" (at {tb[-1].filename}:{tb[-1].lineno})"
    text = " ".join(str(e).split())[:300]
    return f"{type(e).__name__}: {text}{where}"


def _is_agent(obj: Any) -> bool:
    return callable(getattr(obj, "reset", None)) and callable(getattr(obj, "act", None))


class _Session:
    def __init__(self, number: int) -> None:
        self.number = number
        self.agents: dict[int, Any] = {}  # stream -> agent (factory mode)
        self.last_seen = time.monotonic()


class Server:
    """A ROUTER socket serving one agent (or one agent per stream) until `stop()`.

    `agent`: a class or a zero-argument factory (one instance per stream), or an agent object (every
    stream goes to it: it needs `act_batch` to keep several episodes apart). `observations`: what the agent
    wants sent (default: `agent.observations`, else everything; leaving out "rgb" saves the client its
    colour rendering). `token`: a shared secret the client must present (not encryption: keep the server
    on loopback or behind an SSH tunnel on untrusted networks). `config`: what the agent is beside its name
    (its settings, a checkpoint's hash; plain values): with the name, it identifies the evaluation run
    folders the agent writes, so the same agent served at another address continues them and another one
    is refused."""

    def __init__(
        self,
        agent: Any,
        host: str = "127.0.0.1",
        port: int = 0,
        *,
        token: str | None = None,
        name: str | None = None,
        observations: Sequence[str] | None = None,
        config: dict[str, Any] | None = None,
        log: Callable[[str], None] | None = None,
    ) -> None:
        if inspect.isclass(agent) or (callable(agent) and not _is_agent(agent)):
            self.factory: Callable[[], Any] | None = agent
            self.first = agent()  # built now: a bad agent fails before anything is served
            if not _is_agent(self.first):
                raise TypeError(
                    f"{agent!r} built a {type(self.first).__name__}, which has no reset(episode_info) / "
                    "act(observation)"
                )
        elif _is_agent(agent):
            self.factory, self.first = None, agent
        else:
            raise TypeError(
                "serve() needs an agent (reset(episode_info) / act(observation)), its class or a "
                f"factory; got a {type(agent).__name__}"
            )
        self.batched = self.factory is None and callable(getattr(self.first, "act_batch", None))
        self.name = str(name or getattr(self.first, "name", None) or type(self.first).__name__)
        wanted = observations if observations is not None else getattr(self.first, "observations", OBSERVATIONS)
        self.observations = [str(o) for o in wanted]
        unknown = [o for o in self.observations if o not in OBSERVATIONS]
        if unknown:
            raise ValueError(f"observations {unknown} are not provided by ovon (it sends {list(OBSERVATIONS)})")
        self.privileged = bool(getattr(self.first, "privileged", False))
        if config is not None and not isinstance(config, dict):
            raise TypeError(f"config must be a dict of plain values (what the agent is), got a {type(config).__name__}")
        self.config = dict(config or {})
        msgpack.packb(self.config)  # a value msgpack cannot send fails here, not in every handshake
        self.token = token or None
        self.log = log or (lambda line: print(line, file=sys.stderr, flush=True))
        self._context = zmq.Context()
        self._socket = self._context.socket(zmq.ROUTER)
        self._socket.setsockopt(zmq.LINGER, 0)
        self._socket.setsockopt(zmq.ROUTER_MANDATORY, 1)  # a reply to a vanished client raises (ignored)
        self._socket.setsockopt(zmq.MAXMSGSIZE, MAX_FRAME_BYTES)  # a peer sending more is disconnected
        self.host = host
        bracket = f"[{host}]" if ":" in host else host
        if ":" in host:
            self._socket.setsockopt(zmq.IPV6, 1)
        try:
            if int(port) == 0:
                self.port = self._socket.bind_to_random_port(f"tcp://{bracket}")
            else:
                self._socket.bind(f"tcp://{bracket}:{int(port)}")
                self.port = int(port)
        except zmq.ZMQError as e:
            self.close()
            raise OSError(f"cannot listen on {host}:{port} ({e})") from None
        self.address = f"tcp://{bracket}:{self.port}"
        self._sessions: dict[bytes, _Session] = {}
        self._numbers = itertools.count(1)
        self._active: tuple[int, int] | None = None  # plain agent object: the stream it is serving
        self._stop = threading.Event()

    # -- life cycle -------------------------------------------------------------------------------
    def serve_forever(self, poll_ms: int = 100) -> None:
        """Answer requests until `stop()` (from another thread) or KeyboardInterrupt."""
        poller = zmq.Poller()
        poller.register(self._socket, zmq.POLLIN)
        try:
            while not self._stop.is_set():
                if not poller.poll(poll_ms):
                    self._expire()
                    continue
                batch = []
                while len(batch) < 256:
                    try:
                        batch.append(self._socket.recv_multipart(zmq.NOBLOCK, copy=False))
                    except zmq.Again:
                        break
                self._handle(batch)
        finally:
            self.close()

    def stop(self) -> None:
        self._stop.set()

    def close(self) -> None:
        if not self._context.closed:
            self._socket.close(0)
            self._context.term()

    # -- requests ---------------------------------------------------------------------------------
    def _send(self, ident: bytes, header: dict[str, Any]) -> None:
        try:
            self._socket.send_multipart([ident] + pack(header), copy=False)
        except zmq.ZMQError:
            pass  # the client is gone

    def _error(self, ident: bytes, rid: Any, text: str) -> None:
        self._send(ident, {"op": "error", "id": rid, "error": text})

    def _handle(self, messages: list[list[Any]]) -> None:
        pending = []
        for frames in messages:
            if len(frames) < 2:
                continue  # no routing identity: nothing to answer to
            ident, rid = frames[0].bytes, None
            try:
                header = unpack(frames[1:])
                rid = header.get("id")
                op = header["op"]
                if op == "hello":
                    self._send(ident, self._hello(ident, header))
                    continue
                session = self._sessions.get(ident)
                if session is None:
                    raise ProtocolError("no handshake on this connection (the server restarted?): send 'hello' first")
                session.last_seen = time.monotonic()
                if op == "close":
                    self._drop(ident)
                    self._send(ident, {"op": "close", "id": rid})
                elif op in ("reset", "act"):
                    pending.append((ident, rid, op, session, self._items(header, op)))
                else:
                    raise ProtocolError(f"unknown op {op!r} (expected hello, reset, act or close)")
            except ProtocolError as e:
                self._error(ident, rid, f"bad request: {e}")
            except Exception as e:  # noqa: BLE001 - never let one request stop the server
                self._error(ident, rid, f"server error: {_short(e)}")
        if pending:
            self._run(pending)

    def _hello(self, ident: bytes, header: dict[str, Any]) -> dict[str, Any]:
        version = header.get("protocol")
        if version != PROTOCOL:
            raise ProtocolError(
                f"the client speaks protocol {version!r}, this server (ovon_agent {__version__}) speaks {PROTOCOL}"
            )
        if self.token is not None:
            given = header.get("token")
            if not isinstance(given, str) or not hmac.compare_digest(given.encode(), self.token.encode()):
                raise ProtocolError("wrong or missing token")
        self._drop(ident)
        session = self._sessions[ident] = _Session(next(self._numbers))
        self.log(f"ovon_agent: client {session.number} connected ({header.get('client', '?')})")
        return {
            "op": "hello",
            "id": header.get("id"),
            "protocol": PROTOCOL,
            "agent": self.name,
            "observations": self.observations,
            "privileged": self.privileged,
            "batch": self.batched,
            "config": self.config,
            "server": f"ovon_agent {__version__}",
        }

    def _drop(self, ident: bytes) -> None:
        session = self._sessions.pop(ident, None)
        if session is not None and self._active is not None and self._active[0] == session.number:
            self._active = None

    def _expire(self) -> None:
        now = time.monotonic()
        for ident in [i for i, s in self._sessions.items() if now - s.last_seen > SESSION_IDLE_S]:
            self._drop(ident)

    @staticmethod
    def _items(header: dict[str, Any], op: str) -> list[dict[str, Any]]:
        items = header.get("items")
        if not isinstance(items, list) or not 1 <= len(items) <= MAX_ITEMS:
            raise ProtocolError(f"'items' must be a list of 1..{MAX_ITEMS} items")
        for it in items:
            if not isinstance(it, dict):
                raise ProtocolError("every item must be a map")
            s = it.get("stream")
            if not isinstance(s, int) or isinstance(s, bool) or s < 0:
                raise ProtocolError(f"item stream {s!r} is not a non-negative integer")
            if "info" in it and not isinstance(it["info"], dict):
                raise ProtocolError("item info must be a map")
            if op == "act" and not isinstance(it.get("obs"), dict):
                raise ProtocolError("an act item needs 'obs', a map of observations")
            if op == "reset" and "info" not in it:
                raise ProtocolError("a reset item needs 'info', a map")
        return items

    def _agent(self, session: _Session, stream: int) -> Any:
        if self.factory is None:
            return self.first
        agent = session.agents.get(stream)
        if agent is None:
            agent = self.first if self.first is not None else self.factory()
            self.first = None  # the instance built at start-up serves the first stream
            session.agents[stream] = agent
        return agent

    def _key(self, session: _Session, stream: int) -> str:
        return f"{session.number}/{stream}"

    def _run(self, pending: list[tuple[bytes, Any, str, _Session, list[dict[str, Any]]]]) -> None:
        """Resets, then the acts of every request in one `act_batch` call when the agent batches."""
        acts = []  # (request index, agent, observation)
        failed: dict[int, str] = {}
        for r, (_ident, _rid, op, session, items) in enumerate(pending):
            try:
                for it in items:
                    stream = int(it["stream"])
                    agent = self._agent(session, stream)
                    plain = self.factory is None and not self.batched
                    if "info" in it:
                        info = dict(it["info"])
                        if self.factory is None:
                            info["stream"] = self._key(session, stream)
                        try:
                            agent.reset(info)
                        except Exception as e:  # noqa: BLE001 - the agent's own code
                            raise RuntimeError(f"agent.reset raised {_short(e)}") from None
                        if plain:
                            self._active = (session.number, stream)
                    if op == "act":
                        if plain and self._active != (session.number, stream):
                            raise RuntimeError(
                                "this agent object holds one episode at a time (it has no act_batch) and "
                                "episodes of several streams interleave; serve its class (one instance per "
                                "stream) or run evaluate with --workers 1 and remote.batch=1"
                            )
                        obs = dict(it["obs"])
                        if self.factory is None:
                            obs["stream"] = self._key(session, stream)
                        acts.append((r, agent, obs))
            except Exception as e:  # noqa: BLE001
                failed[r] = str(e) if isinstance(e, RuntimeError) else f"server error: {_short(e)}"
        acts = [a for a in acts if a[0] not in failed]
        actions: dict[int, list[int]] = {r: [] for r in range(len(pending))}
        if self.batched and acts:
            try:
                out = list(self.first.act_batch([o for _, _, o in acts]))
                if len(out) != len(acts):
                    raise RuntimeError(f"agent.act_batch returned {len(out)} actions for {len(acts)} observations")
                for (r, _, _), a in zip(acts, out):
                    actions[r].append(self._action(a, "act_batch"))
            except Exception as e:  # noqa: BLE001
                msg = str(e) if isinstance(e, RuntimeError) else f"agent.act_batch raised {_short(e)}"
                for r, _, _ in acts:
                    failed[r] = msg
        else:
            for r, agent, obs in acts:
                if r in failed:
                    continue
                try:
                    actions[r].append(self._action(agent.act(obs), "act"))
                except Exception as e:  # noqa: BLE001
                    failed[r] = str(e) if isinstance(e, RuntimeError) else f"agent.act raised {_short(e)}"
        for r, (ident, rid, op, _session, _items) in enumerate(pending):
            if r in failed:
                self.log(f"ovon_agent: error answered: {failed[r]}")
                self._error(ident, rid, failed[r])
            elif op == "act":
                self._send(ident, {"op": "act", "id": rid, "actions": actions[r]})
            else:
                self._send(ident, {"op": "reset", "id": rid, "n": len(_items)})

    @staticmethod
    def _action(a: Any, where: str) -> int:
        try:
            v = int(a)
            ok = v == a and 0 <= v < N_ACTIONS
        except (TypeError, ValueError):
            ok = False
        if not ok:
            raise RuntimeError(
                f"agent.{where} returned {a!r}; expected an integer action in 0..{N_ACTIONS - 1} (0 STOP, "
                "1 MOVE_FORWARD, 2 TURN_LEFT, 3 TURN_RIGHT, 4 LOOK_UP, 5 LOOK_DOWN)"
            )
        return v


def serve(
    agent: Any,
    host: str = "127.0.0.1",
    port: int = 5555,
    *,
    token: str | None = None,
    name: str | None = None,
    observations: Sequence[str] | None = None,
    config: dict[str, Any] | None = None,
) -> None:
    """Serve `agent` (an object, its class or a factory; see `Server`) until Ctrl-C."""
    server = Server(agent, host, port, token=token, name=name, observations=observations, config=config)
    server.log(f"ovon_agent: serving {server.name!r} (protocol {PROTOCOL}) on {server.address}; stop with Ctrl-C")
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        server.log("ovon_agent: stopped")


# ------------------------------------------------------------------------------------------------
# client


class Client:
    """One connection to a served agent (evaluation workers each open their own).

    Every call waits at most `timeout_s`; a server that closes the connection fails the pending call at
    once. Errors are `RemoteError`s whose text names the address."""

    def __init__(
        self,
        host: str,
        port: int,
        *,
        token: str | None = None,
        timeout_s: float = 60.0,
        client: str = f"ovon_agent {__version__}",
    ) -> None:
        self.address = f"tcp://{f'[{host}]' if ':' in host else host}:{int(port)}"
        self.timeout_s = float(timeout_s)
        self._ids = itertools.count(1)
        self._context = zmq.Context()
        self._socket = self._context.socket(zmq.DEALER)
        self._socket.setsockopt(zmq.LINGER, 0)
        if ":" in host:
            self._socket.setsockopt(zmq.IPV6, 1)
        self._monitor = self._socket.get_monitor_socket(
            zmq.EVENT_CONNECTED | zmq.EVENT_DISCONNECTED | zmq.EVENT_CONNECT_RETRIED
        )
        self._connected = False
        self._refused = False
        self._lost = False
        try:
            self._socket.connect(self.address)
        except zmq.ZMQError as e:  # a host ZeroMQ cannot read ("local host", "http://...", "*")
            self.close()
            raise RemoteError(
                f"cannot connect to {self.address} ({e}): expected HOST a host name, an IPv4 address or an IPv6 "
                "address (without brackets here) and PORT in 1..65535",
                "address",
            ) from None
        try:
            self.hello = self._call(
                {"op": "hello", "protocol": PROTOCOL, "token": token, "client": client}, "the handshake"
            )
            if self.hello.get("protocol") != PROTOCOL:
                raise RemoteError(
                    f"the agent at {self.address} speaks protocol {self.hello.get('protocol')!r}, this client "
                    f"{PROTOCOL}",
                    "refused",
                )
        except BaseException:
            self.close()
            raise

    def _events(self) -> None:
        from zmq.utils.monitor import recv_monitor_message

        while True:
            try:
                event = recv_monitor_message(self._monitor, zmq.NOBLOCK)["event"]
            except zmq.Again:
                return
            if event == zmq.EVENT_CONNECTED:
                self._connected = True
            elif event == zmq.EVENT_DISCONNECTED and self._connected:
                self._lost = True
            elif event == zmq.EVENT_CONNECT_RETRIED and not self._connected:
                self._refused = True

    def _call(self, header: dict[str, Any], what: str) -> dict[str, Any]:
        if self._context.closed:
            raise RemoteError(f"the connection to {self.address} is closed", "disconnected")
        rid = next(self._ids)
        self._socket.send_multipart(pack(dict(header, id=rid)), copy=False)
        deadline = time.monotonic() + self.timeout_s
        poller = zmq.Poller()
        poller.register(self._socket, zmq.POLLIN)
        poller.register(self._monitor, zmq.POLLIN)
        while True:
            self._events()
            if self._lost:
                raise RemoteError(
                    f"the agent at {self.address} closed the connection (the server stopped or crashed) during {what}",
                    "disconnected",
                )
            left = deadline - time.monotonic()
            if left <= 0:
                why = (
                    "nothing is listening there (connection refused)"
                    if self._refused and not self._connected
                    else "no answer"
                )
                raise RemoteError(
                    f"the agent at {self.address} did not answer {what} within {self.timeout_s:g} s: {why}", "timeout"
                )
            ready = dict(poller.poll(max(1, int(min(left, 0.5) * 1000))))
            if self._socket in ready:
                try:
                    reply = unpack(self._socket.recv_multipart(copy=False))
                except ProtocolError as e:  # garbage, extension types, not a map: not an ovon_agent server
                    raise RemoteError(
                        f"the agent at {self.address} answered {what} with a message that does not follow the "
                        f"ovon_agent protocol ({e})",
                        "protocol",
                    ) from None
                # an answer proves the connection even when the monitor's CONNECTED event is still queued
                # (close() says goodbye only on a connection it knows of)
                self._connected = True
                if reply.get("id") != rid:
                    continue  # a late answer to a call that timed out
                if reply["op"] == "error":
                    kind = "refused" if header["op"] == "hello" else "agent"
                    raise RemoteError(
                        f"the agent at {self.address} answered {what} with an error: {reply.get('error')}",
                        kind,
                    )
                return reply

    def reset(self, items: list[dict[str, Any]], what: str = "reset") -> None:
        """`items`: [{"stream": s, "info": {...}}]."""
        self._call({"op": "reset", "items": items}, what)

    def act(self, items: list[dict[str, Any]], what: str = "act") -> list[int]:
        """`items`: [{"stream": s, "obs": {...}, "info": {...} (optional: reset first)}] -> one action each."""
        reply = self._call({"op": "act", "items": items}, what)
        actions = reply.get("actions")
        if (
            not isinstance(actions, list)
            or len(actions) != len(items)
            or not all(isinstance(a, int) and not isinstance(a, bool) and 0 <= a < N_ACTIONS for a in actions)
        ):
            raise RemoteError(
                f"the agent at {self.address} answered {what} with {actions!r}, not {len(items)} actions in "
                f"0..{N_ACTIONS - 1}"
            )
        return actions

    def close(self) -> None:
        """Tell the server to free this connection's agents (best effort), then close."""
        if self._context.closed:
            return
        self._events()  # a disconnection the monitor saw since the last call: no goodbye to send
        if self._connected and not self._lost:
            try:
                self._socket.send_multipart(pack({"op": "close", "id": 0}), zmq.NOBLOCK)
            except zmq.ZMQError:
                pass
        self._socket.disable_monitor()
        self._monitor.close(0)
        # lets the close message leave (a loaded machine needed more than 200 ms); waits only while it is
        # still queued, i.e. at most this long when the server is gone
        self._socket.close(linger=2000)
        self._context.term()


__all__ = ["Client", "OBSERVATIONS", "PROTOCOL", "ProtocolError", "RemoteError", "Server", "pack", "serve", "unpack"]
