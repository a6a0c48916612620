"""Fan-out of independent jobs: in-process, worker processes (default) or Ray tasks (clusters).

Results come back as jobs finish (so callers can write them out incrementally); a `rich` progress bar
counts finished jobs.

Workers die with their parent: `init_worker()`, which every worker process of the project calls (this
pool's initializer, the training vector env's workers), arms the kernel's parent-death signal on Linux
and a watchdog thread everywhere, so a `kill -9` of the main process never leaves workers running. The
pool itself kills its workers when the parent stops iterating (an error, Ctrl-C, a closed generator).
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from typing import Any

PR_SET_PDEATHSIG = 1  # <linux/prctl.h>
WATCHDOG_PERIOD_S = 1.0
_ARMED = False


class WorkerDied(RuntimeError):
    """A worker process of the pool died before finishing its job (killed, out of memory)."""


def _set_pdeathsig() -> bool:
    """Linux: ask the kernel to SIGKILL this process when its parent dies."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def _watchdog(parent_pid: int, sentinel: int | None) -> None:
    """Portable fallback: exit as soon as the parent is gone (its sentinel closes, or we are re-parented)."""
    from multiprocessing.connection import wait

    while True:
        if sentinel is not None:
            try:
                if wait([sentinel], timeout=WATCHDOG_PERIOD_S):
                    os._exit(1)
            except (OSError, ValueError):
                sentinel = None
        else:
            threading.Event().wait(WATCHDOG_PERIOD_S)
        if os.name == "posix" and os.getppid() != parent_pid:
            os._exit(1)


def die_with_parent() -> bool:
    """Make this worker process exit when the process that started it dies (idempotent).

    Only in processes started by `multiprocessing` (spawn, fork or forkserver): the main process of a
    command must not die with the shell that launched it."""
    global _ARMED
    import multiprocessing

    parent = multiprocessing.parent_process()
    if parent is None or _ARMED:
        return _ARMED
    _ARMED = True
    _set_pdeathsig()
    parent_pid = parent.pid
    if os.name == "posix" and parent_pid is not None and os.getppid() != parent_pid:
        os._exit(1)  # the parent died before the signal was armed
    try:
        sentinel = parent.sentinel
    except (AttributeError, ValueError):
        sentinel = None
    threading.Thread(
        target=_watchdog, args=(parent_pid or -1, sentinel), name="ovon-parent-watchdog", daemon=True
    ).start()
    return True


def init_worker() -> None:
    """Per-worker set-up, called by every worker process (and harmless in the main process).

    One thread per worker: a 2-thread process slows 3-4x when another process holds a core. Dies with its
    parent (see `die_with_parent`)."""
    os.environ.setdefault("OMP_NUM_THREADS", "1")  # honoured by torch when a job imports it later
    os.environ.setdefault("LP_NUM_THREADS", "0")  # llvmpipe renders in-thread: one process per core scales
    torch = sys.modules.get("torch")  # importing torch only for this would cost seconds per worker
    if torch is not None:
        torch.set_num_threads(1)
    die_with_parent()


def _stop_pool(pool, futures) -> None:
    """Cancel what has not started and kill the workers now (instead of waiting for running jobs)."""
    for f in futures:
        f.cancel()
    procs = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for p in procs:
        try:
            p.kill()
        except (OSError, AttributeError, ValueError):
            pass
    for p in procs:
        try:
            p.join(timeout=5)
        except (OSError, AttributeError, ValueError, AssertionError):
            pass


def run_jobs(fn: Callable[[Any], Any], jobs: list, workers: int = 1, executor: str = "process") -> Iterator[Any]:
    """Yield `fn(job)` results in completion order. `fn` must be a module-level function."""
    if not jobs:
        return
    if executor == "ray":
        import ray

        if not ray.is_initialized():
            ray.init(address=os.environ.get("RAY_ADDRESS") or None, include_dashboard=False, log_to_driver=False)
        remote = ray.remote(num_cpus=1)(fn)
        pending = [remote.remote(j) for j in jobs]
        try:
            while pending:
                ready, pending = ray.wait(pending, num_returns=1)
                yield ray.get(ready[0])
        finally:
            for ref in pending:
                ray.cancel(ref, force=True)
        return
    if executor != "process":
        raise ValueError(f"unknown executor {executor!r}: use process or ray")
    if workers <= 1 or len(jobs) == 1:
        for j in jobs:
            yield fn(j)
        return
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from concurrent.futures.process import BrokenProcessPool

    pool = ProcessPoolExecutor(min(workers, len(jobs)), mp_context=mp.get_context("spawn"), initializer=init_worker)
    futures = []
    finished = False
    try:
        futures = [pool.submit(fn, j) for j in jobs]
        for f in as_completed(futures):
            try:
                result = f.result()
            except BrokenProcessPool:
                raise WorkerDied(
                    "a worker process died (killed, or out of memory) before finishing its job; "
                    "fix: re-run the same command to resume, with fewer --workers if memory is short"
                ) from None
            yield result
        finished = True
    finally:
        if finished:
            pool.shutdown(wait=True)
        else:
            _stop_pool(pool, futures)


def progress_bar(description: str, total: int, enabled: bool = True):
    """A rich progress context whose `.advance(n)` is a no-op when disabled."""
    from contextlib import nullcontext

    if not enabled:

        class _Null:
            def advance(self, n: int = 1) -> None:
                pass

        return nullcontext(_Null())
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn, TimeRemainingColumn

    class _Bar:
        def __init__(self) -> None:
            self.p = Progress(
                "[bold]{task.description}",
                BarColumn(),
                MofNCompleteColumn(),
                TimeElapsedColumn(),
                TimeRemainingColumn(),
            )
            self.t = self.p.add_task(description, total=total)

        def __enter__(self):
            self.p.__enter__()
            return self

        def __exit__(self, *exc):
            return self.p.__exit__(*exc)

        def advance(self, n: int = 1) -> None:
            self.p.advance(self.t, n)

    return _Bar()
