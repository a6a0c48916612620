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

Arguments (seeds, options, actions) are checked before any command is sent, and every command sent
is answered before the call returns or raises: one bad call cannot leave a reply in a pipe for the next
call to read. A call interrupted between the two (Ctrl-C) or a dead worker leaves the env unusable,
and every later call says so; a closed env says it is closed.
"""

from __future__ import annotations

import multiprocessing as mp
import reprlib
import signal
import traceback
from collections.abc import Callable, Mapping, Sequence
from multiprocessing import shared_memory
from multiprocessing.reduction import ForkingPickler
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

EnvFn = Callable[[], gym.Env]
PRIVATE_INFO = ("privileged",)  # info keys that never cross a process boundary
COMMANDS = ("reset", "step", "call", "call_obs")  # the `_Host` methods a worker serves


class WorkerError(RuntimeError):
    """An env raised in a worker; the message is the env's one-line error, `details` the traceback."""

    def __init__(self, message: str, details: str = "") -> None:
        super().__init__(message)
        self.details = details


class VectorEnvClosedError(gym.error.ClosedEnvironmentError, ValueError):
    """A call on a closed vector env: Gymnasium's error for it, and a ValueError as Python's own for I/O on
    a closed file."""


def _shown(value: Any) -> str:
    """A value for a one-line message (long reprs, e.g. of arrays, shortened)."""
    return " ".join(reprlib.repr(value).split())


def _seed_int(s: Any) -> bool:
    return isinstance(s, int | np.integer) and not isinstance(s, bool | np.bool_) and s >= 0


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
        # envs whose encoder batches (world-vl) hand back pending embeddings, encoded together per step
        for env in self.envs:
            if env.has_wrapper_attr("defer_encoding"):
                env.set_wrapper_attr("defer_encoding", True)

    def _write_all(self, observations: list[dict], changed: dict[int, dict[str, str]]) -> None:
        from ovon.env.encode import resolve_pending

        resolve_pending(observations)
        for j, obs in enumerate(observations):
            self._write(j, obs, changed)

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
        infos, changed, observations = [], {}, []
        self.texts = [None] * len(self.envs)
        for env, seed in zip(self.envs, seeds):
            obs, info = env.reset(seed=seed, options=options)
            observations.append(obs)
            infos.append(_clean_info(info) or None)
        self._write_all(observations, changed)
        return infos, changed

    def step(self, actions: Sequence[Any]) -> tuple:
        n = len(self.envs)
        rewards = np.zeros(n, np.float64)
        terms = np.zeros(n, np.bool_)
        truncs = np.zeros(n, np.bool_)
        infos: list[dict | None] = [None] * n
        changed: dict[int, dict[str, str]] = {}
        observations = []
        for j, (env, a) in enumerate(zip(self.envs, actions)):
            obs, r, term, trunc, info = env.step(a)
            rewards[j], terms[j], truncs[j] = r, term, trunc
            if term or trunc:
                final = _clean_info(info)
                obs, info = env.reset()
                info = {**info, "final_info": final}
            info = _clean_info(info)
            infos[j] = info or None
            observations.append(obs)
        self._write_all(observations, changed)
        return rewards, terms, truncs, infos, changed

    def call(self, name: str, args: Sequence[tuple]) -> list:
        return [getattr(env, name)(*a) for env, a in zip(self.envs, args)]

    def run(self, cmd: str, args: tuple) -> Any:
        """`cmd` (one of COMMANDS) with `args`. When it raises, the text observations are forgotten so that
        the next reply sends them all: the parent discards the failed call's changes."""
        if cmd not in COMMANDS:
            raise ValueError(f"unknown vector env command {cmd!r}")
        try:
            return getattr(self, cmd)(*args)
        except BaseException:
            self.texts = [None] * len(self.envs)
            raise

    def call_obs(self, name: str, args: Sequence[tuple]) -> tuple[list, dict]:
        """Call a method returning (obs, info) on every env and publish the observations."""
        infos, changed, observations = [], {}, []
        self.texts = [None] * len(self.envs)
        for env, a in zip(self.envs, args):
            obs, info = getattr(env, name)(*a)
            observations.append(obs)
            infos.append(_clean_info(info) or None)
        self._write_all(observations, changed)
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
                if cmd == "attach":  # the parent's shared-memory observation buffers
                    for k, (name, shape, dtype) in arg.items():
                        seg = shared_memory.SharedMemory(name=name)  # the parent unlinks it
                        segments.append(seg)
                        host.buffers[k] = np.ndarray(shape, dtype=dtype, buffer=seg.buf)
                    result = None
                else:
                    result = host.run(cmd, arg)
            except Exception as e:  # report the env's error to the parent, keep serving
                conn.send(("error", (str(e).splitlines()[0] if str(e) else type(e).__name__, traceback.format_exc())))
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
        if not isinstance(env_fns, Sequence) or not env_fns or not all(callable(f) for f in env_fns):
            raise ValueError(
                f"env_fns = {_shown(env_fns)}: expected a non-empty list of functions that make an env; "
                "fix: e.g. [functools.partial(build_env, recipe)] * n"
            )
        if isinstance(workers, bool) or not isinstance(workers, int | np.integer) or workers < 0:
            raise ValueError(
                f"workers = {_shown(workers)}: expected an integer >= 0 (0 = every env in this "
                "process); fix: e.g. workers=0, or workers=2 for two worker processes"
            )
        if context not in mp.get_all_start_methods():
            raise ValueError(
                f"context = {_shown(context)}: expected one of {mp.get_all_start_methods()}; fix: leave it out (spawn)"
            )
        self.num_envs = len(env_fns)
        self.copy = copy
        workers = min(int(workers), self.num_envs)  # more workers than envs would idle
        self._segments: list[shared_memory.SharedMemory] = []
        self._conns: list[Any] = []
        self._procs: list[Any] = []
        self._blocks: list[range] = []
        self._local: _Host | None = None
        self._buffers: dict[str, np.ndarray] = {}
        self._broken: str | None = None  # why the workers' pipes can no longer be trusted
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
            self._texts = {
                k: [""] * self.num_envs for k, sp in single_obs.spaces.items() if isinstance(sp, spaces.Text)
            }
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
    def _recv(self, conn) -> Any:
        """One reply; a worker's error as WorkerError (its one-line message, the traceback in `details`)."""
        try:
            status, payload = conn.recv()
        except (EOFError, ConnectionResetError):
            self._broken = "an env worker process died (killed, or out of memory)"
            raise WorkerError(self._broken) from None
        if status != "ok":
            msg, details = payload
            raise WorkerError(msg, details)
        return payload

    def _check_usable(self) -> None:
        """Refuse a call on a closed env, or on one whose workers may still owe a reply."""
        if self.closed:
            raise VectorEnvClosedError("the vector env is closed; fix: make a new one (close() ended its envs)")
        if self._broken:
            raise WorkerError(f"the vector env is unusable: {self._broken}; fix: close() it and make a new one")

    def _run(self, cmd: str, block_args: Callable[[range], tuple], texts_at: int | None) -> list:
        """`cmd` on every block of envs, `block_args(block)` its arguments; the blocks' results in env order.

        Every message is pickled before the first is sent (an unpicklable argument sends nothing) and every
        reply is read before an env's error is raised, so the pipes stay in step; the text changes at index
        `texts_at` of the blocks that succeeded are applied either way."""
        self._check_usable()
        if self._local is not None:
            results = [self._local.run(cmd, block_args(range(self.num_envs)))]
        else:
            try:
                messages = [ForkingPickler.dumps((cmd, block_args(b))) for b in self._blocks]
            except Exception as e:  # noqa: BLE001 - any pickling error
                why = f"{type(e).__name__}: {str(e).splitlines()[0]}" if str(e) else type(e).__name__
                raise ValueError(
                    f"{cmd}: its arguments cannot be sent to the env worker processes ({why}); fix: "
                    "pass picklable values, or workers=0"
                ) from None
            results, error, done = [], None, False
            try:
                for conn, msg in zip(self._conns, messages):
                    try:
                        conn.send_bytes(msg)
                    except OSError:  # a broken pipe: the worker is gone
                        self._broken = "an env worker process died (killed, or out of memory)"
                        raise WorkerError(self._broken) from None
                for conn in self._conns:
                    try:
                        results.append(self._recv(conn))
                    except WorkerError as e:
                        results.append(None)
                        error = error or e
                done = True
            finally:
                if not done and not self._broken:
                    self._broken = f"a {cmd} call was interrupted before every worker answered"
            if error is not None:
                for r in results:
                    if r is not None and texts_at is not None:
                        self._apply_texts(r[texts_at])
                raise error
        if texts_at is not None:
            for r in results:
                self._apply_texts(r[texts_at])
        return results

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

    # -- argument checks (before anything is sent) ----------------------------------------------------
    def _seeds(self, seed: Any) -> list[int | None]:
        """Gymnasium's convention: None, an int (env i gets seed + i) or one int (or None) per env."""
        n = self.num_envs
        if isinstance(seed, np.ndarray) and seed.ndim == 0:
            seed = seed[()]
        if seed is None:
            return [None] * n
        if _seed_int(seed):
            return [int(seed) + i for i in range(n)]
        if (
            isinstance(seed, Sequence | np.ndarray)
            and not isinstance(seed, str | bytes)
            and np.ndim(seed) == 1
            and len(seed) == n
            and all(s is None or _seed_int(s) for s in seed)
        ):
            return [None if s is None else int(s) for s in seed]
        raise ValueError(
            f"seed = {_shown(seed)}: expected None, an integer >= 0 (env i gets seed + i) or a sequence "
            f"of {n} integers >= 0 or None (one per env); fix: e.g. seed=0 or seed=list(range({n}))"
        )

    def _actions(self, actions: Any) -> list:
        """One valid action per env (a Discrete space: ints of the space, floats and bools refused as by
        Gymnasium's `Discrete`); a wrong count or value would step the wrong envs or fail in a worker."""
        n, space = self.num_envs, self.single_action_space
        try:
            arr = np.asarray(actions)
        except Exception:  # noqa: BLE001 - e.g. a CUDA tensor
            arr = np.asarray(None)
        if isinstance(space, spaces.Discrete):
            lo, hi = int(space.start), int(space.start) + int(space.n) - 1
            if arr.shape == (n,) and arr.dtype.kind in "iu" and ((arr >= lo) & (arr <= hi)).all():
                return [int(a) for a in arr]
            expected = f"{n} integers in {lo}..{hi} (one per env; single_action_space {space})"
        else:
            if arr.dtype != object and len(arr.shape) and arr.shape[0] == n and self.action_space.contains(arr):
                return list(arr)
            expected = f"an array of {n} actions (one per env) in action_space {self.action_space}"
        got = f"shape {arr.shape}, dtype {arr.dtype}" if arr.dtype != object else type(actions).__name__
        raise ValueError(
            f"actions = {_shown(actions)} ({got}): expected {expected}; fix: pass e.g. "
            "vec.action_space.sample() or a policy's actions as a CPU integer array"
        )

    # -- Gymnasium API ------------------------------------------------------------------------------
    def reset(self, *, seed: int | Sequence[int | None] | None = None, options: dict | None = None):
        """Reset every env: `seed` None, an int (env i gets seed + i) or one per env; `options` (None or a
        dict) goes to every env."""
        self._check_usable()
        seeds = self._seeds(seed)
        if options is not None and not isinstance(options, Mapping):
            raise ValueError(
                f"options = {_shown(options)}: expected None or a dict (given to every env's reset); "
                "fix: e.g. options={'episode': EpisodeSpec(...)} or leave it out"
            )
        results = self._run("reset", lambda b: ([seeds[i] for i in b], options), texts_at=1)
        return self._obs(), self._infos([i for r in results for i in r[0]])

    def step(self, actions):
        self._check_usable()
        acts = self._actions(actions)
        results = self._run("step", lambda b: ([acts[i] for i in b],), texts_at=4)
        rewards = np.concatenate([r[0] for r in results])
        terms = np.concatenate([r[1] for r in results])
        truncs = np.concatenate([r[2] for r in results])
        infos = [i for r in results for i in r[3]]
        return self._obs(), rewards, terms, truncs, self._infos(infos)

    def call(self, name: str, *args: Any) -> tuple:
        """`getattr(env, name)(*args)` on every env (the outermost wrapper); results in env order."""
        return self.call_each(name, [args] * self.num_envs)

    def call_each(self, name: str, args: Sequence[tuple]) -> tuple:
        """`getattr(env, name)(*args[i])` on env i; results in env order."""
        self._check_usable()
        if (
            not isinstance(name, str)
            or not isinstance(args, Sequence)
            or len(args) != self.num_envs
            or not all(isinstance(a, tuple | list) for a in args)
        ):
            raise ValueError(
                f"call_each({_shown(name)}, {_shown(args)}): expected a method name and "
                f"{self.num_envs} argument tuples (one per env); fix: e.g. call_each('set_state', "
                f"[(s,) for s in states])"
            )
        args = [tuple(a) for a in args]
        return tuple(x for r in self._run("call", lambda b: (name, [args[i] for i in b]), None) for x in r)

    def set_state(self, states: Sequence[Any]):
        """Restore every env's `set_state(state)`; returns the observations and infos reached."""
        self._check_usable()
        if not isinstance(states, Sequence) or len(states) != self.num_envs:
            got = f"{len(states)} env states" if isinstance(states, Sequence) else _shown(states)
            raise ValueError(
                f"states = {got}: expected {self.num_envs} env states (one per env, as get_state() "
                f"returns them); fix: restore states saved from a vector env of {self.num_envs} envs"
            )
        args = [(s,) for s in states]
        results = self._run("call_obs", lambda b: ("set_state", [args[i] for i in b]), texts_at=1)
        return self._obs(), self._infos([i for r in results for i in r[0]])

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
