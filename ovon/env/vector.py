"""The one vector env: several (wrapped) envs per worker process, observations through shared memory.

Why not `gymnasium.vector.AsyncVectorEnv`: it runs one env per process and exchanges one message per env
per step; on a 2-core machine the per-step messaging, not the simulator, then sets the pace (about 400
steps/s against about 870 in one process at 160x120). Here each worker hosts `num_envs / workers` envs,
steps them all on one message, writes every array observation into shared memory (no frames are
pickled) and sends back only rewards, flags, the few non-empty infos and changed goal texts.

Contract (Gymnasium's `VectorEnv`, autoreset mode SAME_STEP): when env i ends an episode in a step, the
step returns its reward and flags, the observation is already the first of the next episode, and
`infos["final_info"]` holds the ended step's info (e.g. `metrics`, `episode`); `final_obs` is not
provided (no consumer here needs it, and it would mean pickling frames). `info["privileged"]` (ground
truth) never leaves its worker. Text observations (the goal) come back as a tuple of str.
Extra methods: `call(name, *args)` calls a method of every env (e.g. `get_state`), `call_each(name,
args)` with one argument per env; `set_state(states)` restores envs and returns their observations.
`workers=0` hosts all envs in this process through the same code path (tests, debugging).
Workers run single-threaded (`ovon.parallel.init_worker`) and die with their parent.
"""

from __future__ import annotations

import multiprocessing as mp
import signal
import traceback
from collections.abc import Callable, Sequence
from multiprocessing import shared_memory
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

EnvFn = Callable[[], gym.Env]
PRIVATE_INFO = ("privileged",)  # info keys that never cross a process boundary


class WorkerError(RuntimeError):
    """An env raised in a worker; the message is the env's one-line error, `details` the traceback."""

    def __init__(self, message: str, details: str = "") -> None:
        super().__init__(message)
        self.details = details


def _array_keys(space: spaces.Dict) -> dict[str, tuple[tuple[int, ...], np.dtype]]:
    """Observation keys that travel through shared memory (Box and Discrete), with shape and dtype."""
    out = {}
    for k, s in space.spaces.items():
        if isinstance(s, spaces.Box):
            out[k] = (tuple(s.shape), np.dtype(s.dtype))
        elif isinstance(s, spaces.Discrete):
            out[k] = ((), np.dtype(np.int64))
        elif not isinstance(s, spaces.Text):
            raise TypeError(f"observation {k!r}: {type(s).__name__} spaces are not supported by ovon's vector env")
    return out


def _clean_info(info: dict) -> dict:
    out = {k: v for k, v in info.items() if k not in PRIVATE_INFO}
    if isinstance(out.get("final_info"), dict):
        out["final_info"] = _clean_info(out["final_info"])
    return out


class _Host:
    """Hosts a block of envs: steps them with same-step autoreset and writes array observations into
    the given buffers (shared memory in a worker, plain arrays in process)."""

    def __init__(self, fns: Sequence[EnvFn], first: int, buffers: dict[str, np.ndarray]) -> None:
        self.envs = [fn() for fn in fns]
        self.first = first
        self.buffers = buffers
        self.texts: list[str | None] = [None] * len(self.envs)

    def _write(self, j: int, obs: dict, changed: dict[int, dict[str, str]]) -> None:
        row = self.first + j
        for k, buf in self.buffers.items():
            buf[row] = obs[k]
        for k, v in obs.items():
            if isinstance(v, str):
                if self.texts[j] != v:
                    self.texts[j] = v
                    changed.setdefault(row, {})[k] = v

    def reset(self, seeds: Sequence[int | None], options: dict | None) -> tuple[list, dict]:
        infos, changed = [], {}
        self.texts = [None] * len(self.envs)
        for j, (env, seed) in enumerate(zip(self.envs, seeds)):
            obs, info = env.reset(seed=seed, options=options)
            self._write(j, obs, changed)
            infos.append(_clean_info(info) or None)
        return infos, changed

    def step(self, actions: Sequence[Any]) -> tuple:
        n = len(self.envs)
        rewards = np.zeros(n, np.float64)
        terms = np.zeros(n, np.bool_)
        truncs = np.zeros(n, np.bool_)
        infos: list[dict | None] = [None] * n
        changed: dict[int, dict[str, str]] = {}
        for j, (env, a) in enumerate(zip(self.envs, actions)):
            obs, r, term, trunc, info = env.step(a)
            rewards[j], terms[j], truncs[j] = r, term, trunc
            if term or trunc:
                final = _clean_info(info)
                obs, info = env.reset()
                info = {**info, "final_info": final}
            info = _clean_info(info)
            infos[j] = info or None
            self._write(j, obs, changed)
        return rewards, terms, truncs, infos, changed

    def call(self, name: str, args: Sequence[tuple]) -> list:
        return [getattr(env, name)(*a) for env, a in zip(self.envs, args)]

    def call_obs(self, name: str, args: Sequence[tuple]) -> tuple[list, dict]:
        """Call a method returning (obs, info) on every env and publish the observations."""
        infos, changed = [], {}
        self.texts = [None] * len(self.envs)
        for j, (env, a) in enumerate(zip(self.envs, args)):
            obs, info = getattr(env, name)(*a)
            self._write(j, obs, changed)
            infos.append(_clean_info(info) or None)
        return infos, changed

    def close(self) -> None:
        for env in self.envs:
            env.close()


def _worker(conn, fns: Sequence[EnvFn], first: int) -> None:
    from ovon.parallel import init_worker

    init_worker()
    # Ctrl-C and a process group's SIGTERM reach the workers too: the parent decides when they stop (a
    # training run finishes its update and checkpoints first), and they die with it (`init_worker`)
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)
    segments, host = [], None
    try:
        host = _Host(fns, first, {})
        env0 = host.envs[0]
        conn.send(("ok", (env0.observation_space, env0.action_space)))
        while True:
            cmd, arg = conn.recv()
            if cmd == "close":
                conn.send(("ok", None))
                break
            try:
                if cmd == "step":
                    result = host.step(arg)
                elif cmd == "reset":
                    result = host.reset(*arg)
                elif cmd == "call":
                    result = host.call(*arg)
                elif cmd == "call_obs":
                    result = host.call_obs(*arg)
                elif cmd == "attach":  # the parent's shared-memory observation buffers
                    for k, (name, shape, dtype) in arg.items():
                        seg = shared_memory.SharedMemory(name=name)  # the parent unlinks it
                        segments.append(seg)
                        host.buffers[k] = np.ndarray(shape, dtype=dtype, buffer=seg.buf)
                    result = None
                else:
                    raise ValueError(f"unknown vector env command {cmd!r}")
            except Exception as e:  # report the env's error to the parent, keep serving
                conn.send(("error", (str(e).splitlines()[0] if str(e) else type(e).__name__,
                                     traceback.format_exc())))
                continue
            conn.send(("ok", result))
    except (KeyboardInterrupt, EOFError, BrokenPipeError):
        pass
    except Exception as e:
        try:
            conn.send(("error", (f"env worker failed to start: {e}", traceback.format_exc())))
        except (BrokenPipeError, EOFError, OSError):
            pass
    finally:
        if host is not None:
            host.close()
        for seg in segments:
            seg.close()
        conn.close()


class ObjectNavVectorEnv(VectorEnv):
    """`len(env_fns)` envs on `workers` processes (0 = in this process). `env_fns` must be picklable
    (module-level functions or `functools.partial` of them) under the "spawn" context."""

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP}

    def __init__(self, env_fns: Sequence[EnvFn], workers: int = 0, context: str = "spawn", copy: bool = True):
        if not env_fns:
            raise ValueError("a vector env needs at least one env")
        self.num_envs = len(env_fns)
        self.copy = copy
        workers = max(0, min(int(workers), self.num_envs))
        self._segments: list[shared_memory.SharedMemory] = []
        self._conns: list[Any] = []
        self._procs: list[Any] = []
        self._blocks: list[range] = []
        self._local: _Host | None = None
        self._buffers: dict[str, np.ndarray] = {}
        try:
            if workers == 0:
                self._local = _Host(env_fns, 0, self._buffers)
                spaces_ = (self._local.envs[0].observation_space, self._local.envs[0].action_space)
            else:
                spaces_ = self._start_workers(env_fns, workers, context)
            single_obs, single_act = spaces_
            self.single_observation_space = single_obs
            self.single_action_space = single_act
            self.observation_space = batch_space(single_obs, self.num_envs)
            self.action_space = batch_space(single_act, self.num_envs)
            self._arrays = _array_keys(single_obs)
            self._texts = {k: [""] * self.num_envs for k, sp in single_obs.spaces.items()
                           if isinstance(sp, spaces.Text)}
            specs = {}
            for k, (shape, dtype) in self._arrays.items():
                full = (self.num_envs, *shape)
                if self._local is not None:
                    self._buffers[k] = np.zeros(full, dtype)
                    continue
                seg = shared_memory.SharedMemory(create=True, size=max(1, int(np.prod(full)) * dtype.itemsize))
                self._segments.append(seg)
                self._buffers[k] = np.ndarray(full, dtype=dtype, buffer=seg.buf)
                specs[k] = (seg.name, full, dtype)
            for c in self._conns:
                c.send(("attach", specs))
            for c in self._conns:
                self._recv(c)
        except BaseException:
            self.close()
            raise

    def _start_workers(self, env_fns: Sequence[EnvFn], workers: int, context: str) -> tuple:
        """Start the worker processes (contiguous blocks of envs); returns worker 0's spaces."""
        ctx = mp.get_context(context)
        per = -(-self.num_envs // workers)
        for w in range(workers):
            block = range(w * per, min(self.num_envs, (w + 1) * per))
            if not block:
                break
            parent, child = ctx.Pipe()
            p = ctx.Process(target=_worker, args=(child, [env_fns[i] for i in block], block.start), daemon=True)
            p.start()
            child.close()
            self._conns.append(parent)
            self._procs.append(p)
            self._blocks.append(block)
        return [self._recv(c) for c in self._conns][0]

    # -- transport ----------------------------------------------------------------------------------
    @staticmethod
    def _recv(conn) -> Any:
        try:
            status, payload = conn.recv()
        except (EOFError, ConnectionResetError):
            raise WorkerError("an env worker process died (killed, or out of memory)") from None
        if status != "ok":
            msg, details = payload
            raise WorkerError(msg, details)
        return payload

    def _obs(self) -> dict[str, Any]:
        obs: dict[str, Any] = {k: (b.copy() if self.copy else b) for k, b in self._buffers.items()}
        for k, vals in self._texts.items():
            obs[k] = tuple(vals)
        return obs

    def _apply_texts(self, changed: dict[int, dict[str, str]]) -> None:
        for row, d in changed.items():
            for k, v in d.items():
                self._texts[k][row] = v

    def _infos(self, per_env: Sequence[dict | None]) -> dict:
        infos: dict = {}
        for i, info in enumerate(per_env):
            if info:
                infos = self._add_info(infos, info, i)
        return infos

    # -- Gymnasium API ------------------------------------------------------------------------------
    def reset(self, *, seed: int | Sequence[int | None] | None = None, options: dict | None = None):
        if seed is None or isinstance(seed, int):
            seeds = [None if seed is None else seed + i for i in range(self.num_envs)]
        else:
            seeds = list(seed)
        infos: list[dict | None] = []
        if self._local is not None:
            per, changed = self._local.reset(seeds, options)
            infos, changes = per, [changed]
        else:
            for conn, block in zip(self._conns, self._blocks):
                conn.send(("reset", ([seeds[i] for i in block], options)))
            changes = []
            for c in self._conns:
                per, changed = self._recv(c)
                infos += per
                changes.append(changed)
        for ch in changes:
            self._apply_texts(ch)
        return self._obs(), self._infos(infos)

    def step(self, actions):
        acts = list(np.asarray(actions).reshape(self.num_envs, *np.shape(actions)[1:]))
        if self._local is not None:
            results = [self._local.step(acts)]
        else:
            for conn, block in zip(self._conns, self._blocks):
                conn.send(("step", [acts[i] for i in block]))
            results = [self._recv(c) for c in self._conns]
        rewards = np.concatenate([r[0] for r in results])
        terms = np.concatenate([r[1] for r in results])
        truncs = np.concatenate([r[2] for r in results])
        infos = [i for r in results for i in r[3]]
        for r in results:
            self._apply_texts(r[4])
        return self._obs(), rewards, terms, truncs, self._infos(infos)

    def call(self, name: str, *args: Any) -> tuple:
        """`getattr(env, name)(*args)` on every env (the outermost wrapper); results in env order."""
        return self.call_each(name, [args] * self.num_envs)

    def call_each(self, name: str, args: Sequence[tuple]) -> tuple:
        if len(args) != self.num_envs:
            raise ValueError(f"call_each needs {self.num_envs} argument tuples, got {len(args)}")
        if self._local is not None:
            return tuple(self._local.call(name, args))
        for conn, block in zip(self._conns, self._blocks):
            conn.send(("call", (name, [args[i] for i in block])))
        return tuple(x for c in self._conns for x in self._recv(c))

    def set_state(self, states: Sequence[Any]):
        """Restore every env's `set_state(state)`; returns the observations and infos reached."""
        if len(states) != self.num_envs:
            raise ValueError(f"saved env state has {len(states)} envs, this vector env has {self.num_envs}")
        args = [(s,) for s in states]
        if self._local is not None:
            per, changed = self._local.call_obs("set_state", args)
            infos, changes = per, [changed]
        else:
            for conn, block in zip(self._conns, self._blocks):
                conn.send(("call_obs", ("set_state", [args[i] for i in block])))
            infos, changes = [], []
            for c in self._conns:
                per, changed = self._recv(c)
                infos += per
                changes.append(changed)
        for ch in changes:
            self._apply_texts(ch)
        return self._obs(), self._infos(infos)

    def get_state(self) -> list:
        return list(self.call("get_state"))

    @property
    def worker_pids(self) -> list[int]:
        return [p.pid for p in self._procs]

    def close_extras(self, **kwargs: Any) -> None:
        if self._local is not None:
            self._local.close()
            self._local = None
        for c in self._conns:
            try:
                c.send(("close", None))
                c.recv()
            except (BrokenPipeError, EOFError, OSError):
                pass
            c.close()
        for p in self._procs:
            p.join(timeout=10)
            if p.is_alive():
                p.terminate()
        self._conns, self._procs = [], []
        self._buffers = {}
        for seg in self._segments:
            seg.close()
            try:
                seg.unlink()
            except FileNotFoundError:
                pass
        self._segments = []
